"""The reference ceiling: the planner at full strength, computed once and shipped as data.

The fast ``mpc`` (:mod:`agents.controllers.mpc`, 3 s horizon) is a practical controller; the
**ceiling** is the same planner with a long horizon (9-15 s), tuned per id on the tuning seeds
3000 and up in the package's ``hyperparams/ceiling.yml`` (:data:`CEILING_SETTINGS_FILE`). It is
the best control the project knows of, and what the benchmark's headline compares with: a
controller's **excess cost** over it, per seed ``(-R[c]) / (-R[ceiling]) - 1``.

It costs 0.03-0.1 s of compute per env and control step, so its per-seed returns on the
benchmark's held-out seeds are computed once (:func:`compute_ceiling`) and shipped in
``reference/ceiling.json`` (:data:`CEILING_FILE`), with the settings, the commit, the compute
per step, the machine and the command; :func:`load_ceiling` reads them back, checked. The
command ``python -m agents.ceiling`` (:mod:`agents.ceiling`) writes the file, and with ``--check``
checks it against a fresh run.

**Same results serially or in parallel.** Episodes are computed in chunks of seeds, each chunk
one batched rollout. A chunk's episodes do not depend on the chunk: the simulator steps each
cluster on its own, and the planner draws each episode's candidates from a generator seeded by
the episode's own initial state (:class:`~agents.controllers.mpc.MPCController`). So a serial
loop and a Ray cluster that maps the same function over the chunks give the same returns, to
the bit on one machine; :func:`compute_ceiling` takes the map to use.

**Seed noise.** The planner is deterministic given its own ``seed``; its seed noise, the spread
of one episode's return over planner seeds, is measured on a few held-out seeds and shipped
with the returns. A fresh run on another machine (other floating-point rounding) must match
the shipped returns to within it (:func:`check_ceiling`).
"""

from __future__ import annotations

import dataclasses
import datetime
import json
import math
import time
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from tether_gym.limits import is_whole_number

from ..common.data import HYPERPARAMS_DIR, REFERENCE_DIR
from ..common.files import atomic_write_text
from ..common.reading import read_json, read_yaml
from ..controllers.mpc import MPCController, MPCSettings, load_mpc_settings
from .rollout import rollout

__all__ = [
    "CEILING_FILE",
    "CEILING_FORMAT",
    "CEILING_FORMAT_VERSION",
    "CEILING_SETTINGS_FILE",
    "CeilingCheck",
    "CeilingDataError",
    "CeilingRun",
    "ChunkResult",
    "SeedNoise",
    "ceiling_chunk",
    "ceiling_ids",
    "check_ceiling",
    "compute_ceiling",
    "iterate_chunks",
    "load_ceiling",
    "load_ceiling_settings",
    "write_ceiling",
]

#: Per-id settings of the ceiling planner (plain YAML, nothing evaluated; no default entry).
CEILING_SETTINGS_FILE = HYPERPARAMS_DIR / "ceiling.yml"
#: The shipped per-seed returns of the ceiling.
CEILING_FILE = REFERENCE_DIR / "ceiling.json"
CEILING_FORMAT = "tether-gym-ceiling"
CEILING_FORMAT_VERSION = 1
#: Seeds per batched rollout: the planner runs 2-3 times faster per episode on a batch of four
#: than on one (its candidate rollouts of several episodes share each kernel call).
DEFAULT_CHUNK = 4
#: A fresh return may differ from the shipped one by this many planner seed-noise standard
#: deviations (:func:`check_ceiling`).
CHECK_TOLERANCE_STDS = 3.0
#: Planner seeds of the seed-noise measurement besides the shipped one (``seed`` 0).
NOISE_PLANNER_SEEDS = (1, 2)

_FIX = "recompute it with python -m agents.ceiling"


class CeilingDataError(ValueError):
    """A ceiling file that is not what :func:`write_ceiling` writes."""


