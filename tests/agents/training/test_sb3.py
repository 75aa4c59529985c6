"""agents.training.sb3 (the loop of agents.train) trains the steps it says, records them, and
always leaves a loadable best/.

``--timesteps 4096`` used to train 16 384 steps (SB3 collects whole rollouts of n_steps x
n_envs), with a progress bar of 16 384/4 096, a config.yml that said 4096, and no best/ policy
because no evaluation fell inside so short a run.
"""

from __future__ import annotations

import json
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import yaml
from stable_baselines3 import PPO, SAC

from agents.evaluation.rollout import rollout
from agents.policies import TrainedPolicy, make_controller
from agents.training.config import TrainConfig
from agents.training.sb3 import make_training_env, rollout_steps, train, whole_rollouts

ENV = "TetherTetrahedron-v0"


def test_rollout_steps_of_on_and_off_policy_models(capsys: pytest.CaptureFixture[str]) -> None:

    ppo = PPO("MlpPolicy", make_training_env(ENV, 4, seed=0, normalize=False), n_steps=64, batch_size=64, device="cpu")
    assert rollout_steps(ppo) == (256, "rollouts of n_steps 64 x 4 envs")
    assert whole_rollouts(ppo, 512, "--timesteps") == 512
    assert capsys.readouterr().out == ""  # a whole number of rollouts: nothing to say
    assert whole_rollouts(ppo, 300, "--timesteps") == 512
    assert "--timesteps 300 rounded up to 512 env steps" in capsys.readouterr().out
    sac = SAC("MlpPolicy", make_training_env(ENV, 2, seed=0, normalize=False), train_freq=3, device="cpu")
    assert rollout_steps(sac) == (6, "train_freq 3 steps x 2 envs")
    episodic = SAC("MlpPolicy", make_training_env(ENV, 2, seed=0, normalize=False), train_freq=(1, "episode"))
    assert rollout_steps(episodic) is None  # episodes vary in length: nothing to round to
    assert whole_rollouts(episodic, 301, "n_timesteps") == 301


