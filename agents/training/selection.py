"""Model selection during training, on fixed evaluation seeds, paired against the scripted baselines.

SB3's ``EvalCallback`` evaluates on whatever episodes its env's seed stream reaches next, so two
evaluations of the same policy see different initial conditions. On tether-gym the spread of
returns between initial conditions is far larger than what separates good controllers: on the
default id the mean of 32 fresh episodes swings by about +-10 between evaluations while the best
scripted baseline (LQR) and the predictive reference differ by 2. A "best model" chosen that way is
mostly the luckiest draw of seeds.

:class:`SeededEvaluation` evaluates every time on the *same* seeds (``EVAL_SEEDS_START`` up,
never the comparison's held-out seeds 10 000-10 063), so that successive evaluations and the
baselines are compared episode by episode:

* at the start of training it rolls out every scripted baseline on those seeds once and takes the
  best eligible one (:func:`agents.evaluation.stats.best_eligible_baseline`) as the bar;
* at every evaluation it reports the policy's mean return and its paired difference from the bar
  with a 95 % t interval, to the console, to TensorBoard (``eval/*``) and to
  ``best/evaluations.json``;
* it saves the policy to ``best/`` when the mean return is the best so far (selection happens on
  these seeds, never on the held-out ones the benchmark reports);
* it records the wall time, counted from the start of the training command, and the step count of
  the first evaluation whose mean return beats each baseline's: the "time to beat the best
  baseline" is the bar's entry.

The bookkeeping is :class:`EvaluationLog`, which trainers outside SB3's callbacks (``agents.ars``)
keep theirs in too.
"""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any

import numpy as np

from tether_gym._optional import needs_extra

from ..common.files import atomic_write_text
from ..policies.spec import PolicySpec

with needs_extra("train", "evaluating policies during training"):
    from stable_baselines3.common.callbacks import BaseCallback

__all__ = [
    "EVALUATIONS_FILE",
    "EVAL_SEEDS_START",
    "EvaluationLog",
    "SeededEvaluation",
    "baseline_returns",
    "episode_returns",
    "evaluation_seeds",
    "print_evaluation_summary",
]

#: The evaluation log in the run's ``best/`` directory.
EVALUATIONS_FILE = "evaluations.json"

#: First evaluation seed; the evaluation episodes are seeds EVAL_SEEDS_START .. +episodes-1 for every
#: run, so runs of different training seeds are selected and compared on the same episodes.
EVAL_SEEDS_START = 1_000_000


def evaluation_seeds(episodes: int) -> list[int]:
    """The seeds of the ``episodes`` evaluation episodes (the same for every run)."""
    return list(range(EVAL_SEEDS_START, EVAL_SEEDS_START + int(episodes)))


def episode_returns(
    controller: Any, env_id: str, seeds: list[int], env_kwargs: dict[str, Any] | None = None
) -> np.ndarray:
    """(E,) undiscounted return of ``controller`` in one episode per seed
    (:func:`agents.evaluation.rollout.rollout`)."""
    from ..evaluation.rollout import rollout

    return rollout(controller, env_id, seeds, env_kwargs=env_kwargs).rewards.sum(axis=1)


def baseline_returns(
    env_id: str, seeds: list[int], env_kwargs: dict[str, Any] | None = None
) -> tuple[dict[str, np.ndarray], str]:
    """Every scripted baseline's (E,) returns on ``seeds``, and the bar: the best eligible one
    (:func:`agents.evaluation.stats.best_eligible_baseline`)."""
    import gymnasium as gym

    from ..controllers.registry import BASELINES, make_baseline
    from ..evaluation.stats import best_eligible_baseline

    env = gym.make(env_id, **dict(env_kwargs or {}))
    returns = {name: episode_returns(make_baseline(name, env), env_id, seeds, env_kwargs) for name in BASELINES}
    env.close()
    bar, _ = best_eligible_baseline({name: float(r.mean()) for name, r in returns.items()})
    return returns, bar


