"""Write the reference scores from a benchmark run: ``python -m agents.scoring BENCHMARK_JSON --commit COMMIT``.

The reference scores (:data:`agents.evaluation.scoring.REFERENCE_FILE`, shipped in the package)
are what :func:`agents.evaluation.scoring.score_policy` scores a policy against: per id, the
held-out seeds and every controller's per-seed returns and statistics. This command converts the
``benchmark.json`` of a run of ``python -m agents.benchmark`` (on the ids' own settings) with
:func:`agents.evaluation.scoring.write_reference`, which checks every statistic against the
per-episode returns on the way::

    python -m agents.scoring outputs/benchmark/benchmark.json --commit 2466a18 --force

A benchmark of new ids alone (``python -m agents.benchmark --envs ...``) is added to the shipped
file with ``--add-to agents/reference/reference_scores.json --force``: the other ids keep their
numbers and their run (:func:`agents.evaluation.scoring.merge_reference`). A rerun of every id of
the file's aggregate (``--track standard``, after shipping new models) is added the same way: it
becomes the file's own run and aggregate, and the ids added earlier keep theirs.

``--ceiling`` prints instead, from the shipped data alone (nothing runs), every controller of the
reference scores against the reference ceiling on the ceiling's seeds: mean return, excess cost
over the ceiling, normalised score with 100 = the ceiling, the room left per id and rliable's
aggregate over ids (:func:`agents.evaluation.ceiling_report.ceiling_table`)::

    python -m agents.scoring --ceiling
    python -m agents.scoring --ceiling --bootstrap-reps 2000   # a quicker aggregate

:func:`score_policy` is importable from here too (``from tether_gym_agents.scoring import
score_policy``, the documented path of earlier releases); its module is
:mod:`agents.evaluation.scoring`.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

from tether_gym.registration import track_of

from .common import cli
from .common.commands import exit_on_error, program
from .evaluation.ceiling import CEILING_FILE, CeilingDataError, load_ceiling
from .evaluation.ceiling_report import ceiling_markdown, ceiling_table
from .evaluation.scoring import REFERENCE_FILE, ReferenceDataError, load_reference, score_policy, write_reference

__all__ = ["ERRORS", "build_parser", "ceiling_report", "main", "score_policy"]

#: The refusals that end the command with ``<program>: error: <message>`` (see :func:`exit_on_error`).
ERRORS = (ReferenceDataError, CeilingDataError, OSError, ValueError)


def build_parser() -> argparse.ArgumentParser:
    """The command line of ``scoring``."""
    parser = argparse.ArgumentParser(
        prog=program("scoring"),
        description="Write the reference scores that agents.scoring.score_policy scores against, from the "
        "benchmark.json of a run of python -m agents.benchmark (on the ids' own settings). Every statistic is "
        "checked against the per-episode returns on the way.",
    )
    parser.add_argument(
        "benchmark_json", nargs="?", type=cli.existing_file, help="the benchmark.json of the run (not with --ceiling)"
    )
    parser.add_argument("--commit", help="the git commit the benchmark ran at (required unless --ceiling)")
    parser.add_argument(
        "--out", type=cli.path_argument, default=str(REFERENCE_FILE), help=f"where to write (default {REFERENCE_FILE})"
    )
    parser.add_argument("--date", help="when the benchmark ran, ISO 8601 (default: benchmark.json's time, UTC)")
    parser.add_argument("--machine", help="the machine it ran on (default: this machine's CPU, cores and OS)")
    parser.add_argument(
        "--add-to",
        type=cli.existing_file,
        help="a reference file to add the benchmark's ids to (its other ids, run and aggregate are kept; "
        "each id then names the run it comes from); usually the same path as --out, with --force",
    )
    parser.add_argument("--force", action="store_true", help="replace an existing file at --out")
    ceiling = parser.add_argument_group(
        "against the reference ceiling",
        "print, from shipped data alone, every controller of the reference scores against the reference ceiling "
        "(excess cost, normalised score with 100 = the ceiling, room left) instead of writing reference scores",
    )
    ceiling.add_argument("--ceiling", action="store_true", help="print the Markdown table against the ceiling")
    ceiling.add_argument(
        "--ceiling-file",
        type=cli.existing_file,
        help=f"the ceiling data (default {CEILING_FILE}; with --ceiling)",
    )
    ceiling.add_argument(
        "--reference-file",
        type=cli.existing_file,
        help=f"the reference scores (default {REFERENCE_FILE}; with --ceiling)",
    )
    ceiling.add_argument(
        "--bootstrap-reps",
        type=cli.int_at_least(100),
        help="bootstrap replications of the aggregate over ids (default: the reference's, 50000: about 3 s of one "
        "core per controller and statistic; with --ceiling)",
    )
    return parser


#: The options of the table against the ceiling, and those of writing reference scores.
_CEILING_OPTIONS = {
    "ceiling_file": "--ceiling-file",
    "reference_file": "--reference-file",
    "bootstrap_reps": "--bootstrap-reps",
}
_WRITING_OPTIONS = {
    "benchmark_json": "benchmark_json",
    "commit": "--commit",
    "date": "--date",
    "machine": "--machine",
    "add_to": "--add-to",
}


def ceiling_report(
    ceiling_file: str | None = None, reference_file: str | None = None, bootstrap_reps: int | None = None
) -> str:
    """The Markdown table of every controller of the reference scores (``reference_file``,
    default the shipped ones) against the reference ceiling (``ceiling_file``, default the
    shipped one), from the files alone (:func:`agents.evaluation.ceiling_report.ceiling_table`)."""
    files = (
        f"ceiling data {ceiling_file or CEILING_FILE} (--ceiling-file), reference scores "
        f"{reference_file or REFERENCE_FILE} (--reference-file)"
    )
    try:
        reference, ceiling = load_reference(reference_file), load_ceiling(ceiling_file)
        # One table and aggregate per track: an aggregate mixing the tracks would let the hard
        # ids' larger room pull the standard track's figures, as the benchmark never does.
        parts = []
        for track in ("standard", "hard"):
            runs = {env_id: run for env_id, run in ceiling.items() if track_of(env_id) == track}
            if runs:
                table = ceiling_table(reference, runs, reps=bootstrap_reps)
                parts.append(ceiling_markdown(table, f"Against the reference ceiling: the {track} track"))
    except (ReferenceDataError, CeilingDataError, FileNotFoundError) as error:
        # The loaders' messages name the file; the command's reader needs the option that picks it.
        raise type(error)(f"{error} [{files}]") from None
    return "\n".join(parts)


def _benchmark_ids(benchmark_json: str) -> list[str]:
    """The ids of a benchmark's ``benchmark.json`` (already checked by :func:`write_reference`)."""
    return list(json.loads(Path(benchmark_json).read_text(encoding="utf-8"))["per_id"])