@dataclasses.dataclass(frozen=True)
class SeedNoise:
    """The planner's seed noise on one id.

    Attributes:
        seeds: (n,) held-out seeds it was measured on.
        planner_seeds: (p,) the planner's own seeds, the shipped one (0) first.
        returns: (p, n) return of each planner seed on each held-out seed.
        std: pooled standard deviation over planner seeds, reward units: the root mean over
            held-out seeds of each seed's sample variance (p - 1 degrees of freedom).
    """

    seeds: np.ndarray
    planner_seeds: np.ndarray
    returns: np.ndarray
    std: float

    @classmethod
    def from_returns(cls, seeds: Sequence[int], planner_seeds: Sequence[int], returns: Any) -> SeedNoise:
        """The noise of a (planner seeds, held-out seeds) table of returns."""
        table = np.asarray(returns, dtype=float)
        if table.shape != (len(planner_seeds), len(seeds)) or len(planner_seeds) < 2:
            raise ValueError(
                f"seed-noise returns must be (planner seeds >= 2, seeds) = ({len(planner_seeds)}, {len(seeds)}); "
                f"got shape {table.shape}"
            )
        std = float(np.sqrt(table.var(axis=0, ddof=1).mean()))
        return cls(np.asarray(seeds, dtype=np.int64), np.asarray(planner_seeds, dtype=np.int64), table, std)

    def as_dict(self) -> dict[str, Any]:
        """The JSON form."""
        return {
            "seeds": self.seeds.tolist(),
            "planner_seeds": self.planner_seeds.tolist(),
            "returns": self.returns.tolist(),
            "std": self.std,
        }


@dataclasses.dataclass(frozen=True)
class CeilingRun:
    """The ceiling's per-seed returns on one id, and how they were computed.

    Attributes:
        env_id: the id.
        settings: the planner's :class:`~agents.controllers.mpc.MPCSettings` fields.
        env_kwargs: keyword arguments of ``gym.make_vec`` on top of the id's own (usually none).
        seeds: (E,) held-out reset seeds, int64.
        returns: (E,) the planner's return on each seed, reward units.
        seconds_per_step: planner compute per env and control step, s (on ``machine``, batched
            in chunks of :data:`DEFAULT_CHUNK` episodes).
        wall_seconds: wall time of the whole computation, s (summed over parallel workers).
        seed_noise: the planner's seed noise (:class:`SeedNoise`).
        commit, date, machine, command: provenance (git commit, ISO 8601 UTC time, CPU and
            cores, the command line).
    """

    env_id: str
    settings: dict[str, Any]
    env_kwargs: dict[str, Any]
    seeds: np.ndarray
    returns: np.ndarray
    seconds_per_step: float
    wall_seconds: float
    seed_noise: SeedNoise
    commit: str
    date: str
    machine: str
    command: str

    def as_dict(self) -> dict[str, Any]:
        """The JSON form (the id is the key it is stored under)."""
        return {
            "controller": "mpc",
            "settings": dict(self.settings),
            "env_kwargs": dict(self.env_kwargs),
            "seeds": self.seeds.tolist(),
            "returns": self.returns.tolist(),
            "seconds_per_step": self.seconds_per_step,
            "wall_seconds": self.wall_seconds,
            "seed_noise": self.seed_noise.as_dict(),
            "commit": self.commit,
            "date": self.date,
            "machine": self.machine,
            "command": self.command,
        }

    def returns_on(self, seeds: Sequence[int]) -> np.ndarray:
        """(len(seeds),) the returns on ``seeds``, in their order; a :class:`KeyError` names a
        seed the ceiling was not computed on."""
        where = {int(seed): index for index, seed in enumerate(self.seeds.tolist())}
        missing = [int(seed) for seed in seeds if int(seed) not in where]
        if missing:
            raise KeyError(
                f"the ceiling of {self.env_id} has no return for seed(s) {missing[:5]}; it covers seeds "
                f"{int(self.seeds.min())}..{int(self.seeds.max())} ({self.seeds.size} seeds): {_FIX} --episodes N"
            )
        return self.returns[[where[int(seed)] for seed in seeds]]


