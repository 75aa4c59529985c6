"""Score your own policy on the benchmark's held-out episodes, against the shipped reference scores.

:func:`score_policy` runs a policy on an id's held-out seeds (episode e starts from the reset
seeded ``seeds[e]``, 10 000 and up, as in ``agents.benchmark`` and ``agents.compare``) through
:func:`agents.evaluation.rollout.rollout`, and computes from its per-episode returns what the
benchmark reports for a controller on that id, with the benchmark's own functions
(:mod:`agents.evaluation.stats`):

* the mean return with its 95 % t interval;
* the paired difference against the id's best scripted baseline, ``d[e] = R[e] - R[best, e]``
  on the same seeds: mean with its 95 % t interval, and the number of episodes where the
  policy did better;
* the normalised score, 0 for passive and 100 for ``mpc``:
  ``100 (mean R - mean R[passive]) / (mean R[mpc] - mean R[passive])``, with its paired
  percentile-bootstrap interval (the benchmark's resamples and bootstrap seed);
* where ceiling data hold the id (the per-seed returns of the reference ceiling, a long-horizon
  planner, on a subset of the held-out seeds): on those of the ceiling's seeds that the policy
  ran, the excess cost over the ceiling, per seed ``(-R[e]) / (-R[ceiling, e]) - 1``, its mean
  with a 95 % t interval, and the normalised score with 100 = the ceiling, with its paired
  bootstrap interval.

The other controllers' returns come from the **reference scores**, a data file shipped in the
package (``reference/reference_scores.json``, :data:`REFERENCE_FILE`): per id, the held-out
seeds and the per-seed returns of passive, every scripted baseline, ``mpc`` and the shipped
models, with the benchmark's statistics of each, which baseline is the best, and the commit,
command, date and machine of the benchmark run. Nothing is rerun but the policy: scoring takes
seconds, where the benchmark's ``mpc`` takes half an hour. The rollouts are deterministic, so
a controller of the reference (``score_policy("lqr", ...)``) reproduces its numbers to the bit.

The reference file is computed, never typed: :func:`reference_from_benchmark` converts a
``benchmark.json`` written by ``python -m agents.benchmark``, and checks on the way that every
statistic in it is what the functions used here give from its per-episode returns; the command
``python -m agents.scoring`` (:mod:`agents.scoring`) writes the file with it::

    python -m agents.scoring outputs/benchmark/benchmark.json --commit 2466a18 --force

Example (``tether_gym_agents.scoring`` has :func:`score_policy` too, the documented path of
earlier releases)::

    from tether_gym_agents.evaluation.scoring import score_policy

    score = score_policy(lambda obs: -0.5 * obs[:, 12:24], "TetherTetrahedron-v0", episodes=16)
    print(score.summary())
"""

from __future__ import annotations

import dataclasses
import datetime
import json
import os
import platform
import re
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from tether_gym.limits import is_whole_number
from tether_gym.registration import ENV_IDS

from ..common.commands import PACKAGE
from ..common.data import REFERENCE_DIR
from ..common.reading import read_json
from .ceiling import CEILING_FILE, load_ceiling
from .rollout import rollout
from .stats import (
    SCORE_BOOTSTRAP_REPS,
    ExcessCost,
    PairedDifference,
    best_eligible_baseline,
    excess_cost,
    paired_difference,
    score_with_interval,
    t_interval,
)

__all__ = [
    "FORMAT",
    "FORMAT_VERSION",
    "REFERENCE_FILE",
    "ReferenceDataError",
    "Score",
    "ceiling_rows",
    "ceiling_seeds_and_returns",
    "load_reference",
    "machine_description",
    "merge_reference",
    "reference_from_benchmark",
    "run_of",
    "score_policy",
    "score_returns",
    "write_reference",
]

#: The shipped reference scores (inside the package, so a wheel carries them).
REFERENCE_FILE = REFERENCE_DIR / "reference_scores.json"
#: The file's ``format`` and ``version`` entries: a reader refuses any other.
FORMAT = "tether-gym reference scores"
FORMAT_VERSION = 1

#: The keys of a controller's entry in the reference file that the statistics fill.
_STATISTICS = ("mean_return", "return_ci95", "failures", "paired_vs_best", "normalised_score")


class ReferenceDataError(ValueError):
    """Reference scores that cannot be used: a file of another format, a benchmark output
    without the entries the scores need, numbers that its returns do not give, or a request
    (id, seeds) that the reference does not hold."""


# ---------------------------------------------------------------------------------------- the score


