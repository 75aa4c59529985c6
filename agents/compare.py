"""Compare controllers side by side: ``python -m agents.compare`` (the project's main job).

Every controller (by default the four scripted baselines and every model shipped in
the package's ``models/<env id>/``) runs the same held-out episodes: episode e starts from the reset
seeded ``seed + e``. The command prints a table, and writes to ``--out``:

* ``comparison.md`` and ``comparison.csv``: the table (see :data:`agents.evaluate.METRICS`);
* ``energy.png``: vibration energy over time, E(t)/E0, median and interquartile band per
  controller;
* ``displacement.png``: one satellite's displacement from its nominal place over time, in the
  first episode, for every controller.

The command is careful with files: it checks ``--out`` (a writable directory, not a symlink,
not inside a file) and refuses to replace an earlier comparison there without ``--force``
before it loads a controller or runs a rollout, and it writes each file atomically (a temporary
file, then a rename). Trained models are read from the safe format (JSON + safetensors);
a pickle-based SB3 model path is refused unless ``--trust-pickle`` is given.

The seeds default to 10 000 and up, far from the seeds that training and its evaluation
callback use (0 and up, and 1 000 000 and up).
"""

from __future__ import annotations

if __name__ == "__main__":  # --help and bad options answered before the slow imports below
    from .common.cli import parse_before_imports

    parse_before_imports("compare")

import argparse
import csv
import io
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from tether_gym._optional import require
from tether_gym.limits import is_whole_number
from tether_gym.registration import DEFAULT_ENV_ID, ENV_IDS

from .common import cli
from .common.cli import HELD_OUT_SEED
from .common.commands import program
from .common.files import (
    OutputError,
    atomic_write,
    atomic_write_text,
    prepare_table_outputs,
)
from .controllers.registry import BASELINES
from .evaluate import METRICS, EpisodeRecord, rollout, summarise
from .pickled import PickleNotTrustedError
from .policies import make_controller, shipped_models
from .safe_format import PolicyFormatError

__all__ = ["compare", "main"]