@dataclasses.dataclass(frozen=True)
class ChunkResult:
    """One batched rollout of the planner: (n,) ``seeds`` and their ``returns``, its ``compute_seconds``
    of planning over ``env_steps`` env and control steps, and its ``wall_seconds``."""

    seeds: list[int]
    returns: list[float]
    compute_seconds: float
    env_steps: int
    wall_seconds: float


@dataclasses.dataclass(frozen=True)
class CeilingCheck:
    """A fresh planner run against the shipped returns on a few seeds.

    Attributes:
        env_id: the id.
        seeds: (n,) the seeds rerun.
        shipped, fresh: (n,) the shipped and the fresh returns.
        tolerance: the largest difference allowed, :data:`CHECK_TOLERANCE_STDS` seed-noise
            standard deviations (reward units).
    """

    env_id: str
    seeds: np.ndarray
    shipped: np.ndarray
    fresh: np.ndarray
    tolerance: float

    @property
    def largest_difference(self) -> float:
        """The largest |fresh - shipped| over the seeds, reward units."""
        return float(np.max(np.abs(self.fresh - self.shipped)))

    @property
    def passed(self) -> bool:
        """Whether every fresh return is within ``tolerance`` of the shipped one."""
        return self.largest_difference <= self.tolerance

    def summary(self) -> str:
        """One line: the id, the verdict and the numbers."""
        verdict = "matches" if self.passed else "DIFFERS FROM"
        return (
            f"{self.env_id}: a fresh run {verdict} the shipped ceiling on seeds {self.seeds.tolist()}: largest "
            f"|difference| {self.largest_difference:.3g} against a tolerance of {self.tolerance:.3g} "
            f"({CHECK_TOLERANCE_STDS:g} x the planner's seed noise)"
        )


def ceiling_ids(path: str | Path | None = None) -> list[str]:
    """The ids that have ceiling settings in ``path`` (default: the package's ceiling.yml)."""
    table = read_yaml(Path(path) if path is not None else CEILING_SETTINGS_FILE) or {}
    if not isinstance(table, dict):
        raise ValueError(f"{path or CEILING_SETTINGS_FILE} must map env ids to ceiling planner settings")
    return [str(key) for key in table]


def load_ceiling_settings(env_id: str, path: str | Path | None = None, **overrides: Any) -> MPCSettings:
    """The ceiling planner's settings of ``env_id`` (its entry of ceiling.yml, or of ``path``),
    with keyword ``overrides`` on top. An id without an entry is refused: the ceiling is tuned
    per id, never taken from a default."""
    file = Path(path) if path is not None else CEILING_SETTINGS_FILE
    known = ceiling_ids(file)
    if env_id not in known:
        raise ValueError(
            f"{file} has no ceiling settings for {env_id!r}; ids with a ceiling: {', '.join(known)}. Tune the "
            "planner for it on the tuning seeds 3000 and up and add an entry"
        )
    return load_mpc_settings(env_id, file, **overrides)


def ceiling_chunk(
    env_id: str, seeds: Sequence[int], settings: Mapping[str, Any], env_kwargs: Mapping[str, Any] | None = None
) -> ChunkResult:
    """One batched rollout of the planner with ``settings`` (MPCSettings fields) on ``seeds``:
    the unit of work a serial loop or a Ray task runs. Plain arguments and result, so that it
    can be shipped to another process."""
    import gymnasium as gym

    started = time.perf_counter()
    kwargs = dict(env_kwargs or {})
    probe = gym.make_vec(env_id, num_envs=len(seeds), **kwargs)
    controller = MPCController(probe, MPCSettings(**settings))
    record = rollout(controller, env_id, list(seeds), name="ceiling", env_kwargs=kwargs)
    probe.close()
    returns = np.nansum(record.rewards, axis=1)
    return ChunkResult(
        seeds=[int(seed) for seed in seeds],
        returns=[float(value) for value in returns],
        compute_seconds=controller.compute_seconds,
        env_steps=controller.env_steps,
        wall_seconds=time.perf_counter() - started,
    )