@dataclasses.dataclass(frozen=True)
class Score:
    """A policy's benchmark statistics on one id's held-out episodes (returns in reward units).

    Attributes:
        env_id: the id.
        name: the policy's name.
        seeds: (E,) the reset seeds, episode e from ``seeds[e]``.
        returns: (E,) the undiscounted return of each episode.
        terminated: (E,) whether each episode ended in a failure (None when not known).
        mean_return: mean of ``returns``.
        return_ci95: half-width of its 95 % t interval.
        failures: number of failed episodes (None when not known).
        best_baseline: the id's best scripted baseline in the reference.
        paired_vs_best: ``returns - R[best_baseline]`` on the same seeds: mean, 95 % t interval,
            wins (episodes better than the baseline); all 0 for the best baseline itself.
        zero, reference: the controllers that score 0 and 100 (``passive``, ``mpc``).
        normalised_score: ``100 (mean R - mean R[zero]) / (mean R[reference] - mean R[zero])``
            on these seeds, or None when not available (see ``score_note``).
        normalised_score_low, normalised_score_high: its 95 % paired percentile-bootstrap
            interval, or None.
        score_note: what the normalised score is, or why it is not available.
        reference_commit: the commit of the benchmark run the reference scores come from.
        ceiling_seeds: the seeds of the ceiling statistics below: the ceiling's seeds that
            ``seeds`` include, in the ceiling's order (empty when there are none).
        ceiling_excess: the excess cost over the reference ceiling on ``ceiling_seeds``
            (fractions: mean of ``(-R[e]) / (-R[ceiling, e]) - 1``, 95 % t interval, seeds
            cheaper than the ceiling), or None when not available (see ``ceiling_note``).
        ceiling_score: the normalised score with 0 = ``zero`` and 100 = the ceiling on
            ``ceiling_seeds``, or None.
        ceiling_score_low, ceiling_score_high: its 95 % paired percentile-bootstrap interval
            (the benchmark's resamples and seed), or None.
        ceiling_note: what the ceiling statistics are, or why they are not available.
    """

    env_id: str
    name: str
    seeds: tuple[int, ...]
    returns: np.ndarray
    terminated: np.ndarray | None
    mean_return: float
    return_ci95: float
    failures: int | None
    best_baseline: str
    paired_vs_best: PairedDifference
    zero: str
    reference: str
    normalised_score: float | None
    normalised_score_low: float | None
    normalised_score_high: float | None
    score_note: str
    reference_commit: str
    ceiling_seeds: tuple[int, ...] = ()
    ceiling_excess: ExcessCost | None = None
    ceiling_score: float | None = None
    ceiling_score_low: float | None = None
    ceiling_score_high: float | None = None
    ceiling_note: str = "not available: no ceiling data"

    @property
    def episodes(self) -> int:
        """E, the number of held-out episodes."""
        return len(self.seeds)

    @property
    def beats_best_baseline(self) -> bool:
        """Whether the paired 95 % interval against the best baseline lies above 0 (the
        benchmark's meaning of "beats the best baseline")."""
        return self.paired_vs_best.low > 0

    def summary(self) -> str:
        """The score in a few lines, as the benchmark's tables write it."""
        paired = self.paired_vs_best
        if self.normalised_score is None:
            score = self.score_note
        elif self.normalised_score_low is None:
            score = f"{self.normalised_score:.1f} [interval n/a] ({self.score_note})"
        else:
            score = (
                f"{self.normalised_score:.1f} [{self.normalised_score_low:.1f}, {self.normalised_score_high:.1f}] "
                f"({self.score_note})"
            )
        failures = "" if self.failures is None else f", {self.failures}/{self.episodes} failed"
        first, last = self.seeds[0], self.seeds[-1]
        span = f"seeds {first}..{last}" if self.seeds == tuple(range(first, last + 1)) else "chosen seeds"
        ceiling = []
        if self.ceiling_excess is not None:
            excess = self.ceiling_excess
            ceiling.append(
                f"  excess cost over the ceiling: {100 * excess.mean:+.1f} % [{100 * excess.low:+.1f}, "
                f"{100 * excess.high:+.1f}] (95 % t interval, {self.ceiling_note}), cheaper than the ceiling on "
                f"{excess.beats}/{excess.episodes} episodes"
            )
            if self.ceiling_score is not None:
                interval = (
                    "[interval n/a]"
                    if self.ceiling_score_low is None
                    else f"[{self.ceiling_score_low:.1f}, {self.ceiling_score_high:.1f}]"
                )
                ceiling.append(
                    f"  normalised score (0 = {self.zero}, 100 = the ceiling): {self.ceiling_score:.1f} {interval}"
                )
        return "\n".join(
            [
                f"{self.name} on {self.env_id}, {self.episodes} held-out episodes "
                f"({span}; reference scores of commit {self.reference_commit})",
                f"  return: {self.mean_return:.1f} ± {self.return_ci95:.1f} (95 % t interval){failures}",
                f"  vs best baseline {self.best_baseline}: {paired.mean:+.2f} [{paired.low:+.2f}, {paired.high:+.2f}] "
                f"(paired, 95 % t interval), better on {paired.wins}/{paired.episodes} episodes",
                f"  normalised score: {score}",
                *ceiling,
            ]
        )


