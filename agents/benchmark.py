"""The benchmark: every id, every controller, on held-out seeds: ``python -m agents.benchmark``.

It runs, on every tether-gym id (:data:`tether_gym.registration.ENV_IDS`), every scripted
baseline (:data:`agents.controllers.registry.BASELINES`), the model-predictive reference ``mpc`` and every
model shipped for the id (:func:`agents.policies.shipped_models`), on the comparison's held-out
episodes: episode e of every controller on an id starts from the reset seeded ``seed + e``
(:data:`agents.compare.HELD_OUT_SEED` = 10 000 and up), through :func:`agents.evaluate.rollout`,
so a row here is the same episodes as the same row of ``agents.compare``. A controller that
:func:`agents.policies.make_controller` does not know on an id (``mpc`` before it exists, a
model shipped for another id) is listed as missing there, with the reason; nothing is invented
for it.

**What it reports, per id.** With ``R[c, e]`` the return (undiscounted sum of rewards) of
controller c in episode e, and E episodes:

* the mean return of each controller with its 95 % t interval (the comparison's
  :func:`agents.evaluate.summarise`);
* the *best scripted baseline*: the baseline with the highest mean return among the eligible
  ones. A baseline whose mean return is below passive's is not eligible, and the table says
  so. (Passive is always run, and is eligible.)
* the *paired difference* of every other controller against that baseline,
  ``d[e] = R[c, e] - R[best, e]`` (the same seed, so the same initial condition): its mean,
  with a 95 % **t interval** ``mean(d) ± t(0.975, E-1) · sd(d) / sqrt(E)`` (``sd`` with E-1
  degrees of freedom, quantile from ``scipy.stats.t``), and the number of episodes where c did
  better;
* the *normalised score*, 0 for passive and 100 for the reference (``mpc``), of the means:

      S[c] = 100 · (R̄[c] - R̄[passive]) / (R̄[ref] - R̄[passive]),

  an affine map of the mean return (as Atari's human-normalised score), so it ranks
  controllers as their mean returns do. Its 95 % interval is a paired percentile bootstrap
  (:data:`SCORE_BOOTSTRAP_REPS` resamples of the seeds, the same seeds for c, passive and the
  reference, seeded with ``--seed``): it includes the uncertainty of the denominator and the
  strong correlation of numerator and denominator, which both grow with a seed's initial
  energy (the reference's own interval is exactly [100, 100]). The score is "not available"
  on an id where the reference did not run, or did not beat passive's mean return.

  Per episode, ``score[c, e] = 100 · (R[c, e] - R[passive, e]) / (R̄[ref] - R̄[passive])``: the
  paired gain over passive on that seed, in units of the reference's mean gain; its mean over
  the episodes is S[c]. These feed the aggregate. (Why not a ratio per episode,
  ``(R[c,e] - R[p,e]) / (R[ref,e] - R[p,e])``: on a seed where the reference gains little over
  passive, it explodes. On each id, passive's smallest return is 2 to 13 % of its mean.)

**Across ids.** As in rliable (Agarwal et al. 2021), with each controller one run whose score
on an id is S[c] (the RL protocol: a run's score is its mean over evaluation episodes): the
interquartile mean :func:`rliable.metrics.aggregate_iqm` of the (1 run × ids) matrix of the
S[c], that is the mean of the middle half of the ids (with 8 ids, of the 4 between the 2 lowest
and the 2 highest), and the mean of the S[c] (:func:`rliable.metrics.aggregate_mean`), over the
ids where the score is available. Each gets a 95 % stratified percentile-bootstrap interval
from :func:`rliable.library.get_interval_estimates`: its ``StratifiedBootstrap`` resamples the
held-out episodes within each id (``--bootstrap-reps`` replications, 50 000 by default as in
rliable, seeded with ``--seed``), and each replication recomputes the per-id scores from the
drawn seeds, paired as above, so mpc's IQM is 100 with the interval [100, 100]. The intervals
cover the sampling of the held-out episodes, not training-seed variation (one shipped model
per id). Two extra rows take, per id, the best scripted baseline, and (when the shipped models
have different names on different ids) the id's shipped model. A row available on fewer ids
than another is not comparable with it: the table gives the count. The per-episode scores
``score[c, e]`` are written out too (``episodes.csv``), for other aggregates.

**Files in** ``--out`` (default ``outputs/benchmark``): ``benchmark.md`` (the tables, for the
README), ``benchmark.json`` (every number, per-episode returns included, and the settings),
``scores.csv`` (per id and controller), ``episodes.csv`` (per episode), ``aggregate.csv``,
and, unless ``--no-plots``, ``normalised_scores.png`` (per id, with the 95 % intervals),
``paired_differences.png`` and ``aggregate.png`` (rliable-style interval estimates). The command
is careful with files as ``agents.compare`` is (see :mod:`agents.common.files`): it checks ``--out``
and refuses to replace an earlier benchmark without ``--force`` before it loads a controller or
runs a rollout, and writes every file atomically.
"""

from __future__ import annotations

if __name__ == "__main__":  # --help and bad options answered before the slow imports below
    from .common.cli import parse_before_imports

    parse_before_imports("benchmark")

import argparse
import csv
import dataclasses
import io
import json
import math
import sys
import time
import warnings
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from tether_gym._optional import needs_extra, require
from tether_gym.limits import is_whole_number
from tether_gym.registration import ENV_IDS

from .common import cli
from .common.cli import HELD_OUT_SEED, REFERENCE
from .common.commands import command_line, program
from .common.files import (
    OutputError,
    atomic_write,
    atomic_write_text,
    prepare_table_outputs,
)
from .controllers.registry import BASELINES
from .evaluate import EpisodeRecord, rollout, summarise
from .pickled import PickleNotTrustedError
from .policies import OtherIdError, make_controller, shipped_models
from .safe_format import PolicyFormatError

with needs_extra("train", "the benchmark's statistics"):
    import scipy.stats

__all__ = [
    "REFERENCE",
    "ZERO",
    "PairedDifference",
    "aggregate_scores",
    "benchmark",
    "best_eligible_baseline",
    "main",
    "normalised_scores",
    "paired_difference",
    "score_interval",
]

#: The controller that scores 0: doing nothing.
ZERO = "passive"
#: Confidence level of every interval.
CONFIDENCE = 0.95
#: Bootstrap resamples of each per-id score interval.
SCORE_BOOTSTRAP_REPS = 10_000
#: Aggregate rows that are not one controller.
BEST_BASELINE_ROW = "best baseline (per id)"
SHIPPED_ROW = "shipped model (per id)"

TABLE_FILES = ("benchmark.md", "benchmark.json", "scores.csv", "episodes.csv", "aggregate.csv")
PLOT_FILES = ("normalised_scores.png", "paired_differences.png", "aggregate.png")


# ---------------------------------------------------------------------------------------- statistics


