"""The hyperparameter files and their checks: every id covered, and errors that name the key."""

from __future__ import annotations

from pathlib import Path

import pytest

import tether_gym
from agents.training.config import TrainConfig
from agents.training.hyperparams import HyperparameterError, load_hyperparameters, validate_hyperparameters
from agents.training.sb3 import train
from tests.agents.helpers import ENV


def test_hyperparameter_files_cover_every_id() -> None:
    for algo in ("ppo", "sac"):
        for env_id in tether_gym.ENV_IDS:
            hyperparams = load_hyperparameters(algo, env_id)
            assert hyperparams["n_timesteps"] > 0 and hyperparams["n_envs"] >= 1


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("default: {n_envs: 4}", "'n_timesteps' is missing"),
        ("default: {n_timesteps: 1e6}", r"'n_timesteps' must be an integer; got the text '1e6' \(YAML reads"),
        ("default: {n_timesteps: 1000, n_steps: lots}", "'n_steps' must be an integer; got the text 'lots'"),
        ("default: {n_timesteps: 1000, n_steps: 12.5}", "'n_steps' must be an integer; got 12.5"),
        (
            "default: {n_timesteps: 1000, learning_rat: 0.001}",
            "unknown key 'learning_rat' .did you mean 'learning_rate'",
        ),
        ("default: {n_timesteps: 1000, learning_rate: lin_fast}", "'learning_rate' must be a positive number or 'lin_"),
        ("default: {n_timesteps: 1000, gamma: 1.5}", r"'gamma' must be in \(0, 1\]"),
        ("default: {n_timesteps: 1000, n_epochs: true}", "'n_epochs' must be an integer, not true"),
        ("default: {n_timesteps: 1000, seed: 3}", "'seed' cannot be set in a hyperparameter file: use --seed"),
        ("default: {n_timesteps: 1000, policy: TransformerPolicy}", "'policy' must be one of"),
        (
            "default: {n_timesteps: 1000, policy_kwargs: {activation_fn: sigmoid}}",
            "'policy_kwargs.activation_fn' must be",
        ),
        (
            "default: {n_timesteps: 1000, policy_kwargs: {net_arch: [64, wide]}}",
            "'policy_kwargs.net_arch' must be a list",
        ),
        (
            "default: {n_timesteps: 1000, policy_kwargs: {netarch: [64]}}",
            "unknown key 'netarch' .did you mean 'net_arch'",
        ),
        ("default: {n_timesteps: 1000, normalize: {clip_ob: 5}}", "unknown key 'clip_ob'"),
        ("default: {n_timesteps: 1000, n_envs: 0}", "'n_envs' must be in 1..100000; got 0"),
        ("default: {n_timesteps: 1000, n_envs: 100001}", "'n_envs' must be in 1..100000; got 100001"),
        ("default: {n_timesteps: 0}", "'n_timesteps' must be >= 1; got 0"),
        # VecNormalize keeps no observation statistics without norm_obs: the first save failed.
        ("default: {n_timesteps: 1000, normalize: {norm_obs: false}}", "'normalize.norm_obs' must be true"),
        ("default: {n_timesteps: 1000, curriculum: {start: 0.2}}", "'curriculum' must be a mapping with exactly"),
        ("default: {n_timesteps: 1000, rollout_buffer_class: RolloutBuffer}", "'rollout_buffer_class' cannot be set"),
        (
            "default: {n_timesteps: 1000, policy_kwargs: {optimizer_kwargs: {eps: 1e-5}}}",
            "'policy_kwargs.optimizer_kwargs.eps' is the text '1e-5', not a number",
        ),
        ("default: [1, 2]", "entry 'default': must be a mapping"),
        ("TetherChain-v0: {n_timesteps: 5}", "no entry for 'TetherTetrahedron-v0' and no 'default'"),
        ("default: {n_timesteps: [1000", "not valid YAML"),
        # PyYAML kept the last of two entries silently: the run used 5 timesteps, or lost an entry.
        ("default: {n_timesteps: 1000, n_timesteps: 5}", "the key 'n_timesteps' appears twice in one mapping"),
        ("default: {n_timesteps: 1000}\ndefault: {n_timesteps: 5}", "the key 'default' appears twice"),
        ("default: &x {n_timesteps: 1000, policy_kwargs: [*x]}", "an alias inside its own anchor"),
        (
            "a: &a [1, 1, 1, 1, 1, 1, 1, 1, 1, 1]\n"
            + "".join(f"{chr(98 + i)}: &{chr(98 + i)} [{', '.join([f'*{chr(97 + i)}'] * 10)}]\n" for i in range(8))
            + "default: {n_timesteps: 1000}",
            "expands to more than 100,000 entries",
        ),
        ("default: " + "[" * 3000, r"nests \[ \] or { } 3000 deep \(at most 64"),
    ],
)
def test_hyperparameter_errors_name_the_key(tmp_path: Path, text: str, message: str) -> None:
    file = tmp_path / "ppo.yml"
    file.write_text(text)
    with pytest.raises(HyperparameterError, match=message):
        train(TrainConfig("ppo", ENV, out=tmp_path / "runs", hyperparams_file=file))
    assert not (tmp_path / "runs").exists()  # refused before anything was written


def test_ppo_schedules_are_unknown_keys_for_sac_and_td3() -> None:
    """SAC and TD3 take no clip_range: accepting it would fail later, inside SB3's constructor."""
    for algo in ("sac", "td3"):
        for key in ("clip_range", "clip_range_vf"):
            with pytest.raises(HyperparameterError, match=f"unknown key '{key}'; {algo}"):
                validate_hyperparameters(algo, {"n_timesteps": 100, key: 0.2})
    assert validate_hyperparameters("ppo", {"n_timesteps": 100, "clip_range": 0.2})["clip_range"] == 0.2


def test_hyperparameter_file_that_is_not_utf8(tmp_path: Path) -> None:
    file = tmp_path / "ppo.yml"
    file.write_bytes(b"default: {n_timesteps: \xff}")
    with pytest.raises(HyperparameterError, match="not UTF-8"):
        load_hyperparameters("ppo", ENV, file)