def _held_out_seeds(entry: dict[str, Any], env_id: str, episodes: int | None, seeds: Sequence[int] | None) -> list[int]:
    """The seeds to score on: the first ``episodes`` of the reference's, or ``seeds``, each one
    the reference holds (an error names what it holds otherwise)."""
    held = [int(seed) for seed in entry["seeds"]]
    span = f"{len(held)} held-out seeds, {held[0]}..{held[-1]}"
    if seeds is not None and episodes is not None:
        raise ReferenceDataError("pass episodes or seeds, not both")
    if seeds is None:
        count = len(held) if episodes is None else episodes
        if not is_whole_number(count) or not 2 <= count <= len(held):
            raise ReferenceDataError(
                f"episodes must be an integer from 2 (for an interval) to {len(held)}: the reference scores of "
                f"{env_id} hold {span}; got {episodes!r}"
            )
        return held[: int(count)]
    if isinstance(seeds, (str, bytes)) or not all(is_whole_number(seed) for seed in seeds):
        raise ReferenceDataError(f"seeds must be a list of integer seeds; got {seeds!r}")
    chosen = [int(seed) for seed in seeds]
    foreign = [seed for seed in chosen if seed not in held]
    if foreign:
        raise ReferenceDataError(
            f"the reference scores of {env_id} hold no returns for seeds {foreign[:5]}: they hold {span}; pass "
            "seeds among those, or episodes=E for the first E"
        )
    if len(chosen) < 2 or len(set(chosen)) != len(chosen):
        raise ReferenceDataError(f"seeds must be at least 2 distinct held-out seeds (for an interval); got {chosen}")
    return chosen


def ceiling_rows(entry: dict[str, Any], env_id: str, ceiling_seeds: Any) -> np.ndarray:
    """The rows (E,) int of the reference entry ``entry`` (an id's, in :func:`load_reference`'s
    data) that hold the ceiling's seeds ``ceiling_seeds`` (E,), in their order: the reference's
    returns at these rows pair with the ceiling's returns. Raises :class:`ReferenceDataError`
    unless the ceiling's seeds are at least 2 distinct seeds among the reference's held-out
    seeds (the ceiling must have run on the benchmark's seeds for the pairing to hold)."""
    held = [int(seed) for seed in entry["seeds"]]
    seeds = np.asarray(ceiling_seeds)
    if seeds.ndim != 1 or seeds.size < 2 or not all(is_whole_number(seed) for seed in seeds.tolist()):
        raise ReferenceDataError(
            f"the ceiling data of {env_id} must hold at least 2 integer seeds (for an interval); got "
            f"{seeds.tolist()!r}: recompute them with python -m agents.ceiling"
        )
    chosen = [int(seed) for seed in seeds.tolist()]
    if len(set(chosen)) != len(chosen):
        raise ReferenceDataError(
            f"the ceiling data of {env_id} repeat seeds ({chosen}): each seed pairs once; recompute them with "
            "python -m agents.ceiling"
        )
    index = {seed: row for row, seed in enumerate(held)}
    foreign = [seed for seed in chosen if seed not in index]
    if foreign:
        raise ReferenceDataError(
            f"the ceiling data of {env_id} hold seeds {foreign[:5]} that its reference scores do not (they hold "
            f"{len(held)} held-out seeds, {held[0]}..{held[-1]}): the ceiling's seeds must be among the benchmark's "
            "held-out seeds for its returns to pair with the other controllers'; recompute the ceiling on them "
            "(python -m agents.ceiling)"
        )
    return np.array([index[seed] for seed in chosen], dtype=np.intp)


def ceiling_seeds_and_returns(run: Any, env_id: str) -> tuple[np.ndarray, np.ndarray]:
    """``run``'s (E,) seeds and (E,) returns (anything with ``.seeds`` and ``.returns``, such
    as a ceiling run of :func:`agents.evaluation.ceiling.load_ceiling`), checked to pair."""
    seeds, returns = np.asarray(getattr(run, "seeds", None)), np.asarray(getattr(run, "returns", None))
    if seeds.ndim != 1 or returns.shape != seeds.shape:
        raise ReferenceDataError(
            f"the ceiling data of {env_id} need one return per seed; got seeds of shape {seeds.shape} and returns "
            f"of shape {returns.shape}: recompute them with python -m agents.ceiling"
        )
    return seeds, returns.astype(np.float64)


def _score_of(
    values: np.ndarray, zero_values: np.ndarray, anchor_values: np.ndarray, data: dict[str, Any]
) -> tuple[float, float | None, float | None]:
    """The normalised score of ``values`` (E,) with 0 = ``zero_values`` and 100 = ``anchor_values``
    (the same seeds), and its paired bootstrap interval with the reference's resamples and seed."""
    bootstrap = data["score_bootstrap"]
    return score_with_interval(
        values,
        zero_values,
        anchor_values,
        reps=bootstrap["reps"],
        seed=bootstrap["seed"],
        confidence=data["confidence"],
    )


def _reference_entry(data: dict[str, Any], env_id: str) -> dict[str, Any]:
    if env_id not in data["per_id"]:
        raise ReferenceDataError(f"the reference scores hold no id {env_id!r}; they hold {', '.join(data['per_id'])}")
    entry: dict[str, Any] = data["per_id"][env_id]
    return entry


