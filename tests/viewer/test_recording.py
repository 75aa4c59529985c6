"""Recorded episodes: what is saved is what the env did, to the bit, and a bad file is refused by name."""

from __future__ import annotations

import json
import zipfile
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import tether_gym  # noqa: F401 - registers the ids
from tether_gym.viewer import (
    FORMAT_VERSION,
    EpisodeRecording,
    RecordingError,
    load_recording,
    record_episode,
    recording_file_name,
    save_recording,
)


class SineThrust:
    """A deterministic policy that uses the thrusters (so that thrust and actions are not zero)."""

    def __init__(self, env: object) -> None:
        self.size = int(env.single_action_space.shape[0])  # type: ignore[attr-defined]
        self.step = 0

    def predict(self, observation: np.ndarray, deterministic: bool = True) -> tuple[np.ndarray, None]:
        self.step += 1
        phase = 0.3 * self.step + np.arange(self.size)
        return (0.5 * np.sin(phase)).astype(np.float32)[None, :], None


def recorded(env_id: str = "TetherTetrahedron-v0", seed: int = 7, **env_kwargs: object) -> EpisodeRecording:
    return record_episode(env_id, seed, SineThrust, "sine", env_kwargs or None)


def test_a_saved_recording_loads_back_to_the_bit(tmp_path: Path) -> None:
    recording = recorded(max_episode_steps=40)
    path = save_recording(recording, tmp_path / "episode")
    assert path.suffix == ".npz"
    loaded = load_recording(path)
    assert loaded.meta == recording.meta
    for name, values in recording.arrays().items():
        np.testing.assert_array_equal(getattr(loaded, name), values, err_msg=name)
        assert getattr(loaded, name).dtype == values.dtype, name
    assert loaded.steps == 40 and loaded.meta["end_reason"] == "time limit"
    assert loaded.meta["return"] == pytest.approx(float(np.nansum(loaded.reward)), rel=1e-12)


@pytest.mark.parametrize("env_id", ["TetherTetrahedron-v0", "TetherCoarseBeadedTetrahedron-v0", "TetherRadialChain-v0"])
def test_a_replayed_recording_reproduces_the_single_envs_positions_to_the_bit(env_id: str, tmp_path: Path) -> None:
    """The recorded commands, replayed through gym.make on the recorded seed, give the recorded
    positions, tensions, rewards and energies exactly: the file is the env's own trajectory."""
    recording = load_recording(save_recording(recorded(env_id, seed=11, max_episode_steps=60), tmp_path / "e.npz"))
    env = gym.make(env_id, max_episode_steps=60)
    env.reset(seed=11)
    sim = env.unwrapped.task.sim
    np.testing.assert_array_equal(sim.positions_[0], recording.positions[0])
    assert recording.thrust[1:].any(), "the policy must thrust for the comparison to mean something"
    for k, action in enumerate(recording.actions, start=1):
        _, reward, terminated, truncated, info = env.step(action)
        np.testing.assert_array_equal(sim.positions_[0], recording.positions[k], err_msg=f"positions at step {k}")
        np.testing.assert_array_equal(sim.tension[0], recording.tension[k], err_msg=f"tension at step {k}")
        np.testing.assert_array_equal(env.unwrapped.task.thrust[0], recording.thrust[k], err_msg=f"thrust at step {k}")
        assert reward == recording.reward[k]
        assert info["vibration_energy"] == recording.energy[k]
    assert truncated and not terminated
    # The beads of tethers with mass are recorded as nodes, with their role.
    roles = recording.meta["roles"]
    assert roles.count("bead") == env.unwrapped.cluster.num_nodes - env.unwrapped.cluster.num_satellites


def test_the_same_seed_records_the_same_episode_to_the_bit() -> None:
    first, second = recorded(max_episode_steps=30), recorded(max_episode_steps=30)
    for name, values in first.arrays().items():
        assert np.array_equal(values, getattr(second, name), equal_nan=True), name


def test_roles_name_the_thrusters_and_the_passive_satellites() -> None:
    recording = recorded(thrusters=(0, 1), max_episode_steps=5)
    assert recording.meta["roles"] == ["thruster", "thruster", "passive", "passive"]
    assert not recording.thrust[:, 2:].any()


