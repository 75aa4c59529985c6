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
``paired_differences.png``, ``aggregate.png`` (rliable-style interval estimates) and
``excess_costs.png`` (per track, the excess costs over the reference ceiling). The command
is careful with files as ``agents.compare`` is (see :mod:`agents.common.files`): it checks ``--out``
and refuses to replace an earlier benchmark without ``--force`` before it loads a controller or
runs a rollout, and writes every file atomically.

**The two tracks.** The hard track is :data:`tether_gym.registration.HARD_TRACK`, every other id
the standard track (``--track`` picks one). Each track has its own aggregate over ids, never one
mixing them: the standard track's (``aggregate``, as before) is over its ids with massless
tethers (the beaded ids are reported per id, as in the reference scores), the hard track's is
``tracks["hard"]["aggregate"]``.

**The reference ceiling** (:mod:`agents.evaluation.ceiling`, the planner at full strength) is
read from its shipped per-seed returns, never rerun. On each id where they exist, on the
ceiling's seeds that the run holds (at least 2; otherwise the id is skipped with why),
``ceiling`` holds per track what :func:`agents.evaluation.ceiling_report.ceiling_table` gives:
every controller's excess cost over the ceiling (per seed ``(-R[c, e]) / (-R[ceiling, e]) - 1``,
mean with a paired 95 % t interval), the normalised score with 100 = the ceiling, the best
scripted law and its excess cost (the room left), and the track's rliable IQM and mean of the
excess costs with stratified-bootstrap intervals.

**Run time and the quick mode.** Before the rollouts it prints the estimated run time
(:func:`estimate_seconds`, the cost model :data:`SECONDS_PER_EPISODE_STEP`): about 2 h for
the full run on a 2-core machine. ``quick`` runs :data:`QUICK_EPISODES` episodes, every baseline
and shipped model, no ``mpc``, in 2 to 4 minutes, and says so in every output.

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

from tether_gym.registration import ENV_IDS, track_of

