"""The rigorous lower bound on each seed's cost against the shipped reference scores.

What it measures
----------------
For every id of ``agents/reference/reference_scores.json`` that is in the scope of
:func:`tether_gym.analysis.cost_lower_bound` (free space, damping proportional to mass, a shape
that is not collinear), on the held-out seeds of that file (10 000-10 063):

* the mean per-seed lower bound on the cost (minus the return) of any controller;
* the mean cost of passive, of the id's best scripted law and of ``mpc``, from the file;
* ``mpc / bound``: how far the best known control is above what is provably unreachable (the
  room that may still be unknown lies between them);
* the smallest margin, over every controller of the file and every seed, of its cost above the
  bound (negative would be a violation: the tests fail on it).

Ids outside the bound's scope are listed with the reason.  Markdown on stdout.

Usage::

    python benchmarks/cost_bound.py            # about 5 s
    python benchmarks/cost_bound.py --substeps 64
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from tether_gym.analysis import CostBoundScopeError, cost_lower_bound
from tether_gym.bench import cpu_model

REFERENCE = Path(__file__).resolve().parents[1] / "agents" / "reference" / "reference_scores.json"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--reference", type=Path, default=REFERENCE, help="reference scores JSON")
    parser.add_argument("--substeps", type=int, default=16, help="integration pieces per control interval")
    args = parser.parse_args()
    data = json.loads(args.reference.read_text())
    print(f"reference scores: {args.reference.name} (commit {data.get('commit')}); substeps {args.substeps}")
    print(f"machine: {cpu_model()}\n")
    print("| id | bound (mean) | passive | best scripted law | mpc | mpc / bound | smallest margin |")
    print("|---|---|---|---|---|---|---|")
    outside: list[str] = []
    start = time.perf_counter()
    for env_id, entry in data["per_id"].items():
        kwargs = {**data.get("env_kwargs", {}), **entry.get("env_kwargs", {})}
        try:
            result = cost_lower_bound(env_id, entry["seeds"], substeps=args.substeps, **kwargs)
        except CostBoundScopeError as error:
            outside.append(f"- {env_id}: {str(error).split(';')[0].removeprefix('cost_lower_bound: ')}")
            continue
        controllers = entry["controllers"]
        cost = {name: -np.asarray(c["returns"], dtype=float) for name, c in controllers.items()}
        margin = min(float((c - result.bounds).min()) for c in cost.values())
        best = entry["best_baseline"]
        mpc = cost["mpc"].mean() if "mpc" in cost else float("nan")
        bound = result.bounds.mean()
        print(
            f"| {env_id} | {bound:.2f} | {cost['passive'].mean():.1f} | {cost[best].mean():.1f} ({best}) | "
            f"{mpc:.1f} | {mpc / bound:.2f} | {margin:+.2f} |"
        )
    print(f"\n{time.perf_counter() - start:.1f} s")
    if outside:
        print("\nOutside the bound's scope:\n" + "\n".join(outside))


if __name__ == "__main__":
    main()
