"""The benchmark's statistics: t intervals, paired differences, the best eligible baseline,
normalised scores with their paired bootstrap intervals, excess costs over a reference ceiling,
and rliable's aggregates over ids.

Every function takes per-episode returns (undiscounted sums of rewards, reward units) of
episodes that share their seeds: entry e of every array is the episode reset with the same
seed, so differences between controllers are paired. :mod:`agents.evaluation.benchmark` defines
what each statistic means in its reports; :mod:`agents.evaluation.scoring` and the training's
model selection and shipping use the same functions, so their numbers are the benchmark's.
"""

from __future__ import annotations

import dataclasses
import math
import warnings
from typing import Any

import numpy as np

from tether_gym._optional import needs_extra, require

with needs_extra("train", "the benchmark's statistics"):
    import scipy.stats

__all__ = [
    "CONFIDENCE",
    "SCORE_BOOTSTRAP_REPS",
    "ZERO",
    "ExcessCost",
    "GapClosed",
    "PairedDifference",
    "aggregate_excess_costs",
    "aggregate_scores",
    "best_eligible_baseline",
    "excess_cost",
    "excess_costs",
    "gap_closed",
    "normalised_scores",
    "paired_difference",
    "rliable_modules",
    "score_interval",
    "score_with_interval",
    "t_interval",
]

#: The controller that scores 0: doing nothing.
ZERO = "passive"
#: Confidence level of every interval.
CONFIDENCE = 0.95
#: Bootstrap resamples of each per-id score interval.
SCORE_BOOTSTRAP_REPS = 10_000


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


def score_with_interval(
    returns: Any,
    zero_returns: Any,
    reference_returns: Any,
    reps: int = SCORE_BOOTSTRAP_REPS,
    seed: int = 0,
    confidence: float = CONFIDENCE,
) -> tuple[float, float | None, float | None]:
    """The normalised score of the mean of ``returns`` (E,) with 0 = ``zero_returns`` and 100 =
    ``reference_returns`` (the same seeds), and the ends of its paired bootstrap interval
    (:func:`score_interval`; None, None where it has none)."""
    score = float(normalised_scores(returns, zero_returns, reference_returns).mean())
    interval = score_interval(returns, zero_returns, reference_returns, reps=reps, seed=seed, confidence=confidence)
    low, high = (None, None) if interval is None else interval
    return score, low, high


@dataclasses.dataclass(frozen=True)
class ExcessCost:
    """A controller's excess cost over a reference ceiling on the ceiling's seeds, as fractions
    (0.044 is 4.4 %; lower is better, 0 is the ceiling's cost, below 0 a cost under it).

    Attributes:
        mean: mean over episodes of the per-seed excess costs ``(-R[e]) / (-R_ceiling[e]) - 1``
            (see :func:`excess_costs`).
        std: their sample standard deviation (E-1 degrees of freedom).
        half_width: half-width of the two-sided t interval of the mean at :data:`CONFIDENCE`.
        low, high: the interval's ends, ``mean ∓ half_width``.
        beats: number of episodes where the controller's cost is below the ceiling's
            (``R[e] > R_ceiling[e]``, an excess cost below 0).
        episodes: E.
    """

    mean: float
    std: float
    half_width: float
    low: float
    high: float
    beats: int
    episodes: int


def excess_costs(returns: Any, ceiling_returns: Any) -> np.ndarray:
    """Per-seed excess costs over the reference ceiling (E,): ``(-R[e]) / (-R_ceiling[e]) - 1``.

    ``returns`` and ``ceiling_returns`` are (E,) undiscounted returns (reward units; tether-gym's
    rewards are costs, so returns are below 0) of the episodes reset with the same E seeds. The
    excess cost is dimensionless: 0.1 means the controller spent 10 % more than the ceiling on
    that seed. Raises ValueError for arrays of different lengths, fewer than 2 episodes,
    non-finite returns, or a ceiling return that is not below 0 (its cost is the denominator)."""
    values = _check_returns("returns", returns)
    ceiling = _check_returns("ceiling_returns", ceiling_returns)
    if values.shape != ceiling.shape:
        raise ValueError(
            f"excess costs need one return per seed on both sides (the ceiling's seeds); got {values.size} and "
            f"{ceiling.size} episodes: pass the controller's returns on the ceiling's seeds"
        )
    free = np.flatnonzero(ceiling >= 0)
    if free.size:
        raise ValueError(
            f"the ceiling's return is {ceiling[free[0]]:.6g} (>= 0) on episode {int(free[0])} ({free.size} of "
            f"{ceiling.size} episodes): the excess cost (-R) / (-R[ceiling]) - 1 divides by the ceiling's cost, which "
            "must be above 0. tether-gym's rewards are costs, so these are not returns of the ceiling on an id's "
            "own rewards: recompute the ceiling data (python -m agents.ceiling), or compare with the normalised "
            "score instead"
        )
    return values / ceiling - 1.0  # (-R) / (-R_ceiling) - 1, the minus signs cancel