from ..common.checks import MAX_NUM_ENVS, check_int
from ..common.cli import HELD_OUT_SEED, REFERENCE, did_you_mean
from ..common.files import holds_output_claims, prepare_table_outputs
from ..common.versions import BENCHMARK_PACKAGES, package_versions
from ..controllers.registry import BASELINES
from ..policies import OtherIdError, make_controller, shipped_models
from ..policies.format import is_policy_dir
from ..policies.layout import PolicyFormatError
from ..policies.pickled import PickleNotTrustedError
from .ceiling import CEILING_FILE, load_ceiling
from .ceiling_report import CeilingId, ceiling_table
from .episodes import checked_seeds, save_episodes
from .plots import plot_aggregate, plot_excess_costs, plot_normalised_scores, plot_paired_differences
from .report import clock, write_benchmark_tables
from .rollout import EpisodeRecord, rollout, summarise
from .scoring import ReferenceDataError
from .stats import (
    CONFIDENCE,
    SCORE_BOOTSTRAP_REPS,
    ZERO,
    ExcessCost,
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

#: The tracks of ``--track``: the standard ids, the hard ones, or both.
TRACKS = ("standard", "hard", "all")
#: Held-out episodes per controller and id of a full run, and of the quick mode.
FULL_EPISODES = 64
QUICK_EPISODES = 8

#: The cost model of the run-time estimate: wall seconds per episode step (one episode advanced
#: by one control step, the episodes of a rollout batched), keyed by (controller is ``mpc``,
#: the id's tethers have beads). Measured on a 2-core AMD EPYC / Intel Xeon with another job
#: sharing the machine: ``mpc`` 0.013 s on the massless ids (the 8-id benchmark took 38 min),
#: about 0.07 s with beaded tethers (27 and 19 min for the two beaded ids, 64 episodes each);
#: the scripted laws and the shipped networks 0.04-0.3 ms massless, 0.3-1.8 ms beaded.
SECONDS_PER_EPISODE_STEP: dict[tuple[bool, bool], float] = {
    (True, False): 0.013,
    (True, True): 0.07,
    (False, False): 1.5e-4,
    (False, True): 1.0e-3,
}
#: Loading the controllers, compiling the kernels, the statistics and the files, s (a rough
#: allowance on top of the rollouts).
OVERHEAD_SECONDS = 60.0

TABLE_FILES = ("benchmark.md", "benchmark.json", "scores.csv", "episodes.csv", "aggregate.csv")
PLOT_FILES = ("normalised_scores.png", "paired_differences.png", "aggregate.png", "excess_costs.png")


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
    episodes: int | None = None
    """Held-out episodes per controller and id, E >= 2, seeds ``seed .. seed+E-1`` (None:
    :data:`FULL_EPISODES`, or :data:`QUICK_EPISODES` with ``quick``)."""
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
    save_episodes: tuple[int, ...] = ()
    """Seeds whose episodes to record for the viewer, per controller (and id), as
    ``out/episodes/<id>/<controller>_seed<S>.npz`` (:mod:`agents.evaluation.episodes`)."""
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
    track: str = "all"
    """The ids' track (:data:`TRACKS`): ``standard``, ``hard``
    (:data:`tether_gym.registration.HARD_TRACK`) or ``all``. With ``env_ids``, every id must be
    on it."""
    quick: bool = False
    """The quick mode, a smoke check of a few minutes: :data:`QUICK_EPISODES` episodes (the
    reference ceiling's first seeds), every baseline and shipped model, no ``mpc``. It fixes the
    episodes and the controllers, so it refuses ``episodes`` and ``controllers``."""
    ceiling_file: str | Path | None = None
    """The reference ceiling's per-seed returns (None: the shipped
    :data:`agents.evaluation.ceiling.CEILING_FILE`, if it exists yet). Read, never rerun."""

    def __post_init__(self) -> None:
        env_ids = _check_names("env_ids (--envs)", self.env_ids, allowed=list(ENV_IDS))
        controllers = _check_names("controllers", self.controllers)
        if self.track not in TRACKS:
            raise ValueError(f"track (--track) must be one of {list(TRACKS)}; got {self.track!r}")
        if not track_ids(self.track):
            raise ValueError(
                f"the {self.track} track has no ids at present (tether_gym.registration.HARD_TRACK says why): "
                "pass --track standard or all"
            )
        if env_ids is not None and self.track != "all":
            off_track = [env_id for env_id in env_ids if env_id not in track_ids(self.track)]
            if off_track:
                raise ValueError(
                    f"--envs names {off_track}, which are not on the {self.track} track (its ids: "
                    f"{', '.join(track_ids(self.track))}): drop --track, or drop those ids"
                )
        if self.quick and (self.episodes is not None or controllers is not None):
            given = "--episodes" if self.episodes is not None else "--controllers"
            raise ValueError(
                f"--quick fixes the episodes ({QUICK_EPISODES}) and the controllers (every baseline and shipped "
                f"model, no {REFERENCE}); drop {given}, or drop --quick for a run of your own settings"
            )
        episodes = self.episodes if self.episodes is not None else QUICK_EPISODES if self.quick else FULL_EPISODES
        object.__setattr__(self, "env_ids", None if env_ids is None else tuple(env_ids))
        object.__setattr__(self, "controllers", None if controllers is None else tuple(controllers))
        object.__setattr__(
            self, "episodes", check_int("episodes", episodes, 2, MAX_NUM_ENVS)
        )  # two at least, for an interval
        object.__setattr__(self, "seed", check_int("seed", self.seed, 0))
        object.__setattr__(self, "save_episodes", checked_seeds("save_episodes", self.save_episodes))
        object.__setattr__(self, "bootstrap_reps", check_int("bootstrap_reps", self.bootstrap_reps, 100))
        reference = self.reference
        if not isinstance(reference, str) or not reference or reference == ZERO:
            raise ValueError(f"reference must name a controller other than {ZERO!r} (it scores 100); got {reference!r}")


def track_ids(track: str) -> list[str]:
    """The ids of ``track`` (:data:`TRACKS`), in the order of :data:`tether_gym.registration.ENV_IDS`:
    the hard track is :data:`tether_gym.registration.HARD_TRACK`, the standard track every other id."""
    if track not in TRACKS:
        raise ValueError(f"track must be one of {list(TRACKS)}; got {track!r}")
    return [env_id for env_id in ENV_IDS if track in ("all", track_of(env_id))]


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
    beaded: bool = False
    """The id's tethers have beads (mass): every step costs more, the planner's most."""


def estimate_seconds(units: Sequence[_Unit], episodes: int) -> float:
    """The run time (s) the cost model :data:`SECONDS_PER_EPISODE_STEP` predicts for ``units``
    with ``episodes`` episodes each, plus :data:`OVERHEAD_SECONDS`."""
    rollouts = sum(
        SECONDS_PER_EPISODE_STEP[(unit.name == REFERENCE, unit.beaded)] * episodes * unit.steps for unit in units
    )
    return rollouts + OVERHEAD_SECONDS


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
    ids = list(config.env_ids or track_ids(config.track))
    rliable_modules()
    out = prepare_table_outputs(
        config.out, TABLE_FILES, PLOT_FILES, config.plots, config.force, what="an earlier benchmark"
    )
    ceiling, ceiling_note = _read_ceiling(config.ceiling_file)
    shipped = {env_id: shipped_models(env_id) for env_id in ids}
    _check_reference(config, shipped)
    requested = _requested_controllers(config, shipped)
    units, missing = _load_controllers(config, ids, requested, shipped)
    episodes = config.episodes
    assert episodes is not None  # set by BenchmarkConfig.__post_init__
    seeds = list(range(config.seed, config.seed + episodes))
    if config.quick:
        print(
            f"QUICK MODE: a smoke check, {QUICK_EPISODES} episodes per controller and id (the reference ceiling's "
            f"first seeds), no {REFERENCE}; its numbers are noisier than a full run's"
        )
    tracks = ", ".join(f"{sum(track_of(env_id) == t for env_id in ids)} {t}" for t in ("standard", "hard"))
    print(
        f"benchmark: {len(ids)} ids ({tracks}), {len(units)} rollouts of {episodes} episodes "
        f"(seeds {seeds[0]}..{seeds[-1]}); estimated run time about {clock(estimate_seconds(units, episodes))} "
        f"on a 2-core machine ({sum(episodes * unit.steps for unit in units)} episode steps; "
        f"{REFERENCE} costs about {1e3 * SECONDS_PER_EPISODE_STEP[(True, False)]:.0f} ms per episode step, "
        f"{1e3 * SECONDS_PER_EPISODE_STEP[(True, True)]:.0f} ms with beaded tethers, the others under 2 ms)"
    )
    print(f"reference ceiling: {ceiling_note}")
    for env_id, entries in missing.items():
        for entry in entries:
            print(f"  missing on {env_id}: {entry['controller']} ({entry['reason']})")
    records, wall, rollout_seconds = _run_rollouts(units, ids, seeds, config.env_kwargs)
    for env_id in ids if config.save_episodes else []:
        names = [unit.name for unit in units if unit.env_id == env_id]
        save_episodes(
            out, env_id, names, config.save_episodes, config.env_kwargs, config.trust_pickle, config.allow_other_id
        )
    print(
        f"rollouts done in {clock(rollout_seconds)}; statistics (rliable's bootstrap: {config.bootstrap_reps} "
        "replications per row) and files..."
    )
    beaded = {unit.env_id: unit.beaded for unit in units}
    results = _analyse(
        ids, records, wall, missing, config.reference, shipped, config.bootstrap_reps, config.seed, beaded
    )
    results["ceiling"] = _against_ceiling(results, ids, ceiling, ceiling_note, config, seeds)
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
        anchor = [] if config.quick else [config.reference]  # the quick mode runs no planner
        candidates = requested or list(dict.fromkeys([*BASELINES, *anchor, *shipped[env_id]]))
        probe = gym.make_vec(env_id, num_envs=1, **dict(config.env_kwargs or {}))
        steps = probe.unwrapped.max_episode_steps
        beaded = int(probe.unwrapped.cluster.num_beads) > 0
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
            units.append(_Unit(env_id, name, controller, int(steps), beaded))
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
        "track": config.track,
        "quick": config.quick,
        "tracks": {track: [env_id for env_id in ids if track_of(env_id) == track] for track in ("standard", "hard")},
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
    beaded: dict[str, bool] | None = None,
) -> dict[str, Any]:
    """Every statistic of the benchmark, as a JSON-ready dict (NaN never appears: None instead).

    The aggregate over ids never mixes tracks: ``aggregate`` is the standard track's, over its ids
    with massless tethers (``beaded`` marks the others, reported per id only, as in the reference
    scores), and ``tracks["hard"]["aggregate"]`` the hard track's, over its ids."""
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
    beaded = beaded or {}
    tracks: dict[str, Any] = {}
    for track in ("standard", "hard"):
        members = [env_id for env_id in ids if track_of(env_id) == track]
        left_out = {
            env_id: "beaded tethers: reported per id, outside the aggregate over the massless ids"
            for env_id in members
            if track == "standard" and beaded.get(env_id, False)
        }
        group = [env_id for env_id in members if env_id not in left_out]
        track_rows = {row: {i: values[i] for i in values if i in group} for row, values in row_returns.items()}
        track_rows = {row: values for row, values in track_rows.items() if values}
        shipped_names = {name for env_id in group for name in records[env_id] if name in shipped[env_id]}
        if len(shipped_names) < 2:
            track_rows.pop(SHIPPED_ROW, None)  # the same numbers as the one shipped name's own row
        aggregate = (
            aggregate_scores(track_rows, zero_returns, reference_returns, reps=bootstrap_reps, seed=seed)
            if track_rows
            else {}
        )
        tracks[track] = {"ids": members, "aggregate_ids": group, "left_out": left_out, "aggregate": aggregate}
    standard = tracks["standard"]
    return {
        "per_id": per_id,
        "aggregate": standard["aggregate"],
        "aggregate_ids": len(standard["aggregate_ids"]),
        "tracks": tracks,
    }


