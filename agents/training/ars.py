"""Augmented Random Search of a linear residual policy on paired seeds: the trainer behind
``python -m agents.ars`` (:func:`train_ars`), its settings (:class:`ARSSettings`, per id in the
package's ``hyperparams/ars.yml``), the update rule (:func:`ars_update`) and the policy it trains
(:class:`LinearResidualPolicy`).

ARS (Mania, Guy and Recht, 2018, arXiv:1803.07055) improves a deterministic policy's parameters
``theta`` directly. At every iteration it draws ``directions`` Gaussian perturbations ``delta``,
runs the policies ``theta + nu delta`` and ``theta - nu delta`` for each, and steps along the
directions whose pair differs most in return:

    theta <- theta + step_size / (top * sigma_R) * sum over the ``top`` best directions of
             (R(theta + nu delta) - R(theta - nu delta)) delta

where ``sigma_R`` is the standard deviation of the 2 ``top`` returns used (version V1-t of the
paper, with observations normalised by statistics fixed before training).

The policy here is a linear correction on top of a scripted baseline (``residual_on``), on the
normalised observation ``z``: ``action = clip(baseline(obs) + clip(W z + b, -1, 1), -1, 1)``. It
starts at ``W = 0, b = 0``, the baseline itself.

**Why ARS, and why paired seeds.** On the ids where a scripted law is best, the known room above
it is small: the model-predictive reference, with the true state and model, gains 0.5-7 % over
the local tension-aware law. PPO and TD3 residuals on that law lose return as soon as their actor
moves (``docs/benchmark.md``): their gradient is that of a *noisy* policy, or of a critic, and
near a strong law both point the wrong way often enough. ARS measures the *deterministic*
policy's return, and every candidate of an iteration (``2 directions``) runs on the *same*
``seeds_per_direction`` episodes, all of them at once in one batched vector env. The difference
``R(theta + nu delta) - R(theta - nu delta)`` is then a paired difference, free of the spread
between episodes' initial conditions (returns from -1 to -130 on the default id), which would
otherwise drown a 1 % gain.

The run directory, evaluation and selection are those of the SB3 trainer (:mod:`.runs`,
:mod:`.selection`); the policy is stored in the safe format as the linear actor of SB3's
``ActorCriticPolicy`` (:func:`save_linear_policy`).
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from tether_gym._optional import needs_extra, require

from ..common.checks import MAX_NUM_ENVS, check_int
from ..common.commands import command_line
from ..common.data import HYPERPARAMS_DIR
from ..common.files import atomic_write_text, holds_output_claims
from ..common.settings import load_settings
from ..controllers.registry import BASELINES, make_baseline
from ..controllers.residual import residual_actions
from ..policies.layout import PolicyFormatError
from ..policies.normalization import NormalizationStatistics
from .runs import clear_earlier_run, prepare_run_dir, save_residual_policy
from .selection import EvaluationLog, baseline_returns, episode_returns, evaluation_seeds

with needs_extra("train", "the ARS settings files"):
    import yaml

__all__ = [
    "ARS_SETTINGS_FILE",
    "NORMALIZATION_SEEDS_START",
    "SEEDS_PER_RUN",
    "TRAINING_SEEDS_START",
    "ARSSettings",
    "LinearResidualPolicy",
    "ars_update",
    "load_ars_settings",
    "observation_statistics",
    "save_linear_policy",
    "train_ars",
]

#: Per-id ARS settings (plain YAML, nothing evaluated).
ARS_SETTINGS_FILE = HYPERPARAMS_DIR / "ars.yml"
#: First seed of the episodes the observation statistics come from, and of the training episodes
#: (each run and iteration takes its own block): far from the evaluation seeds (1 000 000 up), the
#: benchmark's held-out seeds (10 000 up) and the mpc tuning seeds (2 000 up).
NORMALIZATION_SEEDS_START = 50_000_000
TRAINING_SEEDS_START = 100_000_000
#: Seeds set aside per run (seed s trains on TRAINING_SEEDS_START + s * SEEDS_PER_RUN + ...).
SEEDS_PER_RUN = 1_000_000


@dataclasses.dataclass(frozen=True)
class ARSSettings:
    """Settings of :func:`train_ars` (see the module docstring); a run's ``config.yml`` records
    them as its ``hyperparams``."""

    residual_on: str = "local_tension_aware"
    """The scripted baseline the policy corrects (a name of :data:`agents.controllers.registry.BASELINES`)."""
    iterations: int = 100
    """ARS updates."""
    directions: int = 16
    """Perturbation directions per iteration (each run with + and -)."""
    top: int = 8
    """Directions kept for the update (the largest ``max(R+, R-)``), <= ``directions``."""
    seeds_per_direction: int = 16
    """Episodes per candidate, the same seeds for every candidate of an iteration (so an
    iteration runs ``2 directions seeds_per_direction`` episodes at once)."""
    exploration: float = 0.005
    """``nu``, the standard deviation of the perturbation of each weight. A weight maps one
    normalised observation component (about unit spread) to normalised thrust."""
    step_size: float = 0.001
    """``alpha``, the update's step in units of ``sigma_R``-scaled directions."""
    eval_every: int = 10
    """Iterations between evaluations on the evaluation seeds."""
    eval_episodes: int = 64
    """Evaluation episodes (seeds 1 000 000 up, as the SB3 trainer's)."""
    normalization_episodes: int = 64
    """Baseline episodes whose states give the observation statistics."""

    def __post_init__(self) -> None:
        if self.residual_on not in BASELINES:
            raise ValueError(f"ars setting residual_on must be one of {sorted(BASELINES)}; got {self.residual_on!r}")
        names = ("iterations", "directions", "top", "seeds_per_direction", "eval_every")
        for name in (*names, "eval_episodes", "normalization_episodes"):
            least = 1 if name in names else 2  # 2: a spread, an interval
            # Stored as a plain int (a numpy integer passes the check), so that config.yml can hold it.
            # The evaluation and normalisation episodes run as one vector env: at most MAX_NUM_ENVS.
            most = None if name in names else MAX_NUM_ENVS
            object.__setattr__(self, name, check_int(f"ars setting {name}", getattr(self, name), least, most))
        if self.top > self.directions:
            raise ValueError(f"ars setting top ({self.top}) must be <= directions ({self.directions})")
        for name in ("exploration", "step_size"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int | float) or not (np.isfinite(value) and value > 0):
                raise ValueError(f"ars setting {name} must be a positive number; got {value!r}")