def excess_cost(returns: Any, ceiling_returns: Any, confidence: float = CONFIDENCE) -> ExcessCost:
    """The mean excess cost over the ceiling of (E,) ``returns`` against (E,) ``ceiling_returns``
    on the same seeds, with its t interval (:func:`excess_costs` per seed, :func:`t_interval`
    of their mean): paired, since both sides of a ratio share their seed. Raises ValueError as
    :func:`excess_costs` does."""
    costs = excess_costs(returns, ceiling_returns)
    mean, std, half_width = t_interval(costs, confidence)
    return ExcessCost(
        mean=mean,
        std=std,
        half_width=half_width,
        low=mean - half_width,
        high=mean + half_width,
        beats=int(np.sum(costs < 0)),
        episodes=int(costs.size),
    )


@dataclasses.dataclass(frozen=True)
class GapClosed:
    """How much of a scripted law's excess cost over the ceiling a controller removes, on the
    ceiling's seeds (a fraction: 0.5 is half the gap, 0 the law's cost, 1 the ceiling's, below 0
    a cost above the law's).

    Attributes:
        fraction: ``(mean(x_law) - mean(x_c)) / mean(x_law)``, x the per-seed excess costs
            (:func:`excess_costs`) of the law and the controller.
        low, high: its paired percentile-bootstrap interval at :data:`CONFIDENCE` (seeds drawn
            with replacement, the same seeds for the controller, the law and the ceiling).
        episodes: E.
    """

    fraction: float
    low: float
    high: float
    episodes: int


def gap_closed(
    returns: Any,
    law_returns: Any,
    ceiling_returns: Any,
    reps: int = SCORE_BOOTSTRAP_REPS,
    seed: int = 0,
    confidence: float = CONFIDENCE,
) -> GapClosed | None:
    """The fraction of the gap between a scripted law and the ceiling that ``returns`` close.

    ``returns``, ``law_returns`` and ``ceiling_returns`` are (E,) returns (reward units) of the
    episodes reset with the same E seeds. The gap is the law's mean excess cost over the ceiling;
    the fraction closed is the part of it the controller's mean excess cost removes. It is a ratio
    of means, so its interval is a paired percentile bootstrap (:func:`scipy.stats.bootstrap`,
    ``reps`` resamples seeded with ``seed``) rather than a t interval. None when the law's mean
    excess cost is not above 0 (no gap to close). Raises ValueError as :func:`excess_costs`."""
    controller = excess_costs(returns, ceiling_returns)
    law = excess_costs(law_returns, ceiling_returns)
    if law.mean() <= 0.0:
        return None

    def statistic(drawn_controller: np.ndarray, drawn_law: np.ndarray, axis: int = -1) -> np.ndarray:
        gap = drawn_law.mean(axis=axis)
        # A resample whose law is not above the ceiling has no gap; it counts as closing none.
        return np.where(gap > 0.0, 1.0 - drawn_controller.mean(axis=axis) / np.where(gap > 0.0, gap, 1.0), 0.0)

    result = scipy.stats.bootstrap(
        (controller, law),
        statistic,
        paired=True,
        vectorized=True,
        n_resamples=reps,
        confidence_level=confidence,
        method="percentile",
        random_state=np.random.default_rng(seed),
    )
    interval = result.confidence_interval
    return GapClosed(
        fraction=float(1.0 - controller.mean() / law.mean()),
        low=float(interval.low),
        high=float(interval.high),
        episodes=int(controller.size),
    )


