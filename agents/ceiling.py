"""Compute, check and show the reference ceiling: ``python -m agents.ceiling [--check | --show]``.

The ceiling (:mod:`agents.evaluation.ceiling`) is the planner at full strength, whose per-seed
returns on the benchmark's held-out seeds are shipped as data, ``reference/ceiling.json``:

* ``--envs ID ... --episodes 64`` runs the planner with each id's settings of
  ``hyperparams/ceiling.yml`` on the held-out seeds 10 000 and up, measures its seed noise, and
  writes the returns into the file (other ids are kept). It shows each chunk of seeds as it
  finishes, with the time left.
* ``--check --envs ID ... --count 2`` reruns the planner on a few seeds of each id and compares
  with the shipped returns, within 3 times the planner's seed noise; exit status 1 if any id
  differs.
* ``--show`` prints a table of the shipped ceiling: settings, seeds, mean return, seed noise and
  compute per step.

The episodes are embarrassingly parallel. With the ``rllib`` extra installed (Ray), ``compute``
and ``check`` run the chunks of seeds as Ray tasks, on a local instance (``--workers`` caps its
CPUs) or on an existing cluster (``--address HOST:PORT``); without Ray, or with ``--serial``, they
run one after another. Each chunk's returns are the same either way (see the library module)::

    python -m agents.ceiling --envs TetherDelayedTetrahedron-v0 --episodes 64 --commit 1a2b3c4
    python -m agents.ceiling --check --count 2
"""

from __future__ import annotations

import argparse
import importlib.util
import sys
from collections.abc import Callable, Iterator
from typing import Any

from .common import cli
from .common.checks import MAX_NUM_ENVS
from .common.commands import command_line, exit_on_error, program
from .evaluation.ceiling import (
    CEILING_FILE,
    DEFAULT_CHUNK,
    CeilingDataError,
    CeilingRun,
    ChunkMap,
    ChunkResult,
    ceiling_ids,
    check_ceiling,
    compute_ceiling,
    load_ceiling,
    write_ceiling,
)
from .evaluation.scoring import machine_description

__all__ = ["ERRORS", "build_parser", "main", "ray_map", "run_ceiling"]

#: The refusals that end the command with ``<program>: error: <message>``.
ERRORS = (CeilingDataError, OSError, ValueError)


def build_parser() -> argparse.ArgumentParser:
    """The command line of ``ceiling``."""
    parser = argparse.ArgumentParser(
        prog=program("ceiling"),
        description="Compute (the default), check or show the reference ceiling: the long-horizon planner's "
        "per-seed returns on the benchmark's held-out seeds, shipped as data.",
    )
    mode = parser.add_mutually_exclusive_group()
    mode.add_argument("--check", action="store_true", help="rerun --count seeds per id and compare with the file")
    mode.add_argument("--show", action="store_true", help="print the file as a table")
    parser.add_argument("--envs", nargs="+", metavar="ID", help="ids (default: those in ceiling.yml / in the file)")
    parser.add_argument(
        "--episodes",
        type=cli.int_at_least(2, MAX_NUM_ENVS),
        default=64,
        help="held-out seeds per id to compute (default 64)",
    )
    parser.add_argument(
        "--seed", type=cli.int_at_least(0), default=cli.HELD_OUT_SEED, help="the first held-out seed (default 10000)"
    )
    parser.add_argument(
        "--noise-seeds", type=cli.int_at_least(1), default=2, help="held-out seeds of the seed-noise measurement"
    )
    parser.add_argument(
        "--chunk", type=cli.int_at_least(1, MAX_NUM_ENVS), default=DEFAULT_CHUNK, help="episodes per batched rollout"
    )
    parser.add_argument("--count", type=cli.int_at_least(1), default=2, help="with --check: seeds rerun per id")
    parser.add_argument("--commit", default="unknown", help="the git commit the planner runs at (recorded)")
    parser.add_argument("--machine", help="the machine (default: this machine's CPU, cores and OS)")
    parser.add_argument("--serial", action="store_true", help="run the chunks one after another, even with Ray")
    parser.add_argument("--address", help="join the Ray cluster at HOST:PORT (or 'auto') instead of a local one")
    parser.add_argument("--workers", type=cli.int_at_least(1), help="CPUs of the local Ray instance (default: all)")
    parser.add_argument(
        "--file", type=cli.path_argument, default=str(CEILING_FILE), help=f"the ceiling file (default {CEILING_FILE})"
    )
    return parser