def score_returns(
    returns: Any,
    env_id: str,
    seeds: Sequence[int],
    name: str = "policy",
    terminated: Any = None,
    reference: dict[str, Any] | str | Path | None = None,
    ceiling: Mapping[str, Any] | str | Path | None = None,
) -> Score:
    """The benchmark's statistics of per-episode returns measured on held-out seeds.

    For returns from a rollout of one's own (:func:`score_policy` runs it for you). ``returns``
    (E,) are the undiscounted returns of the episodes reset with ``seeds`` (E,), each a seed
    the reference holds for ``env_id``, on the id's own settings; ``terminated`` (E,) bool,
    optional, flags failed episodes. ``reference`` is the reference data (a dict from
    :func:`load_reference`, or a path; default: the shipped file).

    The paired difference is taken against the best baseline's returns on the same seeds (the
    best baseline is the reference's, chosen on all its episodes); the normalised score and its
    bootstrap interval use passive's and the reference controller's returns on those seeds, with
    the benchmark's resample count and bootstrap seed, so the numbers are those a benchmark over
    these seeds reports.

    ``ceiling`` maps ids to their reference-ceiling runs (anything with ``.seeds`` (C,) and
    ``.returns`` (C,), such as :func:`agents.evaluation.ceiling.load_ceiling`'s), or is the path
    of a ceiling file. The default pairs shipped data with shipped data: the shipped ceiling
    (:data:`agents.evaluation.ceiling.CEILING_FILE`, when it exists) when ``reference`` is the
    shipped reference (None), and no ceiling with a reference of one's own; ``{}`` is no
    ceiling. When it holds ``env_id``, the score also has the excess cost over the ceiling and the
    normalised score with 100 = the ceiling, on the ceiling's seeds among ``seeds`` (at least
    2 of them; the note says why not otherwise). Raises :class:`ReferenceDataError` for an id or
    seeds the reference does not hold, or ceiling seeds it does not hold; ValueError for returns
    that are not E finite numbers, or a ceiling return that is not below 0."""
    runs = _ceiling_runs(ceiling, reference)
    data = reference if isinstance(reference, dict) else load_reference(reference)
    entry = _reference_entry(data, env_id)
    chosen = _held_out_seeds(entry, env_id, None, seeds)
    rows = [entry["seeds"].index(seed) for seed in chosen]
    values = np.asarray(returns, dtype=np.float64)
    if values.shape != (len(chosen),) or not np.all(np.isfinite(values)):
        raise ValueError(f"returns must be {len(chosen)} finite numbers, one per seed; got shape {values.shape}")
    controllers = entry["controllers"]

    def reference_returns(controller: str) -> np.ndarray:
        return np.asarray(controllers[controller]["returns"], dtype=np.float64)[rows]

    best = entry["best_baseline"]
    paired = paired_difference(values, reference_returns(best))
    mean, _, half_width = t_interval(values, data["confidence"])
    zero, anchor = data["zero"], data["reference"]
    score = low = high = None
    if anchor not in controllers:
        note = f"not available: {anchor} did not run on this id"
    else:
        zero_values, anchor_values = reference_returns(zero), reference_returns(anchor)
        if not anchor_values.mean() > zero_values.mean():
            note = (
                f"not available: {anchor}'s mean return ({anchor_values.mean():.4g}) is not above {zero}'s "
                f"({zero_values.mean():.4g}) on these seeds"
            )
        else:
            note = f"0 = {zero}, 100 = {anchor}"
            score, low, high = _score_of(values, zero_values, anchor_values, data)
    ceiling_fields = _ceiling_statistics(values, chosen, entry, env_id, runs, data)
    ended = None if terminated is None else np.asarray(terminated, dtype=bool)
    if ended is not None and ended.shape != values.shape:
        raise ValueError(f"terminated must be {values.size} flags, one per seed; got shape {ended.shape}")
    return Score(
        env_id=env_id,
        name=name,
        seeds=tuple(chosen),
        returns=values,
        terminated=ended,
        mean_return=mean,
        return_ci95=half_width,
        failures=None if ended is None else int(ended.sum()),
        best_baseline=best,
        paired_vs_best=paired,
        zero=zero,
        reference=anchor,
        normalised_score=score,
        normalised_score_low=low,
        normalised_score_high=high,
        score_note=note,
        reference_commit=run_of(data, env_id)["commit"],
        **ceiling_fields,
    )


def _ceiling_runs(
    ceiling: Mapping[str, Any] | str | Path | None, reference: dict[str, Any] | str | Path | None
) -> Mapping[str, Any]:
    """The ceiling runs per id that ``ceiling`` names (see :func:`score_returns`)."""
    if ceiling is None:
        return load_ceiling() if reference is None and CEILING_FILE.is_file() else {}
    if isinstance(ceiling, (str, Path)):
        return load_ceiling(ceiling)
    return ceiling