def load_ars_settings(env_id: str | None, path: str | Path | None = None, **overrides: Any) -> ARSSettings:
    """The ARS settings of ``env_id``: its entry of the package's ``hyperparams/ars.yml`` (or of ``path``,
    which may also be a run's ``config.yml``), else the file's ``default`` entry, with keyword
    ``overrides`` on top."""
    file = Path(path) if path is not None else ARS_SETTINGS_FILE
    return load_settings(ARSSettings, file, env_id, "ARS", overrides, run_algo="ars")


def ars_update(
    theta: np.ndarray, deltas: np.ndarray, plus: np.ndarray, minus: np.ndarray, top: int, step_size: float
) -> np.ndarray:
    """One ARS step (V1-t): ``theta`` (any shape P) moved along the ``top`` directions of
    ``deltas`` (D, *P) with the largest ``max(plus, minus)``, weighted by ``plus - minus`` (D,
    returns of ``theta +- nu delta``) and scaled by ``step_size / (top * sigma)``, ``sigma`` the
    standard deviation of the 2 ``top`` returns used (the step is 0 when they are all equal)."""
    plus, minus = np.asarray(plus, dtype=float), np.asarray(minus, dtype=float)
    if plus.shape != (deltas.shape[0],) or minus.shape != plus.shape:
        raise ValueError(f"plus and minus must have shape ({deltas.shape[0]},); got {plus.shape} and {minus.shape}")
    if not 1 <= top <= deltas.shape[0]:
        raise ValueError(f"top must be in 1..{deltas.shape[0]}; got {top}")
    kept = np.argsort(-np.maximum(plus, minus), kind="stable")[:top]
    sigma = float(np.concatenate([plus[kept], minus[kept]]).std())
    if sigma == 0.0:
        return theta.copy()
    step = np.tensordot(plus[kept] - minus[kept], deltas[kept], axes=1)
    return theta + step_size / (top * sigma) * step


