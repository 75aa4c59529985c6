"""The comparison's settings (``agents.evaluation.comparison.CompareConfig``): checked when made,
and frozen. (The comparison's runs and refusals are tested with the command, in
``tests/agents/test_agents.py`` and ``tests/agents/test_agents_safety.py``.)"""

from __future__ import annotations

import csv
import dataclasses
import time
from pathlib import Path

import numpy as np
import pytest

import agents.compare
import agents.convert
import agents.evaluation.comparison
import agents.policies
import agents.policies.loaded
import agents.train
import agents.training.sb3
from agents.common.files import OutputError, OutputExistsError
from agents.evaluation.comparison import CompareConfig, compare
from tests.agents.helpers import ENV, SHORT


def test_the_config_keeps_checked_values_and_is_frozen() -> None:
    config = CompareConfig(controllers=["passive", "lqr"], episodes=np.int64(3), seed=np.int32(7))
    assert config.controllers == ("passive", "lqr")
    assert (config.episodes, config.seed) == (3, 7)
    assert type(config.episodes) is int and type(config.seed) is int
    with pytest.raises(dataclasses.FrozenInstanceError):
        config.episodes = 4  # type: ignore[misc]


@pytest.mark.parametrize(
    ("settings", "message"),
    [
        ({"episodes": 1}, "episodes must be an integer in 2..100000; got 1"),
        ({"episodes": True}, "episodes must be an integer in 2..100000; got True"),
        ({"satellite": -1}, "satellite must be an integer >= 0; got -1"),
        ({"controllers": "lqr"}, "controllers must be a list of names or paths"),
        ({"controllers": ["lqr", ""]}, "controllers must be a list of names or paths"),
        ({"save_episodes": [3, -1]}, "save_episodes must be an integer >= 0; got -1"),
        ({"save_episodes": 3}, "save_episodes must be a list of seeds"),
    ],
)
def test_bad_settings_are_refused_with_their_name(settings: dict[str, object], message: str) -> None:
    with pytest.raises(ValueError, match=message):
        CompareConfig(**settings)  # type: ignore[arg-type]


def test_saved_episodes_are_the_comparisons_own_episodes_to_the_bit(tmp_path: Path) -> None:
    """--save-episodes reruns a seed one episode at a time; for the scripted laws (whose actions
    do not depend on the batch) that is the episode of the table, reward for reward."""
    from tether_gym.viewer import load_recording

    names = ["passive", "lqr", "local_tension_aware"]
    config = CompareConfig(
        controllers=names,
        episodes=3,
        seed=50,
        plots=False,
        out=tmp_path,
        save_episodes=(51,),
        env_kwargs={"max_episode_steps": 40},
    )
    records, _ = compare(config)
    for name, record in zip(names, records, strict=True):
        recording = load_recording(tmp_path / "episodes" / "TetherTetrahedron-v0" / f"{name}_seed51.npz")
        np.testing.assert_array_equal(recording.reward[1:], record.rewards[1], err_msg=name)
        np.testing.assert_array_equal(recording.energy, record.energy[1], err_msg=name)


@pytest.mark.slow
def test_comparison_loads_a_trained_model_and_is_reproducible(trained_run: Path, tmp_path: Path) -> None:
    controllers = ["passive", "velocity_feedback", "lqr", "tension_aware", str(trained_run)]
    kwargs = dict(
        env_id="TetherTetrahedron-v0",
        controllers=controllers,
        episodes=3,
        seed=123,
        env_kwargs={"max_episode_steps": 40},
    )
    records, summaries = compare(CompareConfig(out=tmp_path / "a", **kwargs))
    assert [r.name for r in records[:4]] == ["passive", "velocity_feedback", "lqr", "tension_aware"]
    table = (tmp_path / "a" / "comparison.md").read_text()
    for record in records:
        assert f"| {record.name} |" in table
    for name in ("energy.png", "displacement.png", "comparison.csv"):
        assert (tmp_path / "a" / name).stat().st_size > 0
    compare(CompareConfig(out=tmp_path / "b", plots=False, **kwargs))
    rows_a = list(csv.reader(open(tmp_path / "a" / "comparison.csv")))
    rows_b = list(csv.reader(open(tmp_path / "b" / "comparison.csv")))
    assert rows_a == rows_b and len(rows_a) == 1 + len(controllers)
    # Scripted control beats doing nothing even over 4 s.
    energy = {r.name: np.nanmean(r.energy[:, -1] / r.energy[:, 0]) for r in records}
    assert energy["velocity_feedback"] < energy["passive"]


@pytest.fixture
def no_work(monkeypatch: pytest.MonkeyPatch) -> None:
    """Make any rollout, controller load or env build fail the test: a refusal must come first."""

    def forbidden(*args: object, **kwargs: object) -> None:
        raise AssertionError("work started before the outputs were checked")

    monkeypatch.setattr(agents.evaluation.comparison, "rollout", forbidden)
    monkeypatch.setattr(agents.evaluation.comparison, "make_controller", forbidden)
    monkeypatch.setattr(agents.training.sb3, "make_training_env", forbidden)


def bad_outputs(tmp_path: Path) -> dict[str, Path]:
    file = tmp_path / "a_file"
    file.write_text("keep me")
    real = tmp_path / "real"
    real.mkdir()
    link = tmp_path / "link"
    link.symlink_to(real, target_is_directory=True)
    return {"is a file": file, "inside .* which is a file": file / "sub", "symlink": link}


def test_compare_refuses_a_bad_out_before_any_work(tmp_path: Path, no_work: None) -> None:
    for message, out in bad_outputs(tmp_path).items():
        start = time.perf_counter()
        with pytest.raises(OutputError, match=message):
            agents.compare.main(["--out", str(out), "--episodes", "2"])
        assert time.perf_counter() - start < 0.5, message
    assert (tmp_path / "a_file").read_text() == "keep me" and not any((tmp_path / "real").iterdir())
    if Path("/proc/self").is_dir():  # a directory nobody can create files in, even root
        with pytest.raises(OutputError, match="cannot be created|not writable"):
            agents.compare.main(["--out", "/proc/self/tether-gym-out"])


def test_compare_refuses_to_overwrite_and_to_follow_symlinks(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    out = tmp_path / "compare"
    kwargs = dict(env_id=ENV, controllers=["passive", "lqr"], episodes=2, plots=False, env_kwargs=SHORT)
    compare(CompareConfig(out=out, **kwargs))
    first = (out / "comparison.csv").read_text()
    monkeypatch.setattr(
        agents.evaluation.comparison, "rollout", lambda *a, **k: pytest.fail("rollout before the refusal")
    )
    with pytest.raises(OutputExistsError, match="comparison.md, comparison.csv .*--force"):
        compare(CompareConfig(out=out, **kwargs))
    monkeypatch.undo()
    compare(CompareConfig(out=out, force=True, **kwargs))
    assert (out / "comparison.csv").read_text() == first  # same seeds: same numbers
    assert not [p for p in out.iterdir() if p.name.startswith(".")]  # no temporary files left
    outside = tmp_path / "outside.md"
    outside.write_text("not yours")
    (out / "comparison.md").unlink()
    (out / "comparison.md").symlink_to(outside)
    with pytest.raises(OutputError, match="symlink"):
        compare(CompareConfig(out=out, force=True, **kwargs))
    assert outside.read_text() == "not yours" and (out / "comparison.md").is_symlink()