def write_npz(path: Path, **arrays: np.ndarray) -> Path:
    with path.open("wb") as file:
        np.savez(file, **arrays)
    return path


def test_bad_files_are_refused_with_the_problem_named(tmp_path: Path) -> None:
    good = save_recording(recorded(max_episode_steps=5), tmp_path / "good.npz")
    with pytest.raises(RecordingError, match="no recording at"):
        load_recording(tmp_path / "missing.npz")
    (tmp_path / "text.npz").write_text("not an archive")
    with pytest.raises(RecordingError, match="not an .npz archive"):
        load_recording(tmp_path / "text.npz")
    truncated = tmp_path / "truncated.npz"
    truncated.write_bytes(good.read_bytes()[:300])
    with pytest.raises(RecordingError, match="corrupt|not an .npz"):
        load_recording(truncated)
    with pytest.raises(RecordingError, match="not a tether-gym episode recording .no 'meta'"):
        load_recording(write_npz(tmp_path / "foreign.npz", weights=np.zeros(3)))
    pickled = tmp_path / "pickled.npz"
    np.savez(pickled, meta=np.array({"format": "x"}, dtype=object))
    with pytest.raises(RecordingError, match="object arrays.*pickle"):
        load_recording(pickled)
    other = write_npz(tmp_path / "other.npz", meta=np.array(json.dumps({"format": "something-else"})))
    with pytest.raises(RecordingError, match="its format is 'something-else'"):
        load_recording(other)

    def altered(name: str, change: dict | None = None, **arrays: np.ndarray) -> Path:
        with np.load(good, allow_pickle=False) as archive:
            contents = {key: archive[key] for key in archive.files}
        meta = json.loads(str(contents["meta"]))
        meta.update(change or {})
        contents.update(meta=np.array(json.dumps(meta)), **arrays)
        return write_npz(tmp_path / name, **contents)

    with pytest.raises(RecordingError, match=f"format 2; this tether-gym reads format {FORMAT_VERSION}"):
        load_recording(altered("newer.npz", {"format_version": FORMAT_VERSION + 1}))
    with pytest.raises(RecordingError, match="array 'positions' must be float of shape \\(6, 4, 3\\)"):
        load_recording(altered("shape.npz", positions=np.zeros((6, 5, 3))))
    with pytest.raises(RecordingError, match="array 'slack' must be bool"):
        load_recording(altered("dtype.npz", slack=np.zeros((6, 6))))
    with pytest.raises(RecordingError, match="time and positions must be finite"):
        load_recording(altered("nan.npz", time=np.full(6, np.nan)))
    with pytest.raises(RecordingError, match="a cable joins a node outside 0..3"):
        load_recording(altered("cable.npz", {"cables": [[0, 9]] * 6}))
    with pytest.raises(RecordingError, match="lacks the arrays \\['energy'\\]"):
        with zipfile.ZipFile(good) as archive, zipfile.ZipFile(tmp_path / "partial.npz", "w") as partial:
            for item in archive.namelist():
                if item != "energy.npy":
                    partial.writestr(item, archive.read(item))
        load_recording(tmp_path / "partial.npz")


def test_a_bad_seed_is_refused() -> None:
    with pytest.raises(ValueError, match="seed must be an integer >= 0"):
        record_episode("TetherTetrahedron-v0", -1, SineThrust, "sine")


@pytest.mark.parametrize(
    ("controller", "expected"),
    [
        ("lqr", "lqr_seed7.npz"),
        ("runs/TetherTetrahedron-v0/ppo_seed0", "ppo_seed0_seed7.npz"),
        ("runs/x/", "x_seed7.npz"),
        ("my policy: v2*", "my_policy__v2__seed7.npz"),
        ("..", ".._seed7.npz"),
    ],
)
def test_a_recording_file_name_is_one_safe_name(controller: str, expected: str) -> None:
    name = recording_file_name(controller, 7)
    assert name == expected
    assert "/" not in name and "\\" not in name
