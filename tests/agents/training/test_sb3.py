"""agents.training.sb3 (the loop of agents.train) trains the steps it says, records them, and
always leaves a loadable best/.

``--timesteps 4096`` used to train 16 384 steps (SB3 collects whole rollouts of n_steps x
n_envs), with a progress bar of 16 384/4 096, a config.yml that said 4096, and no best/ policy
because no evaluation fell inside so short a run.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import yaml

from agents.policies import TrainedPolicy
from agents.training.config import TrainConfig
from agents.training.sb3 import make_training_env, rollout_steps, train, whole_rollouts

ENV = "TetherTetrahedron-v0"


def test_rollout_steps_of_on_and_off_policy_models(capsys: pytest.CaptureFixture[str]) -> None:
    from stable_baselines3 import PPO, SAC

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
