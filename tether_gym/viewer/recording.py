"""Recorded episodes: what the viewer draws, per control step, saved as plain ``.npz`` data.

An :class:`EpisodeRecording` holds one episode of one controller: every node's position (beads
of tethers with mass included), every cable's tension, slack and broken flags, the thrust on
every node, the commands the controller gave, the reward and the vibration energy, from the reset
(frame 0) to the episode's end (frame T). :class:`EpisodeStepper` makes one, a control step at a
time (the live viewer shows the frames as they come); :func:`record_episode` runs it to the end.

The file format is numpy's ``.npz`` with ``allow_pickle=False`` on both sides: arrays of numbers
and booleans, and the metadata as a JSON string. Loading one never runs code, and
:func:`load_recording` checks every array's shape and type before the viewer sees it.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import tempfile
import zipfile
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any, Protocol

import numpy as np

__all__ = [
    "FORMAT",
    "FORMAT_VERSION",
    "EpisodeRecording",
    "EpisodeStepper",
    "RecordingError",
    "load_recording",
    "record_episode",
    "recording_file_name",
    "save_recording",
]

#: The ``format`` field of a recording's metadata: what tells a recording from another ``.npz``.
FORMAT = "tether-gym-episode"
#: The version this code writes and the newest it reads.
FORMAT_VERSION = 1

#: Metadata fields every recording has (see :class:`EpisodeRecording`).
META_FIELDS = (
    "format",
    "format_version",
    "env_id",
    "env_kwargs",
    "controller",
    "seed",
    "cluster",
    "frame",
    "control_interval",
    "max_steps",
    "cables",
    "roles",
    "thrusters",
    "max_thrust",
    "nominal",
    "terminated",
    "end_reason",
    "return",
)


class RecordingError(ValueError):
    """A file that is not a readable tether-gym episode recording; the message names the file,
    the problem and the fix."""


class Policy(Protocol):
    """What steps an episode: Stable-Baselines3's ``predict`` on a batch of one observation."""

    def predict(self, observation: np.ndarray, deterministic: bool = True) -> tuple[np.ndarray, Any]: ...


@dataclasses.dataclass(frozen=True, eq=False)
class EpisodeRecording:
    """One episode, frame by frame (frame 0 is the reset; T = the number of control steps taken).

    Attributes:
        meta: JSON-able metadata: ``env_id``, ``env_kwargs``, ``controller`` (its name), ``seed``,
            ``cluster`` (the preset's name), ``frame`` (``{"kind": "inertial" | "hill" |
            "rotating", "rate": rad/s}``), ``control_interval`` (s), ``max_steps``, ``cables``
            ((m, 2) node pairs), ``roles`` (per node: ``"thruster"``, ``"passive"`` or ``"bead"``),
            ``thrusters`` (the nodes with thrusters), ``max_thrust`` (N, per thruster),
            ``nominal`` ((n, 3) nominal positions, m), ``terminated``, ``end_reason`` and
            ``return`` (the sum of the rewards), besides ``format`` and ``format_version``.
        time: (T+1,) simulation time, s.
        positions: (T+1, n, 3) node positions in the cluster's frame, m.
        tension: (T+1, m) cable tensions, N.
        slack: (T+1, m) cables carrying no tension (broken ones included).
        broken: (T+1, m) cables that have broken.
        thrust: (T+1, n, 3) thrust force on each node over the step that led to the frame, N
            (zero at frame 0 and on nodes without thrusters).
        actions: (T, A) the commands given, as the env received them (float32).
        reward: (T+1,) reward of the step that led to each frame (NaN at frame 0).
        energy: (T+1,) vibration energy, J.
    """

    meta: dict[str, Any]
    time: np.ndarray
    positions: np.ndarray
    tension: np.ndarray
    slack: np.ndarray
    broken: np.ndarray
    thrust: np.ndarray
    actions: np.ndarray
    reward: np.ndarray
    energy: np.ndarray

    @property
    def steps(self) -> int:
        """T, the control steps recorded."""
        return int(self.actions.shape[0])

    def arrays(self) -> dict[str, np.ndarray]:
        """The per-frame arrays by name (every field but ``meta``)."""
        return {field.name: getattr(self, field.name) for field in dataclasses.fields(self) if field.name != "meta"}


#: Each array's dtype kind and shape, in terms of T (steps), n (nodes), m (cables), A (action size).
ARRAY_SPECS: dict[str, tuple[str, tuple[str, ...]]] = {
    "time": ("f", ("T+1",)),
    "positions": ("f", ("T+1", "n", "3")),
    "tension": ("f", ("T+1", "m")),
    "slack": ("b", ("T+1", "m")),
    "broken": ("b", ("T+1", "m")),
    "thrust": ("f", ("T+1", "n", "3")),
    "actions": ("f", ("T", "A")),
    "reward": ("f", ("T+1",)),
    "energy": ("f", ("T+1",)),
}