#: A map over the chunks: ``map_chunks(function, chunks)`` yields ``function(*chunk)`` for each
#: chunk, in order (:func:`iterate_chunks`, or the command's Ray map).
ChunkMap = Callable[[Callable[..., ChunkResult], list[tuple[Any, ...]]], Iterable[ChunkResult]]


def _chunks(seeds: Sequence[int], size: int) -> list[list[int]]:
    return [list(seeds[start : start + size]) for start in range(0, len(seeds), size)]


def compute_ceiling(
    env_id: str,
    seeds: Sequence[int],
    settings: MPCSettings | None = None,
    env_kwargs: Mapping[str, Any] | None = None,
    *,
    noise_seeds: int = 2,
    chunk: int = DEFAULT_CHUNK,
    map_chunks: ChunkMap | None = None,
    progress: Callable[[str], None] | None = None,
    commit: str = "unknown",
    machine: str = "unknown",
    command: str = "",
) -> CeilingRun:
    """The ceiling's returns on ``seeds``, and its seed noise on the first ``noise_seeds`` of them.

    Args:
        env_id: the id.
        seeds: held-out reset seeds (non-negative, distinct).
        settings: the planner's settings (default: :func:`load_ceiling_settings`).
        env_kwargs: keyword arguments of ``gym.make_vec`` on top of the id's own.
        noise_seeds: held-out seeds of the seed-noise measurement (>= 1), rerun with the planner
            seeds :data:`NOISE_PLANNER_SEEDS`.
        chunk: episodes per batched rollout.
        map_chunks: how the chunks run (default: :func:`iterate_chunks`, serially).
        progress: called with a line after each chunk.
        commit, machine, command: provenance recorded in the result.
    """
    seed_list = [int(seed) for seed in seeds]
    if not seed_list or any(not is_whole_number(seed) or seed < 0 for seed in seeds):
        raise ValueError(f"seeds must be one or more non-negative integers; got {list(seeds)[:5]}")
    if len(set(seed_list)) != len(seed_list):
        raise ValueError("seeds must be distinct: the ceiling has one return per seed")
    if not is_whole_number(chunk) or chunk < 1 or not is_whole_number(noise_seeds) or noise_seeds < 1:
        raise ValueError(f"chunk and noise_seeds must be whole numbers >= 1; got {chunk!r}, {noise_seeds!r}")
    settings = settings if settings is not None else load_ceiling_settings(env_id)
    base = dataclasses.asdict(settings)
    noise_seed_list = seed_list[: min(noise_seeds, len(seed_list))]
    jobs: list[tuple[Any, ...]] = [(env_id, part, base, dict(env_kwargs or {})) for part in _chunks(seed_list, chunk)]
    for planner_seed in NOISE_PLANNER_SEEDS:
        other = {**base, "seed": planner_seed}
        jobs += [(env_id, part, other, dict(env_kwargs or {})) for part in _chunks(noise_seed_list, chunk)]
    runner = map_chunks if map_chunks is not None else iterate_chunks
    started = time.perf_counter()
    results: list[ChunkResult] = []
    for done, result in enumerate(runner(ceiling_chunk, jobs), start=1):
        results.append(result)
        if progress is not None:
            elapsed = time.perf_counter() - started
            left = elapsed / done * (len(jobs) - done)
            progress(
                f"{env_id}: chunk {done}/{len(jobs)} (seeds {result.seeds[0]}..{result.seeds[-1]}, planner seed "
                f"{jobs[done - 1][2]['seed']}) mean return {np.mean(result.returns):.2f}; {elapsed:.0f} s so far, "
                f"about {left:.0f} s left"
            )
    main_chunks = len(_chunks(seed_list, chunk))
    shipped = results[:main_chunks]
    returns = np.array([value for result in shipped for value in result.returns])
    by_planner = [[value for result in shipped for value in result.returns][: len(noise_seed_list)]]
    rest = results[main_chunks:]
    per_planner = len(_chunks(noise_seed_list, chunk))
    for index in range(len(NOISE_PLANNER_SEEDS)):
        part = rest[index * per_planner : (index + 1) * per_planner]
        by_planner.append([value for result in part for value in result.returns])
    noise = SeedNoise.from_returns(noise_seed_list, [settings.seed, *NOISE_PLANNER_SEEDS], by_planner)
    compute = sum(result.compute_seconds for result in shipped)
    steps = sum(result.env_steps for result in shipped)
    return CeilingRun(
        env_id=env_id,
        settings=base,
        env_kwargs=dict(env_kwargs or {}),
        seeds=np.asarray(seed_list, dtype=np.int64),
        returns=returns,
        seconds_per_step=compute / max(steps, 1),
        wall_seconds=sum(result.wall_seconds for result in results),
        seed_noise=noise,
        commit=commit,
        date=datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ"),
        machine=machine,
        command=command,
    )