def aggregate_excess_costs(
    returns: dict[str, dict[str, Any]],
    ceiling_returns: dict[str, Any],
    reps: int = 50_000,
    seed: int = 0,
    confidence: float = CONFIDENCE,
) -> dict[str, dict[str, Any]]:
    """rliable's aggregates over ids of the mean excess costs over the ceiling, one entry per row.

    ``returns[row][env_id]`` holds the row's (E,) returns on the ceiling's seeds of an id, and
    ``ceiling_returns[env_id]`` the ceiling's (E,) returns on them. A row's value on an id is its
    mean excess cost (:func:`excess_cost`'s ``mean``, a fraction); over the ids where the row ran:

    * ``iqm``: :func:`rliable.metrics.aggregate_iqm` of the (1, ids) matrix of those values, the
      mean of the middle half of the ids;
    * ``mean``: :func:`rliable.metrics.aggregate_mean`, their mean;
    * ``*_low`` / ``*_high``: their stratified percentile-bootstrap interval over seeds within
      ids (:func:`rliable.library.get_interval_estimates`, ``reps`` replications seeded with
      ``seed``), as :func:`aggregate_scores` has it: each replication draws E seeds with
      replacement within every id, the same seeds for the row and the ceiling (the ceiling's
      own interval is [0, 0]). The percentile interval is the quantiles of the replications'
      values, whichever way is better, so ``low`` is the lower excess cost (the better end).

    The ids of a row need the same episode count E. Raises ValueError as :func:`excess_costs`
    does, naming the row and the id."""
    _, metrics = rliable_modules()
    results: dict[str, dict[str, Any]] = {}
    for name, per_id in returns.items():
        ids = list(per_id)
        if not ids:
            raise ValueError(f"row {name!r} has no id to aggregate over")
        columns = []
        for env_id in ids:
            if env_id not in ceiling_returns:
                raise ValueError(f"row {name!r} has returns on {env_id}, where the ceiling has none")
            try:
                columns.append(excess_costs(per_id[env_id], ceiling_returns[env_id]))
            except ValueError as error:
                raise ValueError(f"{name!r} on {env_id}: {error}") from None
        episodes = {column.size for column in columns}
        if len(episodes) != 1:
            raise ValueError(
                f"row {name!r} has different episode counts on its ids: {sorted(episodes)}; the stratified bootstrap "
                "draws the same number of seeds within every id: give every id the same ceiling seeds' count"
            )
        costs = np.stack(columns, axis=1)  # (E, ids)

        def statistics(drawn: np.ndarray, costs: np.ndarray = costs) -> np.ndarray:
            """IQM and mean over ids of the per-id mean excess costs of the episodes ``drawn`` ((E, ids) indices)."""
            per_id_means = costs[drawn.astype(np.intp), np.arange(costs.shape[1])].mean(axis=0)[None, :]  # (1, ids)
            return np.array([_iqm(per_id_means), metrics.aggregate_mean(per_id_means)])

        results[name] = _aggregate_entry(name, ids, costs.shape[0], statistics, reps, seed, confidence)
    return results


def rliable_modules() -> tuple[Any, Any]:
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
    _, metrics = rliable_modules()
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
            return np.array([_iqm(per_id_scores), metrics.aggregate_mean(per_id_scores)])

        results[name] = _aggregate_entry(name, ids, gain.shape[0], statistics, reps, seed, confidence)
    return results


def _aggregate_entry(
    name: str,
    ids: list[str],
    episodes: int,
    statistics: Any,
    reps: int,
    seed: int,
    confidence: float,
) -> dict[str, Any]:
    """One row's aggregate: the IQM and mean that ``statistics`` gives on the (episodes, ids)
    matrix of every episode, with their stratified-bootstrap intervals, and the ids it covers."""
    (iqm, mean), (iqm_low, iqm_high, mean_low, mean_high) = _stratified_bootstrap(
        name, episodes, len(ids), statistics, reps, seed, confidence
    )
    return {
        "iqm": iqm,
        "iqm_low": iqm_low,
        "iqm_high": iqm_high,
        "mean": mean,
        "mean_low": mean_low,
        "mean_high": mean_high,
        "ids": len(ids),
        "env_ids": ids,
        "episodes": int(episodes),
    }


def _iqm(scores: np.ndarray) -> float:
    """:func:`rliable.metrics.aggregate_iqm` of ``scores`` (runs, ids), to the bit: the mean of the
    middle half of its values, scipy's 25 % trimmed mean, with scipy's operations. Written out
    because the bootstrap calls it once per replication, and scipy's argument-checking wrapper
    costs about 0.7 ms a call (35 s a row at 50 000 replications); the numbers are the same
    (a test compares them)."""
    values = scores.ravel()
    cut = int(0.25 * values.size)
    return float(np.mean(np.partition(values, (cut, values.size - cut - 1))[cut : values.size - cut]))


def _stratified_bootstrap(
    name: str,
    episodes: int,
    ids: int,
    statistics: Any,
    reps: int,
    seed: int,
    confidence: float,
) -> tuple[tuple[float, float], tuple[float | None, float | None, float | None, float | None]]:
    """rliable's stratified percentile bootstrap of ``statistics`` (a function of an (E, ids)
    matrix of drawn episode indices that returns ``[IQM, mean]`` over ids) for one row.

    Returns ``((iqm, mean), (iqm_low, iqm_high, mean_low, mean_high))``; the interval's ends are
    None when a replication had no value (``statistics`` returned NaN)."""
    library, _ = rliable_modules()
    indices = np.tile(np.arange(episodes, dtype=np.float64)[:, None], (1, ids))
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
    return (float(iqm), float(mean)), (iqm_low, iqm_high, mean_low, mean_high)
