"""The plots of the comparison and of the benchmark, PNG files drawn with matplotlib (the ``plots``
extra) on its Agg backend, so no display is needed. Each file is written atomically.

* The comparison (:mod:`agents.evaluation.comparison`): :func:`plot_energy` and
  :func:`plot_displacement`, from the episode records.
* The benchmark (:mod:`agents.evaluation.benchmark`): :func:`plot_normalised_scores`,
  :func:`plot_paired_differences`, :func:`plot_aggregate` and :func:`plot_excess_costs`, from its results (the dict
  written to ``benchmark.json``). Scores beyond :data:`SCORE_AXIS` are cut at the axis' edge and
  written out.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from tether_gym._optional import require

from ..common.files import atomic_write
from .report import controller_columns
from .rollout import EpisodeRecord
from .stats import ZERO

__all__ = [
    "EXCESS_AXIS",
    "SCORE_AXIS",
    "plot_aggregate",
    "plot_displacement",
    "plot_energy",
    "plot_excess_costs",
    "plot_normalised_scores",
    "plot_paired_differences",
]

#: What each command's plots are called in the message that names the missing extra.
COMPARISON = "the comparison's plots (or pass --no-plots)"
BENCHMARK = "the benchmark's plots (or pass --no-plots)"


def _pyplot(purpose: str) -> Any:
    """matplotlib's pyplot on the Agg backend (files only, no display needed), or an ImportError
    that names the ``plots`` extra and ``purpose``."""
    require("matplotlib", "plots", purpose).use("Agg")
    return require("matplotlib.pyplot", "plots", purpose)


def _save(plt: Any, fig: Any, path: Path) -> None:
    """Lay ``fig`` out, write it to ``path`` as a 120 dpi PNG (atomically) and close it."""
    fig.tight_layout()
    with atomic_write(path) as temporary:
        fig.savefig(temporary, dpi=120, format="png")
    plt.close(fig)


# ---------------------------------------------------------------------------------------- the comparison


def plot_energy(records: list[EpisodeRecord], path: Path, env_id: str) -> None:
    """E(t)/E0: median line and interquartile band per controller, log scale."""
    plt = _pyplot(COMPARISON)

    fig, ax = plt.subplots(figsize=(8, 4.8))
    for record in records:
        ratio = record.energy / record.energy[:, :1]
        median = np.nanmedian(ratio, axis=0)
        low, high = np.nanpercentile(ratio, [25, 75], axis=0)
        line = ax.semilogy(record.time, median, label=record.name)[0]
        ax.fill_between(record.time, low, high, color=line.get_color(), alpha=0.18, linewidth=0)
    ax.axhline(0.05, color="0.5", linestyle=":", linewidth=1)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("vibration energy / initial")
    ax.set_title(
        f"{env_id}: vibration energy, median and interquartile range over {records[0].energy.shape[0]} episodes"
    )
    ax.grid(True, which="both", alpha=0.3)
    ax.legend()
    _save(plt, fig, path)


def plot_displacement(records: list[EpisodeRecord], path: Path, env_id: str, satellite: int) -> None:
    """Satellite ``satellite``'s displacement components over time in the first episode."""
    plt = _pyplot(COMPARISON)

    fig, axes = plt.subplots(3, 1, figsize=(8, 6.5), sharex=True)
    for record in records:
        for axis, ax in enumerate(axes):
            ax.plot(record.time, 1e3 * record.displacement[0, :, axis], label=record.name, linewidth=1.1)
    for axis, ax in enumerate(axes):
        ax.set_ylabel(f"{'xyz'[axis]} (mm)")
        ax.grid(True, alpha=0.3)
    axes[-1].set_xlabel("time (s)")
    axes[0].set_title(f"{env_id}: satellite {satellite} displacement from nominal, episode seed {records[0].seeds[0]}")
    axes[0].legend(ncol=3, fontsize=8)
    _save(plt, fig, path)


# ---------------------------------------------------------------------------------------- the benchmark