def _ceiling_statistics(
    values: np.ndarray,
    chosen: list[int],
    entry: dict[str, Any],
    env_id: str,
    ceiling: Mapping[str, Any] | None,
    data: dict[str, Any],
) -> dict[str, Any]:
    """The :class:`Score` fields of the ceiling (``ceiling_*``) for ``values`` (E,) on the seeds
    ``chosen`` (E,) of ``env_id``: on the ceiling's seeds among ``chosen``, in its order."""
    if ceiling is None or env_id not in ceiling:
        return {"ceiling_note": f"not available: no ceiling data for {env_id}"}
    seeds, ceiling_values = ceiling_seeds_and_returns(ceiling[env_id], env_id)
    ceiling_rows(entry, env_id, seeds)  # the ceiling's seeds are the benchmark's, or a clear error
    position = {seed: k for k, seed in enumerate(chosen)}
    shared = [k for k, seed in enumerate(seeds.tolist()) if int(seed) in position]
    if len(shared) < 2:
        return {
            "ceiling_note": (
                f"not available: {len(shared)} of the ceiling's {seeds.size} seeds ({int(seeds[0])}..{int(seeds[-1])}) "
                "are among the scored seeds; an interval needs 2"
            )
        }
    own = values[[position[int(seeds[k])] for k in shared]]
    on_ceiling = ceiling_values[shared]
    zero_values = np.asarray(entry["controllers"][data["zero"]]["returns"], dtype=np.float64)[
        ceiling_rows(entry, env_id, seeds[shared])
    ]
    fields: dict[str, Any] = {
        "ceiling_seeds": tuple(int(seeds[k]) for k in shared),
        "ceiling_excess": excess_cost(own, on_ceiling, data["confidence"]),
        "ceiling_note": f"{len(shared)} ceiling seeds",
    }
    if on_ceiling.mean() > zero_values.mean():
        score, low, high = _score_of(own, zero_values, on_ceiling, data)
        fields.update(ceiling_score=score, ceiling_score_low=low, ceiling_score_high=high)
    else:
        fields["ceiling_note"] += (
            f"; no normalised score: the ceiling's mean return ({on_ceiling.mean():.4g}) is not above "
            f"{data['zero']}'s ({zero_values.mean():.4g}) on these seeds"
        )
    return fields


class _CallablePolicy:
    """A function from a batch of observations (N, obs_dim) to actions (N, act_dim), with the
    ``predict`` interface :func:`agents.evaluation.rollout.rollout` drives."""

    def __init__(self, function: Callable[[np.ndarray], Any], action_size: int, name: str) -> None:
        self.function = function
        self.action_size = action_size
        self.name = name

    def predict(self, observation: np.ndarray, deterministic: bool = True) -> tuple[np.ndarray, None]:
        actions = np.asarray(self.function(observation), dtype=np.float32)
        expected = (observation.shape[0], self.action_size)
        if actions.shape != expected:
            raise ValueError(
                f"the policy {self.name} returned actions of shape {actions.shape} for observations of shape "
                f"{observation.shape}; it must return {expected}: one row of {self.action_size} thrust commands "
                "in [-1, 1] per observation"
            )
        return actions, None


def _controller(policy: Any, env_id: str, name: str | None, env_kwargs: dict[str, Any]) -> tuple[Any, str]:
    """``policy`` as something :func:`agents.evaluation.rollout.rollout` runs, and its name."""
    import gymnasium as gym

    from ..policies import make_controller

    if isinstance(policy, (str, Path)):
        probe = gym.make_vec(env_id, num_envs=1, **env_kwargs)
        try:
            controller = make_controller(str(policy), probe)
        finally:
            probe.close()
        return controller, name or getattr(controller, "name", str(policy))
    label = name or getattr(policy, "name", None) or getattr(policy, "__name__", None) or type(policy).__name__
    if callable(getattr(policy, "predict", None)):
        return policy, str(label)
    if callable(policy):
        probe = gym.make_vec(env_id, num_envs=1, **env_kwargs)
        action_size = int(probe.single_action_space.shape[0])
        probe.close()
        return _CallablePolicy(policy, action_size, str(label)), str(label)
    raise TypeError(
        f"policy must be a function from observations (N, obs_dim) to actions (N, act_dim), an object with "
        f"predict(obs, deterministic=True) (an SB3 model, a TrainedPolicy), or a controller name; got "
        f"{type(policy).__name__}"
    )


