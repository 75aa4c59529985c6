"""The benchmark, ``python -m agents.benchmark``'s library part: every id, every controller, on held-out seeds.

It runs, on every tether-gym id (:data:`tether_gym.registration.ENV_IDS`), every scripted
baseline (:data:`agents.controllers.registry.BASELINES`), the model-predictive reference ``mpc``
and every model shipped for the id (:func:`agents.policies.shipped_models`), on the comparison's
held-out episodes: episode e of every controller on an id starts from the reset seeded
``seed + e`` (:data:`agents.common.cli.HELD_OUT_SEED` = 10 000 and up), through
:func:`agents.evaluation.rollout.rollout`, so a row here is the same episodes as the same row of
``agents.compare``. A controller that
:func:`agents.policies.make_controller` does not know on an id (``mpc`` before it exists, a
model shipped for another id) is listed as missing there, with the reason; nothing is invented
for it.

**What it reports, per id.** With ``R[c, e]`` the return (undiscounted sum of rewards) of
controller c in episode e, and E episodes:

* the mean return of each controller with its 95 % t interval (the comparison's
  :func:`agents.evaluation.rollout.summarise`);
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
  (:data:`~agents.evaluation.stats.SCORE_BOOTSTRAP_REPS` resamples of the seeds, the same seeds
  for c, passive and the reference, seeded with ``--seed``): it includes the uncertainty of the
  denominator and the strong correlation of numerator and denominator, which both grow with a
  seed's initial energy (the reference's own interval is exactly [100, 100]). The score is "not available"
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

**Where it lives.** :func:`benchmark` runs what one :class:`BenchmarkConfig` asks for, in named
steps (controllers loaded, rollouts with a progress display, statistics, files); the statistics
are :mod:`agents.evaluation.stats`, the tables :mod:`agents.evaluation.report` and the plots
:mod:`agents.evaluation.plots`.
"""

from __future__ import annotations

import dataclasses
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from tether_gym.registration import ENV_IDS

from ..common.checks import MAX_NUM_ENVS, check_int
from ..common.cli import HELD_OUT_SEED, REFERENCE, did_you_mean
from ..common.files import holds_output_claims, prepare_table_outputs
from ..common.versions import BENCHMARK_PACKAGES, package_versions
from ..controllers.registry import BASELINES
from ..policies import OtherIdError, make_controller, shipped_models
from ..policies.format import is_policy_dir
from ..policies.layout import PolicyFormatError
from ..policies.pickled import PickleNotTrustedError
from .plots import plot_aggregate, plot_normalised_scores, plot_paired_differences
from .report import clock, write_benchmark_tables
from .rollout import EpisodeRecord, rollout, summarise
from .stats import (
    CONFIDENCE,
    ZERO,
    aggregate_scores,
    best_eligible_baseline,
    normalised_scores,
    paired_difference,
    rliable_modules,
    score_interval,
)

__all__ = [
    "BEST_BASELINE_ROW",
    "PLOT_FILES",
    "SHIPPED_ROW",
    "TABLE_FILES",
    "BenchmarkConfig",
    "benchmark",
]

#: Aggregate rows that are not one controller.
BEST_BASELINE_ROW = "best baseline (per id)"
SHIPPED_ROW = "shipped model (per id)"

TABLE_FILES = ("benchmark.md", "benchmark.json", "scores.csv", "episodes.csv", "aggregate.csv")
PLOT_FILES = ("normalised_scores.png", "paired_differences.png", "aggregate.png")


# ---------------------------------------------------------------------------------------- the settings