@pytest.mark.slow
def test_a_short_run_trains_what_it_says_and_leaves_a_best_policy(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    run = train(
        TrainConfig(
            "ppo",
            ENV,
            seed=0,
            out=tmp_path,
            timesteps=300,
            num_envs=4,
            overrides={"n_steps": 64, "batch_size": 64},
            eval_freq=10_000,
            eval_episodes=2,
            checkpoint_freq=10_000,
            progress_bar=False,
        )
    )
    out = capsys.readouterr().out
    assert "--timesteps 300 rounded up to 512 env steps" in out
    assert "no evaluation ran in 512 steps (--eval-freq 10,000): evaluating the final policy" in out
    config = yaml.safe_load((run / "config.yml").read_text())
    assert config["hyperparams"]["n_timesteps"] == 512 and config["num_timesteps"] == 512
    assert TrainedPolicy(run).metadata["num_timesteps"] == 512
    best = TrainedPolicy(run, best=True)  # loads: its manifest and files are complete
    assert best.metadata["num_timesteps"] == 512
    log = json.loads((run / "best" / "evaluations.json").read_text())
    assert [entry["timesteps"] for entry in log["evaluations"]] == [512]
    assert log["training"]["timesteps"] == 512


def _check_evaluations(run: Path) -> None:
    """best/evaluations.json: every evaluation on the same seeds, paired against the best baseline
    rolled out on those seeds, and the best/ policy is the one with the best mean return."""
    from agents.training.selection import evaluation_seeds

    log = json.loads((run / "best" / "evaluations.json").read_text())
    seeds = evaluation_seeds(2)
    assert log["seeds"] == [seeds[0], seeds[-1]] and log["bar"] == max(log["baselines"], key=log["baselines"].get)
    assert [entry["timesteps"] for entry in log["evaluations"]] == [256, 512]
    assert (
        log["training"]["timesteps"] == 512 and log["training"]["wall_time_s"] >= log["evaluations"][-1]["wall_time_s"]
    )
    env = gym.make("TetherTetrahedron-v0")
    bar = rollout(make_controller(log["bar"], env), "TetherTetrahedron-v0", seeds).rewards.sum(axis=1)
    assert bar.mean() == pytest.approx(log["baselines"][log["bar"]], rel=1e-12)
    for entry in log["evaluations"]:
        assert entry["difference_vs_bar"] == pytest.approx(np.mean(np.array(entry["returns"]) - bar), rel=1e-9)
        assert entry["difference_low"] < entry["difference_vs_bar"] < entry["difference_high"]
    best = TrainedPolicy(run, best=True)
    best.attach(env)
    returns = rollout(best, "TetherTetrahedron-v0", seeds).rewards.sum(axis=1)
    assert returns.mean() == pytest.approx(log["best_mean_return"], rel=1e-6)
    assert log["best_mean_return"] == max(entry["mean_return"] for entry in log["evaluations"])
    for name, beat in log["first_beat"].items():
        first = next(entry for entry in log["evaluations"] if entry["mean_return"] > log["baselines"][name])
        assert beat == {"timesteps": first["timesteps"], "wall_time_s": first["wall_time_s"]}
    assert set(log["first_beat"]) == {
        name
        for name, value in log["baselines"].items()
        if any(entry["mean_return"] > value for entry in log["evaluations"])
    }


@pytest.mark.slow
def test_training_smoke_writes_everything(trained_run: Path) -> None:
    safe = (
        "policy.json",
        "policy.safetensors",
        "normalization.json",
        "training.safetensors",
        "training.json",
        "MANIFEST.sha256",
    )
    for name in ("config.yml", *safe, *(f"best/{name}" for name in safe), "best/evaluations.json"):
        assert (trained_run / name).is_file(), name
    assert any((trained_run / "tensorboard").rglob("events.out.tfevents.*"))
    _check_evaluations(trained_run)
    assert sorted(p.name for p in (trained_run / "checkpoints").iterdir()) == ["ppo_256_steps", "ppo_512_steps"]
    for checkpoint in (trained_run / "checkpoints").iterdir():
        assert sorted(p.name for p in checkpoint.iterdir()) == sorted(safe)
    # Nothing the project writes is a pickle.
    assert not [p for p in trained_run.rglob("*") if p.suffix in (".zip", ".pkl", ".pt", ".pth")]
    policy = TrainedPolicy(trained_run)
    obs = np.zeros((3,) + gym.make("TetherTetrahedron-v0").observation_space.shape, dtype=np.float32)
    actions, _ = policy.predict(obs)
    assert actions.shape == (3, 12)
    assert TrainedPolicy(trained_run, best=True).metadata["num_timesteps"] in (256, 512)


@pytest.mark.slow
def test_training_resumes_from_a_checkpoint(trained_run: Path, tmp_path: Path) -> None:
    run = train(
        TrainConfig(
            "ppo",
            "TetherTetrahedron-v0",
            seed=0,
            out=tmp_path,
            timesteps=256,
            num_envs=4,
            overrides={"n_steps": 64, "batch_size": 64},
            resume=trained_run / "checkpoints" / "ppo_256_steps",
            eval_freq=10_000,
            eval_episodes=2,
            checkpoint_freq=10_000,
            progress_bar=False,
        )
    )
    assert TrainedPolicy(run).metadata["num_timesteps"] == 512  # 256 from the checkpoint + 256 more


def test_curriculum_raises_the_training_difficulty_on_schedule(tmp_path: Path) -> None:

    from agents.controllers.base import task_of
    from agents.training.callbacks import DifficultyCurriculum

    schedule = DifficultyCurriculum(0.2, 0.5, 1000)
    assert [schedule.difficulty_at(t) for t in (0, 250, 500, 900)] == pytest.approx([0.2, 0.6, 1.0, 1.0])
    venv = make_training_env("TetherSpinningTriangle-v0", 4, seed=0, normalize=False)
    model = PPO("MlpPolicy", venv, n_steps=32, batch_size=64, n_epochs=1, device="cpu")
    model.learn(256, callback=DifficultyCurriculum(0.0, 1.0, 512))
    assert task_of(venv).difficulty == pytest.approx(0.5, abs=0.02)
    with pytest.raises(ValueError, match="curriculum"):
        DifficultyCurriculum(1.5, 0.5, 1000)


@pytest.mark.slow
def test_sac_training_smoke(tmp_path: Path) -> None:
    run = train(
        TrainConfig(
            "sac",
            "TetherTetrahedron-v0",
            seed=0,
            out=tmp_path,
            timesteps=200,
            num_envs=2,
            overrides={"learning_starts": 50, "batch_size": 32, "gradient_steps": 1},
            eval_freq=10_000,
            eval_episodes=2,
            checkpoint_freq=10_000,
            progress_bar=False,
        )
    )
    assert TrainedPolicy(run).algo == "sac"