class EpisodeStepper:
    """Steps one episode of a policy on ``gym.make_vec(env_id, num_envs=1)``, keeping every frame.

    Args:
        env_id: a registered tether-gym id.
        seed: the reset seed (an int >= 0).
        make_policy: builds the policy from the (vector) env it will control; a policy with an
            ``attach(env)`` method (one that reads the env's state, such as ``mpc``) is attached.
        name: the controller's name, recorded.
        env_kwargs: keyword arguments of ``gym.make_vec``.

    The env is a one-episode vector env with next-step autoreset, so that the state after the
    last step is still there to record. :meth:`step` advances one control step; :attr:`done`
    says the episode has ended; :meth:`recording` returns the frames so far.
    """

    def __init__(
        self,
        env_id: str,
        seed: int,
        make_policy: Callable[[Any], Policy],
        name: str,
        env_kwargs: Mapping[str, Any] | None = None,
    ) -> None:
        import gymnasium as gym
        from gymnasium.vector import AutoresetMode

        import tether_gym  # noqa: F401 - registers the ids

        if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
            raise ValueError(f"seed must be an integer >= 0; got {seed!r}")
        kwargs = dict(env_kwargs or {})
        self.env: Any = gym.make_vec(env_id, num_envs=1, autoreset_mode=AutoresetMode.NEXT_STEP, **kwargs)
        self.policy = make_policy(self.env)
        if hasattr(self.policy, "attach"):
            self.policy.attach(self.env)
        unwrapped: Any = self.env.unwrapped
        self.task = unwrapped.task
        max_steps = unwrapped.max_episode_steps
        self.max_steps = int(max_steps) if max_steps is not None else None
        cluster = self.task.cluster
        thrusters = [int(node) for node in self.task.thrusters]
        roles = ["bead" if bead else "passive" for bead in cluster.is_bead]
        for node in thrusters:
            roles[node] = "thruster"
        self.meta: dict[str, Any] = {
            "format": FORMAT,
            "format_version": FORMAT_VERSION,
            "env_id": env_id,
            "env_kwargs": _jsonable(kwargs),
            "controller": name,
            "seed": int(seed),
            "cluster": cluster.name,
            "frame": {"kind": cluster.frame.kind, "rate": float(cluster.frame.rate)},
            "control_interval": float(self.task.config.control_interval),
            "max_steps": self.max_steps,
            "cables": np.asarray(cluster.cables, dtype=np.int64).reshape(-1, 2).tolist(),
            "roles": roles,
            "thrusters": thrusters,
            "max_thrust": [float(value) for value in self.task.max_thrust],
            "nominal": np.asarray(cluster.positions, dtype=float).tolist(),
            "terminated": False,
            "end_reason": "running",
            "return": 0.0,
        }
        self.observation, _ = self.env.reset(seed=int(seed))
        self.frames: dict[str, list[np.ndarray]] = {name: [] for name in ARRAY_SPECS if name != "actions"}
        self.actions: list[np.ndarray] = []
        self.done = False
        self._count = 0
        self._capture(reward=math.nan)

    def _capture(self, reward: float) -> None:
        from tether_gym.envs.contract import Scalar

        sim, task = self.task.sim, self.task
        self.frames["time"].append(np.asarray(float(sim.time[0])))
        self.frames["positions"].append(sim.positions_[0].copy())
        self.frames["tension"].append(np.asarray(sim.tension[0], dtype=float).copy())
        self.frames["slack"].append(np.asarray(sim.slack[0], dtype=bool).copy())
        self.frames["broken"].append(np.asarray(sim.broken[0], dtype=bool).copy())
        self.frames["thrust"].append(np.asarray(task.thrust[0], dtype=float).copy())
        self.frames["reward"].append(np.asarray(reward, dtype=float))
        self.frames["energy"].append(np.asarray(float(task.scalars[0, Scalar.VIBRATION_ENERGY])))
        # Counted once the whole frame is in: the live view reads the lists from another thread.
        self._count += 1

    @property
    def count(self) -> int:
        """Frames recorded so far (steps + 1)."""
        return self._count

    def step(self) -> bool:
        """Advance one control step (nothing once the episode has ended); returns :attr:`done`."""
        if self.done:
            return True
        actions, _ = self.policy.predict(self.observation, deterministic=True)
        actions = np.asarray(actions, dtype=np.float32).reshape(1, -1)
        self.observation, reward, terminated, truncated, infos = self.env.step(actions)
        self.actions.append(actions[0].copy())
        self._capture(reward=float(reward[0]))
        self.meta["return"] = float(self.meta["return"]) + float(reward[0])
        if bool(terminated[0] or truncated[0]):
            self.done = True
            self.meta["terminated"] = bool(terminated[0])
            reason = str(infos["end_reason"][0]) if "end_reason" in infos else "running"
            # A time limit is no failure, and the env names no reason for it.
            self.meta["end_reason"] = "time limit" if reason == "running" and not terminated[0] else reason
            self.env.close()
        return self.done

    def recording(self) -> EpisodeRecording:
        """The frames so far as a recording (its own copies)."""
        count = self._count
        arrays = {name: np.stack(values[:count]) for name, values in self.frames.items()}
        action_size = int(self.env.single_action_space.shape[0])
        actions = np.stack(self.actions[: count - 1]) if count > 1 else np.zeros((0, action_size), np.float32)
        return EpisodeRecording(meta=json.loads(json.dumps(self.meta)), actions=actions, **arrays)