class LinearResidualPolicy:
    """``clip(baseline(obs) + clip(W z + b, -1, 1), -1, 1)`` with ``z`` the normalised observation,
    one ``(W, b)`` per row of the batch or one for all (a controller for
    :func:`agents.evaluation.rollout.rollout`).

    Args:
        residual_on: the baseline's name; it is built for the env of :meth:`attach`.
        statistics: the observation statistics (``z = statistics.normalize_obs(obs)``).
        weights: (A, O + 1) or (R, A, O + 1): ``W`` and, in the last column, ``b``.
    """

    name = "ars"

    def __init__(self, residual_on: str, statistics: NormalizationStatistics, weights: np.ndarray) -> None:
        self.residual_on, self.statistics = residual_on, statistics
        self.weights = np.asarray(weights, dtype=float)
        self.baseline: Any = None

    def attach(self, env: Any) -> None:
        """Build the baseline for ``env`` (the env the rollout steps)."""
        self.baseline = make_baseline(self.residual_on, env)

    def predict(
        self, observation: np.ndarray, state: Any = None, episode_start: Any = None, deterministic: bool = True
    ) -> tuple[np.ndarray, None]:
        """Actions (N, A) for observations (N, O)."""
        if self.baseline is None:
            raise RuntimeError("attach(env) the policy before predicting: its baseline needs the env's cluster")
        z = self.statistics.normalize_obs(observation).astype(float)
        gains, bias = self.weights[..., :-1], self.weights[..., -1]
        correction = np.einsum("...ao,...o->...a", gains, z) + bias
        return residual_actions(self.baseline, observation, np.clip(correction, -1.0, 1.0)), None


def observation_statistics(env_id: str, residual_on: str, seeds: list[int]) -> NormalizationStatistics:
    """Mean and variance of the observations the baseline's closed loop visits on ``seeds``, as
    fixed normalisation statistics (no reward scaling)."""
    import gymnasium as gym
    from gymnasium.vector import AutoresetMode

    envs = gym.make_vec(env_id, num_envs=len(seeds), autoreset_mode=AutoresetMode.SAME_STEP)
    baseline = make_baseline(residual_on, envs)
    observation, _ = envs.reset(seed=seeds)
    alive = np.ones(len(seeds), dtype=bool)
    visited = []
    while alive.any():
        visited.append(observation[alive])
        action, _ = baseline.predict(observation)
        observation, _, terminated, truncated, _ = envs.step(action)
        alive &= ~(terminated | truncated)
    envs.close()
    return NormalizationStatistics.fixed(np.concatenate(visited))


