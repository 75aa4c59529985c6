"""Every controller of the reference scores against the reference ceiling, from shipped data alone.

The reference ceiling (:mod:`agents.evaluation.ceiling`) is the planner at full strength; its
per-seed returns on a subset of the benchmark's held-out seeds are shipped beside the reference
scores (:mod:`agents.evaluation.scoring`), which hold every other controller's per-seed returns on
all of them. :func:`ceiling_table` pairs the two on the ceiling's seeds, without running
anything, and gives per id and controller:

* the mean return (reward units) with its 95 % t interval;
* the **excess cost over the ceiling**, per seed ``(-R[c, e]) / (-R[ceiling, e]) - 1``: its mean
  over the ceiling's seeds with a 95 % t interval (paired: both sides of each ratio share their
  seed), and the seeds where the controller was cheaper than the ceiling;
* the normalised score with 0 = passive and 100 = the ceiling, with its paired bootstrap
  interval (the reference's resamples and bootstrap seed);
* the **gap closed**: the fraction of the best scripted law's excess cost that the controller
  removes, with its paired bootstrap interval (:func:`~.stats.gap_closed`; the issue's goal for
  a learned controller on a hard id is half of it);

per id, the ceiling's compute per env and control step, and the **room left**: the lowest mean
excess cost of any scripted law on those seeds (how much better than every hand-written law the
ceiling is); and over the ids, rliable's IQM and mean of the excess costs and of the normalised
scores, with stratified-bootstrap intervals over seeds within ids (the reference's aggregate
resamples and seed). :func:`ceiling_markdown` writes it as Markdown;
``python -m agents.scoring --ceiling`` prints it.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from .scoring import ReferenceDataError, ceiling_rows, ceiling_seeds_and_returns
from .stats import (
    ExcessCost,
    GapClosed,
    aggregate_excess_costs,
    aggregate_scores,
    excess_cost,
    gap_closed,
    score_with_interval,
    t_interval,
)

__all__ = ["BEST_LAW_ROW", "CEILING", "CeilingId", "CeilingRow", "CeilingTable", "ceiling_markdown", "ceiling_table"]

#: The row name of the ceiling itself.
CEILING = "ceiling"
#: The aggregate's row of the best scripted law of each id (the one with the least room left).
BEST_LAW_ROW = "best law (per id)"
#: The reference's kind of a scripted law (passive is one too, but no law: it is the zero).
_LAW = "baseline"


@dataclasses.dataclass(frozen=True)
class CeilingRow:
    """One controller on one id, on the ceiling's seeds.

    Attributes:
        env_id: the id.
        controller: its name in the reference scores (or :data:`CEILING`).
        kind: its kind there (``baseline``, ``reference``, ``shipped model``; ``ceiling``).
        returns: (E,) its returns on the ceiling's seeds, reward units.
        mean_return: mean return over the ceiling's seeds, reward units.
        return_ci95: half-width of its 95 % t interval.
        excess: the excess cost over the ceiling (fractions, :class:`~.stats.ExcessCost`).
        score: the normalised score, 0 = passive, 100 = the ceiling (None when the ceiling's
            mean return is not above passive's on these seeds).
        score_low, score_high: its 95 % paired bootstrap interval, or None.
        gap: the fraction of the id's best scripted law's excess cost it closes
            (:func:`~.stats.gap_closed`), or None when that law is not above the ceiling's cost.
    """

    env_id: str
    controller: str
    kind: str
    returns: np.ndarray
    mean_return: float
    return_ci95: float
    excess: ExcessCost
    score: float | None
    score_low: float | None
    score_high: float | None
    gap: GapClosed | None = None


@dataclasses.dataclass(frozen=True)
class CeilingId:
    """One id's ceiling and what its controllers leave to it.

    Attributes:
        env_id: the id.
        seeds: (E,) the ceiling's seeds, all among the reference's held-out seeds.
        seconds_per_step: the ceiling planner's compute per env and control step, s (None when
            the ceiling data do not say).
        machine: the machine that compute was measured on ("" when not known).
        best_law: the scripted law with the lowest mean excess cost on these seeds.
        room_left: its excess cost: how much the ceiling improves on every scripted law.
        rows: every controller of the reference on this id, then the ceiling.
    """

    env_id: str
    seeds: tuple[int, ...]
    seconds_per_step: float | None
    machine: str
    best_law: str
    room_left: ExcessCost
    rows: tuple[CeilingRow, ...]


@dataclasses.dataclass(frozen=True)
class CeilingTable:
    """:func:`ceiling_table`'s result.

    Attributes:
        ids: one :class:`CeilingId` per id with ceiling data, in the reference's order.
        aggregate: per controller (and ``best law (per id)``), over the ids where it ran:
            ``{"excess": ..., "score": ...}``, each an entry of
            :func:`~.stats.aggregate_excess_costs` or :func:`~.stats.aggregate_scores` (IQM,
            mean, their interval ends, ``ids``, ``env_ids``, ``episodes``); ``score`` is empty
            where ``aggregate_note`` says why.
        aggregate_note: "" or a note on the aggregate: over which seeds it runs where the ids'
            ceilings hold different numbers of seeds (each id's lowest seeds, as many as the
            fewest), or why part of it is missing.
        ids_total: the number of ids the aggregate is over.
        skipped: ids of the ceiling data that the reference scores do not hold, with why.
        bootstrap: the aggregate's ``{"reps": ..., "seed": ...}``.
    """

    ids: tuple[CeilingId, ...]
    aggregate: dict[str, dict[str, dict[str, Any]]]
    aggregate_note: str
    ids_total: int
    skipped: dict[str, str]
    bootstrap: dict[str, int]


def _id_table(env_id: str, entry: dict[str, Any], run: Any, reference: dict[str, Any]) -> CeilingId:
    seeds, ceiling_returns = ceiling_seeds_and_returns(run, env_id)
    rows_of_seeds = ceiling_rows(entry, env_id, seeds)
    controllers = entry["controllers"]
    zero = reference["zero"]
    zero_returns = np.asarray(controllers[zero]["returns"], dtype=np.float64)[rows_of_seeds]
    bootstrap = reference["score_bootstrap"]
    confidence = reference["confidence"]
    scaled = ceiling_returns.mean() > zero_returns.mean()
    rows = []
    named = [
        (name, item["kind"], np.asarray(item["returns"], dtype=np.float64)[rows_of_seeds])
        for name, item in controllers.items()
    ]
    for name, kind, values in [*named, (CEILING, CEILING, ceiling_returns)]:
        try:
            excess = excess_cost(values, ceiling_returns, confidence)
        except ValueError as error:
            raise ReferenceDataError(f"{env_id}, {name} against the ceiling: {error}") from None
        mean, _, half_width = t_interval(values, confidence)
        score = low = high = None
        if scaled:
            score, low, high = score_with_interval(
                values,
                zero_returns,
                ceiling_returns,
                reps=bootstrap["reps"],
                seed=bootstrap["seed"],
                confidence=confidence,
            )
        rows.append(CeilingRow(env_id, name, kind, values, mean, half_width, excess, score, low, high))
    laws = [row for row in rows if row.kind == _LAW and row.controller != zero]
    if not laws:
        raise ReferenceDataError(
            f"the reference scores of {env_id} hold no scripted law besides {zero}: no room left to state"
        )
    best = min(laws, key=lambda row: row.excess.mean)  # min keeps the first of equal values
    rows = [
        dataclasses.replace(
            row,
            gap=gap_closed(
                row.returns, best.returns, ceiling_returns, bootstrap["reps"], bootstrap["seed"], confidence
            ),
        )
        for row in rows
    ]
    return CeilingId(
        env_id=env_id,
        seeds=tuple(int(seed) for seed in seeds.tolist()),
        seconds_per_step=getattr(run, "seconds_per_step", None),
        machine=str(getattr(run, "machine", "") or ""),
        best_law=best.controller,
        room_left=best.excess,
        rows=tuple(rows),
    )


def ceiling_table(
    reference: dict[str, Any], ceiling: Mapping[str, Any], reps: int | None = None, seed: int | None = None
) -> CeilingTable:
    """Every controller of ``reference`` against the ceiling, on the ceiling's seeds of each id.

    Args:
        reference: reference scores (:func:`agents.evaluation.scoring.load_reference`'s dict).
        ceiling: id -> ceiling run, anything with ``.seeds`` (E,) and ``.returns`` (E,) (and
            optionally ``.seconds_per_step`` and ``.machine``), such as
            :func:`agents.evaluation.ceiling.load_ceiling`'s.
        reps, seed: the aggregate's bootstrap replications and seed (default: the reference's
            ``aggregate_bootstrap``, as the benchmark's aggregate has them).

    Returns:
        the :class:`CeilingTable`. Ids of ``ceiling`` that ``reference`` does not hold are left
        out and listed in ``skipped``.

    Raises:
        ReferenceDataError: an id's ceiling seeds are not among its reference seeds, or are
            fewer than 2; a ceiling return is not below 0; no id to tabulate.
    """
    per_id = reference["per_id"]
    skipped = {
        env_id: "the reference scores hold no returns for it: add its benchmark with python -m agents.scoring --add-to"
        for env_id in ceiling
        if env_id not in per_id
    }
    ids = tuple(_id_table(env_id, per_id[env_id], ceiling[env_id], reference) for env_id in per_id if env_id in ceiling)
    if not ids:
        raise ReferenceDataError(
            f"the ceiling data hold none of the reference's ids ({', '.join(per_id)}); they hold "
            f"{', '.join(ceiling) or 'none'}: compute the ceiling with python -m agents.ceiling"
        )
    settings = reference.get("aggregate_bootstrap", {})
    bootstrap = {
        "reps": int(reps if reps is not None else settings.get("reps", 50_000)),
        "seed": int(seed if seed is not None else settings.get("random_state", 0)),
    }
    aggregate: dict[str, dict[str, dict[str, Any]]] = {}
    counts = {len(item.seeds) for item in ids}
    common = min(counts)
    note = ""
    if len(counts) != 1:
        # The stratified bootstrap draws as many seeds within every id, so the aggregate keeps each
        # id's lowest `common` ceiling seeds: the held-out seeds every id's ceiling holds.
        note = (
            f"aggregate over each id's first {common} ceiling seeds, the most every id holds (the ids' ceilings "
            f"hold {sorted(counts)}); the per-id rows use all of each id's"
        )
    returns: dict[str, dict[str, np.ndarray]] = {}
    zero: dict[str, np.ndarray] = {}
    ceilings: dict[str, np.ndarray] = {}
    for item in ids:
        kept = np.sort(np.argsort(np.asarray(item.seeds), kind="stable")[:common])
        values = {row.controller: row.returns[kept] for row in item.rows}
        zero[item.env_id] = values[reference["zero"]]
        ceilings[item.env_id] = values[CEILING]
        for name, on_seeds in values.items():
            returns.setdefault(name, {})[item.env_id] = on_seeds
        returns.setdefault(BEST_LAW_ROW, {})[item.env_id] = values[item.best_law]
    scaled = all(ceilings[env_id].mean() > zero[env_id].mean() for env_id in ceilings)
    excess = aggregate_excess_costs(returns, ceilings, reps=bootstrap["reps"], seed=bootstrap["seed"])
    scores = aggregate_scores(returns, zero, ceilings, reps=bootstrap["reps"], seed=bootstrap["seed"]) if scaled else {}
    if not scaled:
        unscaled = "no aggregate of the normalised scores: on some id the ceiling's mean return is not above passive's"
        note = f"{note}; {unscaled}" if note else unscaled
    aggregate = {name: {"excess": excess[name], "score": scores.get(name, {})} for name in returns}
    return CeilingTable(ids, aggregate, note, len(ids), skipped, bootstrap)


def _percent(excess: ExcessCost) -> str:
    return f"{100 * excess.mean:+.1f} % [{100 * excess.low:+.1f}, {100 * excess.high:+.1f}]"


def _gap(gap: GapClosed | None) -> str:
    if gap is None:
        return "—"
    return f"{100 * gap.fraction:+.0f} % [{100 * gap.low:+.0f}, {100 * gap.high:+.0f}]"


def _score(score: float | None, low: float | None, high: float | None) -> str:
    if score is None:
        return "n/a"
    return f"{score:.1f} [interval n/a]" if low is None or high is None else f"{score:.1f} [{low:.1f}, {high:.1f}]"


def _aggregate_cell(entry: dict[str, Any], key: str, percent: bool) -> str:
    if not entry:
        return "n/a"
    scale, unit = (100.0, " %") if percent else (1.0, "")
    value, low, high = entry[key], entry[f"{key}_low"], entry[f"{key}_high"]
    sign = "+" if percent else ""
    if low is None or high is None:
        return f"{scale * value:{sign}.1f}{unit} [interval n/a]"
    return f"{scale * value:{sign}.1f}{unit} [{scale * low:{sign}.1f}, {scale * high:{sign}.1f}]"


def _seconds(value: float | None) -> str:
    if value is None or not math.isfinite(value):
        return "n/a"
    return f"{value:.3g} s"


def _span(seeds: tuple[int, ...]) -> str:
    first, last = seeds[0], seeds[-1]
    return f"{len(seeds)} ({first}..{last})" if seeds == tuple(range(first, last + 1)) else f"{len(seeds)} (chosen)"


def ceiling_markdown(table: CeilingTable, title: str = "Against the reference ceiling") -> str:
    """``table`` as Markdown under the heading ``## <title>``: the room left per id, the
    aggregate over ids, then one table per id of every controller (mean return ± 95 % t
    half-width; excess cost over the ceiling, mean [95 % t interval] in %; seeds cheaper than the
    ceiling; normalised score [95 % bootstrap interval], 0 = passive, 100 = the ceiling; the
    fraction of the best law's gap closed [95 % paired bootstrap interval], in %)."""
    lines = [
        f"## {title}",
        "",
        "Excess cost over the ceiling, per seed (-R[c]) / (-R[ceiling]) - 1: mean over the ceiling's seeds with its "
        "paired 95 % t interval; lower is better, 0 is the ceiling. Room left: the lowest excess cost of a scripted "
        "law. Normalised score: 0 = passive, 100 = the ceiling.",
        "",
        "| id | ceiling seeds | ceiling mean return | ceiling compute per step | best law | room left |",
        "|---|---|---|---|---|---|",
    ]
    for item in table.ids:
        ceiling_row = next(row for row in item.rows if row.kind == CEILING)
        machine = f" ({item.machine})" if item.machine else ""
        lines.append(
            f"| {item.env_id} | {_span(item.seeds)} | {ceiling_row.mean_return:.1f} ± {ceiling_row.return_ci95:.1f} | "
            f"{_seconds(item.seconds_per_step)}{machine} | {item.best_law} | {_percent(item.room_left)} |"
        )
    lines.append("")
    lines += [
        f"Over the {table.ids_total} id{'s' if table.ids_total != 1 else ''} (rliable's IQM and mean, "
        "95 % stratified-bootstrap intervals over seeds "
        f"within ids, {table.bootstrap['reps']} replications, seed {table.bootstrap['seed']}; a row over fewer ids "
        "is not comparable with the others):",
        "",
        "| controller | ids | excess cost IQM | excess cost mean | normalised score IQM | normalised score mean |",
        "|---|---|---|---|---|---|",
    ]
    for name, entry in table.aggregate.items():
        excess, score = entry["excess"], entry["score"]
        lines.append(
            f"| {name} | {excess['ids']}/{table.ids_total} | {_aggregate_cell(excess, 'iqm', True)} | "
            f"{_aggregate_cell(excess, 'mean', True)} | {_aggregate_cell(score, 'iqm', False)} | "
            f"{_aggregate_cell(score, 'mean', False)} |"
        )
    lines.append("")
    if table.aggregate_note:
        lines += [f"({table.aggregate_note}.)", ""]
    for item in table.ids:
        lines += [
            f"### {item.env_id}",
            "",
            "| controller | mean return | excess cost over the ceiling | cheaper than the ceiling | normalised score "
            f"| gap to {item.best_law} closed |",
            "|---|---|---|---|---|---|",
        ]
        for row in item.rows:
            name = f"**{row.controller}**" if row.controller == item.best_law else row.controller
            lines.append(
                f"| {name} | {row.mean_return:.1f} ± {row.return_ci95:.1f} | {_percent(row.excess)} | "
                f"{row.excess.beats}/{row.excess.episodes} | {_score(row.score, row.score_low, row.score_high)} | "
                f"{_gap(row.gap)} |"
            )
        lines.append("")
    for env_id, reason in table.skipped.items():
        lines.append(f"Not tabled: {env_id}: {reason}.")
    return "\n".join(lines).rstrip("\n") + "\n"