def _progress_printer(name: str) -> Any:
    """A progress callback that redraws one line on a terminal, and prints once otherwise."""
    interactive = sys.stdout.isatty()
    start = time.perf_counter()

    def report(done: int, total: int) -> None:
        if interactive and (done % 10 == 0 or done == total):
            bar = "#" * (30 * done // total)
            print(f"\r  {name:<22} [{bar:<30}] {done}/{total} steps", end="", flush=True)
        if done == total:
            elapsed = time.perf_counter() - start
            print(("\r" if interactive else "") + f"  {name:<22} {total} steps in {elapsed:5.1f} s" + " " * 20)

    return report


#: The files a comparison writes (the plots only when plotting).
TABLE_FILES = ("comparison.md", "comparison.csv")
PLOT_FILES = ("energy.png", "displacement.png")


def _check_int(name: str, value: Any, minimum: int) -> int:
    if not is_whole_number(value) or value < minimum:
        raise ValueError(f"{name} must be an integer >= {minimum}; got {value!r}")
    return int(value)


def compare(
    env_id: str = DEFAULT_ENV_ID,
    controllers: list[str] | None = None,
    episodes: int = 64,
    seed: int = HELD_OUT_SEED,
    out: str | Path = "outputs/compare",
    satellite: int = 0,
    plots: bool = True,
    env_kwargs: dict[str, Any] | None = None,
    force: bool = False,
    trust_pickle: bool = False,
    allow_other_id: bool = False,
) -> tuple[list[EpisodeRecord], list[dict[str, Any]]]:
    """Evaluate ``controllers`` (names or model paths; default: every baseline and shipped
    model) on ``episodes`` episodes seeded ``seed, seed+1, ...``; write the table and plots to
    ``out``. Returns the episode records and the summaries, in the controllers' order.

    Before any rollout it checks the arguments, the output directory (``OutputError`` for a
    file, a symlink, a path inside a file or an unwritable place; ``OutputExistsError`` for an
    earlier comparison there unless ``force``) and loads every controller (pickle-based model
    files only with ``trust_pickle``; a policy trained on another id than ``env_id`` only with
    ``allow_other_id``, else :class:`agents.policies.OtherIdError`)."""
    import gymnasium as gym

    if env_id not in ENV_IDS:
        raise ValueError(f"unknown env id {env_id!r}; tether-gym ids are {list(ENV_IDS)}")
    episodes = _check_int("episodes", episodes, 2)  # two at least, for a confidence interval
    seed = _check_int("seed", seed, 0)
    satellite = _check_int("satellite", satellite, 0)
    if controllers is not None:
        if isinstance(controllers, str) or not all(isinstance(name, str) and name for name in controllers):
            raise ValueError(f"controllers must be a list of names or paths; got {controllers!r}")
        if not controllers:
            raise ValueError("controllers must name at least one controller (or be None for the default set)")
        repeated = sorted({name for name in controllers if controllers.count(name) > 1})
        if repeated:
            raise ValueError(f"controllers lists {repeated} more than once: each row of the table needs its own name")
    out = prepare_table_outputs(out, TABLE_FILES, PLOT_FILES, plots, force, what="an earlier comparison")
    names = list(controllers) if controllers else (list(BASELINES) + list(shipped_models(env_id)))
    probe = gym.make_vec(env_id, num_envs=1, **dict(env_kwargs or {}))
    num_nodes = probe.unwrapped.task.cluster.num_nodes
    if satellite >= num_nodes:
        raise ValueError(f"satellite must be in 0..{num_nodes - 1} for {env_id}; got {satellite}")
    policies = [
        make_controller(name, probe, trust_pickle=trust_pickle, allow_other_id=allow_other_id) for name in names
    ]
    probe.close()
    seeds = list(range(seed, seed + episodes))
    print(f"{env_id}: {len(names)} controllers x {episodes} episodes (seeds {seed}..{seed + episodes - 1})")
    records = []
    for name, policy in zip(names, policies, strict=True):
        label = getattr(policy, "name", name) if name in BASELINES else name
        records.append(
            rollout(
                policy,
                env_id,
                seeds,
                name=label,
                satellite=satellite,
                env_kwargs=env_kwargs,
                progress=_progress_printer(label),
            )
        )
    summaries = [summarise(record) for record in records]
    table = markdown_table(records, summaries)
    header = (
        f"{env_id}, {episodes} episodes per controller, seeds {seed}..{seed + episodes - 1}, "
        f"{records[0].time[-1]:.0f} s each\n\n"
    )
    atomic_write_text(out / "comparison.md", header + table + "\n")
    write_csv(out / "comparison.csv", records, summaries)
    print()
    print(table)
    if plots:
        plot_energy(records, out / "energy.png", env_id)
        plot_displacement(records, out / "displacement.png", env_id, satellite)
    print(
        f"\nwrote {out / 'comparison.md'}, {out / 'comparison.csv'}"
        + (f", {out / 'energy.png'}, {out / 'displacement.png'}" if plots else "")
    )
    return records, summaries


def markdown_table(records: list[EpisodeRecord], summaries: list[dict[str, Any]]) -> str:
    """The comparison as a Markdown table, one row per controller."""
    headers = ["controller"] + [f"{title} ({unit})" if unit else title for _, title, unit in METRICS]
    lines = ["| " + " | ".join(headers) + " |", "|" + "---|" * len(headers)]
    for record, summary in zip(records, summaries, strict=True):
        lines.append("| " + " | ".join([record.name] + [summary["cells"][key] for key, _, _ in METRICS]) + " |")
    return "\n".join(lines)


def write_csv(path: Path, records: list[EpisodeRecord], summaries: list[dict[str, Any]]) -> None:
    """The comparison's numbers, one row per controller."""
    keys = list(summaries[0]["values"])
    stream = io.StringIO(newline="")
    writer = csv.writer(stream)
    writer.writerow(["controller"] + keys)
    for record, summary in zip(records, summaries, strict=True):
        writer.writerow([record.name] + [summary["values"][key] for key in keys])
    atomic_write_text(path, stream.getvalue())


def _pyplot() -> Any:
    """matplotlib's pyplot on the Agg backend (files only, no display needed)."""
    require("matplotlib", "plots", "the comparison's plots (or pass --no-plots)").use("Agg")
    return require("matplotlib.pyplot", "plots", "the comparison's plots (or pass --no-plots)")


def plot_energy(records: list[EpisodeRecord], path: Path, env_id: str) -> None:
    """E(t)/E0: median line and interquartile band per controller, log scale."""
    plt = _pyplot()

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
    fig.tight_layout()
    with atomic_write(path) as temporary:
        fig.savefig(temporary, dpi=120, format="png")
    plt.close(fig)


def plot_displacement(records: list[EpisodeRecord], path: Path, env_id: str, satellite: int) -> None:
    """Satellite ``satellite``'s displacement components over time in the first episode."""
    plt = _pyplot()

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
    fig.tight_layout()
    with atomic_write(path) as temporary:
        fig.savefig(temporary, dpi=120, format="png")
    plt.close(fig)


def build_parser() -> argparse.ArgumentParser:
    """The command line of ``compare`` (defined in :mod:`agents.common.cli`, which the console script parses
    with before this module's slow imports)."""
    return cli.build_parser("compare")


def main(argv: list[str] | None = None) -> tuple[list[EpisodeRecord], list[dict[str, Any]]]:
    args = build_parser().parse_args(argv)
    return compare(
        env_id=args.env,
        controllers=args.controllers,
        episodes=args.episodes,
        seed=args.seed,
        out=args.out,
        satellite=args.satellite,
        plots=not args.no_plots,
        force=args.force,
        trust_pickle=args.trust_pickle,
        allow_other_id=args.allow_other_id,
    )


if __name__ == "__main__":
    try:
        main()
    except (PickleNotTrustedError, OutputError, PolicyFormatError, ValueError, OSError, ImportError) as error:
        sys.exit(f"{program('compare')}: error: {error}")