def record_episode(
    env_id: str,
    seed: int,
    make_policy: Callable[[Any], Policy],
    name: str,
    env_kwargs: Mapping[str, Any] | None = None,
) -> EpisodeRecording:
    """Run one whole episode (see :class:`EpisodeStepper` for the arguments) and return it."""
    stepper = EpisodeStepper(env_id, seed, make_policy, name, env_kwargs)
    while not stepper.step():
        pass
    return stepper.recording()


def _jsonable(value: Any) -> Any:
    """``value`` as JSON data (numpy scalars and arrays, tuples), or a RecordingError naming it."""
    try:
        return json.loads(json.dumps(value, default=lambda v: v.tolist() if hasattr(v, "tolist") else str(v)))
    except (TypeError, ValueError) as error:
        raise RecordingError(f"env_kwargs cannot be recorded as JSON data: {error}") from None


def recording_file_name(controller: str, seed: int) -> str:
    """The file name of ``controller``'s episode on ``seed``: ``<controller>_seed<seed>.npz``, the
    controller's last path component (a model's folder) with every character that is not a
    letter, a digit or ``-_.`` replaced by ``_``, so that any name is one safe file name."""
    stem = Path(controller).name or controller
    safe = "".join(c if c.isalnum() or c in "-_." else "_" for c in stem)
    return f"{safe}_seed{int(seed)}.npz"


def save_recording(recording: EpisodeRecording, path: str | os.PathLike[str]) -> Path:
    """Write ``recording`` to ``path`` (``.npz`` is appended if missing), atomically: a temporary
    file beside it, then a rename. Returns the path written."""
    target = Path(path)
    if target.suffix != ".npz":
        target = target.with_name(target.name + ".npz")
    check_recording(recording, str(target))
    target.parent.mkdir(parents=True, exist_ok=True)
    handle, temporary = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".npz", dir=target.parent)
    try:
        with os.fdopen(handle, "wb") as file:
            arrays: dict[str, Any] = {"meta": np.array(json.dumps(recording.meta)), **recording.arrays()}
            np.savez_compressed(file, **arrays)
        # mkstemp's file is private (0600); a recording is shared data, with the usual permissions.
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(temporary, 0o666 & ~umask)
        os.replace(temporary, target)
    except BaseException:
        Path(temporary).unlink(missing_ok=True)
        raise
    return target