def score_policy(
    policy: Any,
    env_id: str,
    episodes: int | None = None,
    seeds: Sequence[int] | None = None,
    name: str | None = None,
    reference: dict[str, Any] | str | Path | None = None,
    progress: Callable[[int, int], None] | None = None,
    ceiling: Mapping[str, Any] | str | Path | None = None,
) -> Score:
    """Run ``policy`` on ``env_id``'s held-out episodes and score it as the benchmark does.

    Args:
        policy: one of
            - a function from a batch of observations (N, obs_dim) float32 to actions
              (N, act_dim) in [-1, 1] (the env clips thrust beyond the limit);
            - an object with ``predict(obs, deterministic=True) -> (actions, state)``: a
              Stable-Baselines3 model, a :class:`agents.policies.TrainedPolicy`, a baseline.
              An SB3 model trained on normalised observations needs its statistics: pass
              ``TrainedPolicy.from_parts(model.policy, vec_normalize, env_id, algo)``;
            - a name :func:`agents.policies.make_controller` knows (``"lqr"``, a shipped model
              such as ``"ars"``, or a policy directory).
        env_id: a tether-gym id, on its own settings (the reference's).
        episodes: score on the first E held-out seeds (2 <= E <= the reference's 64); default:
            all of them. A smaller E is quicker, and its statistics are those of a benchmark
            over those seeds.
        seeds: instead of ``episodes``, the held-out seeds to score on (each one the reference
            holds).
        name: the name in the summary (default: the policy's ``name``, function name or type).
        reference: the reference scores (a dict from :func:`load_reference`, or a path; default:
            the shipped :data:`REFERENCE_FILE`).
        progress: optional ``progress(steps_done, steps_total)``, called after each step.
        ceiling: the reference ceiling's runs per id, or a ceiling file (see
            :func:`score_returns`); default: the shipped ceiling with the shipped reference.

    Returns:
        the :class:`Score`: mean return with its 95 % t interval, the paired difference against
        the id's best scripted baseline, and the normalised score (0 = passive, 100 = mpc) with
        its 95 % paired bootstrap interval; with ceiling data for the id, also the excess cost
        over the ceiling and the normalised score with 100 = the ceiling, on its seeds.

    Raises:
        ReferenceDataError: an id, ``episodes`` or ``seeds`` that the reference does not hold.
        TypeError: ``policy`` is none of the above.
        ValueError: the policy's actions have the wrong shape (or other errors of the rollout).
    """
    runs = _ceiling_runs(ceiling, reference)  # read before anything runs, as the reference is
    data = reference if isinstance(reference, dict) else load_reference(reference)
    entry = _reference_entry(data, env_id)
    chosen = _held_out_seeds(entry, env_id, episodes, seeds)  # checked before anything runs
    env_kwargs = dict(data["env_kwargs"])
    controller, label = _controller(policy, env_id, name, env_kwargs)
    record = rollout(controller, env_id, chosen, name=label, env_kwargs=env_kwargs, progress=progress)
    returns = record.rewards.sum(axis=1)
    return score_returns(
        returns, env_id, chosen, name=label, terminated=record.terminated, reference=data, ceiling=runs
    )


# ---------------------------------------------------------------------------------------- the reference data


def machine_description() -> str:
    """This machine in a line: CPU model (:func:`tether_gym.bench.cpu_model`), logical cores, OS."""
    from tether_gym.bench import cpu_model

    return f"{cpu_model()}, {os.cpu_count()} logical cores, {platform.system()} {platform.machine()}"


def _require(mapping: Any, keys: Sequence[str], where: str) -> None:
    if not isinstance(mapping, dict):
        raise ReferenceDataError(f"{where} must be a JSON object; got {type(mapping).__name__}")
    absent = [key for key in keys if key not in mapping]
    if absent:
        raise ReferenceDataError(f"{where} lacks {absent}: is it a benchmark.json of python -m agents.benchmark?")


def _check_statistics(data: dict[str, Any]) -> None:
    """Recompute every controller's statistics from its per-episode returns with
    :func:`score_returns` and the best-baseline rule, and raise :class:`ReferenceDataError`
    unless each equals the stored number exactly."""
    for env_id, entry in data["per_id"].items():
        controllers = entry["controllers"]
        baselines = {name: item["mean_return"] for name, item in controllers.items() if item["kind"] == "baseline"}
        best, _ = best_eligible_baseline(baselines, data["zero"])
        if best != entry["best_baseline"]:
            raise ReferenceDataError(
                f"{env_id}: the best baseline is {best} by its means, not {entry['best_baseline']}"
            )
        for name, item in controllers.items():
            score = score_returns(
                item["returns"], env_id, entry["seeds"], name=name, terminated=item["terminated"], reference=data
            )
            computed = _statistics_of(score, best)
            stored = {key: item[key] for key in _STATISTICS}
            if computed != stored:
                raise ReferenceDataError(
                    f"{env_id} {name}: the statistics of its returns are {computed}, the file has {stored}; "
                    "a benchmark.json of another version of agents.benchmark?"
                )


def _statistics_of(score: Score, best: str) -> dict[str, Any]:
    """``score``'s numbers in the benchmark.json layout."""
    paired = None if score.name == best else dataclasses.asdict(score.paired_vs_best)
    normalised = (
        None
        if score.normalised_score is None
        else {"mean": score.normalised_score, "low": score.normalised_score_low, "high": score.normalised_score_high}
    )
    return {
        "mean_return": score.mean_return,
        "return_ci95": score.return_ci95,
        "failures": score.failures,
        "paired_vs_best": paired,
        "normalised_score": normalised,
    }


