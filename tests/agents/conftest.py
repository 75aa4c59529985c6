"""Fixtures shared by the agents' tests: a short PPO run through the training command, and a
tiny in-memory PPO with its SB3 files."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest
import yaml
from stable_baselines3 import PPO

from agents.training.config import TrainConfig
from agents.training.sb3 import make_training_env, train
from tests.agents.helpers import ENV, SHORT, crafted_zip, payload


@pytest.fixture(scope="session")
def trained_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A few hundred PPO steps, with a checkpoint, through the project's own training script."""
    out = tmp_path_factory.mktemp("runs")
    return train(
        TrainConfig(
            "ppo",
            "TetherTetrahedron-v0",
            seed=0,
            out=out,
            timesteps=512,
            num_envs=4,
            overrides={"n_steps": 64, "batch_size": 64},
            eval_freq=256,
            eval_episodes=2,
            checkpoint_freq=256,
            progress_bar=False,
        )
    )


@pytest.fixture(scope="session")
def sb3_model() -> tuple[PPO, object]:
    """A tiny PPO (256 steps) with VecNormalize statistics, in memory."""
    venv = make_training_env(ENV, 4, seed=0, normalize={"norm_obs": True, "norm_reward": True}, env_kwargs=SHORT)
    model = PPO(
        "MlpPolicy",
        venv,
        n_steps=64,
        batch_size=64,
        n_epochs=2,
        seed=0,
        device="cpu",
        policy_kwargs={"net_arch": [32, 32], "log_std_init": -1.0},
    )
    model.learn(256)
    return model, venv


@pytest.fixture(scope="session")
def sb3_run(sb3_model: tuple[PPO, object], tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The tiny model as SB3 writes it: model.zip + vecnormalize.pkl (+ config.yml)."""
    model, venv = sb3_model
    run = tmp_path_factory.mktemp("sb3_run")
    model.save(run / "model.zip")
    venv.save(str(run / "vecnormalize.pkl"))
    (run / "config.yml").write_text(yaml.safe_dump({"algo": "ppo", "env_id": ENV, "seed": 0}))
    return run


@pytest.fixture(params=["vecnormalize.pkl", "model.zip"])
def crafted(request: pytest.FixtureRequest, sb3_run: Path, tmp_path: Path) -> tuple[Path, Path]:
    """(run directory, marker): a copy of the SB3 run with a payload in one of its two files."""
    run, marker = tmp_path / "crafted", tmp_path / "marker"
    shutil.copytree(sb3_run, run)
    if request.param == "vecnormalize.pkl":
        (run / "vecnormalize.pkl").write_bytes(payload(marker, (sb3_run / "vecnormalize.pkl").read_bytes()))
    else:
        crafted_zip(sb3_run / "model.zip", run / "model.zip", marker)
    return run, marker