@dataclasses.dataclass(frozen=True)
class BenchmarkConfig:
    """What :func:`benchmark` runs, how it scores and where it writes. The values are checked when
    it is made (ValueError naming the field); ``env_ids`` and ``controllers`` are kept as tuples."""

    env_ids: tuple[str, ...] | None = None
    """The ids to run, each once (None: every id of :data:`tether_gym.registration.ENV_IDS`)."""
    controllers: tuple[str, ...] | None = None
    """Names (baselines, ``mpc``, shipped model names) or policy directories, each once, run on
    every id where :func:`agents.policies.make_controller` accepts them (None: every baseline,
    ``reference`` and every shipped model of each id). Passive is always added: it is the score's
    zero and the eligibility bar."""
    episodes: int = 64
    """Held-out episodes per controller and id, E >= 2, seeds ``seed .. seed+E-1``."""
    seed: int = HELD_OUT_SEED
    """The first held-out seed; it also seeds the bootstrap."""
    out: str | Path = "outputs/benchmark"
    """The output directory; an earlier benchmark there is replaced only with ``force``."""
    force: bool = False
    """Replace an earlier benchmark in ``out``."""
    plots: bool = True
    """Write the PNG plots (needs matplotlib, the ``plots`` extra)."""
    trust_pickle: bool = False
    """Allow pickle-based SB3 model paths in ``controllers``."""
    allow_other_id: bool = False
    """Run a policy directory of ``controllers`` on every id of its observation shape, not only on
    the id it was trained on (with a warning)."""
    reference: str = REFERENCE
    """The controller that scores 100 (default ``mpc``). Another name gives a differently
    anchored score, labelled as such in every table."""
    bootstrap_reps: int = 50_000
    """Bootstrap replications of the aggregate's intervals (at least 100)."""
    env_kwargs: dict[str, Any] | None = None
    """Passed to ``gym.make_vec`` for every id (tests shorten the episodes with
    ``{"max_episode_steps": ...}``; the reference scores use the ids' own settings)."""
    command: str | None = None
    """The command line recorded in the outputs (None: the Python call)."""

    def __post_init__(self) -> None:
        env_ids = _check_names("env_ids (--envs)", self.env_ids, allowed=list(ENV_IDS))
        controllers = _check_names("controllers", self.controllers)
        object.__setattr__(self, "env_ids", None if env_ids is None else tuple(env_ids))
        object.__setattr__(self, "controllers", None if controllers is None else tuple(controllers))
        object.__setattr__(
            self, "episodes", check_int("episodes", self.episodes, 2, MAX_NUM_ENVS)
        )  # two at least, for an interval
        object.__setattr__(self, "seed", check_int("seed", self.seed, 0))
        object.__setattr__(self, "bootstrap_reps", check_int("bootstrap_reps", self.bootstrap_reps, 100))
        reference = self.reference
        if not isinstance(reference, str) or not reference or reference == ZERO:
            raise ValueError(f"reference must name a controller other than {ZERO!r} (it scores 100); got {reference!r}")


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
        estimate = "" if left is None or index + 1 == len(self.units) else f", about {clock(left)} left"
        print(
            ("\r" if self.interactive else "")
            + f"  [{index + 1}/{len(self.units)}] {unit.env_id} {unit.name}: {seconds:.1f} s "
            + f"(elapsed {clock(elapsed)}{estimate})"
            + " " * 10,
            flush=True,
        )


def _reason(error: Exception) -> str:
    """A one-line reason for a missing controller."""
    text = str(error).splitlines()[0] if str(error) else type(error).__name__
    return text if len(text) <= 160 else text[:157] + "..."


@holds_output_claims
def benchmark(config: BenchmarkConfig) -> dict[str, Any]:
    """Run the benchmark ``config`` describes and write its files to ``config.out``; returns
    everything written to ``benchmark.json`` as a dict (see the module docstring for the
    definitions).

    Before any rollout it checks ``out`` (``OutputError`` for a file, a symlink, a path inside a
    file or an unwritable place; ``OutputExistsError`` for an earlier benchmark unless
    ``force``), that rliable (and matplotlib for plots) can be imported, and loads every
    controller on every id (so a corrupted model or an untrusted pickle stops it at once; an
    unknown name raises ValueError)."""
    started_at = time.perf_counter()
    ids = list(config.env_ids or ENV_IDS)
    rliable_modules()
    out = prepare_table_outputs(
        config.out, TABLE_FILES, PLOT_FILES, config.plots, config.force, what="an earlier benchmark"
    )
    shipped = {env_id: shipped_models(env_id) for env_id in ids}
    _check_reference(config, shipped)
    requested = _requested_controllers(config, shipped)
    units, missing = _load_controllers(config, ids, requested, shipped)
    seeds = list(range(config.seed, config.seed + config.episodes))
    print(
        f"benchmark: {len(ids)} ids, {len(units)} rollouts of {config.episodes} episodes "
        f"(seeds {seeds[0]}..{seeds[-1]})"
    )
    for env_id, entries in missing.items():
        for entry in entries:
            print(f"  missing on {env_id}: {entry['controller']} ({entry['reason']})")
    records, wall, rollout_seconds = _run_rollouts(units, ids, seeds, config.env_kwargs)
    print(
        f"rollouts done in {clock(rollout_seconds)}; statistics (rliable's bootstrap: {config.bootstrap_reps} "
        "replications per row) and files..."
    )
    results = _analyse(ids, records, wall, missing, config.reference, shipped, config.bootstrap_reps, config.seed)
    results["settings"] = _settings(config, ids, seeds)
    results["rollout_seconds"] = rollout_seconds
    # From the call to the statistics, loading the controllers included; writing the files is left out,
    # since the time is written into them.
    results["wall_seconds"] = time.perf_counter() - started_at
    _write_outputs(out, results, config.plots)
    total_seconds = time.perf_counter() - started_at
    print(
        f"\nthe benchmark took {clock(total_seconds)} ({total_seconds:.0f} s): {len(units)} rollouts in "
        f"{clock(rollout_seconds)}, the rest loading controllers, statistics and files"
    )
    return results