class EvaluationLog:
    """A training run's evaluations on the evaluation seeds, as ``best/evaluations.json`` holds
    them: each evaluation's returns and paired difference from the bar, the best mean so far, and
    the first evaluation that beat each baseline (see the module docstring).

    Args:
        env_id: the id trained on.
        seeds: the evaluation seeds.
        baseline_returns: every scripted baseline's (E,) returns on ``seeds``; ``bar``: the best
            eligible one (:func:`baseline_returns` gives both).
        started: ``time.perf_counter()`` at the start of training; wall times count from it.
        best_mean: the mean return a first "best" must exceed (default: any).
    """

    def __init__(
        self,
        env_id: str,
        seeds: list[int],
        baseline_returns: dict[str, np.ndarray],
        bar: str,
        started: float,
        best_mean: float = -np.inf,
    ) -> None:
        self.env_id, self.seeds, self.baseline_returns, self.bar = env_id, seeds, baseline_returns, bar
        self.started, self.best_mean = started, best_mean
        self.history: list[dict[str, Any]] = []
        #: For each baseline, the first evaluation whose mean return beat its mean: {timesteps, wall_time_s}.
        self.first_beat: dict[str, dict[str, Any]] = {}
        #: Set by :meth:`finish`: the wall time and step count at the end of training.
        self.finished: dict[str, Any] | None = None

    def add(self, returns: np.ndarray, timesteps: int, **extra: Any) -> tuple[dict[str, Any], Any, bool]:
        """Record an evaluation's (E,) ``returns`` after ``timesteps`` env steps (``extra``: more
        entries of its record); returns its record, its paired difference from the bar
        (:class:`agents.evaluation.stats.PairedDifference`) and whether it is the best so far."""
        from ..evaluation.stats import paired_difference

        paired = paired_difference(returns, self.baseline_returns[self.bar])
        entry = {
            "timesteps": int(timesteps),
            **extra,
            "wall_time_s": round(time.perf_counter() - self.started, 2),
            "mean_return": float(returns.mean()),
            "returns": returns.tolist(),
            "difference_vs_bar": paired.mean,
            "difference_low": paired.low,
            "difference_high": paired.high,
            "wins": paired.wins,
        }
        self.history.append(entry)
        for name, baseline in self.baseline_returns.items():
            if name not in self.first_beat and returns.mean() > baseline.mean():
                self.first_beat[name] = {"timesteps": entry["timesteps"], "wall_time_s": entry["wall_time_s"]}
        new_best = returns.mean() > self.best_mean
        if new_best:
            self.best_mean = float(returns.mean())
        return entry, paired, new_best

    def summary(self) -> dict[str, Any]:
        """What the run's ``best/evaluations.json`` holds."""
        return {
            "env_id": self.env_id,
            "seeds": [self.seeds[0], self.seeds[-1]],
            "baselines": {name: float(r.mean()) for name, r in self.baseline_returns.items()},
            "bar": self.bar,
            "best_mean_return": None if not self.history else self.best_mean,
            "first_beat": self.first_beat,
            "training": self.finished,
            "evaluations": self.history,
        }

    def finish(self, timesteps: int, **extra: Any) -> None:
        """Record the end of training: ``timesteps`` trained, the wall time, and ``extra``."""
        self.finished = {
            "timesteps": int(timesteps),
            "wall_time_s": round(time.perf_counter() - self.started, 2),
            **extra,
        }

    def write(self, log_dir: Path) -> None:
        """Write :meth:`summary` to ``log_dir/evaluations.json``."""
        log_dir.mkdir(parents=True, exist_ok=True)
        atomic_write_text(log_dir / EVALUATIONS_FILE, json.dumps(self.summary(), indent=1) + "\n")


