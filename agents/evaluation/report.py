"""The tables of the benchmark and of the comparison: Markdown for reading, CSV and JSON for
other tools. The numbers come computed (:mod:`agents.evaluation.benchmark`,
:func:`agents.evaluation.rollout.summarise`); this module only lays them out, and writes each
file atomically (:func:`agents.common.files.atomic_write_text`).
"""

from __future__ import annotations

import csv
import io
import json
import math
from pathlib import Path
from typing import Any

from ..common.files import atomic_write_text
from ..controllers.registry import BASELINES
from .rollout import METRICS, EpisodeRecord
from .stats import SCORE_BOOTSTRAP_REPS, ZERO

__all__ = [
    "benchmark_markdown",
    "clock",
    "comparison_markdown",
    "controller_columns",
    "json_ready",
    "write_benchmark_tables",
    "write_comparison_csv",
    "write_comparison_tables",
]


# ---------------------------------------------------------------------------------------- the benchmark


def clock(seconds: float) -> str:
    """``m:ss`` (or ``h:mm:ss``)."""
    whole = round(seconds)
    hours, rest = divmod(whole, 3600)
    return f"{hours}:{rest // 60:02d}:{rest % 60:02d}" if hours else f"{rest // 60}:{rest % 60:02d}"


def json_ready(value: Any) -> Any:
    """``value`` with NaN and infinities replaced by None (strict JSON has neither)."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {key: json_ready(item) for key, item in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_ready(item) for item in value]
    return value


def controller_columns(results: dict[str, Any]) -> list[str]:
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


#: What each track is, for the tables' headings.
_TRACK_TITLES = {
    "standard": "Standard track",
    "hard": "Hard track (room left over the best scripted law)",
}


def _track_overview(results: dict[str, Any], track: str, group: dict[str, Any], columns: list[str]) -> list[str]:
    """The overview of one track's ids: mean returns, normalised scores, and the track's own
    aggregate over ids (never one mixing tracks)."""
    reference = results["settings"]["reference"]
    ids = group["ids"]
    aggregate = group["aggregate"]
    aggregate_ids = group.get("aggregate_ids", ids)
    lines = [
        f"## {_TRACK_TITLES.get(track, track)}: {len(ids)} ids",
        "",
        "### Mean return per id (95 % t interval)",
        "",
        "| id | " + " | ".join(columns) + " |",
        "|---|" + "---|" * len(columns),
    ]
    for env_id in ids:
        entry = results["per_id"][env_id]
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
            f"### Normalised score per id (0 = {ZERO}, 100 = {reference}; score of the means "
            "[95 % paired bootstrap interval])"
        ),
        "",
        "| id | " + " | ".join(columns) + " |",
        "|---|" + "---|" * len(columns),
    ]
    for env_id in ids:
        entry = results["per_id"][env_id]
        cells = [_score_cell(entry["controllers"].get(name)) for name in columns]
        lines.append(f"| {env_id} | " + " | ".join(cells) + " |")
    lines += [
        "",
        (
            f"### Aggregate over the {track} track's ids (normalised scores; rliable: IQM and mean over ids, 95 % "
            "stratified bootstrap)"
        ),
        "",
    ]
    left_out = group.get("left_out") or {}
    if left_out:
        lines += [f"Outside the aggregate: {', '.join(f'{i} ({why})' for i, why in left_out.items())}.", ""]
    if aggregate:
        lines += ["| controller | ids | IQM [95 % CI] | mean [95 % CI] |", "|---|---|---|---|"]
        for row, values in aggregate.items():
            lines.append(
                f"| {row} | {values['ids']}/{len(aggregate_ids)} | "
                f"{_aggregate_cell(values, 'iqm')} | {_aggregate_cell(values, 'mean')} |"
            )
        lines += ["", "A row over fewer ids than another is not comparable with it.", ""]
    else:
        lines += [
            f"Not available: the normalised score needs {reference}, which did not run (or did not "
            f"beat {ZERO}) on any id of this track.",
            "",
        ]
    return lines


def _percent_cell(excess: dict[str, Any] | None) -> str:
    if excess is None:
        return "—"
    return f"{100 * excess['mean']:+.1f} % [{100 * excess['low']:+.1f}, {100 * excess['high']:+.1f}]"


def _aggregate_percent(entry: dict[str, Any], key: str) -> str:
    if not entry:
        return "n/a"
    low, high = entry[f"{key}_low"], entry[f"{key}_high"]
    if low is None or high is None:
        return f"{100 * entry[key]:+.1f} % [interval n/a]"
    return f"{100 * entry[key]:+.1f} % [{100 * low:+.1f}, {100 * high:+.1f}]"


def _ceiling_sections(ceiling: dict[str, Any] | None) -> list[str]:
    """Per track, every controller's excess cost over the reference ceiling (the ceiling's shipped
    returns on the seeds the benchmark ran): per id the best law and its excess cost (the room
    left) and every other controller's; the track's aggregate of excess costs and of the scores
    with 100 = the ceiling."""
    if not ceiling:
        return []
    lines = [
        "## Against the reference ceiling",
        "",
        (
            f"Reference ceiling: {ceiling['source']}. Excess cost over the ceiling, per seed "
            "(-R[c]) / (-R[ceiling]) - 1, mean over the ceiling's seeds that this run holds [paired 95 % t "
            "interval]; lower is better, 0 is the ceiling. Room left: the excess cost of the best scripted law."
        ),
        "",
    ]
    for track, entry in ceiling["tracks"].items():
        lines += [f"### {_TRACK_TITLES.get(track, track)}: excess cost over the ceiling", ""]
        per_id = entry["per_id"]
        names: list[str] = []
        for item in per_id.values():
            names += [n for n in item["controllers"] if n not in names and n != "ceiling" and n != item["best_law"]]
        if per_id:
            lines += [
                "| id | ceiling seeds | best law | room left | " + " | ".join(names) + " |",
                "|---|---|---|---|" + "---|" * len(names),
            ]
            for env_id, item in per_id.items():
                others = [
                    "(best law)"
                    if name == item["best_law"]
                    else _percent_cell((item["controllers"].get(name) or {}).get("excess_cost"))
                    for name in names
                ]
                lines.append(
                    f"| {env_id} | {len(item['seeds'])} | {item['best_law']} | {_percent_cell(item['room_left'])} | "
                    + " | ".join(others)
                    + " |"
                )
            lines.append("")
        skipped = {env_id: why for env_id, why in entry["coverage"].items() if why.startswith("skipped")}
        for env_id, why in skipped.items():
            lines.append(f"- {env_id}: {why}.")
        if skipped:
            lines.append("")
        if entry["aggregate"]:
            lines += [
                (
                    f"Over the {track} track's ids with a ceiling (rliable's IQM and mean, 95 % stratified-bootstrap "
                    "intervals over seeds within ids; score: 0 = passive, 100 = the ceiling):"
                ),
                "",
                "| controller | ids | excess cost IQM | excess cost mean | score IQM | score mean |",
                "|---|---|---|---|---|---|",
            ]
            for name, values in entry["aggregate"].items():
                excess, score = values["excess"], values["score"]
                score_cells = [_aggregate_cell(score, key) if score else "n/a" for key in ("iqm", "mean")]
                lines.append(
                    f"| {name} | {excess['ids']}/{len(per_id)} | {_aggregate_percent(excess, 'iqm')} | "
                    f"{_aggregate_percent(excess, 'mean')} | " + " | ".join(score_cells) + " |"
                )
            lines.append("")
        if entry["aggregate_note"]:
            lines += [f"({entry['aggregate_note']}.)", ""]
    return lines


def benchmark_markdown(results: dict[str, Any]) -> str:
    """``benchmark.md``: overview tables (mean return and normalised score per id), the
    aggregate, and a detailed table per id, with the definitions."""
    settings = results["settings"]
    seeds, reference = settings["seeds"], settings["reference"]
    columns = controller_columns(results)
    quick = settings.get("quick", False)
    lines = [
        "# tether-gym benchmark" + (" (QUICK MODE: a smoke check)" if quick else ""),
        "",
        (
            f"{len(settings['env_ids'])} ids; {settings['episodes']} held-out episodes per controller and id "
            f"(seeds {seeds[0]}..{seeds[-1]}); normalised score: 0 = {ZERO}, 100 = {reference}. "
            f"Made by `{settings['command']}` in {clock(results['wall_seconds'])}."
        ),
        "",
    ]
    if quick:
        lines += [
            (
                f"**Quick mode**: {settings['episodes']} episodes and no {reference}, a smoke check whose numbers are "
                "noisier than a full run's; the reference ceiling and the shipped reference scores give the "
                "planner's numbers."
            ),
            "",
        ]
    tracks = results.get("tracks") or {"standard": {"ids": list(results["per_id"]), "aggregate": results["aggregate"]}}
    for track, group in tracks.items():
        if group["ids"]:
            lines += _track_overview(results, track, group, columns)
    lines += _ceiling_sections(results.get("ceiling"))
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


def _aggregates_by_track(results: dict[str, Any]) -> list[tuple[str, dict[str, Any]]]:
    """Each track's aggregate over ids, the standard track's (``results["aggregate"]``) first."""
    tracks = results.get("tracks") or {}
    hard = (tracks.get("hard") or {}).get("aggregate") or {}
    return [("standard", results["aggregate"]), ("hard", hard)]


def write_benchmark_tables(out: Path, results: dict[str, Any]) -> None:
    """The benchmark's tables in ``out``, each written atomically: ``benchmark.md``
    (:func:`benchmark_markdown`), ``benchmark.json`` (``results``, strict JSON: None for NaN),
    ``scores.csv`` (per id and controller), ``episodes.csv`` (per episode) and ``aggregate.csv``
    (per aggregate row); an empty cell for a number that is not available."""
    atomic_write_text(out / "benchmark.md", benchmark_markdown(results))
    text = json.dumps(json_ready(results), indent=1, allow_nan=False)
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
            ["row", "ids", "iqm", "iqm_low", "iqm_high", "mean", "mean_low", "mean_high", "env_ids", "track"],
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
                    track,
                ]
                for track, aggregate in _aggregates_by_track(results)
                for row, v in aggregate.items()
            ],
        ),
    )


# ---------------------------------------------------------------------------------------- the comparison


def comparison_markdown(records: list[EpisodeRecord], summaries: list[dict[str, Any]]) -> str:
    """The comparison as a Markdown table, one row per controller."""
    headers = ["controller"] + [f"{title} ({unit})" if unit else title for _, title, unit in METRICS]
    lines = ["| " + " | ".join(headers) + " |", "|" + "---|" * len(headers)]
    for record, summary in zip(records, summaries, strict=True):
        lines.append("| " + " | ".join([record.name] + [summary["cells"][key] for key, _, _ in METRICS]) + " |")
    return "\n".join(lines)


def write_comparison_csv(path: Path, records: list[EpisodeRecord], summaries: list[dict[str, Any]]) -> None:
    """The comparison's numbers, one row per controller."""
    keys = list(summaries[0]["values"])
    stream = io.StringIO(newline="")
    writer = csv.writer(stream)
    writer.writerow(["controller"] + keys)
    for record, summary in zip(records, summaries, strict=True):
        writer.writerow([record.name] + [summary["values"][key] for key in keys])
    atomic_write_text(path, stream.getvalue())


def write_comparison_tables(
    out: Path, env_id: str, episodes: int, seed: int, records: list[EpisodeRecord], summaries: list[dict[str, Any]]
) -> str:
    """``comparison.md`` (a line naming the id, the episodes, their seeds ``seed ..
    seed+episodes-1`` and their length, then :func:`comparison_markdown`) and ``comparison.csv``
    (:func:`write_comparison_csv`) in ``out``, each written atomically; returns the Markdown table."""
    table = comparison_markdown(records, summaries)
    header = (
        f"{env_id}, {episodes} episodes per controller, seeds {seed}..{seed + episodes - 1}, "
        f"{records[0].time[-1]:.0f} s each\n\n"
    )
    atomic_write_text(out / "comparison.md", header + table + "\n")
    write_comparison_csv(out / "comparison.csv", records, summaries)
    return table