def _check_reference(config: BenchmarkConfig, shipped: dict[str, dict[str, Path]]) -> None:
    """Refuse, before any rollout, a ``reference`` that names no controller of the selected ids (a
    misspelt one would run nothing and leave every score "not available"), with the closest name."""
    known = [*BASELINES, REFERENCE, *(m for models in shipped.values() for m in models)]
    reference = config.reference
    if reference in known or reference in (config.controllers or ()) or is_policy_dir(reference):
        return
    raise ValueError(
        f"--reference {reference!r} is no controller of the selected ids{did_you_mean(reference, known)}: "
        f"pass a baseline ({', '.join(BASELINES)}), {REFERENCE}, a model shipped for the selected ids, or a "
        "policy directory"
    )


def _requested_controllers(config: BenchmarkConfig, shipped: dict[str, dict[str, Path]]) -> list[str] | None:
    """The controllers to run on every id, passive first when the config does not name it (None:
    each id's default set). ValueError for a name that is no controller of the selected ids."""
    names = config.controllers
    if names is None:
        return None
    known = {*BASELINES, REFERENCE, config.reference, *(m for models in shipped.values() for m in models)}
    unknown = [name for name in names if name not in known and not Path(name).exists()]
    if unknown:
        hints = "".join(did_you_mean(name, known) for name in unknown)
        raise ValueError(
            f"unknown controllers {unknown}{hints}: not a baseline ({', '.join(BASELINES)}), {REFERENCE}, the "
            f"reference {config.reference!r}, a model shipped for the selected ids, or an existing policy "
            "directory"
        )
    if ZERO not in names:
        print(f"adding {ZERO!r}: it is the normalised score's zero and the best-baseline rule's bar")
    return ([ZERO] if ZERO not in names else []) + list(names)


def _load_controllers(
    config: BenchmarkConfig, ids: list[str], requested: list[str] | None, shipped: dict[str, dict[str, Path]]
) -> tuple[list[_Unit], dict[str, list[dict[str, str]]]]:
    """Every controller on every id, loaded: the rollouts to do, in order, and per id the
    controllers it does not have, each with the reason. A corrupted model or an untrusted pickle
    raises; a controller unknown on an id (``mpc`` before it exists, a model shipped for another
    id, a policy trained on another id without ``allow_other_id``) is missing there."""
    import gymnasium as gym

    units: list[_Unit] = []
    missing: dict[str, list[dict[str, str]]] = {}
    for env_id in ids:
        candidates = requested or list(dict.fromkeys([*BASELINES, config.reference, *shipped[env_id]]))
        probe = gym.make_vec(env_id, num_envs=1, **dict(config.env_kwargs or {}))
        steps = probe.unwrapped.max_episode_steps
        missing[env_id] = []
        for name in candidates:
            try:
                controller = make_controller(
                    name, probe, trust_pickle=config.trust_pickle, allow_other_id=config.allow_other_id
                )
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
    return units, missing


def _run_rollouts(
    units: list[_Unit], ids: list[str], seeds: list[int], env_kwargs: dict[str, Any] | None
) -> tuple[dict[str, dict[str, EpisodeRecord]], dict[str, dict[str, float]], float]:
    """Every rollout, with the progress display: the records and the wall times (s) per id and
    controller, and the time all of them took (s)."""
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
    return records, wall, time.perf_counter() - progress.start


def _settings(config: BenchmarkConfig, ids: list[str], seeds: list[int]) -> dict[str, Any]:
    """The results' ``settings``: what ran, how it was scored, and the versions of the packages
    the numbers depend on."""
    names = None if config.controllers is None else list(config.controllers)
    return {
        "command": config.command
        or f"{__name__}.benchmark(BenchmarkConfig(env_ids={ids!r}, controllers={names!r}, "
        f"episodes={config.episodes}, seed={config.seed}, reference={config.reference!r}))",
        "env_ids": ids,
        "episodes": config.episodes,
        "seeds": seeds,
        "reference": config.reference,
        "zero": ZERO,
        "confidence": CONFIDENCE,
        "bootstrap": {
            "method": "percentile, stratified by id, paired (rliable)",
            "reps": config.bootstrap_reps,
            "random_state": config.seed,
        },
        "env_kwargs": dict(config.env_kwargs or {}),
        "versions": package_versions(BENCHMARK_PACKAGES),
    }


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


def _write_outputs(out: Path, results: dict[str, Any], plots: bool) -> None:
    """Every file of the benchmark, each written atomically: the tables, then (``plots``) the plots."""
    write_benchmark_tables(out, results)
    written = [out / name for name in TABLE_FILES]
    if plots:
        plot_normalised_scores(results, out / "normalised_scores.png")
        plot_paired_differences(results, out / "paired_differences.png")
        plot_aggregate(results, out / "aggregate.png")
        written += [out / name for name in PLOT_FILES]
    print("wrote " + ", ".join(str(path) for path in written))