def reference_from_benchmark(
    results: dict[str, Any], commit: str, date: str, machine: str | None = None
) -> dict[str, Any]:
    """The reference scores (the dict written to :data:`REFERENCE_FILE`) from the results of a
    benchmark (``benchmark.json`` of ``python -m agents.benchmark``, loaded).

    Per id it keeps the held-out seeds, which baseline is the best, the missing controllers and,
    per controller, its kind, per-episode returns and the benchmark's statistics. It adds
    ``commit`` (of the benchmark run), ``date`` (ISO 8601, UTC) and ``machine`` (default:
    :func:`machine_description`), and the settings the statistics need. It then recomputes
    every statistic from the returns (:func:`score_returns`) and raises
    :class:`ReferenceDataError` unless each equals the benchmark's number exactly, so the file
    cannot hold a number its returns do not give (or that lacks an entry the scores need). The
    benchmark's ``env_kwargs`` are kept, and :func:`score_policy` makes its envs with them."""
    _require(results, ("per_id", "aggregate", "settings"), "the benchmark results")
    settings = results["settings"]
    _require(
        settings,
        ("command", "episodes", "seeds", "reference", "zero", "confidence", "bootstrap", "env_kwargs"),
        "the benchmark's settings",
    )
    if not re.fullmatch(r"[0-9a-f]{7,40}", commit):
        raise ReferenceDataError(f"commit must be a git commit hash (7 to 40 hex digits); got {commit!r}")
    per_id = {}
    for env_id, entry in results["per_id"].items():
        _require(entry, ("best_baseline", "score", "controllers", "missing", "seeds"), f"per_id[{env_id!r}]")
        controllers = {}
        for name, item in entry["controllers"].items():
            _require(item, ("kind", "returns", "terminated", *_STATISTICS), f"per_id[{env_id!r}].controllers[{name!r}]")
            controllers[name] = {
                "kind": item["kind"],
                **{key: item[key] for key in _STATISTICS},
                "returns": item["returns"],
                "terminated": item["terminated"],
            }
        per_id[env_id] = {
            "seeds": entry["seeds"],
            "best_baseline": entry["best_baseline"],
            "score": entry["score"],
            "missing": entry["missing"],
            "controllers": controllers,
        }
    data = {
        "format": FORMAT,
        "version": FORMAT_VERSION,
        "about": (
            "Per-episode returns and statistics of every controller of python -m agents.benchmark on each id's "
            "held-out seeds; agents.scoring.score_policy scores a policy against them. Written by "
            "python -m agents.scoring from the benchmark.json of the run named here; do not edit by hand."
        ),
        "commit": commit,
        "command": settings["command"],
        "date": date,
        "machine": machine or machine_description(),
        "versions": settings.get("versions", {}),
        "episodes": settings["episodes"],
        "zero": settings["zero"],
        "reference": settings["reference"],
        "confidence": settings["confidence"],
        # What agents.evaluation.benchmark passes to score_interval: its resample count and the first held-out seed.
        "score_bootstrap": {"reps": SCORE_BOOTSTRAP_REPS, "seed": settings["bootstrap"]["random_state"]},
        # The shipped file's are {}: the ids' own settings (a test checks). Tests make shorter ones.
        "env_kwargs": settings["env_kwargs"],
        "aggregate_bootstrap": settings["bootstrap"],
        "aggregate": results["aggregate"],
        "per_id": per_id,
    }
    _check_statistics(data)
    return data


#: What must agree between reference scores for one to extend the other: the seeds' count, the
#: anchors, and every setting the statistics depend on.
_SHARED_SETTINGS = (
    "format",
    "version",
    "episodes",
    "zero",
    "reference",
    "confidence",
    "score_bootstrap",
    "env_kwargs",
    "aggregate_bootstrap",
)
#: Where an id's numbers come from: the benchmark run's provenance.
_RUN_KEYS = ("commit", "command", "date", "machine", "versions")


def run_of(data: dict[str, Any], env_id: str) -> dict[str, Any]:
    """The provenance (commit, command, date, machine, versions) of the benchmark run that gave
    ``env_id``'s numbers in the reference scores ``data``: the file's own run, or the run of the
    addition (see :func:`merge_reference`) that holds the id."""
    for addition in data.get("additions", []):
        if env_id in addition["ids"]:
            return {key: addition[key] for key in _RUN_KEYS}
    return {key: data.get(key) for key in _RUN_KEYS}


