"""ARS (agents.training.ars, the command agents.ars): the update rule, the settings, and a run whose
saved policy acts as trained."""

from __future__ import annotations

from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import yaml

from agents.ars import main
from agents.policies import TrainedPolicy
from agents.policies.format import read_metadata
from agents.training.ars import ARSSettings, LinearResidualPolicy, ars_update, load_ars_settings, train_ars
from agents.training.shipping import reproduce_command

TINY = {
    "iterations": 2,
    "directions": 2,
    "top": 1,
    "seeds_per_direction": 2,
    "exploration": 0.05,
    "step_size": 0.01,
    "eval_every": 1,
    "eval_episodes": 4,
    "normalization_episodes": 2,
}


def test_ars_update_climbs_a_concave_objective() -> None:
    """On R(theta) = -|theta - target|^2 the paired finite differences point uphill: repeated
    updates approach the target."""
    rng = np.random.default_rng(0)
    target = rng.normal(size=(3, 4))
    objective = lambda theta: -float(((theta - target) ** 2).sum())  # noqa: E731
    theta = np.zeros((3, 4))
    start = objective(theta)
    for _ in range(200):
        deltas = rng.standard_normal((8, 3, 4))
        plus = np.array([objective(theta + 0.05 * d) for d in deltas])
        minus = np.array([objective(theta - 0.05 * d) for d in deltas])
        theta = ars_update(theta, deltas, plus, minus, top=4, step_size=0.05)
    assert objective(theta) > start / 4  # the squared distance to the target cut by three quarters


def test_ars_update_keeps_the_top_directions_and_scales_by_their_spread() -> None:
    deltas = np.eye(3)[:, None, :]  # three directions, theta of shape (1, 3)
    plus, minus = np.array([1.0, 5.0, 0.0]), np.array([0.0, 1.0, 0.0])
    theta = ars_update(np.zeros((1, 3)), deltas, plus, minus, top=2, step_size=1.0)
    sigma = np.std([5.0, 1.0, 1.0, 0.0])  # directions 1 and 0 are kept (max 5 and 1)
    np.testing.assert_allclose(theta, [[1.0 / (2 * sigma), 4.0 / (2 * sigma), 0.0]])
    same = ars_update(theta, deltas, np.ones(3), np.ones(3), top=2, step_size=1.0)
    np.testing.assert_array_equal(same, theta)  # no spread: no step
    with pytest.raises(ValueError, match="plus and minus"):
        ars_update(theta, deltas, np.ones(2), np.ones(2), top=1, step_size=1.0)
    with pytest.raises(ValueError, match="top"):
        ars_update(theta, deltas, plus, minus, top=4, step_size=1.0)


@pytest.mark.parametrize(
    ("overrides", "message"),
    [
        ({"residual_on": "oracle"}, "residual_on must be one of"),
        ({"top": 20}, "top .* must be <= directions"),
        ({"exploration": -1.0}, "exploration must be a positive number"),
        ({"step_size": float("nan")}, "step_size must be a positive number"),
        ({"iterations": 0}, "iterations must be an integer >= 1"),
        ({"eval_episodes": 1}, "eval_episodes must be an integer in 2..100000"),
        ({"directions": True}, "directions must be an integer"),
    ],
)
def test_bad_settings_are_named(overrides: dict, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        ARSSettings(**overrides)


def test_settings_file_entries_and_unknown_keys(tmp_path: Path) -> None:
    assert load_ars_settings("TetherChain-v0").residual_on == "lqr"
    assert load_ars_settings("TetherHub-v0", iterations=3).iterations == 3
    bad = tmp_path / "ars.yml"
    bad.write_text("default: {iterationz: 3}\n")
    with pytest.raises(ValueError, match="unknown ARS setting.*iterationz"):
        load_ars_settings("TetherHub-v0", bad)


def test_a_run_saves_a_policy_that_acts_as_trained(tmp_path: Path) -> None:
    """The exported policy (SB3's linear actor in the safe format) gives the actions of the
    weights ARS trained, loads with algo 'ars' and its baseline, and the run's config.yml
    reproduces the settings."""
    settings = ARSSettings(residual_on="local_tension_aware", **TINY)
    run = train_ars("TetherTriangle-v0", seed=5, out=tmp_path, settings=settings, progress=False)
    assert (run / "best" / "evaluations.json").is_file() and (run / "config.yml").is_file()
    assert any((run / "tensorboard").iterdir())
    metadata = read_metadata(run)
    assert metadata["algo"] == "ars" and metadata["residual_on"] == "local_tension_aware"
    assert load_ars_settings(None, run / "config.yml") == settings

    loaded = TrainedPolicy(run)
    env = gym.make_vec("TetherTriangle-v0", num_envs=8)
    loaded.attach(env)
    import torch

    net = loaded.policy.action_net
    theta = np.concatenate([net.weight.detach().numpy(), net.bias.detach().numpy()[:, None]], axis=1)
    assert np.abs(theta).max() > 0  # two updates moved it
    mine = LinearResidualPolicy("local_tension_aware", loaded.normalizer, theta.astype(float))
    mine.attach(env)
    observation, _ = env.reset(seed=list(range(8)))
    for _ in range(5):
        expected, _ = mine.predict(observation)
        actual, _ = loaded.predict(observation, deterministic=True)
        np.testing.assert_allclose(actual, expected, atol=1e-5)
        observation, *_ = env.step(actual)
    assert torch.is_tensor(net.weight)


def test_the_command_line_records_a_command_ship_can_replay(tmp_path: Path) -> None:
    hyperparams = tmp_path / "tiny.yml"
    hyperparams.write_text(yaml.safe_dump({"default": {"residual_on": "lqr", **TINY, "iterations": 1}}))
    run = main(
        ["--env", "TetherChain-v0", "--seed", "2", "--out", str(tmp_path / "runs"), "--hyperparams", str(hyperparams)]
        + ["--no-progress"]
    )
    config = yaml.safe_load((run / "config.yml").read_text())
    assert config["hyperparams"]["iterations"] == 1 and "--hyperparams" in config["command"]
    command = reproduce_command({"env_id": "TetherChain-v0", "algo": "ars", "seed": 2, **config}, "agents/models")
    assert "--algo" not in command and "agents/models/TetherChain-v0/ars/config.yml" in command
    with pytest.raises(Exception, match="already holds a run"):
        main(["--env", "TetherChain-v0", "--seed", "2", "--out", str(tmp_path / "runs"), "--no-progress"])


def test_the_same_seed_trains_the_same_weights(tmp_path: Path) -> None:
    """Perturbations, training seeds and rollouts are all seeded: a rerun gives the same bits."""
    settings = ARSSettings(residual_on="lqr", **TINY)
    first = train_ars("TetherTriangle-v0", seed=3, out=tmp_path / "a", settings=settings, progress=False)
    second = train_ars("TetherTriangle-v0", seed=3, out=tmp_path / "b", settings=settings, progress=False)
    other = train_ars("TetherTriangle-v0", seed=4, out=tmp_path / "c", settings=settings, progress=False)
    for name in ("policy.safetensors", "best/policy.safetensors"):
        assert (first / name).read_bytes() == (second / name).read_bytes()
    assert (first / "policy.safetensors").read_bytes() != (other / "policy.safetensors").read_bytes()
