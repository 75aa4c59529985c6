"""Shipped models: they give their recorded reference actions, and a corrupted or unlisted file is a clear error."""

from __future__ import annotations

import shutil
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
from agents.common.cli import REFERENCE_FILE
from agents.policies import MODELS_DIR, TrainedPolicy, make_controller, shipped_models
from agents.policies.format import load_tensors
from agents.policies.layout import ChecksumError
from tests.agents.helpers import ENV
from tether_gym import ENV_IDS

SHIPPED = [(env_id, name) for env_id in ENV_IDS for name in shipped_models(env_id)]


@pytest.mark.parametrize(("env_id", "name"), SHIPPED)
def test_shipped_models_give_their_reference_actions(env_id: str, name: str) -> None:
    """The observations and actions recorded when the model was shipped (by agents.ship, or from
    the pickle-based original, PPO.load + VecNormalize, by agents.convert), against the shipped
    safe policy.

    Recorded on another machine, the actions may differ in the last bit where torch picks other
    vector kernels, so the comparison allows 1e-6 of full thrust; a wrong weight, layer order or
    normaliser moves them by orders of magnitude more.  Within one process the safe loader is
    checked bit for bit against PPO.load (test_converter_output_matches_sb3_load)."""
    directory = shipped_models(env_id)[name]
    reference = load_tensors((directory / REFERENCE_FILE).read_bytes(), directory / REFERENCE_FILE)
    observations, expected = reference["observations"].numpy(), reference["actions"].numpy()
    assert observations.shape[0] >= 512 and np.isfinite(observations).all()
    policy = TrainedPolicy(directory)
    normalized = policy.normalizer.normalize_obs(observations).astype(np.float32) if policy.normalizer else observations
    actions = policy.policy.predict(normalized, deterministic=True)[0]  # the network's part (residual policies too)
    assert actions.dtype == expected.dtype
    np.testing.assert_allclose(actions, expected, rtol=0, atol=1e-6)
    assert not list(directory.glob("*.zip")) and not list(directory.glob("*.pkl"))


@pytest.mark.parametrize(("env_id", "name"), SHIPPED)
def test_direct_actions_are_sb3_predicts_to_the_bit(env_id: str, name: str) -> None:
    """TrainedPolicy.predict computes a Gaussian actor's deterministic action without SB3's
    predict (agents.policies.loaded.actor_mean_actions, for speed); on every shipped model it gives
    predict's actions to the bit, batched and one observation at a time, and through
    TrainedPolicy.predict too."""
    policy = TrainedPolicy(shipped_models(env_id)[name])
    rng = np.random.default_rng(7)
    rows = rng.normal(0.0, 2.0, (33, policy.observation_size)).astype(np.float32)
    if not agents.policies.loaded.gaussian_actor(policy.policy):
        pytest.skip(f"{env_id} {name} is not a Gaussian actor: it acts through SB3's predict")
    assert policy.direct_actions
    batched = agents.policies.loaded.actor_mean_actions(policy.policy, rows)
    np.testing.assert_array_equal(batched, policy.policy.predict(rows, deterministic=True)[0], strict=True)
    for row in rows[:5]:  # rows inside a larger array: other memory alignments
        single = agents.policies.loaded.actor_mean_actions(policy.policy, row)
        np.testing.assert_array_equal(single, policy.policy.predict(row, deterministic=True)[0], strict=True)
    if policy.residual_on is None and policy.multiagent is None:
        through = policy.predict(rows * 0.1)[0]
        raw = policy.normalizer.normalize_obs(rows * 0.1).astype(np.float32) if policy.normalizer else rows * 0.1
        np.testing.assert_array_equal(through, policy.policy.predict(raw, deterministic=True)[0], strict=True)


@pytest.fixture
def fake_models_dir(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """A copy of the shipped models, standing in for agents/models."""
    root = tmp_path / "models"
    shutil.copytree(MODELS_DIR, root)
    monkeypatch.setattr(agents.policies.loaded, "MODELS_DIR", root.resolve())
    return root / ENV / "ppo"


def test_a_corrupted_shipped_model_is_a_clear_error(fake_models_dir: Path) -> None:
    env = gym.make_vec(ENV, num_envs=1)
    make_controller("ppo", env)  # intact: loads
    weights = bytearray((fake_models_dir / "policy.safetensors").read_bytes())
    weights[-1] ^= 0x01  # one bit of one weight
    (fake_models_dir / "policy.safetensors").write_bytes(bytes(weights))
    with pytest.raises(ChecksumError, match=r"policy\.safetensors: SHA-256 .* does not match MANIFEST\.sha256"):
        make_controller("ppo", env)


def test_shipped_models_need_an_exact_manifest(fake_models_dir: Path) -> None:
    (fake_models_dir / "model.zip").write_bytes(b"not listed")
    with pytest.raises(ChecksumError, match="files not listed: .'model.zip'."):
        TrainedPolicy(fake_models_dir)
    (fake_models_dir / "model.zip").unlink()
    (fake_models_dir / "MANIFEST.sha256").unlink()
    assert "ppo" not in agents.policies.shipped_models(ENV)  # not offered without its manifest
    with pytest.raises(ChecksumError, match="no MANIFEST.sha256"):
        TrainedPolicy(fake_models_dir)
