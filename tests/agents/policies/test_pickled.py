"""Pickle-based SB3 files load only on opt-in.

The crafted model directories hold real payloads: unpickling them writes a marker file (and
then returns the genuine object, so that a trusted load still works). A test first shows that
the payload fires when unpickled directly, so the tests that expect no marker can fail."""

from __future__ import annotations

import pickle
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import agents.compare
import agents.convert
import agents.evaluation.comparison
import agents.policies
import agents.policies.loaded
import agents.train
import agents.training.sb3
from agents.policies import TrainedPolicy, make_controller
from agents.policies.pickled import PickleNotTrustedError, PickleTrustWarning
from tests.agents.helpers import ENV


def test_the_payloads_are_real(crafted: tuple[Path, Path]) -> None:
    """Unpickled directly, each crafted file runs its code (and still gives the genuine object)."""
    run, marker = crafted
    from stable_baselines3.common.save_util import load_from_zip_file
    from stable_baselines3.common.vec_env import VecNormalize

    normalizer = pickle.loads((run / "vecnormalize.pkl").read_bytes())
    data, _, _ = load_from_zip_file(run / "model.zip")
    assert marker.read_text() == "pwned"
    assert isinstance(normalizer, VecNormalize) and data["policy_class"].__name__ == "ActorCriticPolicy"


def test_no_loader_or_command_unpickles_without_the_opt_in(crafted: tuple[Path, Path], tmp_path: Path) -> None:
    run, marker = crafted
    env = gym.make_vec(ENV, num_envs=1)
    attempts = [
        lambda: TrainedPolicy(run),
        lambda: TrainedPolicy(run / "model.zip"),
        lambda: make_controller(str(run), env),
        lambda: agents.compare.main(
            ["--controllers", "passive", str(run), "--episodes", "2", "--out", str(tmp_path / "compare")]
        ),
        lambda: agents.train.main(
            [
                "--resume",
                str(run / "model.zip"),
                "--out",
                str(tmp_path / "runs"),
                "--timesteps",
                "64",
                "--n-envs",
                "4",
                "--no-progress",
            ]
        ),
        lambda: agents.train.main(["--resume", str(run), "--out", str(tmp_path / "runs"), "--timesteps", "64"]),
        lambda: agents.convert.main([str(run), str(tmp_path / "converted")]),
    ]
    for attempt in attempts:
        with pytest.raises(PickleNotTrustedError, match="arbitrary code") as error:
            attempt()
        assert "--trust-pickle" in str(error.value) and "agents.convert" in str(error.value)
    assert not marker.exists()
    assert not (tmp_path / "compare" / "comparison.md").exists()
    assert not (tmp_path / "runs").exists()  # refused before the run directory was made


def test_opting_in_loads_pickle_files_with_a_warning(crafted: tuple[Path, Path], tmp_path: Path) -> None:
    """With the opt-in, every path loads the crafted files -- and so runs their code, which is
    what the warning is about."""
    run, marker = crafted
    env = gym.make_vec(ENV, num_envs=1)
    attempts = [
        lambda: TrainedPolicy(run, trust_pickle=True).predict(np.zeros((2, 30), dtype=np.float32)),
        lambda: make_controller(str(run), env, trust_pickle=True),
        lambda: agents.compare.main(
            [
                "--controllers",
                "passive",
                str(run),
                "--episodes",
                "2",
                "--no-plots",
                "--trust-pickle",
                "--out",
                str(tmp_path / "compare"),
            ]
        ),
        lambda: agents.train.main(
            [
                "--resume",
                str(run / "model.zip"),
                "--trust-pickle",
                "--out",
                str(tmp_path / "runs"),
                "--timesteps",
                "64",
                "--n-envs",
                "4",
                "--no-progress",
                "--eval-freq",
                "100000",
                "--checkpoint-freq",
                "100000",
                "--eval-episodes",
                "2",
            ]
        ),
        lambda: agents.convert.main([str(run), str(tmp_path / "converted"), "--trust-pickle"]),
    ]
    for attempt in attempts:
        with pytest.warns(PickleTrustWarning, match="runs any code"):
            attempt()
        assert marker.exists()
        marker.unlink()
    assert f"| {run} |" in (tmp_path / "compare" / "comparison.md").read_text()
    resumed = TrainedPolicy(tmp_path / "runs" / ENV / "ppo_seed0")
    assert resumed.metadata["num_timesteps"] == 512  # 256 in the zip + one rollout of 4 x 64, counted on
    TrainedPolicy(tmp_path / "converted")  # the converted copy loads without the opt-in
    assert not marker.exists()