def main(argv: list[str] | None = None) -> dict[str, Any]:
    """Run the command with ``argv`` (default: the process's arguments); returns the reference
    scores it wrote, or with ``--ceiling`` ``{"ceiling_markdown": the table it printed}``."""
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.ceiling:
        given = [option for dest, option in _WRITING_OPTIONS.items() if getattr(args, dest) is not None]
        given += ["--out"] * (args.out != str(REFERENCE_FILE)) + ["--force"] * args.force
        if given:
            parser.error(f"--ceiling prints a table from the shipped data and writes nothing: drop {', '.join(given)}")
        text = ceiling_report(args.ceiling_file, args.reference_file, args.bootstrap_reps)
        print(text, end="")
        return {"ceiling_markdown": text}
    extra = [option for dest, option in _CEILING_OPTIONS.items() if getattr(args, dest) is not None]
    if extra:
        parser.error(f"{', '.join(extra)} go with --ceiling")
    missing = [
        name for name, value in (("benchmark_json", args.benchmark_json), ("--commit", args.commit)) if value is None
    ]
    if missing:
        parser.error(f"the following arguments are required: {', '.join(missing)} (or pass --ceiling)")
    data = write_reference(
        args.benchmark_json, args.commit, args.out, args.date, args.machine, args.force, add_to=args.add_to
    )
    controllers = sum(len(entry["controllers"]) for entry in data["per_id"].values())
    # merge_reference makes a benchmark that holds every id of the aggregate the file's own run.
    added_ids = {env_id for entry in data.get("additions", []) for env_id in entry["ids"]}
    if args.add_to is not None and not added_ids & set(_benchmark_ids(args.benchmark_json)):
        print(
            f"wrote {args.out}: {', '.join(data['aggregate_ids'])} rerun (commit {data['commit']}, {data['date']}) as "
            f"the file's own run and aggregate, {len(data['additions'])} additions of other ids kept; every statistic "
            "matches its returns"
        )
        return data
    if args.add_to is not None:
        added = data["additions"][-1]
        print(
            f"wrote {args.out}: added {', '.join(added['ids'])} (commit {added['commit']}, {added['date']}) to the "
            f"{len(data['per_id']) - len(added['ids'])} other ids; every statistic matches its returns"
        )
        return data
    print(
        f"wrote {args.out}: {len(data['per_id'])} ids, {controllers} controllers, {data['episodes']} episodes each "
        f"(commit {data['commit']}, {data['date']}); every statistic matches its returns"
    )
    return data


if __name__ == "__main__":
    exit_on_error("scoring", main, ERRORS)
