"""The comparison, ``python -m agents.compare``'s library part: controllers side by side on one id.

Every controller (by default the scripted baselines and every model shipped for the id) runs the
same held-out episodes: episode e starts from the reset seeded ``seed + e``
(:func:`agents.evaluation.rollout.rollout`). :func:`compare` summarises each controller
(:func:`agents.evaluation.rollout.summarise`, the columns of
:data:`agents.evaluation.rollout.METRICS`), prints the table and writes it
(:func:`agents.evaluation.report.write_comparison_tables`) with its plots
(:mod:`agents.evaluation.plots`). What it is asked to do is one :class:`CompareConfig`, whose
values are checked when it is made.
"""

from __future__ import annotations

import dataclasses
import sys
import time
from pathlib import Path
from typing import Any

from tether_gym.registration import DEFAULT_ENV_ID, ENV_IDS

from ..common.checks import MAX_NUM_ENVS, check_int
from ..common.cli import HELD_OUT_SEED
from ..common.files import holds_output_claims, prepare_table_outputs
from ..controllers.registry import BASELINES
from ..policies import make_controller, shipped_models
from .episodes import checked_seeds, save_episodes
from .plots import plot_displacement, plot_energy
from .report import write_comparison_tables
from .rollout import EpisodeRecord, rollout, summarise

__all__ = ["PLOT_FILES", "TABLE_FILES", "CompareConfig", "compare"]

#: The files a comparison writes (the plots only when plotting).
TABLE_FILES = ("comparison.md", "comparison.csv")
PLOT_FILES = ("energy.png", "displacement.png")


@dataclasses.dataclass(frozen=True)
class CompareConfig:
    """What :func:`compare` runs and where it writes; the values are checked when it is made
    (ValueError naming the field)."""

    env_id: str = DEFAULT_ENV_ID
    """The tether-gym id every controller runs on."""
    controllers: tuple[str, ...] | None = None
    """Controller names (baselines, ``mpc``, shipped model names) or policy directories, each
    once (a row of the table is named after it); None: every baseline and every model shipped for
    ``env_id``."""
    episodes: int = 64
    """Held-out episodes per controller, E >= 2 (for a confidence interval)."""
    seed: int = HELD_OUT_SEED
    """The first held-out seed: episode e starts from the reset seeded ``seed + e``."""
    out: str | Path = "outputs/compare"
    """The output directory."""
    satellite: int = 0
    """The satellite whose displacement the displacement plot shows (an index into the cluster)."""
    plots: bool = True
    """Write the PNG plots (needs matplotlib, the ``plots`` extra)."""
    env_kwargs: dict[str, Any] | None = None
    """Passed to ``gym.make_vec`` (tests shorten the episodes with ``{"max_episode_steps": ...}``)."""
    force: bool = False
    """Replace an earlier comparison in ``out``."""
    trust_pickle: bool = False
    """Allow pickle-based SB3 model paths in ``controllers``."""
    allow_other_id: bool = False
    """Run a policy trained on another id than ``env_id`` (with a warning), instead of refusing it."""
    save_episodes: tuple[int, ...] = ()
    """Seeds whose episodes to record for the viewer, per controller (and id), as
    ``out/episodes/<id>/<controller>_seed<S>.npz`` (:mod:`agents.evaluation.episodes`)."""

    def __post_init__(self) -> None:
        object.__setattr__(self, "save_episodes", checked_seeds("save_episodes", self.save_episodes))
        if self.env_id not in ENV_IDS:
            raise ValueError(f"unknown env id {self.env_id!r}; tether-gym ids are {list(ENV_IDS)}")
        object.__setattr__(self, "episodes", check_int("episodes", self.episodes, 2, MAX_NUM_ENVS))
        object.__setattr__(self, "seed", check_int("seed", self.seed, 0))
        object.__setattr__(self, "satellite", check_int("satellite", self.satellite, 0))
        controllers = self.controllers
        if controllers is not None:
            if isinstance(controllers, str) or not all(isinstance(name, str) and name for name in controllers):
                raise ValueError(f"controllers must be a list of names or paths; got {controllers!r}")
            if not controllers:
                raise ValueError("controllers must name at least one controller (or be None for the default set)")
            controllers = tuple(controllers)
            repeated = sorted({name for name in controllers if controllers.count(name) > 1})
            if repeated:
                raise ValueError(
                    f"controllers lists {repeated} more than once: each row of the table needs its own name"
                )
            object.__setattr__(self, "controllers", controllers)


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


@holds_output_claims
def compare(config: CompareConfig) -> tuple[list[EpisodeRecord], list[dict[str, Any]]]:
    """Evaluate ``config.controllers`` on ``config.episodes`` episodes seeded ``seed, seed+1,
    ...``; write the table and plots to ``config.out``. Returns the episode records and the
    summaries, in the controllers' order.

    Before any rollout it checks the output directory (``OutputError`` for a file, a symlink, a
    path inside a file or an unwritable place; ``OutputExistsError`` for an earlier comparison
    there unless ``force``), the satellite against the id's cluster, and loads every controller
    (pickle-based model files only with ``trust_pickle``; a policy trained on another id than
    ``env_id`` only with ``allow_other_id``, else :class:`agents.policies.OtherIdError`)."""
    import gymnasium as gym

    env_id, episodes, seed, satellite = config.env_id, config.episodes, config.seed, config.satellite
    out = prepare_table_outputs(
        config.out, TABLE_FILES, PLOT_FILES, config.plots, config.force, what="an earlier comparison"
    )
    names = list(config.controllers) if config.controllers else (list(BASELINES) + list(shipped_models(env_id)))
    probe = gym.make_vec(env_id, num_envs=1, **dict(config.env_kwargs or {}))
    # Beads of tethers with mass are nodes too, but neither observed nor plotted.
    num_satellites = probe.unwrapped.task.cluster.num_satellites
    if satellite >= num_satellites:
        raise ValueError(f"satellite must be in 0..{num_satellites - 1} for {env_id}; got {satellite}")
    policies = [
        make_controller(name, probe, trust_pickle=config.trust_pickle, allow_other_id=config.allow_other_id)
        for name in names
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
                env_kwargs=config.env_kwargs,
                progress=_progress_printer(label),
            )
        )
    summaries = [summarise(record) for record in records]
    table = write_comparison_tables(out, env_id, episodes, seed, records, summaries)
    print()
    print(table)
    if config.save_episodes:
        save_episodes(
            out, env_id, names, config.save_episodes, config.env_kwargs, config.trust_pickle, config.allow_other_id
        )
    if config.plots:
        plot_energy(records, out / "energy.png", env_id)
        plot_displacement(records, out / "displacement.png", env_id, satellite)
    print(
        f"\nwrote {out / 'comparison.md'}, {out / 'comparison.csv'}"
        + (f", {out / 'energy.png'}, {out / 'displacement.png'}" if config.plots else "")
    )
    return records, summaries