def _read_ceiling(path: str | Path | None) -> tuple[dict[str, Any], str]:
    """The reference ceiling's runs (id -> :class:`~agents.evaluation.ceiling.CeilingRun`) and a
    line saying where they come from. The shipped file may not exist yet: then none, and the line
    says so; a file named by ``path`` must exist. A malformed file raises
    :class:`~agents.evaluation.ceiling.CeilingDataError` (before any rollout)."""
    file = CEILING_FILE if path is None else Path(path)
    if not file.is_file():
        if path is not None:
            raise FileNotFoundError(
                f"--ceiling-file {file}: no such file; pass a ceiling file written by python -m agents.ceiling, or "
                "drop --ceiling-file for the shipped one"
            )
        return {}, f"none: no shipped ceiling at {file} yet (python -m agents.ceiling computes it)"
    runs = load_ceiling(file)
    return runs, f"read from {file} ({len(runs)} ids; not rerun)"


@dataclasses.dataclass(frozen=True)
class _CeilingOnSeeds:
    """The ceiling's returns on the seeds the benchmark ran: what :func:`ceiling_table` pairs."""

    seeds: np.ndarray
    returns: np.ndarray
    seconds_per_step: float
    machine: str


def _ceiling_on_seeds(run: Any, seeds: list[int], env_kwargs: dict[str, Any]) -> tuple[_CeilingOnSeeds | None, str]:
    """``run`` restricted to the ceiling seeds among the benchmark's ``seeds``, and a line saying
    which; None (with why) when its returns cannot pair with the benchmark's: other env settings,
    or fewer than 2 of its seeds run here."""
    if dict(run.env_kwargs) != dict(env_kwargs):
        return None, (
            f"skipped: the ceiling ran with env_kwargs {dict(run.env_kwargs)}, the benchmark with {dict(env_kwargs)}; "
            "its returns do not pair"
        )
    ran = set(seeds)
    kept = [index for index, seed in enumerate(run.seeds.tolist()) if int(seed) in ran]
    span = f"{int(run.seeds.min())}..{int(run.seeds.max())}" if run.seeds.size else "none"
    if len(kept) < 2:
        return None, (
            f"skipped: the benchmark's seeds ({seeds[0]}..{seeds[-1]}) hold {len(kept)} of the ceiling's "
            f"{run.seeds.size} seeds ({span}); 2 at least are needed: run with --seed and --episodes covering them"
        )
    on_seeds = _CeilingOnSeeds(run.seeds[kept], run.returns[kept], float(run.seconds_per_step), str(run.machine))
    return on_seeds, f"on {len(kept)} of the ceiling's {run.seeds.size} seeds ({span})"


