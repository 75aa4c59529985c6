"""Run directories: an earlier run is kept without --force, a run resumes from its own directory,
and a checkpoint that does not fit is refused."""

from __future__ import annotations

from pathlib import Path

import pytest

import agents.compare
import agents.convert
import agents.evaluation.comparison
import agents.policies
import agents.policies.loaded
import agents.train
import agents.training.sb3
from agents.common.files import OutputError, OutputExistsError
from agents.policies import TrainedPolicy, shipped_models
from agents.policies.layout import PolicyFormatError
from agents.training.config import TrainConfig
from agents.training.sb3 import train
from tests.agents.helpers import ENV

TINY = dict(
    timesteps=256,
    num_envs=4,
    overrides={"n_steps": 64, "batch_size": 64, "n_epochs": 1},
    eval_freq=128,
    eval_episodes=2,
    progress_bar=False,
)


@pytest.mark.slow
def test_train_refuses_to_overwrite_a_run_without_force(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    run = train(TrainConfig("ppo", ENV, seed=3, out=tmp_path, checkpoint_freq=128, **TINY))
    assert sorted(p.name for p in (run / "checkpoints").iterdir()) == ["ppo_128_steps", "ppo_256_steps"]
    config = (run / "config.yml").read_text()
    with monkeypatch.context() as patch:
        patch.setattr(
            agents.training.sb3, "make_training_env", lambda *a, **k: pytest.fail("env built before the refusal")
        )
        with pytest.raises(OutputExistsError, match=r"already holds a run .*--force"):
            train(TrainConfig("ppo", ENV, seed=3, out=tmp_path, checkpoint_freq=128, **TINY))
    assert (run / "config.yml").read_text() == config
    # Another seed: another run directory.
    train(TrainConfig("ppo", ENV, seed=4, out=tmp_path, checkpoint_freq=128, **TINY))
    # --force replaces the run: the earlier checkpoints go, new ones come.
    train(TrainConfig("ppo", ENV, seed=3, out=tmp_path, checkpoint_freq=10_000, force=True, **TINY))
    assert not (run / "checkpoints").exists() or not any((run / "checkpoints").iterdir())
    assert TrainedPolicy(run).metadata["num_timesteps"] == 256
    # A symlink anywhere in the run directory is refused, even with --force.
    (run / "best" / "evaluations.json").unlink()
    (run / "best" / "evaluations.json").symlink_to(tmp_path / "elsewhere.json")
    with pytest.raises(OutputError, match="symlink"):
        train(TrainConfig("ppo", ENV, seed=3, out=tmp_path, force=True, **TINY))


@pytest.mark.slow
def test_train_resumes_from_its_own_directory_with_force(tmp_path: Path) -> None:
    run = train(TrainConfig("ppo", ENV, seed=0, out=tmp_path, checkpoint_freq=128, **TINY))
    checkpoint = run / "checkpoints" / "ppo_128_steps"
    with pytest.raises(OutputExistsError):
        train(TrainConfig("ppo", ENV, seed=0, out=tmp_path, resume=checkpoint, **TINY))
    train(TrainConfig("ppo", ENV, seed=0, out=tmp_path, resume=checkpoint, force=True, checkpoint_freq=10_000, **TINY))
    assert TrainedPolicy(run).metadata["num_timesteps"] == 128 + 256
    assert checkpoint.is_dir() and not (run / "checkpoints" / "ppo_256_steps").exists()


@pytest.mark.slow
def test_resume_refuses_a_checkpoint_that_does_not_fit(tmp_path: Path) -> None:
    run = train(TrainConfig("ppo", ENV, seed=0, out=tmp_path / "a", checkpoint_freq=10_000, **TINY))
    overrides = {**TINY["overrides"], "policy_kwargs": {"net_arch": [16], "activation_fn": "relu"}}
    with pytest.raises(PolicyFormatError, match="net_arch.*resume with the run's hyperparameters"):
        train(TrainConfig("ppo", ENV, seed=0, out=tmp_path / "b", resume=run, **{**TINY, "overrides": overrides}))
    with pytest.raises(PolicyFormatError, match="--algo ppo"):
        train(TrainConfig("sac", ENV, seed=0, out=tmp_path / "c", resume=run, **{**TINY, "overrides": {}}))
    with pytest.raises(PolicyFormatError, match="inference only"):
        train(TrainConfig("ppo", ENV, seed=0, out=tmp_path / "d", resume=shipped_models(ENV)["ppo"], **TINY))