@dataclasses.dataclass(frozen=True)
class PairedDifference:
    """Controller a minus controller b over the same seeds, in return units.

    Attributes:
        mean: mean over episodes of ``a[e] - b[e]``.
        std: sample standard deviation of the differences (E-1 degrees of freedom).
        half_width: half-width of the two-sided t interval at :data:`CONFIDENCE`.
        low, high: the interval's ends, ``mean ∓ half_width``.
        wins: number of episodes where ``a[e] > b[e]``.
        episodes: E.
    """

    mean: float
    std: float
    half_width: float
    low: float
    high: float
    wins: int
    episodes: int


def _check_returns(name: str, values: Any) -> np.ndarray:
    array = np.asarray(values, dtype=np.float64)
    if array.ndim != 1 or array.size < 2:
        raise ValueError(f"{name} must be a 1-D array of at least 2 per-episode returns; got shape {array.shape}")
    if not np.all(np.isfinite(array)):
        raise ValueError(f"{name} has NaN or infinite returns: a return must be a finite number")
    return array


def _check_scored_returns(
    returns: Any, zero_returns: Any, reference_returns: Any, purpose: str
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The three (E,) return arrays of a score (controller, passive, reference), checked to be
    per-episode returns of the same seeds; ``purpose`` ("normalised scores need") starts the
    message when they are not."""
    returns = _check_returns("returns", returns)
    zero = _check_returns("zero_returns", zero_returns)
    reference = _check_returns("reference_returns", reference_returns)
    if not returns.shape == zero.shape == reference.shape:
        raise ValueError(
            f"{purpose} the same seeds on every side; got {returns.size}, {zero.size} and {reference.size} episodes"
        )
    return returns, zero, reference


def t_interval(values: np.ndarray, confidence: float = CONFIDENCE) -> tuple[float, float, float]:
    """``(mean, sample std, half-width)`` of the two-sided t interval of the mean of ``values``
    (1-D, at least 2 entries): ``t(1 - (1 - confidence)/2, n - 1) · std / sqrt(n)``."""
    count = values.size
    mean = float(values.mean())
    std = float(values.std(ddof=1))
    half_width = float(scipy.stats.t.ppf(0.5 + confidence / 2, count - 1) * std / math.sqrt(count))
    return mean, std, half_width


def paired_difference(returns: Any, baseline_returns: Any, confidence: float = CONFIDENCE) -> PairedDifference:
    """The paired difference ``returns - baseline_returns`` (both (E,), episode e of each on the
    same seed) with its t interval. Raises ValueError for arrays of different lengths, fewer
    than 2 episodes, or non-finite returns."""
    a = _check_returns("returns", returns)
    b = _check_returns("baseline_returns", baseline_returns)
    if a.shape != b.shape:
        raise ValueError(f"paired returns need one value per seed on both sides; got {a.size} and {b.size} episodes")
    differences = a - b
    mean, std, half_width = t_interval(differences, confidence)
    return PairedDifference(
        mean=mean,
        std=std,
        half_width=half_width,
        low=mean - half_width,
        high=mean + half_width,
        wins=int(np.sum(differences > 0)),
        episodes=int(a.size),
    )


def best_eligible_baseline(mean_returns: dict[str, float], zero: str = ZERO) -> tuple[str, dict[str, str]]:
    """The best scripted baseline of an id, and why the others are not it.

    ``mean_returns`` maps each scripted baseline that ran to its mean return; it must include
    ``zero`` (passive). A baseline whose mean return is below ``zero``'s is not eligible; the
    best is the eligible one with the highest mean return (the first listed on a tie).

    Returns ``(best name, {name: note})`` with a note for every baseline: ``"best"``,
    ``"eligible"`` or ``"not eligible: mean return below passive's"``."""
    if zero not in mean_returns:
        raise ValueError(f"the best-baseline rule compares with {zero!r}, which is not among {sorted(mean_returns)}")
    bar = mean_returns[zero]
    eligible = [name for name, value in mean_returns.items() if value >= bar]
    best = max(eligible, key=lambda name: mean_returns[name])  # max keeps the first of equal values
    excluded = f"not eligible: mean return below {zero}'s"
    notes = {name: "best" if name == best else "eligible" if name in eligible else excluded for name in mean_returns}
    return best, notes


def normalised_scores(returns: Any, zero_returns: Any, reference_returns: Any) -> np.ndarray:
    """Per-episode normalised scores (E,): ``100 (R[e] - R0[e]) / (mean(Rref) - mean(R0))``.

    ``returns``, ``zero_returns`` (passive) and ``reference_returns`` (mpc) are (E,) returns on
    the same seeds. Raises ValueError when the reference's mean return is not above passive's
    (the scale would be zero or reversed)."""
    returns, zero, reference = _check_scored_returns(returns, zero_returns, reference_returns, "normalised scores need")
    gap = float(reference.mean() - zero.mean())
    if not gap > 0:
        raise ValueError(f"the reference's mean return is not above passive's (gap {gap:.4g}): no score scale")
    return 100.0 * (returns - zero) / gap


def score_interval(
    returns: Any,
    zero_returns: Any,
    reference_returns: Any,
    reps: int = SCORE_BOOTSTRAP_REPS,
    seed: int = 0,
    confidence: float = CONFIDENCE,
) -> tuple[float, float] | None:
    """Paired percentile-bootstrap interval of the score of the means,
    ``100 (mean R - mean R0) / (mean Rref - mean R0)``.

    Each of ``reps`` resamples draws E seeds with replacement, the same seeds for the three
    (E,) return arrays, so the interval carries the denominator's uncertainty and the
    correlation between numerator and denominator (both grow with a seed's initial energy).
    Returns ``(low, high)``, or None when more than ``(1 - confidence) / 2`` of the resamples
    have a reference no better than passive (the scale itself is then uncertain)."""
    returns, zero, reference = _check_scored_returns(
        returns, zero_returns, reference_returns, "a paired bootstrap needs"
    )
    picks = np.random.default_rng(seed).integers(0, returns.size, size=(reps, returns.size))
    gains = (returns - zero)[picks].mean(axis=1)
    scales = (reference - zero)[picks].mean(axis=1)
    tail = (1.0 - confidence) / 2
    usable = scales > 0
    if np.mean(~usable) > tail:
        return None
    ratios = 100.0 * gains[usable] / scales[usable]
    low, high = np.quantile(ratios, [tail, 1.0 - tail])
    return float(low), float(high)


def _rliable() -> tuple[Any, Any]:
    """rliable's ``library`` and ``metrics`` modules, or an ImportError that says how to get them."""
    library = require("rliable.library", "train", "the benchmark's aggregate over ids (rliable==1.2.0, pandas<3)")
    metrics = require("rliable.metrics", "train", "the benchmark's aggregate over ids (rliable==1.2.0, pandas<3)")
    return library, metrics


def aggregate_scores(
    returns: dict[str, dict[str, Any]],
    zero_returns: dict[str, Any],
    reference_returns: dict[str, Any],
    reps: int = 50_000,
    seed: int = 0,
    confidence: float = CONFIDENCE,
) -> dict[str, dict[str, Any]]:
    """rliable's aggregates over ids of the normalised scores, one entry per row of ``returns``.

    ``returns[row][env_id]`` holds the row's (E,) returns on an id, and ``zero_returns[env_id]``
    and ``reference_returns[env_id]`` passive's and the reference's on the same seeds. Each row
    is one run (a controller, or one shipped model per id), whose score on an id is the score of
    its mean return, :func:`normalised_scores` averaged over the episodes. Over the ids where
    the row ran:

    * ``iqm``: :func:`rliable.metrics.aggregate_iqm` of the (1, ids) matrix of those scores, the
      mean of the middle half of the ids (scipy's 25 % trimmed mean);
    * ``mean``: :func:`rliable.metrics.aggregate_mean`, the mean of the per-id scores;
    * ``*_low`` / ``*_high``: their stratified percentile-bootstrap interval from
      :func:`rliable.library.get_interval_estimates` with ``reps`` replications. rliable's
      :class:`~rliable.library.StratifiedBootstrap` resamples an (E, ids) matrix of episode
      indices within each id; each replication's per-id scores are the scores of the means of
      the drawn seeds, the same seeds for the row, passive and the reference, so the resampling
      stays paired (the reference's own interval is exactly [100, 100]). A replication whose
      reference is no better than passive on some id has no score; if any does, the interval
      is None.

    The resampling is seeded with ``seed``: the intervals reproduce, and a row's interval does
    not depend on the other rows."""
    library, metrics = _rliable()
    results: dict[str, dict[str, Any]] = {}
    for name, per_id in returns.items():
        ids = list(per_id)
        if not ids:
            raise ValueError(f"row {name!r} has no id to aggregate over")
        gains, scales = [], []
        for env_id in ids:
            values = _check_returns(f"returns of {name!r} on {env_id}", per_id[env_id])
            zero = _check_returns(f"zero_returns on {env_id}", zero_returns[env_id])
            reference = _check_returns(f"reference_returns on {env_id}", reference_returns[env_id])
            if not values.shape == zero.shape == reference.shape:
                raise ValueError(
                    f"{name!r} on {env_id}: the returns need the same seeds on every side; got "
                    f"{values.size}, {zero.size} and {reference.size} episodes"
                )
            gains.append(values - zero)
            scales.append(reference - zero)
        episodes = {gain.size for gain in gains}
        if len(episodes) != 1:
            raise ValueError(f"row {name!r} has different episode counts on its ids: {sorted(episodes)}")
        gain, scale = np.stack(gains, axis=1), np.stack(scales, axis=1)  # (E, ids)

        def statistics(drawn: np.ndarray, gain: np.ndarray = gain, scale: np.ndarray = scale) -> np.ndarray:
            """IQM and mean over ids of the per-id scores of the episodes ``drawn`` ((E, ids) indices)."""
            columns = np.arange(gain.shape[1])
            picks = drawn.astype(np.intp)
            denominator = scale[picks, columns].mean(axis=0)
            if not np.all(denominator > 0):
                return np.array([math.nan, math.nan])
            per_id_scores = (100.0 * gain[picks, columns].mean(axis=0) / denominator)[None, :]  # (1 run, ids)
            return np.array([metrics.aggregate_iqm(per_id_scores), metrics.aggregate_mean(per_id_scores)])

        indices = np.tile(np.arange(gain.shape[0], dtype=np.float64)[:, None], (1, len(ids)))
        # rliable 1.2.0's StratifiedBootstrap.update_indices draws its resamples from numpy's
        # global generator (np.random.choice) and ignores ``random_state``: seed the global
        # generator for the call, and put back its state after it, so that the intervals
        # reproduce and nobody else's random stream is disturbed.
        global_state = np.random.get_state()
        np.random.seed(seed)
        try:
            with warnings.catch_warnings():
                # rliable hands arch the RandomState through arch's deprecated ``random_state``
                # keyword; arch only warns about the keyword's name.
                warnings.filterwarnings("ignore", "random_state is deprecated", FutureWarning)
                points, intervals = library.get_interval_estimates(
                    {name: indices},
                    statistics,
                    method="percentile",
                    reps=reps,
                    confidence_interval_size=confidence,
                    random_state=np.random.RandomState(seed),
                )
        finally:
            np.random.set_state(global_state)
        (iqm, mean), ((iqm_low, mean_low), (iqm_high, mean_high)) = points[name], intervals[name]
        bounds = [iqm_low, iqm_high, mean_low, mean_high]
        iqm_low, iqm_high, mean_low, mean_high = (None if not np.all(np.isfinite(bounds)) else float(b) for b in bounds)
        results[name] = {
            "iqm": float(iqm),
            "iqm_low": iqm_low,
            "iqm_high": iqm_high,
            "mean": float(mean),
            "mean_low": mean_low,
            "mean_high": mean_high,
            "ids": len(ids),
            "env_ids": ids,
            "episodes": int(gain.shape[0]),
        }
    return results


# ---------------------------------------------------------------------------------------- the run


@dataclasses.dataclass
class _Unit:
    """One rollout to do: a controller on an id."""

    env_id: str
    name: str
    controller: Any
    steps: int


class _Progress:
    """Progress over every rollout: a redrawn line per rollout on a terminal, one printed line
    per finished rollout, each with the elapsed time and an estimate of the time left.

    The estimate uses each controller's measured wall time per control step (the E episodes are
    stepped together) on the ids it has already run; a controller not timed yet is assumed to
    cost the mean of those that are."""

    def __init__(self, units: list[_Unit]) -> None:
        self.units = units
        self.start = time.perf_counter()
        self.rates: dict[str, list[float]] = {}
        self.interactive = sys.stdout.isatty()

    def estimate_left(self, done: int) -> float | None:
        known = {name: float(np.mean(rates)) for name, rates in self.rates.items()}
        if not known:
            return None
        fallback = float(np.mean(list(known.values())))
        return sum(known.get(unit.name, fallback) * unit.steps for unit in self.units[done:])

    def callback(self, index: int) -> Callable[[int, int], None]:
        unit = self.units[index]
        label = f"[{index + 1}/{len(self.units)}] {unit.env_id} {unit.name}"

        def report(steps_done: int, steps_total: int) -> None:
            if self.interactive and (steps_done % 10 == 0 or steps_done == steps_total):
                print(f"\r  {label}: step {steps_done}/{steps_total}", end="", flush=True)

        return report

    def finished(self, index: int, seconds: float, steps_run: int) -> None:
        unit = self.units[index]
        self.rates.setdefault(unit.name, []).append(seconds / max(steps_run, 1))
        elapsed = time.perf_counter() - self.start
        left = self.estimate_left(index + 1)
        estimate = "" if left is None or index + 1 == len(self.units) else f", about {_clock(left)} left"
        print(
            ("\r" if self.interactive else "")
            + f"  [{index + 1}/{len(self.units)}] {unit.env_id} {unit.name}: {seconds:.1f} s "
            + f"(elapsed {_clock(elapsed)}{estimate})"
            + " " * 10,
            flush=True,
        )


def _clock(seconds: float) -> str:
    """``m:ss`` (or ``h:mm:ss``)."""
    whole = round(seconds)
    hours, rest = divmod(whole, 3600)
    return f"{hours}:{rest // 60:02d}:{rest % 60:02d}" if hours else f"{rest // 60}:{rest % 60:02d}"


def _check_int(name: str, value: Any, minimum: int) -> int:
    if not is_whole_number(value) or value < minimum:
        raise ValueError(f"{name} must be an integer >= {minimum}; got {value!r}")
    return int(value)


def _check_names(name: str, values: Any, allowed: Sequence[str] | None = None) -> list[str] | None:
    """None, or a non-empty list of distinct non-empty strings (from ``allowed`` if given)."""
    if values is None:
        return None
    if isinstance(values, str) or not all(isinstance(v, str) and v for v in values):
        raise ValueError(f"{name} must be a list of names; got {values!r}")
    values = list(values)
    if not values:
        raise ValueError(f"{name} must name at least one entry (or be None for all)")
    repeated = sorted({v for v in values if values.count(v) > 1})
    if repeated:
        raise ValueError(f"{name} lists {repeated} more than once")
    if allowed is not None:
        unknown = [v for v in values if v not in allowed]
        if unknown:
            raise ValueError(f"{name}: unknown {unknown}; tether-gym ids are {list(allowed)}")
    return values


def _reason(error: Exception) -> str:
    """A one-line reason for a missing controller."""
    text = str(error).splitlines()[0] if str(error) else type(error).__name__
    return text if len(text) <= 160 else text[:157] + "..."


def benchmark(
    env_ids: Sequence[str] | None = None,
    controllers: Sequence[str] | None = None,
    episodes: int = 64,
    seed: int = HELD_OUT_SEED,
    out: str | Path = "outputs/benchmark",
    force: bool = False,
    plots: bool = True,
    trust_pickle: bool = False,
    allow_other_id: bool = False,
    reference: str = REFERENCE,
    bootstrap_reps: int = 50_000,
    env_kwargs: dict[str, Any] | None = None,
    command: str | None = None,
) -> dict[str, Any]:
    """Run the benchmark and write its files to ``out``; returns everything written to
    ``benchmark.json`` as a dict (see the module docstring for the definitions).

    Args:
        env_ids: ids to run (default: every id of :data:`tether_gym.registration.ENV_IDS`).
        controllers: names (baselines, ``mpc``, shipped model names) or policy directories, run
            on every id where :func:`agents.policies.make_controller` accepts them (default:
            every baseline, ``reference`` and every shipped model of each id). Passive is
            always added: it is the score's zero and the eligibility bar.
        episodes: held-out episodes per controller and id (E >= 2), seeds ``seed .. seed+E-1``.
        seed: first held-out seed; also seeds the bootstrap.
        out: output directory; an earlier benchmark there is replaced only with ``force``.
        plots: write the PNG plots (needs matplotlib).
        trust_pickle: allow pickle-based SB3 model paths in ``controllers``.
        allow_other_id: run a policy directory of ``controllers`` on every id of its observation
            shape, not only on the id it was trained on (with a warning).
        reference: the controller that scores 100 (default ``mpc``). Another name gives a
            differently anchored score, labelled as such in every table.
        bootstrap_reps: bootstrap replications of the aggregate's intervals.
        env_kwargs: passed to ``gym.make_vec`` for every id (tests shorten the episodes with
            ``{"max_episode_steps": ...}``; the reference scores use the ids' own settings).
        command: the command line recorded in the outputs (default: a Python call).

    Before any rollout it checks every argument, ``out`` (``OutputError`` for a file, a
    symlink, a path inside a file or an unwritable place; ``OutputExistsError`` for an earlier
    benchmark unless ``force``), that rliable (and matplotlib for plots) can be imported, and
    loads every controller on every id (so a corrupted model or an untrusted pickle stops it
    at once; an unknown name raises ValueError)."""
    import gymnasium as gym

    started_at = time.perf_counter()
    ids = _check_names("env_ids", env_ids, allowed=list(ENV_IDS)) or list(ENV_IDS)
    names = _check_names("controllers", controllers)
    episodes = _check_int("episodes", episodes, 2)  # two at least, for an interval
    seed = _check_int("seed", seed, 0)
    bootstrap_reps = _check_int("bootstrap_reps", bootstrap_reps, 100)
    if not isinstance(reference, str) or not reference or reference == ZERO:
        raise ValueError(f"reference must name a controller other than {ZERO!r} (it scores 100); got {reference!r}")
    _rliable()
    out = prepare_table_outputs(out, TABLE_FILES, PLOT_FILES, plots, force, what="an earlier benchmark")

    shipped = {env_id: shipped_models(env_id) for env_id in ids}
    if names is None:
        requested = None
    else:
        known = {*BASELINES, REFERENCE, reference, *(m for models in shipped.values() for m in models)}
        unknown = [name for name in names if name not in known and not Path(name).exists()]
        if unknown:
            raise ValueError(
                f"unknown controllers {unknown}: not a baseline ({', '.join(BASELINES)}), {REFERENCE}, the "
                f"reference {reference!r}, a model shipped for the selected ids, or an existing policy "
                "directory"
            )
        requested = ([ZERO] if ZERO not in names else []) + names
        if ZERO not in names:
            print(f"adding {ZERO!r}: it is the normalised score's zero and the best-baseline rule's bar")

    units: list[_Unit] = []
    missing: dict[str, list[dict[str, str]]] = {}
    for env_id in ids:
        candidates = requested or list(dict.fromkeys([*BASELINES, reference, *shipped[env_id]]))
        probe = gym.make_vec(env_id, num_envs=1, **dict(env_kwargs or {}))
        steps = probe.unwrapped.max_episode_steps
        missing[env_id] = []
        for name in candidates:
            try:
                controller = make_controller(name, probe, trust_pickle=trust_pickle, allow_other_id=allow_other_id)
            except (PolicyFormatError, PickleNotTrustedError):
                raise  # a corrupted model or an untrusted pickle is an error, not a missing controller
            except OtherIdError as error:
                reason = f"trained on {error.trained}; --allow-other-id runs it on other ids"
                missing[env_id].append({"controller": name, "reason": reason})
                continue
            except (ValueError, FileNotFoundError) as error:
                elsewhere = [other for other in ids if name in shipped[other]]
                reason = (
                    f"not shipped for this id, only for {', '.join(elsewhere)}"
                    if elsewhere and name not in shipped[env_id]
                    else _reason(error)
                )
                missing[env_id].append({"controller": name, "reason": reason})
                continue
            units.append(_Unit(env_id, name, controller, int(steps)))
        probe.close()
    seeds = list(range(seed, seed + episodes))
    print(f"benchmark: {len(ids)} ids, {len(units)} rollouts of {episodes} episodes (seeds {seeds[0]}..{seeds[-1]})")
    for env_id, entries in missing.items():
        for entry in entries:
            print(f"  missing on {env_id}: {entry['controller']} ({entry['reason']})")

    progress = _Progress(units)
    records: dict[str, dict[str, EpisodeRecord]] = {env_id: {} for env_id in ids}
    wall: dict[str, dict[str, float]] = {env_id: {} for env_id in ids}
    for index, unit in enumerate(units):
        started = time.perf_counter()
        record = rollout(
            unit.controller,
            unit.env_id,
            seeds,
            name=unit.name,
            env_kwargs=env_kwargs,
            progress=progress.callback(index),
        )
        seconds = time.perf_counter() - started
        records[unit.env_id][unit.name] = record
        wall[unit.env_id][unit.name] = seconds
        progress.finished(index, seconds, int(record.end_step.max()))
    rollout_seconds = time.perf_counter() - progress.start
    print(
        f"rollouts done in {_clock(rollout_seconds)}; statistics (rliable's bootstrap: {bootstrap_reps} "
        "replications per row) and files..."
    )

    results = _analyse(ids, records, wall, missing, reference, shipped, bootstrap_reps, seed)
    results["settings"] = {
        "command": command
        or f"{__package__}.benchmark.benchmark(env_ids={ids!r}, controllers={names!r}, "
        f"episodes={episodes}, seed={seed}, reference={reference!r})",
        "env_ids": ids,
        "episodes": episodes,
        "seeds": seeds,
        "reference": reference,
        "zero": ZERO,
        "confidence": CONFIDENCE,
        "bootstrap": {
            "method": "percentile, stratified by id, paired (rliable)",
            "reps": bootstrap_reps,
            "random_state": seed,
        },
        "env_kwargs": dict(env_kwargs or {}),
        "versions": _versions(),
    }
    results["rollout_seconds"] = rollout_seconds
    # From the call to the statistics, loading the controllers included; writing the files is left out,
    # since the time is written into them.
    results["wall_seconds"] = time.perf_counter() - started_at
    _write_outputs(out, results, records, plots)
    total_seconds = time.perf_counter() - started_at
    print(
        f"\nthe benchmark took {_clock(total_seconds)} ({total_seconds:.0f} s): {len(units)} rollouts in "
        f"{_clock(rollout_seconds)}, the rest loading controllers, statistics and files"
    )
    return results


def _versions() -> dict[str, str]:
    """Versions of the packages whose behaviour the numbers depend on."""
    from importlib import metadata

    versions = {}
    for package in ("tether-gym", "numpy", "scipy", "rliable", "arch", "stable-baselines3", "torch"):
        try:
            versions[package] = metadata.version(package)
        except metadata.PackageNotFoundError:
            versions[package] = "not installed"
    return versions


def _analyse(
    ids: list[str],
    records: dict[str, dict[str, EpisodeRecord]],
    wall: dict[str, dict[str, float]],
    missing: dict[str, list[dict[str, str]]],
    reference: str,
    shipped: dict[str, dict[str, Path]],
    bootstrap_reps: int,
    seed: int,
) -> dict[str, Any]:
    """Every statistic of the benchmark, as a JSON-ready dict (NaN never appears: None instead)."""
    per_id: dict[str, Any] = {}
    row_returns: dict[str, dict[str, np.ndarray]] = {}  # aggregate row -> id -> (E,) returns
    zero_returns: dict[str, np.ndarray] = {}  # id -> passive's (E,) returns, where the score exists
    reference_returns: dict[str, np.ndarray] = {}
    for env_id in ids:
        rows = records[env_id]
        returns = {name: record.rewards.sum(axis=1) for name, record in rows.items()}
        means = {name: float(values.mean()) for name, values in returns.items()}
        baselines = {name: means[name] for name in rows if name in BASELINES}
        best, notes = best_eligible_baseline(baselines)
        scores: dict[str, np.ndarray] = {}
        if reference not in rows:
            score_note = f"not available: {reference} did not run on this id"
        elif not means[reference] > means[ZERO]:
            score_note = (
                f"not available: {reference}'s mean return ({means[reference]:.4g}) is not above "
                f"{ZERO}'s ({means[ZERO]:.4g})"
            )
        else:
            score_note = f"0 = {ZERO}, 100 = {reference}"
            scores = {
                name: normalised_scores(values, returns[ZERO], returns[reference]) for name, values in returns.items()
            }
        controllers = {}
        for name, record in rows.items():
            summary = summarise(record)["values"]
            episode_steps = record.seeds.size * max(1, int(record.end_step.max()))
            paired = None if name == best else dataclasses.asdict(paired_difference(returns[name], returns[best]))
            entry: dict[str, Any] = {
                "kind": (
                    "baseline"
                    if name in BASELINES
                    else "reference"
                    if name == reference
                    else "shipped model"
                    if name in shipped[env_id]
                    else "policy"
                ),
                "mean_return": means[name],
                "return_ci95": summary["return_ci95"],
                "failures": int(record.terminated.sum()),
                "wall_seconds": wall[env_id][name],
                "wall_ms_per_episode_step": 1e3 * wall[env_id][name] / episode_steps,
                "baseline_note": notes.get(name),
                "paired_vs_best": paired,
                "normalised_score": None,
                "returns": returns[name].tolist(),
                "terminated": record.terminated.astype(bool).tolist(),
                "normalised_scores": scores[name].tolist() if name in scores else None,
            }
            if name in scores:
                interval = score_interval(returns[name], returns[ZERO], returns[reference], seed=seed)
                entry["normalised_score"] = {
                    "mean": float(scores[name].mean()),
                    "low": None if interval is None else interval[0],
                    "high": None if interval is None else interval[1],
                }
                row_returns.setdefault(name, {})[env_id] = returns[name]
            controllers[name] = entry
        if scores:
            zero_returns[env_id], reference_returns[env_id] = returns[ZERO], returns[reference]
            row_returns.setdefault(BEST_BASELINE_ROW, {})[env_id] = returns[best]
            models = [name for name in rows if name in shipped[env_id]]
            if len(models) == 1:
                row_returns.setdefault(SHIPPED_ROW, {})[env_id] = returns[models[0]]
        seeds = next(iter(rows.values())).seeds.tolist()
        per_id[env_id] = {
            "best_baseline": best,
            "score": score_note,
            "controllers": controllers,
            "missing": missing[env_id],
            "seeds": seeds,
        }
    shipped_names = {name for env_id in ids for name in records[env_id] if name in shipped[env_id]}
    if len(shipped_names) < 2:
        row_returns.pop(SHIPPED_ROW, None)  # the same numbers as the one shipped name's own row
    aggregate = (
        aggregate_scores(row_returns, zero_returns, reference_returns, reps=bootstrap_reps, seed=seed)
        if row_returns
        else {}
    )
    return {"per_id": per_id, "aggregate": aggregate, "aggregate_ids": len(ids)}


# ---------------------------------------------------------------------------------------- outputs


def _json_ready(value: Any) -> Any:
    """``value`` with NaN and infinities replaced by None (strict JSON has neither)."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {key: _json_ready(item) for key, item in value.items()}
    if isinstance(value, (list, tuple)):
        return [_json_ready(item) for item in value]
    return value


def _columns(results: dict[str, Any]) -> list[str]:
    """Every controller that ran on some id, in the order baselines, reference, the rest."""
    seen: list[str] = []
    for entry in results["per_id"].values():
        for name in entry["controllers"]:
            if name not in seen:
                seen.append(name)
    reference = results["settings"]["reference"]
    ordered = [name for name in BASELINES if name in seen] + [reference] * (reference in seen) + seen
    return list(dict.fromkeys(ordered))  # each once, in that order


def _score_cell(entry: dict[str, Any] | None) -> str:
    if entry is None:
        return "—"
    score = entry["normalised_score"]
    if score is None:
        return "n/a"
    if score["low"] is None:
        return f"{score['mean']:.1f} [interval n/a]"
    return f"{score['mean']:.1f} [{score['low']:.1f}, {score['high']:.1f}]"


def _aggregate_cell(row: dict[str, Any], key: str) -> str:
    if row[key + "_low"] is None:
        return f"{row[key]:.1f} [interval n/a]"
    return f"{row[key]:.1f} [{row[key + '_low']:.1f}, {row[key + '_high']:.1f}]"


def markdown_report(results: dict[str, Any]) -> str:
    """``benchmark.md``: overview tables (mean return and normalised score per id), the
    aggregate, and a detailed table per id, with the definitions."""
    settings = results["settings"]
    seeds, reference = settings["seeds"], settings["reference"]
    columns = _columns(results)
    lines = [
        "# tether-gym benchmark",
        "",
        (
            f"{len(settings['env_ids'])} ids; {settings['episodes']} held-out episodes per controller and id "
            f"(seeds {seeds[0]}..{seeds[-1]}); normalised score: 0 = {ZERO}, 100 = {reference}. "
            f"Made by `{settings['command']}` in {_clock(results['wall_seconds'])}."
        ),
        "",
        "## Mean return per id (95 % t interval)",
        "",
        "| id | " + " | ".join(columns) + " |",
        "|---|" + "---|" * len(columns),
    ]
    for env_id, entry in results["per_id"].items():
        cells = []
        for name in columns:
            item = entry["controllers"].get(name)
            cell = "—" if item is None else f"{item['mean_return']:.1f} ± {item['return_ci95']:.1f}"
            if name == entry["best_baseline"]:
                cell = f"**{cell}**"
            elif item is not None and (item["baseline_note"] or "").startswith("not eligible"):
                cell += " ✗"
            cells.append(cell)
        lines.append(f"| {env_id} | " + " | ".join(cells) + " |")
    lines += [
        "",
        (
            f"Bold: the id's best scripted baseline. ✗: a baseline whose mean return is below "
            f"{ZERO}'s, not eligible as best baseline. —: not run on the id (see the missing list "
            "below)."
        ),
        "",
        (
            f"## Normalised score per id (0 = {ZERO}, 100 = {reference}; score of the means "
            "[95 % paired bootstrap interval])"
        ),
        "",
        "| id | " + " | ".join(columns) + " |",
        "|---|" + "---|" * len(columns),
    ]
    for env_id, entry in results["per_id"].items():
        cells = [_score_cell(entry["controllers"].get(name)) for name in columns]
        lines.append(f"| {env_id} | " + " | ".join(cells) + " |")
    lines += [
        "",
        ("## Aggregate over ids (normalised scores; rliable: IQM and mean over ids, 95 % stratified bootstrap)"),
        "",
    ]
    if results["aggregate"]:
        lines += ["| controller | ids | IQM [95 % CI] | mean [95 % CI] |", "|---|---|---|---|"]
        for row, values in results["aggregate"].items():
            lines.append(
                f"| {row} | {values['ids']}/{results['aggregate_ids']} | "
                f"{_aggregate_cell(values, 'iqm')} | {_aggregate_cell(values, 'mean')} |"
            )
        lines += ["", "A row over fewer ids than another is not comparable with it."]
    else:
        lines.append(
            f"Not available: the normalised score needs {reference}, which did not run (or did not "
            f"beat {ZERO}) on any id."
        )
    lines += ["", "## Per id", ""]
    for env_id, entry in results["per_id"].items():
        best = entry["best_baseline"]
        lines += [f"### {env_id}", "", f"Best scripted baseline: **{best}**. Normalised score: {entry['score']}."]
        excluded = [
            name
            for name, item in entry["controllers"].items()
            if (item["baseline_note"] or "").startswith("not eligible")
        ]
        if excluded:
            lines.append(f"Not eligible as best baseline (mean return below {ZERO}'s): {', '.join(excluded)}.")
        if entry["missing"]:
            reasons = [f"{m['controller']} ({m['reason']})" for m in entry["missing"]]
            lines.append("Missing: " + "; ".join(reasons) + ".")
        lines += [
            "",
            (
                f"| controller | return (mean ± 95% CI) | failures | Δ return vs {best} "
                f"(mean [95% CI]) | better than {best} | normalised score | wall time (s) |"
            ),
            "|---|---|---|---|---|---|---|",
        ]
        for name, item in entry["controllers"].items():
            paired = item["paired_vs_best"]
            delta = "—" if paired is None else f"{paired['mean']:+.1f} [{paired['low']:+.1f}, {paired['high']:+.1f}]"
            wins = "—" if paired is None else f"{paired['wins']}/{paired['episodes']}"
            lines.append(
                f"| {name} | {item['mean_return']:.1f} ± {item['return_ci95']:.1f} | "
                f"{item['failures']}/{len(item['returns'])} | {delta} | {wins} | "
                f"{_score_cell(item)} | {item['wall_seconds']:.1f} |"
            )
        lines.append("")
    lines += [
        "## Definitions",
        "",
        (
            "- Return: the undiscounted sum of the rewards of an episode. Episode e of every controller on an "
            "id starts from the reset seeded `seed + e`."
        ),
        (
            "- Best scripted baseline: the highest mean return among the scripted baselines whose mean return "
            f"is not below {ZERO}'s."
        ),
        "- Δ return: paired by seed, d[e] = R[c, e] - R[best, e]; mean(d) ± t(0.975, E-1) sd(d)/√E.",
        (
            f"- Normalised score: 100 (mean R[c] - mean R[{ZERO}]) / (mean R[{reference}] - mean R[{ZERO}]), "
            f"with a paired percentile-bootstrap interval ({SCORE_BOOTSTRAP_REPS} resamples of the seeds, the "
            f"same for c, {ZERO} and {reference}). Per episode: 100 (R[c, e] - R[{ZERO}, e]) / "
            f"(mean R[{reference}] - mean R[{ZERO}]), whose mean is the score."
        ),
        (
            "- Aggregate: rliable's IQM over ids (the mean of the middle half of the per-id scores) and mean "
            f"over ids, with {settings['bootstrap']['reps']} stratified percentile-bootstrap replications: "
            "episodes resampled within each id, the per-id scores recomputed from each resample, paired "
            f"(seeded with {settings['bootstrap']['random_state']})."
        ),
    ]
    return "\n".join(lines) + "\n"


def _csv_text(header: list[str], rows: list[list[Any]]) -> str:
    stream = io.StringIO(newline="")
    writer = csv.writer(stream)
    writer.writerow(header)
    writer.writerows(
        ["" if v is None or (isinstance(v, float) and not math.isfinite(v)) else v for v in row] for row in rows
    )
    return stream.getvalue()


def _write_outputs(
    out: Path, results: dict[str, Any], records: dict[str, dict[str, EpisodeRecord]], plots: bool
) -> None:
    """Every file of the benchmark, each written atomically."""
    atomic_write_text(out / "benchmark.md", markdown_report(results))
    text = json.dumps(_json_ready(results), indent=1, allow_nan=False)
    atomic_write_text(out / "benchmark.json", text + "\n")
    score_rows, episode_rows = [], []
    for env_id, entry in results["per_id"].items():
        for name, item in entry["controllers"].items():
            paired, score = item["paired_vs_best"] or {}, item["normalised_score"] or {}
            score_rows.append(
                [
                    env_id,
                    name,
                    item["kind"],
                    item["mean_return"],
                    item["return_ci95"],
                    item["failures"],
                    item["baseline_note"],
                    entry["best_baseline"],
                    paired.get("mean"),
                    paired.get("low"),
                    paired.get("high"),
                    paired.get("wins"),
                    score.get("mean"),
                    score.get("low"),
                    score.get("high"),
                    item["wall_seconds"],
                ]
            )
            per_episode_scores = item["normalised_scores"] or [None] * len(item["returns"])
            for seed, value, ended, episode_score in zip(
                entry["seeds"], item["returns"], item["terminated"], per_episode_scores, strict=True
            ):
                episode_rows.append([env_id, name, seed, value, int(ended), episode_score])
    atomic_write_text(
        out / "scores.csv",
        _csv_text(
            [
                "env_id",
                "controller",
                "kind",
                "mean_return",
                "return_ci95",
                "failures",
                "baseline_note",
                "best_baseline",
                "paired_diff_mean",
                "paired_diff_low",
                "paired_diff_high",
                "paired_wins",
                "normalised_score",
                "normalised_score_low",
                "normalised_score_high",
                "wall_seconds",
            ],
            score_rows,
        ),
    )
    atomic_write_text(
        out / "episodes.csv",
        _csv_text(["env_id", "controller", "seed", "return", "terminated", "normalised_score"], episode_rows),
    )
    atomic_write_text(
        out / "aggregate.csv",
        _csv_text(
            ["row", "ids", "iqm", "iqm_low", "iqm_high", "mean", "mean_low", "mean_high", "env_ids"],
            [
                [
                    row,
                    v["ids"],
                    v["iqm"],
                    v["iqm_low"],
                    v["iqm_high"],
                    v["mean"],
                    v["mean_low"],
                    v["mean_high"],
                    " ".join(v["env_ids"]),
                ]
                for row, v in results["aggregate"].items()
            ],
        ),
    )
    written = [out / name for name in TABLE_FILES]
    if plots:
        plot_normalised_scores(results, out / "normalised_scores.png")
        plot_paired_differences(results, out / "paired_differences.png")
        plot_aggregate(results, out / "aggregate.png")
        written += [out / name for name in PLOT_FILES]
    print("wrote " + ", ".join(str(path) for path in written))


def _pyplot() -> Any:
    require("matplotlib", "plots", "the benchmark's plots (or pass --no-plots)").use("Agg")
    return require("matplotlib.pyplot", "plots", "the benchmark's plots (or pass --no-plots)")


def _save(fig: Any, path: Path) -> None:
    plt = _pyplot()
    fig.tight_layout()
    with atomic_write(path) as temporary:
        fig.savefig(temporary, dpi=120, format="png")
    plt.close(fig)


def _placeholder(path: Path, title: str, message: str) -> None:
    """A figure that says why there is nothing to plot (the file set stays the same)."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(8, 2.5))
    ax.axis("off")
    ax.set_title(title)
    ax.text(0.5, 0.5, message, ha="center", va="center", wrap=True)
    _save(fig, path)


#: The widest score axis of the plots, so that 0 and 100 stay readable: a controller that loses
#: formations scores thousands below 0; its bar or interval is cut at the axis' edge and labelled.
SCORE_AXIS = (-200.0, 400.0)


def _score_axis(values: list[float]) -> tuple[float, float]:
    """Axis limits that show 0, 100 and ``values`` with a margin, within :data:`SCORE_AXIS`."""
    low = max(SCORE_AXIS[0], min([-20.0, *values]) - 10.0)
    high = min(SCORE_AXIS[1], max([120.0, *values]) + 10.0)
    return low, high


def plot_normalised_scores(results: dict[str, Any], path: Path) -> None:
    """Per id, a bar per controller: the normalised score with its 95 % interval. Bars beyond
    :data:`SCORE_AXIS` are cut at its edge and labelled with their value."""
    plt = _pyplot()
    reference = results["settings"]["reference"]
    ids = [
        env_id
        for env_id, entry in results["per_id"].items()
        if any(item["normalised_score"] for item in entry["controllers"].values())
    ]
    if not ids:
        _placeholder(
            path, "normalised score", f"not available: {reference} did not run, or did not beat {ZERO}, on any id"
        )
        return
    columns = [name for name in _columns(results) if name != ZERO]
    scores = [
        item["normalised_score"]
        for entry in results["per_id"].values()
        for item in entry["controllers"].values()
        if item["normalised_score"]
    ]
    low_limit, high_limit = _score_axis(
        [s[key] for s in scores for key in ("mean", "low", "high") if s[key] is not None]
    )
    fig, ax = plt.subplots(figsize=(max(8.0, 1.3 * len(ids) + 3), 5.2))
    width = 0.8 / max(len(columns), 1)
    for k, name in enumerate(columns):
        x, mean, error = [], [], []
        for i, env_id in enumerate(ids):
            item = results["per_id"][env_id]["controllers"].get(name)
            if item is not None and item["normalised_score"] is not None:
                x.append(i - 0.4 + width * (k + 0.5))
                score = item["normalised_score"]
                mean.append(score["mean"])
                # The interval's ends within the axis (none: no error bar), as distances from the
                # bar's end, also cut at the axis.
                low, high, end = np.clip(
                    [
                        score["low"] if score["low"] is not None else score["mean"],
                        score["high"] if score["high"] is not None else score["mean"],
                        score["mean"],
                    ],
                    low_limit,
                    high_limit,
                )
                error.append((max(end - low, 0.0), max(high - end, 0.0)))
        if not x:
            continue
        shown = np.clip(mean, low_limit, high_limit)
        ax.bar(x, shown, width, yerr=np.transpose(error), capsize=2, label=name, error_kw={"linewidth": 0.8})
        for xi, value, cut in zip(x, mean, shown, strict=True):
            if value != cut:  # written inside the cut bar, from its cut end
                ax.text(
                    xi,
                    0.97 * cut,
                    f"{value:.0f}",
                    ha="center",
                    va="bottom" if cut < 0 else "top",
                    fontsize=7,
                    rotation=90,
                    color="white",
                )
    ax.axhline(0, color="0.3", linewidth=0.8)
    ax.axhline(100, color="0.3", linewidth=0.8, linestyle="--")
    ax.set_ylim(low_limit, high_limit)
    ax.set_xticks(range(len(ids)), [env_id.removeprefix("Tether") for env_id in ids], rotation=20, ha="right")
    ax.set_ylabel(f"normalised score (0 = {ZERO}, 100 = {reference})")
    ax.set_title(
        f"normalised score per id over {results['settings']['episodes']} episodes (95 % paired bootstrap interval)",
        fontsize=10,
    )
    ax.grid(True, axis="y", alpha=0.3)
    ax.legend(fontsize=8, ncol=min(len(columns), 5), loc="upper center", bbox_to_anchor=(0.5, -0.22), frameon=False)
    _save(fig, path)


def plot_paired_differences(results: dict[str, Any], path: Path) -> None:
    """Per id, every controller's paired return difference against the id's best scripted
    baseline: mean and 95 % t interval (a forest plot on a symmetric-log axis, since a lost
    formation costs thousands). Green: interval above 0; red: below 0."""
    plt = _pyplot()
    labels, means, lows, highs = [], [], [], []
    for env_id, entry in results["per_id"].items():
        for name, item in entry["controllers"].items():
            paired = item["paired_vs_best"]
            if paired is None:
                continue
            labels.append(f"{env_id.removeprefix('Tether')}: {name} − {entry['best_baseline']}")
            means.append(paired["mean"])
            lows.append(paired["low"])
            highs.append(paired["high"])
    if not labels:
        _placeholder(path, "paired differences", "nothing to compare: only the best baseline ran")
        return
    fig, ax = plt.subplots(figsize=(8, 0.28 * len(labels) + 1.3))
    y = np.arange(len(labels))[::-1]
    colours = np.where(np.asarray(lows) > 0, "tab:green", np.where(np.asarray(highs) < 0, "tab:red", "0.4"))
    ax.hlines(y, lows, highs, colors=colours, linewidth=2)
    ax.scatter(means, y, c=colours, s=14, zorder=3)
    ax.axvline(0, color="0.3", linewidth=0.8)
    ax.set_xscale("symlog", linthresh=10.0)
    ax.set_yticks(y, labels, fontsize=7)
    ax.set_xlabel("return minus the best scripted baseline's, paired by seed (mean, 95 % t interval)", fontsize=9)
    ax.grid(True, axis="x", alpha=0.3)
    _save(fig, path)


def plot_aggregate(results: dict[str, Any], path: Path) -> None:
    """rliable-style interval estimates across ids: per row, the 95 % stratified-bootstrap
    interval as a bar and the point estimate as a tick, for the IQM and the mean. Values beyond
    :data:`SCORE_AXIS` are cut at its edge and written out."""
    plt = _pyplot()
    reference = results["settings"]["reference"]
    aggregate = results["aggregate"]
    if not aggregate:
        _placeholder(
            path, "aggregate over ids", f"not available: {reference} did not run, or did not beat {ZERO}, on any id"
        )
        return
    rows = list(aggregate)
    keys = ("iqm", "iqm_low", "iqm_high", "mean", "mean_low", "mean_high")
    low_limit, high_limit = _score_axis(
        [aggregate[row][key] for row in rows for key in keys if aggregate[row][key] is not None]
    )
    fig, axes = plt.subplots(1, 2, figsize=(9, 0.45 * len(rows) + 1.6), sharey=True)
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for ax, key, title in zip(axes, ("iqm", "mean"), ("IQM", "mean"), strict=True):
        for j, row in enumerate(rows):
            values = aggregate[row]
            low, high, point = (
                float(np.clip(values[key] if values[k] is None else values[k], low_limit, high_limit))
                for k in (f"{key}_low", f"{key}_high", key)
            )
            ax.barh(j, max(high - low, 0.5), left=low, height=0.6, color=colours[j % len(colours)], alpha=0.75)
            ax.vlines(point, j - 0.3, j + 0.3, color="k", linewidth=1.5)
            if point != values[key]:
                ax.text(
                    point,
                    j,
                    f" {values[key]:.0f} ",
                    ha="left" if point == low_limit else "right",
                    va="center",
                    fontsize=7,
                )
        ax.axvline(0, color="0.5", linewidth=0.8)
        ax.axvline(100, color="0.5", linewidth=0.8, linestyle="--")
        ax.set_xlim(low_limit, high_limit)
        ax.set_title(title)
        ax.grid(True, axis="x", alpha=0.3)
    axes[0].set_yticks(
        range(len(rows)),
        [f"{row} ({aggregate[row]['ids']}/{results['aggregate_ids']} ids)" for row in rows],
        fontsize=8,
    )
    axes[0].invert_yaxis()
    fig.supxlabel(
        f"normalised score (0 = {ZERO}, 100 = {reference}); values off the axis written at its edge", fontsize=9
    )
    fig.suptitle("aggregate over ids: point estimate and 95 % stratified-bootstrap interval (rliable)", fontsize=10)
    _save(fig, path)


# ---------------------------------------------------------------------------------------- command line


def build_parser() -> argparse.ArgumentParser:
    """The command line of ``benchmark`` (defined in :mod:`agents.common.cli`, which the console script parses
    with before this module's slow imports)."""
    return cli.build_parser("benchmark")


def main(argv: list[str] | None = None) -> dict[str, Any]:
    arguments = sys.argv[1:] if argv is None else list(argv)
    args = build_parser().parse_args(arguments)
    return benchmark(
        env_ids=args.envs,
        controllers=args.controllers,
        episodes=args.episodes,
        seed=args.seed,
        out=args.out,
        force=args.force,
        plots=not args.no_plots,
        trust_pickle=args.trust_pickle,
        allow_other_id=args.allow_other_id,
        reference=args.reference,
        bootstrap_reps=args.bootstrap_reps,
        command=command_line("benchmark", arguments),
    )


if __name__ == "__main__":
    try:
        main()
    except (PickleNotTrustedError, OutputError, PolicyFormatError, ValueError, OSError, ImportError) as error:
        sys.exit(f"{program('benchmark')}: error: {error}")