def _placeholder(path: Path, title: str, message: str) -> None:
    """A figure that says why there is nothing to plot (the file set stays the same)."""
    plt = _pyplot(BENCHMARK)
    fig, ax = plt.subplots(figsize=(8, 2.5))
    ax.axis("off")
    ax.set_title(title)
    ax.text(0.5, 0.5, message, ha="center", va="center", wrap=True)
    _save(plt, fig, path)


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
    plt = _pyplot(BENCHMARK)
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
    columns = [name for name in controller_columns(results) if name != ZERO]
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
    _save(plt, fig, path)


def plot_paired_differences(results: dict[str, Any], path: Path) -> None:
    """Per id, every controller's paired return difference against the id's best scripted
    baseline: mean and 95 % t interval (a forest plot on a symmetric-log axis, since a lost
    formation costs thousands). Green: interval above 0; red: below 0."""
    plt = _pyplot(BENCHMARK)
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
    _save(plt, fig, path)


def plot_aggregate(results: dict[str, Any], path: Path) -> None:
    """rliable-style interval estimates across ids: per row, the 95 % stratified-bootstrap
    interval as a bar and the point estimate as a tick, for the IQM and the mean. Values beyond
    :data:`SCORE_AXIS` are cut at its edge and written out."""
    plt = _pyplot(BENCHMARK)
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
    _save(plt, fig, path)


#: The excess-cost axis of :func:`plot_excess_costs`, in %: the strong controllers sit within tens
#: of % of the ceiling, passive hundreds of % above it; values beyond are cut at the edge and written.
EXCESS_AXIS = (-20.0, 100.0)


def plot_excess_costs(results: dict[str, Any], path: Path) -> None:
    """Per track, every controller's excess cost over the reference ceiling on each id (mean and
    95 % t interval, in %; 0 = the ceiling), from the results' ``ceiling`` entry; the best law of
    each id in bold. Values beyond :data:`EXCESS_AXIS` are cut at its edge and written out. A
    figure that says why when no id has ceiling data."""
    plt = _pyplot(BENCHMARK)
    tracks = {
        track: entry["per_id"]
        for track, entry in ((results.get("ceiling") or {}).get("tracks") or {}).items()
        if entry["per_id"]
    }
    if not tracks:
        _placeholder(path, "excess cost over the reference ceiling", "not available: no id has ceiling data here")
        return
    low_limit, high_limit = EXCESS_AXIS
    heights = [sum(len(item["controllers"]) - 1 for item in per_id.values()) for per_id in tracks.values()]
    fig, axes = plt.subplots(
        len(tracks),
        1,
        figsize=(9, 0.22 * sum(heights) + 1.5 * len(tracks)),
        squeeze=False,
        gridspec_kw={"height_ratios": heights},
    )
    for ax, (track, per_id) in zip(axes[:, 0], tracks.items(), strict=True):
        labels: list[str] = []
        for env_id, item in per_id.items():
            for name, row in item["controllers"].items():
                if name == "ceiling":
                    continue
                j = len(labels)
                excess = row["excess_cost"]
                mean, low, high = (
                    float(np.clip(100 * excess[k], low_limit, high_limit)) for k in ("mean", "low", "high")
                )
                ax.barh(
                    j, high - low, left=low, height=0.6, color="C1" if name == item["best_law"] else "C0", alpha=0.7
                )
                ax.vlines(mean, j - 0.3, j + 0.3, color="k", linewidth=1.2)
                if mean != 100 * excess["mean"]:
                    text = f" {100 * excess['mean']:.0f} % "
                    ax.text(mean, j, text, ha="right" if mean == high_limit else "left", va="center", fontsize=7)
                labels.append(f"{env_id}: {name}" + (" (best law)" if name == item["best_law"] else ""))
        ax.set_yticks(range(len(labels)), labels, fontsize=7)
        ax.invert_yaxis()
        ax.axvline(0, color="0.5", linewidth=0.8)
        ax.set_xlim(low_limit, high_limit)
        ax.set_title(f"{track} track", fontsize=9)
        ax.grid(True, axis="x", alpha=0.3)
    fig.supxlabel(
        "excess cost over the reference ceiling, % (mean over its seeds, 95 % t interval); 0 = the ceiling", fontsize=9
    )
    _save(plt, fig, path)
