"""How much of the reference planner's gain lives in its memory, and whether a student can learn it:
``python benchmarks/planner_memory.py [--env ID] [--plans S,MEMORY,I ...] [--dataset RUN/dataset.npz]``.

The ceiling planner (``agents/evaluation/ceiling.py``) warm-starts every step's search from the
plan it kept from the step before. A DAgger student that acts on the observation alone can learn
only the part of the planner's correction that the state determines. This script measures both
sides of that:

1. **The planner with and without memory.** It runs the id's ceiling planner on the tuning seeds
   (3000 up, never the held-out ones) with each ``--plans`` variant ``samples,memory,iterations``
   and prints the mean return, the per-seed returns and the planning time per env and control
   step, beside the prior law alone. ``memory`` is ``plan`` (the whole plan carried between
   steps and shifted, the planner's default), ``none`` (every step searches from the zero plan,
   the prior alone: ``warm_start: false``) or ``action`` (the next search starts from the last
   planned correction held over the control horizon: a memory of one action, as a student fed
   its previous output would have).
2. **Random persistent corrections** (``--random``): the prior law plus an Ornstein-Uhlenbeck
   correction of the given standard deviations (normalised thrust) and lag-1 autocorrelation
   0.95, the statistics of the planner's corrections. If these helped, the planner's gain would
   need no search.
3. **How predictable the plan's evolution is** (``--dataset``, the ``dataset.npz`` of a DAgger
   run): on the held-out episodes of the run (its early-stopping episodes, never fitted), the R²
   of ridge-regression predictions of the correction ``y[t]`` from the normalised observation,
   from ``y[t-1]``, and of its increment ``y[t] - y[t-1]`` from both; and the R² of a free run of
   the linear model of ``y[t]`` on (observation, ``y[t-1]``) fed its own predictions, as a
   student with memory would act.

Prints the CPU model. Each planner variant takes about 1-7 minutes on the hard id (its cost is
about proportional to samples x iterations).
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

import numpy as np

TUNING_SEEDS = [3000, 3001, 3002, 3003]
RIDGE = 1.0
MEMORIES = ("plan", "none", "action")
#: Lag-1 autocorrelation of the random corrections: the planner's own, on the hard id.
RANDOM_AUTOCORRELATION = 0.95


def parse_plan(text: str) -> tuple[int, str, int]:
    """``samples,memory,iterations`` -> (samples, memory, iterations)."""
    parts = text.split(",")
    if len(parts) != 3 or parts[1] not in MEMORIES or not (parts[0].isdigit() and parts[2].isdigit()):
        raise argparse.ArgumentTypeError(
            f"a plan is samples,memory,iterations with memory one of {', '.join(MEMORIES)}, such as 16,plan,1; "
            f"got {text!r}"
        )
    return int(parts[0]), parts[1], int(parts[2])


def held_action_planner(env: Any, settings: Any) -> Any:
    """The planner whose next search starts from its last planned correction held over the
    control horizon, instead of from its whole shifted plan (``memory`` ``action``)."""
    from tether_gym_agents.controllers.mpc import MPCController

    class HeldActionPlanner(MPCController):
        def _update(self, candidates: np.ndarray, costs: np.ndarray) -> np.ndarray:
            plan = super()._update(candidates, costs)
            self.first_correction = plan[:, 0].copy()
            return plan

        def predict(self, observation: np.ndarray, *args: Any, **kwargs: Any) -> tuple[np.ndarray, Any]:
            action, state = super().predict(observation, *args, **kwargs)
            self.plan[:] = 0.0
            self.plan[:, : self.planned_steps] = self.first_correction[:, None]
            return action, state

    return HeldActionPlanner(env, settings)


def planner_rows(env_id: str, plans: list[tuple[int, str, int]], randoms: list[float], seeds: list[int]) -> None:
    """Print the prior law's, each planner variant's and each random correction's returns on ``seeds``."""
    import gymnasium as gym
    from tether_gym_agents.controllers.mpc import MPCController
    from tether_gym_agents.controllers.registry import make_baseline
    from tether_gym_agents.evaluation.ceiling import load_ceiling_settings
    from tether_gym_agents.evaluation.rollout import rollout

    base = load_ceiling_settings(env_id)
    probe = gym.make_vec(env_id, num_envs=len(seeds))

    def row(name: str, returns: np.ndarray, seconds: str = "") -> None:
        per_seed = ", ".join(f"{value:.2f}" for value in returns)
        print(f"| {name} | {returns.mean():.2f} | {per_seed} | {seconds} |", flush=True)

    print("| controller | mean return | per seed | planning per env and control step |")
    print("|---|---|---|---|")
    row(f"{base.prior} (the prior)", rollout(make_baseline(base.prior, probe), env_id, seeds).rewards.sum(axis=1))
    for sigma in randoms:
        row(
            f"{base.prior} + random correction, std {sigma}",
            random_correction_returns(env_id, base.prior, sigma, seeds),
        )
    for samples, memory, iterations in plans:
        settings = load_ceiling_settings(env_id, samples=samples, warm_start=memory != "none", iterations=iterations)
        planner = held_action_planner(probe, settings) if memory == "action" else MPCController(probe, settings)
        returns = np.nansum(rollout(planner, env_id, seeds).rewards, axis=1)
        row(
            f"planner, {samples} samples x {iterations} iteration(s), memory: {memory}",
            returns,
            f"{planner.seconds_per_step:.3f} s",
        )
    probe.close()