def _excess_dict(excess: ExcessCost) -> dict[str, Any]:
    return dataclasses.asdict(excess)


def _ceiling_id_dict(item: CeilingId) -> dict[str, Any]:
    """One id of :func:`ceiling_table`, as JSON-ready numbers (fractions for the excess costs)."""
    return {
        "seeds": list(item.seeds),
        "ceiling_seconds_per_step": item.seconds_per_step,
        "ceiling_machine": item.machine,
        "best_law": item.best_law,
        "room_left": _excess_dict(item.room_left),
        "controllers": {
            row.controller: {
                "kind": row.kind,
                "mean_return": row.mean_return,
                "return_ci95": row.return_ci95,
                "excess_cost": _excess_dict(row.excess),
                "ceiling_score": None
                if row.score is None
                else {"mean": row.score, "low": row.score_low, "high": row.score_high},
                "gap_closed": None if row.gap is None else dataclasses.asdict(row.gap),
            }
            for row in item.rows
        },
    }


def _against_ceiling(
    results: dict[str, Any],
    ids: list[str],
    ceiling: dict[str, Any],
    note: str,
    config: BenchmarkConfig,
    seeds: list[int],
) -> dict[str, Any]:
    """Every controller against the reference ceiling, per track, from the ceiling's shipped
    returns on the seeds the benchmark ran (:func:`agents.evaluation.ceiling_report.ceiling_table`):
    per id, the excess cost over the ceiling of every controller (mean over the ceiling's seeds,
    95 % t interval, paired), the normalised score with 100 = the ceiling, the best scripted law
    and its excess cost, the room left; per track, rliable's IQM and mean of the excess costs and
    scores with stratified-bootstrap intervals. Ids without usable ceiling data are listed with why."""
    reference = {
        "zero": ZERO,
        "confidence": CONFIDENCE,
        "score_bootstrap": {"reps": SCORE_BOOTSTRAP_REPS, "seed": config.seed},
        "aggregate_bootstrap": {"reps": config.bootstrap_reps, "random_state": config.seed},
    }
    env_kwargs = dict(config.env_kwargs or {})
    tracks: dict[str, Any] = {}
    for track in ("standard", "hard"):
        members = [env_id for env_id in ids if track_of(env_id) == track]
        if not members:
            continue
        usable: dict[str, _CeilingOnSeeds] = {}
        coverage: dict[str, str] = {}
        for env_id in members:
            if env_id not in ceiling:
                coverage[env_id] = "skipped: the ceiling data hold no returns for this id"
                continue
            on_seeds, coverage[env_id] = _ceiling_on_seeds(ceiling[env_id], seeds, env_kwargs)
            if on_seeds is not None:
                usable[env_id] = on_seeds
        entry: dict[str, Any] = {"coverage": coverage, "per_id": {}, "aggregate": {}, "aggregate_note": ""}
        # The ids outside the track's aggregate of normalised scores (the beaded ones) stay outside this one too.
        left_out = results["tracks"][track]["left_out"]
        inside = {env_id: run for env_id, run in usable.items() if env_id not in left_out}
        outside = {env_id: run for env_id, run in usable.items() if env_id in left_out}
        for part, aggregated in ((inside, True), (outside, False)):
            if not part:
                continue
            data = {**reference, "per_id": {env_id: results["per_id"][env_id] for env_id in part}}
            try:
                table = ceiling_table(data, part)
            except ReferenceDataError as error:
                entry["aggregate_note"] = f"not available: {error}"
                print(f"  ceiling, {track} track: {entry['aggregate_note']}")
                continue
            entry["per_id"].update({item.env_id: _ceiling_id_dict(item) for item in table.ids})
            if aggregated:
                entry["aggregate"] = table.aggregate
                entry["aggregate_note"] = table.aggregate_note
        entry["per_id"] = {env_id: entry["per_id"][env_id] for env_id in members if env_id in entry["per_id"]}
        for env_id, line in coverage.items():
            print(f"  ceiling on {env_id}: {line}")
        tracks[track] = entry
    return {"source": note, "tracks": tracks}


def _write_outputs(out: Path, results: dict[str, Any], plots: bool) -> None:
    """Every file of the benchmark, each written atomically: the tables, then (``plots``) the plots."""
    write_benchmark_tables(out, results)
    written = [out / name for name in TABLE_FILES]
    if plots:
        plot_normalised_scores(results, out / "normalised_scores.png")
        plot_paired_differences(results, out / "paired_differences.png")
        plot_aggregate(results, out / "aggregate.png")
        plot_excess_costs(results, out / "excess_costs.png")
        written += [out / name for name in PLOT_FILES]
    print("wrote " + ", ".join(str(path) for path in written))