def save_linear_policy(
    directory: Path,
    env_id: str,
    residual_on: str,
    statistics: NormalizationStatistics,
    theta: np.ndarray,
    timesteps: int,
    provenance: dict[str, Any],
    extra_files: tuple[str, ...] = (),
    whole_directory: bool = False,
) -> Path:
    """Write ``theta`` (A, O + 1) in the safe format, as the linear actor of an SB3
    ``ActorCriticPolicy`` (``net_arch: {pi: [], vf: []}``) with ``algo: ars``. With
    ``whole_directory`` (``best/``), the save replaces ``directory`` as a whole
    (:func:`agents.common.files.atomic_directory`), so an interrupt never leaves it half-written."""
    import torch
    from stable_baselines3 import PPO

    from tether_gym.sb3 import make_sb3_vec_env

    venv = make_sb3_vec_env(env_id, 1, seed=0)
    with torch.random.fork_rng(devices=[]):
        model = PPO(
            "MlpPolicy", venv, policy_kwargs={"net_arch": {"pi": [], "vf": []}}, device="cpu", n_steps=64, batch_size=64
        )
    action_net = model.policy.action_net
    if tuple(action_net.weight.shape) != theta[:, :-1].shape:
        shape = tuple(action_net.weight.shape)
        raise PolicyFormatError(f"ARS weights {theta.shape} do not fit {env_id}'s action net {shape}")
    with torch.no_grad():
        action_net.weight.copy_(torch.as_tensor(theta[:, :-1], dtype=torch.float32))
        action_net.bias.copy_(torch.as_tensor(theta[:, -1], dtype=torch.float32))
        # ARS has no critic: the host policy's value head is unused, and zero rather than
        # randomly initialised so that the same run writes the same bytes.
        for parameter in model.policy.value_net.parameters():
            parameter.zero_()
    model.num_timesteps = int(timesteps)
    venv.close()
    return save_residual_policy(
        directory, model, statistics, env_id, provenance, residual_on, "ars", extra_files, whole_directory
    )