class SeededEvaluation(BaseCallback):
    """Evaluate the policy every ``every`` calls on fixed seeds, paired against the best scripted
    baseline (see the module docstring).

    Args:
        env_id: the id trained on.
        episodes: evaluation episodes (seeds :func:`evaluation_seeds`).
        every: callback calls (vector steps) between evaluations.
        log_dir: where ``evaluations.json`` goes (the run's ``best/``).
        on_new_best: a callback run when the mean return is the best so far (saves ``best/``).
        started: ``time.perf_counter()`` at the start of the training command.
        env_kwargs: the env's keyword arguments (``env_kwargs`` of the hyperparameters).
        spec: how the policy's outputs become actions (residual, multi-agent); default centralised.
        verbose: 1 prints a line per evaluation.
    """

    def __init__(
        self,
        env_id: str,
        episodes: int,
        every: int,
        log_dir: Path,
        on_new_best: BaseCallback,
        started: float,
        env_kwargs: dict[str, Any] | None = None,
        spec: PolicySpec | None = None,
        verbose: int = 1,
    ) -> None:
        super().__init__(verbose=verbose)
        self.env_id, self.seeds, self.every = env_id, evaluation_seeds(episodes), max(int(every), 1)
        self.log_dir, self.on_new_best, self.started = Path(log_dir), on_new_best, started
        self.env_kwargs, self.spec = dict(env_kwargs or {}), spec if spec is not None else PolicySpec()
        #: The evaluations, from the start of training (when the baselines have been rolled out).
        self.log = EvaluationLog(env_id, self.seeds, {}, "", started)
        self.policy: Any = None

    @property
    def history(self) -> list[dict[str, Any]]:
        return self.log.history

    @property
    def first_beat(self) -> dict[str, dict[str, Any]]:
        return self.log.first_beat

    @property
    def best_mean(self) -> float:
        return self.log.best_mean

    @property
    def bar(self) -> str:
        return self.log.bar

    @property
    def baseline_returns(self) -> dict[str, np.ndarray]:
        return self.log.baseline_returns

    def _init_callback(self) -> None:
        self.on_new_best.init_callback(self.model)

    def _on_training_start(self) -> None:
        returns, bar = baseline_returns(self.env_id, self.seeds, self.env_kwargs)
        self.log = EvaluationLog(self.env_id, self.seeds, returns, bar, self.started)
        self.policy = self._policy()
        if self.verbose:
            means = ", ".join(f"{name} {r.mean():.2f}" for name, r in self.baseline_returns.items())
            print(f"evaluation seeds {self.seeds[0]}..{self.seeds[-1]}: {means}; the bar is {self.bar}", flush=True)

    def _policy(self) -> Any:
        """The model's policy as a controller, built once: it holds the model's own policy and
        normaliser objects, so it acts with their weights and statistics of the moment (and a
        residual policy's baseline is designed once, not at every evaluation)."""
        from ..policies import TrainedPolicy

        policy = TrainedPolicy.from_parts(
            self.model.policy,
            self.model.get_vec_normalize_env(),
            self.env_id,
            algo=type(self.model).__name__.lower(),
            spec=self.spec,
        )
        if self.spec.residual_on is not None:
            import gymnasium as gym

            env = gym.make(self.env_id, **self.env_kwargs)
            policy.attach(env)
            env.close()
        return policy

    def _on_step(self) -> bool:
        if self.n_calls % self.every == 0:
            self.evaluate()
        return True

    def evaluate(self) -> dict[str, Any]:
        """Run the evaluation now; returns (and logs) its entry."""
        returns = episode_returns(self.policy, self.env_id, self.seeds, self.env_kwargs)
        entry, paired, new_best = self.log.add(returns, self.num_timesteps)
        wall = entry["wall_time_s"]
        self.logger.record("eval/mean_return", entry["mean_return"])
        self.logger.record(f"eval/difference_vs_{self.bar}", paired.mean)
        self.logger.record(f"eval/difference_vs_{self.bar}_low", paired.low)
        if new_best:
            self.on_new_best.on_step()
        if self.verbose:
            print(
                f"eval at {entry['timesteps']:,} steps ({wall:.0f} s): return {returns.mean():.2f}, "
                f"vs {self.bar} {paired.mean:+.2f} [{paired.low:+.2f}, {paired.high:+.2f}]"
                + (" (new best)" if new_best else ""),
                flush=True,
            )
        self.write()
        return entry

    def summary(self) -> dict[str, Any]:
        """What the run's ``best/evaluations.json`` holds."""
        return self.log.summary()

    def finish(self, timesteps: int) -> None:
        """Record the end of training (``timesteps`` trained, wall time since the command started)
        and write the log."""
        self.log.finish(timesteps)
        self.write()

    def write(self) -> None:
        self.log.write(self.log_dir)


def print_evaluation_summary(evaluation: SeededEvaluation | EvaluationLog) -> None:
    """One line: the best evaluation return against the bar, and when training first beat it."""
    if not evaluation.history:
        return
    beat = evaluation.first_beat.get(evaluation.bar)
    print(
        f"best evaluation return {evaluation.best_mean:.2f} against {evaluation.bar} "
        f"{evaluation.baseline_returns[evaluation.bar].mean():.2f} on the evaluation seeds; "
        + (
            f"first beat it at {beat['timesteps']:,} steps, {beat['wall_time_s']:.0f} s after the command started"
            if beat
            else "never beat it"
        )
    )