def ray_map(address: str | None, workers: int | None) -> ChunkMap:
    """A chunk map that runs each chunk as a Ray task (one CPU each) and yields the results in
    order; it starts a local instance, or joins ``address``."""
    from .training.rllib import connect

    def run(function: Callable[..., ChunkResult], jobs: list[tuple[Any, ...]]) -> Iterator[ChunkResult]:
        import ray

        started = connect(address, workers)
        try:
            remote = ray.remote(num_cpus=1)(function)
            pending = [remote.remote(*job) for job in jobs]
            for reference in pending:
                yield ray.get(reference)
        finally:
            if started:
                ray.shutdown()

    return run


def _runner(args: argparse.Namespace) -> tuple[ChunkMap | None, str]:
    """The chunk map the arguments ask for, and a line that says which."""
    have_ray = importlib.util.find_spec("ray") is not None
    if args.serial or not have_ray:
        if args.address:
            raise ValueError("--address needs Ray (pip install 'tether-gym[rllib]'), without --serial")
        reason = "--serial" if args.serial else "Ray is not installed (the rllib extra)"
        return None, f"running serially ({reason})"
    where = f"the Ray cluster at {args.address}" if args.address else "a local Ray instance"
    return ray_map(args.address, args.workers), f"running on {where}"


def main(argv: list[str] | None = None) -> int:
    """Run the command with ``argv`` (default: the process's arguments); returns the exit status.
    Every argument is checked here, before :func:`run_ceiling` starts any work."""
    args = build_parser().parse_args(argv)
    shipped: dict[str, CeilingRun] = {}
    if args.show or args.check:
        try:
            shipped = load_ceiling(args.file)
        except (OSError, CeilingDataError) as error:
            raise ValueError(f"--file {args.file}: {error}") from error
    known = list(shipped) if shipped else ceiling_ids()
    unknown = [env_id for env_id in args.envs or () if env_id not in known]
    if unknown:
        where = f"{args.file}" if shipped else "hyperparams/ceiling.yml"
        raise ValueError(f"--envs: no ceiling for {unknown} in {where}; known: {', '.join(known)}")
    runner, how = (None, "") if args.show else _runner(args)
    command = command_line("ceiling", argv if argv is not None else sys.argv[1:])
    return run_ceiling(args, list(args.envs or known), shipped, runner, how, command)


def run_ceiling(
    args: argparse.Namespace,
    ids: list[str],
    shipped: dict[str, CeilingRun],
    runner: ChunkMap | None,
    how: str,
    command: str,
) -> int:
    """The work of the checked command line: show, check (exit status 1 if an id differs) or
    compute and write ``ids``' ceiling."""
    if args.show:
        print(_table({env_id: shipped[env_id] for env_id in ids}))
        return 0
    if args.check:
        print(f"ceiling check: {len(ids)} id(s), {args.count} seed(s) each, {how}", flush=True)
        failed = 0
        for env_id in ids:
            result = check_ceiling(shipped[env_id], count=args.count, map_chunks=runner)
            print(result.summary(), flush=True)
            failed += not result.passed
        return 1 if failed else 0
    seeds = list(range(args.seed, args.seed + args.episodes))
    machine = args.machine or machine_description()
    print(f"ceiling: {len(ids)} id(s), seeds {seeds[0]}..{seeds[-1]}, {how}", flush=True)
    for env_id in ids:
        run = compute_ceiling(
            env_id,
            seeds,
            noise_seeds=args.noise_seeds,
            chunk=args.chunk,
            map_chunks=runner,
            progress=lambda line: print(line, flush=True),
            commit=args.commit,
            machine=machine,
            command=command,
        )
        write_ceiling([run], args.file)
        print(
            f"{env_id}: mean return {run.returns.mean():.2f} over {run.seeds.size} seeds, seed noise "
            f"{run.seed_noise.std:.3f}, {run.seconds_per_step:.3f} s of planning per env step; wrote {args.file}",
            flush=True,
        )
    return 0


def _table(runs: dict[str, Any]) -> str:
    """The shipped ceiling as a Markdown table."""
    lines = [
        "| id | seeds | mean return | seed noise | horizon (steps) | samples | prior | s per env step | commit |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for env_id, run in runs.items():
        s = run.settings
        lines.append(
            f"| {env_id} | {run.seeds.min()}..{run.seeds.max()} ({run.seeds.size}) | {run.returns.mean():.2f} | "
            f"{run.seed_noise.std:.3f} | {s['horizon']} | {s['samples']} | {s['prior']} | "
            f"{run.seconds_per_step:.3f} | {run.commit} |"
        )
    return "\n".join(lines)


if __name__ == "__main__":
    exit_on_error("ceiling", lambda: sys.exit(main()), ERRORS)