def merge_reference(base: dict[str, Any], addition: dict[str, Any]) -> dict[str, Any]:
    """Reference scores holding ``base``'s ids and ``addition``'s (both reference dicts, as
    :func:`reference_from_benchmark` makes them).

    A benchmark of new ids need not rerun the old ones: their per-seed returns do not depend on
    the other ids. The merged file keeps ``base``'s run and its aggregate, which covers only the
    ids it was computed over (``aggregate_ids``), and lists each addition's run and ids under
    ``additions``; :func:`run_of` says which run gave an id. An addition's ids replace those of an
    earlier addition.

    An addition that holds every id of ``base``'s aggregate is a rerun of it (new shipped models,
    say): its run and aggregate become the merged file's own, and ``base``'s additions of other
    ids are kept, so a track is rerun without rerunning the ids added to it. Raises
    :class:`ReferenceDataError` when a shared setting differs (the scores would not be
    comparable) or an addition holds some of the aggregate's ids but not all (the aggregate
    over ids would then mix two runs)."""
    for key in _SHARED_SETTINGS:
        if base.get(key) != addition.get(key):
            raise ReferenceDataError(
                f"the addition's {key} is {addition.get(key)!r}, the reference's {base.get(key)!r}: scores of other "
                "settings are not comparable; run the benchmark with the reference's settings"
            )
    if addition.get("additions"):
        raise ReferenceDataError("the addition is itself a merged file: add the benchmark of each run on its own")
    aggregate_ids = list(base.get("aggregate_ids", base["per_id"]))
    new_ids = list(addition["per_id"])
    replaced = sorted(set(new_ids) & set(aggregate_ids))
    rerun = set(aggregate_ids) <= set(new_ids)
    if replaced and not rerun:
        missing = [env_id for env_id in aggregate_ids if env_id not in new_ids]
        raise ReferenceDataError(
            f"{replaced} are ids of the reference's aggregate, but the addition lacks {missing}: an addition replaces "
            "the aggregate's ids only all together; rerun the benchmark on every one of them"
        )
    earlier = []
    for entry in base.get("additions", []):
        kept = [env_id for env_id in entry["ids"] if env_id not in new_ids]
        if kept:
            earlier.append({**entry, "ids": kept})
    per_id = {env_id: entry for env_id, entry in base["per_id"].items() if env_id not in new_ids}
    per_id.update(addition["per_id"])
    # In the order of the registry, as a benchmark of every id lists them (ids it does not know last).
    rank = {env_id: k for k, env_id in enumerate(ENV_IDS)}
    per_id = dict(sorted(per_id.items(), key=lambda item: rank.get(item[0], len(rank))))
    if rerun:
        merged = {**addition, "aggregate_ids": new_ids, "additions": earlier, "per_id": per_id}
    else:
        merged = {
            **base,
            "aggregate_ids": aggregate_ids,
            "additions": [*earlier, {"ids": new_ids, **{key: addition[key] for key in _RUN_KEYS}}],
            "per_id": per_id,
        }
    _check_statistics(merged)
    return merged


def load_reference(path: str | Path | None = None) -> dict[str, Any]:
    """The reference scores from ``path`` (default: the shipped :data:`REFERENCE_FILE`).

    Raises FileNotFoundError when the file is missing, :class:`ReferenceDataError` when it is
    not a reference-scores file of this version."""
    file = REFERENCE_FILE if path is None else Path(path)
    if not file.is_file():
        raise FileNotFoundError(
            f"no reference scores at {file}: write them from a benchmark with python -m {PACKAGE}.scoring "
            "BENCHMARK_JSON --commit COMMIT --out PATH"
        )
    data = read_json(file, ReferenceDataError, "rewrite it with python -m agents.scoring")
    if not isinstance(data, dict) or data.get("format") != FORMAT or data.get("version") != FORMAT_VERSION:
        found = (data.get("format"), data.get("version")) if isinstance(data, dict) else type(data).__name__
        raise ReferenceDataError(
            f"{file} is not a {FORMAT!r} file of version {FORMAT_VERSION} (found {found}): rewrite it with "
            f"python -m {PACKAGE}.scoring from a benchmark.json"
        )
    _require(data, ("commit", "zero", "reference", "confidence", "score_bootstrap", "env_kwargs", "per_id"), str(file))
    return data


def write_reference(
    benchmark_json: str | Path,
    commit: str,
    out: str | Path = REFERENCE_FILE,
    date: str | None = None,
    machine: str | None = None,
    force: bool = False,
    add_to: str | Path | None = None,
) -> dict[str, Any]:
    """Convert ``benchmark_json`` with :func:`reference_from_benchmark` and write the reference
    scores to ``out`` (atomically); returns them. ``date`` defaults to the time
    ``benchmark_json`` was last written (the end of the benchmark run), in UTC. An existing
    ``out`` is replaced only with ``force``. With ``add_to`` (a reference file), the benchmark's
    ids are added to that file's with :func:`merge_reference` instead."""
    from ..common.files import OutputError, atomic_write_text, check_output_files

    source = Path(benchmark_json)
    target = Path(out)
    if not target.parent.is_dir():
        raise OutputError(f"--out {target}: {target.parent} is not a directory: pass a path in an existing directory")
    # Checked before the benchmark is read: a symlink or a directory at --out is refused, an
    # existing file is replaced only with force.
    check_output_files(target.parent, [target.name], force, argument="--out", what="an earlier scoring")
    results = read_json(source, ReferenceDataError, "pass the benchmark.json that python -m agents.benchmark wrote")
    if date is None:
        written = datetime.datetime.fromtimestamp(source.stat().st_mtime, tz=datetime.timezone.utc)
        date = written.replace(microsecond=0).isoformat().replace("+00:00", "Z")
    data = reference_from_benchmark(results, commit, date, machine)
    if add_to is not None:
        data = merge_reference(load_reference(add_to), data)
    atomic_write_text(target, json.dumps(data, indent=1, allow_nan=False) + "\n")
    return data