def check_ceiling(
    run: CeilingRun, seeds: Sequence[int] | None = None, count: int = 2, map_chunks: ChunkMap | None = None
) -> CeilingCheck:
    """Rerun the planner of ``run`` on ``seeds`` (default: its last ``count`` seeds, which the
    seed-noise measurement did not use) and compare with the shipped returns."""
    chosen = [int(seed) for seed in (seeds if seeds is not None else run.seeds.tolist()[-count:])]
    shipped = run.returns_on(chosen)
    runner = map_chunks if map_chunks is not None else iterate_chunks
    jobs = [(run.env_id, part, dict(run.settings), dict(run.env_kwargs)) for part in _chunks(chosen, DEFAULT_CHUNK)]
    fresh = np.array([value for result in runner(ceiling_chunk, jobs) for value in result.returns])
    tolerance = CHECK_TOLERANCE_STDS * run.seed_noise.std
    return CeilingCheck(run.env_id, np.asarray(chosen, dtype=np.int64), shipped, fresh, tolerance)


def _number(entry: Mapping[str, Any], key: str, where: str, minimum: float = 0.0) -> float:
    value = entry.get(key)
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or value < minimum:
        raise CeilingDataError(f"{where}: {key} must be a finite number >= {minimum:g}; got {value!r}: {_FIX}")
    return float(value)