def load_recording(path: str | os.PathLike[str]) -> EpisodeRecording:
    """Read a recording written by :func:`save_recording`, without pickle, and check it.

    Raises:
        RecordingError: the file is missing, is not an ``.npz`` archive, holds object arrays
            (which would need pickle), is another kind of ``.npz`` (no tether-gym metadata), was
            written by a newer format version, or has an array of the wrong shape or type.
    """
    source = Path(path)
    where = str(source)
    if not source.is_file():
        raise RecordingError(f"no recording at {where}: pass the path of an .npz file written by a recording")
    if not zipfile.is_zipfile(source):
        raise RecordingError(f"{where} is not a tether-gym episode recording: not an .npz archive (corrupt or foreign)")
    try:
        with np.load(source, allow_pickle=False) as archive:
            contents = {name: archive[name] for name in archive.files}
    except ValueError as error:
        if "allow_pickle" in str(error) or "Object arrays" in str(error):
            raise RecordingError(
                f"{where} holds object arrays, which only pickle can load, and pickle can run code: refused "
                f"(a recording holds numbers only)"
            ) from None
        raise RecordingError(f"{where} is not a readable .npz archive: {error}") from None
    except (OSError, zipfile.BadZipFile, EOFError) as error:
        raise RecordingError(f"{where} is not a readable .npz archive (corrupt or truncated): {error}") from None
    meta_array = contents.pop("meta", None)
    if meta_array is None or meta_array.shape != () or meta_array.dtype.kind != "U":
        raise RecordingError(
            f"{where} is an .npz archive but not a tether-gym episode recording (no 'meta' entry): "
            f"record one with tether-gym-view --record, agents.compare --save-episodes or save_recording()"
        )
    try:
        meta = json.loads(str(meta_array))
    except json.JSONDecodeError as error:
        raise RecordingError(f"{where}: its metadata is not valid JSON ({error}); the file is corrupt") from None
    if not isinstance(meta, dict) or meta.get("format") != FORMAT:
        found = meta.get("format") if isinstance(meta, dict) else type(meta).__name__
        raise RecordingError(f"{where} is not a tether-gym episode recording: its format is {found!r}, not {FORMAT!r}")
    version = meta.get("format_version")
    if not isinstance(version, int) or isinstance(version, bool) or version < 1:
        raise RecordingError(f"{where}: format_version must be a positive integer; got {version!r} (corrupt file)")
    if version > FORMAT_VERSION:
        raise RecordingError(
            f"{where} was written in recording format {version}; this tether-gym reads format "
            f"{FORMAT_VERSION} and older: upgrade tether-gym"
        )
    missing = [name for name in ARRAY_SPECS if name not in contents]
    if missing:
        raise RecordingError(f"{where} lacks the arrays {missing}; the file is incomplete or corrupt")
    recording = EpisodeRecording(meta=meta, **{name: contents[name] for name in ARRAY_SPECS})
    check_recording(recording, where)
    return recording


def check_recording(recording: EpisodeRecording, where: str) -> None:
    """Raise :class:`RecordingError` (naming ``where`` and the field) unless the recording's
    metadata and arrays are complete and consistent with each other."""
    meta = recording.meta
    absent = [name for name in META_FIELDS if name not in meta]
    if absent:
        raise RecordingError(f"{where}: the metadata lacks {absent}; the file is incomplete or corrupt")
    try:
        cables = np.asarray(meta["cables"], dtype=np.int64).reshape(-1, 2)
        nominal = np.asarray(meta["nominal"], dtype=float)
        interval = float(meta["control_interval"])
    except (TypeError, ValueError) as error:
        raise RecordingError(
            f"{where}: malformed cables, nominal or control_interval in its metadata ({error})"
        ) from None
    n = nominal.shape[0] if nominal.ndim == 2 and nominal.shape[1] == 3 else -1
    if n < 1:
        raise RecordingError(f"{where}: nominal must be an (n, 3) list of node positions; got shape {nominal.shape}")
    if len(meta["roles"]) != n or any(role not in ("thruster", "passive", "bead") for role in meta["roles"]):
        raise RecordingError(f"{where}: roles must name each of the {n} nodes 'thruster', 'passive' or 'bead'")
    if cables.size and (cables.min() < 0 or cables.max() >= n):
        raise RecordingError(f"{where}: a cable joins a node outside 0..{n - 1}")
    if not math.isfinite(interval) or interval <= 0:
        raise RecordingError(f"{where}: control_interval must be a positive number of seconds; got {interval}")
    frame = meta["frame"]
    if not isinstance(frame, dict) or frame.get("kind") not in ("inertial", "hill", "rotating"):
        raise RecordingError(f"{where}: frame must be {{'kind': 'inertial' | 'hill' | 'rotating', 'rate': ...}}")
    steps = recording.actions.shape[0] if recording.actions.ndim == 2 else -1
    sizes = {"T": steps, "T+1": steps + 1, "n": n, "m": cables.shape[0], "3": 3, "A": recording.actions.shape[-1]}
    for name, (kind, dims) in ARRAY_SPECS.items():
        array = getattr(recording, name)
        expected = tuple(sizes[dim] for dim in dims)
        if array.dtype.kind != kind or array.shape != expected:
            wanted = "bool" if kind == "b" else "float"
            raise RecordingError(
                f"{where}: array {name!r} must be {wanted} of shape {expected} ({' x '.join(dims)}); "
                f"got {array.dtype} of shape {array.shape}"
            )
    if steps < 0 or not np.all(np.isfinite(recording.time)) or not np.all(np.isfinite(recording.positions)):
        raise RecordingError(f"{where}: time and positions must be finite numbers")
