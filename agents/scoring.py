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
numbers and their run (:func:`agents.evaluation.scoring.merge_reference`).

:func:`score_policy` is importable from here too (``from tether_gym_agents.scoring import
score_policy``, the documented path of earlier releases); its module is
:mod:`agents.evaluation.scoring`.
"""

from __future__ import annotations

import argparse
from typing import Any

from .common import cli
from .common.commands import exit_on_error, program
from .evaluation.scoring import REFERENCE_FILE, ReferenceDataError, score_policy, write_reference

__all__ = ["ERRORS", "build_parser", "main", "score_policy"]

#: The refusals that end the command with ``<program>: error: <message>`` (see :func:`exit_on_error`).
ERRORS = (ReferenceDataError, OSError, ValueError)


def build_parser() -> argparse.ArgumentParser:
    """The command line of ``scoring``."""
    parser = argparse.ArgumentParser(
        prog=program("scoring"),
        description="Write the reference scores that agents.scoring.score_policy scores against, from the "
        "benchmark.json of a run of python -m agents.benchmark (on the ids' own settings). Every statistic is "
        "checked against the per-episode returns on the way.",
    )
    parser.add_argument("benchmark_json", type=cli.existing_file, help="the benchmark.json of the run")
    parser.add_argument("--commit", required=True, help="the git commit the benchmark ran at")
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
    return parser


def main(argv: list[str] | None = None) -> dict[str, Any]:
    """Run the command with ``argv`` (default: the process's arguments); returns the reference
    scores it wrote."""
    args = build_parser().parse_args(argv)
    data = write_reference(
        args.benchmark_json, args.commit, args.out, args.date, args.machine, args.force, add_to=args.add_to
    )
    controllers = sum(len(entry["controllers"]) for entry in data["per_id"].values())
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