@holds_output_claims
def train_ars(
    env_id: str,
    seed: int = 1,
    out: str | Path = "runs",
    settings: ARSSettings | None = None,
    force: bool = False,
    progress: bool = True,
    command: str | None = None,
) -> Path:
    """Train a linear residual policy with ARS (see the module docstring); returns the run directory.

    Args:
        env_id: a registered tether-gym id.
        seed: the run's seed: it draws the perturbations and picks the block of training seeds.
        out: parent of the run directory ``<out>/<env_id>/ars_seed<seed>``.
        settings: default: ``load_ars_settings(env_id)``.
        force: replace an earlier run in the same directory.
        progress: show a progress bar.
        command: the command line recorded in ``config.yml``.
    """
    from stable_baselines3.common.logger import configure

    import tether_gym
    from tether_gym.registration import ENV_IDS

    from ..evaluation.rollout import rollout

    if env_id not in ENV_IDS:
        raise ValueError(f"unknown env id {env_id!r}; choose one of {', '.join(ENV_IDS)}")
    seed = check_int("seed", seed, 0, 999)
    s = settings if settings is not None else load_ars_settings(env_id)
    if s.iterations * s.seeds_per_direction > SEEDS_PER_RUN:
        raise ValueError(f"iterations x seeds_per_direction must be <= {SEEDS_PER_RUN:,} (the run's block of seeds)")
    require("tensorboard", "train", "the training's TensorBoard logs")  # SB3's logger would only assert
    if progress:
        require("tqdm", "train", "the progress bar (or pass --no-progress)")
    run = prepare_run_dir(out, env_id, "ars", seed, force)
    if force:
        clear_earlier_run(run, "ars", set())
    record = {
        "algo": "ars",
        "env_id": env_id,
        "seed": seed,
        "hyperparams": dataclasses.asdict(s),
        "command": command or command_line("ars", ["--env", env_id, "--seed", str(seed)]),
        "tether_gym_version": tether_gym.__version__,
    }
    atomic_write_text(run / "config.yml", yaml.safe_dump(record, sort_keys=False))
    provenance = {"seed": seed, "command": record["command"], "config": "config.yml of the run directory"}
    logger = configure(str(run / "tensorboard"), ["tensorboard", "csv"])
    started = time.perf_counter()

    normalization_seeds = range(NORMALIZATION_SEEDS_START, NORMALIZATION_SEEDS_START + s.normalization_episodes)
    statistics = observation_statistics(env_id, s.residual_on, list(normalization_seeds))
    seeds = evaluation_seeds(s.eval_episodes)
    by_name, bar = baseline_returns(env_id, seeds)
    # A first "best" must beat the baseline the policy starts as.
    log = EvaluationLog(env_id, seeds, by_name, bar, started, best_mean=float(by_name[s.residual_on].mean()))
    rng = np.random.default_rng(seed)
    action_size, observation_size = _sizes(env_id)
    theta = np.zeros((action_size, observation_size + 1))
    block = TRAINING_SEEDS_START + seed * SEEDS_PER_RUN
    timesteps = 0
    best_iteration = 0
    bar_update = _progress_bar(s.iterations, f"ars {env_id} seed {seed}", progress)
    for iteration in range(1, s.iterations + 1):
        deltas = rng.standard_normal((s.directions, *theta.shape))
        candidates = np.concatenate([theta + s.exploration * deltas, theta - s.exploration * deltas])
        episode_seeds = block + (iteration - 1) * s.seeds_per_direction + np.arange(s.seeds_per_direction)
        policy = LinearResidualPolicy(s.residual_on, statistics, np.repeat(candidates, s.seeds_per_direction, axis=0))
        record = rollout(policy, env_id, np.tile(episode_seeds, 2 * s.directions).tolist())
        timesteps += int(record.end_step.sum())
        returns = record.rewards.sum(axis=1).reshape(2 * s.directions, s.seeds_per_direction).mean(axis=1)
        plus, minus = returns[: s.directions], returns[s.directions :]
        theta = ars_update(theta, deltas, plus, minus, s.top, s.step_size)
        logger.record("train/candidate_return_mean", float(returns.mean()))
        logger.record("train/weight_max", float(np.abs(theta).max()))
        logger.record("time/iterations", iteration)
        if iteration % s.eval_every == 0 or iteration == s.iterations:
            returns_eval = episode_returns(LinearResidualPolicy(s.residual_on, statistics, theta), env_id, seeds)
            entry, paired, new_best = log.add(returns_eval, timesteps, iteration=iteration)
            for key in ("mean_return", "difference_vs_bar"):
                logger.record(f"eval/{key}", entry[key])
            if new_best:
                best_iteration = iteration
                save_linear_policy(
                    run / "best", env_id, s.residual_on, statistics, theta, timesteps, provenance, whole_directory=True
                )
            bar_update(f"eval {entry['mean_return']:.2f}, {paired.mean:+.2f} vs {bar}")
        logger.dump(timesteps)
        bar_update(None)
    log.finish(timesteps, best_iteration=best_iteration)
    if best_iteration == 0:  # never above the baseline: best/ is the starting point, the baseline itself
        save_linear_policy(
            run / "best", env_id, s.residual_on, statistics, np.zeros_like(theta), 0, provenance, whole_directory=True
        )
    log.write(run / "best")
    final = (run, env_id, s.residual_on, statistics, theta, timesteps, provenance)
    save_linear_policy(*final, extra_files=("config.yml",))
    logger.close()
    last = log.history[-1]
    print(
        f"trained ars on {env_id} for {s.iterations} iterations ({timesteps:,} env steps) in "
        f"{log.finished['wall_time_s'] / 60:.1f} min; best evaluation {log.best_mean:.2f} at iteration "
        f"{best_iteration} against {bar} {by_name[bar].mean():.2f} (last: {last['difference_vs_bar']:+.2f} "
        f"[{last['difference_low']:+.2f}, {last['difference_high']:+.2f}]); run directory {run}"
    )
    return run


def _sizes(env_id: str) -> tuple[int, int]:
    import gymnasium as gym

    env = gym.make(env_id)
    sizes = int(env.action_space.shape[0]), int(env.observation_space.shape[0])
    env.close()
    return sizes


def _progress_bar(total: int, label: str, enabled: bool) -> Callable[[str | None], None]:
    """An update function: ``update(None)`` advances one iteration, ``update(text)`` sets the postfix."""
    if not enabled:
        return lambda text: None
    tqdm = require("tqdm", "train", "the progress bar (or pass --no-progress)").tqdm

    bar = tqdm(total=total, desc=label, unit="it")

    def update(text: str | None) -> None:
        if text is None:
            bar.update(1)
            if bar.n >= total:
                bar.close()
        else:
            bar.set_postfix_str(text)

    return update