def random_correction_returns(env_id: str, law_name: str, sigma: float, seeds: list[int]) -> np.ndarray:
    """(len(seeds),) returns of ``law_name`` plus an Ornstein-Uhlenbeck correction of standard
    deviation ``sigma`` (normalised thrust) and lag-1 autocorrelation 0.95 (generator seed 0)."""
    import gymnasium as gym
    from tether_gym_agents.controllers.registry import make_baseline
    from tether_gym_agents.evaluation.rollout import rollout

    probe = gym.make_vec(env_id, num_envs=len(seeds))
    law = make_baseline(law_name, probe)
    probe.close()
    rng = np.random.default_rng(0)
    rho = RANDOM_AUTOCORRELATION
    correction = np.zeros((len(seeds), law.action_size))

    class RandomlyCorrectedLaw:
        def predict(self, observation: np.ndarray, *args: Any, **kwargs: Any) -> tuple[np.ndarray, None]:
            nonlocal correction
            action, _ = law.predict(observation)
            correction = rho * correction + np.sqrt(1.0 - rho**2) * sigma * rng.standard_normal(correction.shape)
            return np.clip(action + correction, -1, 1).astype(np.float32), None

    return rollout(RandomlyCorrectedLaw(), env_id, seeds).rewards.sum(axis=1)


def _design(features: np.ndarray) -> np.ndarray:
    """The features with a column of ones: the linear models' intercept."""
    return np.c_[features, np.ones(len(features))]


def _ridge(features: np.ndarray, targets: np.ndarray) -> np.ndarray:
    design = _design(features)
    return np.linalg.solve(design.T @ design + RIDGE * np.eye(design.shape[1]), design.T @ targets)


def _apply(features: np.ndarray, weights: np.ndarray) -> np.ndarray:
    return _design(features) @ weights


def _r2(targets: np.ndarray, predictions: np.ndarray) -> float:
    return float(1.0 - ((targets - predictions) ** 2).sum() / ((targets - targets.mean(axis=0)) ** 2).sum())


def predictability_rows(path: Path) -> None:
    """Print the held-out R² of the correction's predictions from a DAgger run's dataset."""
    data = np.load(path)
    observations, targets = data["observations"].astype(float), data["targets"].astype(float)
    episodes, held_out = data["episode"], data["held_out"]
    if not held_out.any():
        raise SystemExit(f"{path} holds no held-out episodes (a run with validation_every 0): nothing to test on")
    fitted = ~held_out
    scale = observations[fitted].std(axis=0)
    normalised = (observations - observations[fitted].mean(axis=0)) / np.where(scale > 0, scale, 1.0)
    previous = np.zeros_like(targets)
    for episode in np.unique(episodes):
        rows = np.flatnonzero(episodes == episode)  # in step order: the run stores its states step by step
        previous[rows[1:]] = targets[rows[:-1]]
    increment = targets - previous
    both = np.c_[normalised, previous]
    print(f"{int(held_out.sum())} held-out states of {len(targets)} ({path}); ridge {RIDGE}")
    print("| prediction | held-out R² |")
    print("|---|---|")
    for name, features, target in [
        ("y[t] from the observation", normalised, targets),
        ("y[t] from y[t-1]", previous, targets),
        ("y[t] from the observation and y[t-1]", both, targets),
        ("y[t] - y[t-1] from the observation and y[t-1]", both, increment),
    ]:
        weights = _ridge(features[fitted], target[fitted])
        print(f"| {name} | {_r2(target[held_out], _apply(features[held_out], weights)):.3f} |")
    weights = _ridge(both[fitted], targets[fitted])
    free, labels = [], []
    for episode in np.unique(episodes[held_out]):
        carried = np.zeros(targets.shape[1])
        for row in np.flatnonzero(episodes == episode):
            carried = np.clip(_apply(np.r_[normalised[row], carried][None], weights)[0], -1.0, 1.0)
            free.append(carried)
            labels.append(targets[row])
    free_r2 = _r2(np.asarray(labels), np.asarray(free))
    print(f"| free run of y[t] from the observation and its own y[t-1] | {free_r2:.3f} |")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--env", default="TetherCoarseBeadedTetrahedron-v0", help="an id with ceiling settings")
    parser.add_argument(
        "--plans",
        nargs="*",
        type=parse_plan,
        default=[(16, "plan", 1), (16, "none", 1), (16, "action", 1), (32, "none", 4), (128, "none", 1)],
        help="planner variants samples,memory,iterations (default: 16,plan,1 16,none,1 16,action,1 32,none,4 "
        "128,none,1; --plans alone skips them)",
    )
    parser.add_argument(
        "--random",
        nargs="*",
        type=float,
        default=[0.1, 0.19],
        help="std of random corrections (default 0.1 0.19; --random alone skips them)",
    )
    parser.add_argument("--seeds", type=int, default=len(TUNING_SEEDS), help="tuning seeds, 3000 up (default 4)")
    parser.add_argument("--dataset", type=Path, help="a DAgger run's dataset.npz: test how predictable its labels are")
    args = parser.parse_args()
    from tether_gym.bench import cpu_model

    print(f"CPU: {cpu_model()}")
    if args.dataset is not None:
        predictability_rows(args.dataset)
        print()
    if args.plans or args.random:
        seeds = list(range(TUNING_SEEDS[0], TUNING_SEEDS[0] + args.seeds))
        planner_rows(args.env, args.plans, args.random, seeds)


if __name__ == "__main__":
    main()