def _run_from_dict(env_id: str, entry: Any, where: str) -> CeilingRun:
    if not isinstance(entry, dict):
        raise CeilingDataError(f"{where}: the entry must be an object; got {type(entry).__name__}: {_FIX}")
    for key, kind in (
        ("settings", dict),
        ("env_kwargs", dict),
        ("seeds", list),
        ("returns", list),
        ("seed_noise", dict),
    ):
        if not isinstance(entry.get(key), kind):
            raise CeilingDataError(f"{where}: {key} must be a JSON {kind.__name__}; got {entry.get(key)!r:.80}: {_FIX}")
    try:
        MPCSettings(**entry["settings"])
    except (TypeError, ValueError) as error:
        raise CeilingDataError(f"{where}: its planner settings are invalid ({error}): {_FIX}") from error
    seeds = entry["seeds"]
    if not seeds or any(not is_whole_number(seed) or isinstance(seed, bool) or seed < 0 for seed in seeds):
        raise CeilingDataError(f"{where}: seeds must be non-negative integers: {_FIX}")
    if len(set(seeds)) != len(seeds):
        raise CeilingDataError(f"{where}: seeds must be distinct: {_FIX}")
    returns = (
        np.asarray(entry["returns"], dtype=float)
        if all(isinstance(value, (int, float)) and not isinstance(value, bool) for value in entry["returns"])
        else None
    )
    if returns is None or returns.shape != (len(seeds),) or not np.isfinite(returns).all():
        raise CeilingDataError(f"{where}: returns must be one finite number per seed ({len(seeds)}): {_FIX}")
    noise = entry["seed_noise"]
    try:
        seed_noise = SeedNoise.from_returns(noise["seeds"], noise["planner_seeds"], noise["returns"])
    except (KeyError, TypeError, ValueError) as error:
        raise CeilingDataError(f"{where}: seed_noise is malformed ({error}): {_FIX}") from error
    text = {key: entry.get(key) for key in ("commit", "date", "machine", "command")}
    if not all(isinstance(value, str) for value in text.values()):
        raise CeilingDataError(f"{where}: commit, date, machine and command must be strings: {_FIX}")
    return CeilingRun(
        env_id=env_id,
        settings=dict(entry["settings"]),
        env_kwargs=dict(entry["env_kwargs"]),
        seeds=np.asarray(seeds, dtype=np.int64),
        returns=returns,
        seconds_per_step=_number(entry, "seconds_per_step", where),
        wall_seconds=_number(entry, "wall_seconds", where),
        seed_noise=seed_noise,
        **text,  # type: ignore[arg-type]
    )


def load_ceiling(path: str | Path | None = None) -> dict[str, CeilingRun]:
    """The shipped ceiling (or the one at ``path``): id -> :class:`CeilingRun`, checked.

    Raises FileNotFoundError when the file is missing, :class:`CeilingDataError` when it is not a
    ceiling file of this version or an entry is malformed (naming the entry and the fix)."""
    file = CEILING_FILE if path is None else Path(path)
    if not file.is_file():
        raise FileNotFoundError(f"no ceiling at {file}: {_FIX} --envs ID ... --out {file}")
    data = read_json(file, CeilingDataError, _FIX)
    if not isinstance(data, dict) or (data.get("format"), data.get("format_version")) != (
        CEILING_FORMAT,
        CEILING_FORMAT_VERSION,
    ):
        found = (data.get("format"), data.get("format_version")) if isinstance(data, dict) else type(data).__name__
        raise CeilingDataError(
            f"{file} is not a {CEILING_FORMAT!r} file of version {CEILING_FORMAT_VERSION} (found {found}): {_FIX}"
        )
    ids = data.get("ids")
    if not isinstance(ids, dict):
        raise CeilingDataError(f"{file}: 'ids' must map env ids to their ceiling: {_FIX}")
    return {str(env_id): _run_from_dict(str(env_id), entry, f"{file} [{env_id}]") for env_id, entry in ids.items()}


def write_ceiling(runs: Iterable[CeilingRun], path: str | Path | None = None, merge: bool = True) -> Path:
    """Write ``runs`` to ``path`` (default: the shipped :data:`CEILING_FILE`), atomically. With
    ``merge`` the file's other ids are kept (a run replaces its id's entry); the ids are stored
    in sorted order, so that the file's diff shows what changed."""
    file = CEILING_FILE if path is None else Path(path)
    existing = load_ceiling(file) if merge and file.is_file() else {}
    entries = {env_id: run.as_dict() for env_id, run in existing.items()}
    entries.update({run.env_id: run.as_dict() for run in runs})
    data = {
        "format": CEILING_FORMAT,
        "format_version": CEILING_FORMAT_VERSION,
        "ids": {env_id: entries[env_id] for env_id in sorted(entries)},
    }
    atomic_write_text(file, json.dumps(data, indent=1) + "\n")
    return file


def iterate_chunks(function: Callable[..., ChunkResult], jobs: list[tuple[Any, ...]]) -> Iterator[ChunkResult]:
    """The serial map: ``function(*job)`` for each job, in order."""
    for job in jobs:
        yield function(*job)
