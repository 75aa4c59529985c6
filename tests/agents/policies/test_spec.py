"""PolicySpec (agents.policies.spec): how a policy's outputs become actions, as one value that
travels from training through policy.json to the loaded policy."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import pytest
from stable_baselines3 import PPO

from agents.policies import PolicySpec, TrainedPolicy
from agents.policies.format import load_policy, policy_metadata, read_metadata, save_policy
from tether_gym.sb3 import make_sb3_vec_env

ENV = "TetherTriangle-v0"


@pytest.fixture(scope="module")
def model() -> PPO:
    venv = make_sb3_vec_env(ENV, 1, seed=0, max_episode_steps=20)
    return PPO("MlpPolicy", venv, n_steps=16, batch_size=16, device="cpu", policy_kwargs={"net_arch": [8]}, seed=0)


def test_the_default_is_a_centralised_policy_whose_outputs_are_its_actions() -> None:
    spec = PolicySpec()
    assert spec.residual_on is None and spec.multiagent is None and not spec.decentralised
    assert PolicySpec(multiagent={}).decentralised  # {} is every multi-agent default, not "none"
    assert PolicySpec.from_metadata({}) == spec  # files older than both settings


def test_a_spec_is_frozen_and_keeps_its_own_copy_of_the_options() -> None:
    options = {"reward": "team", "communication": {"hops": 1}}
    spec = PolicySpec(multiagent=options)
    options["reward"] = "local"
    assert spec.multiagent == {"reward": "team", "communication": {"hops": 1}}
    assert list(spec.multiagent) == ["reward", "communication"]  # the given order, which policy.json keeps
    with pytest.raises(dataclasses.FrozenInstanceError):
        spec.residual_on = "lqr"  # type: ignore[misc]
    # Hashable although the options are a dict: equal specs hash equally.
    assert hash(PolicySpec("lqr", {"reward": "team"})) == hash(PolicySpec("lqr", {"reward": "team"}))
    assert PolicySpec("lqr") != PolicySpec("lqr", {})


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"residual_on": 3}, "residual_on must be a baseline's name or None"),
        ({"multiagent": ["reward"]}, "multiagent must be a mapping of multi-agent options"),
    ],
)
def test_a_spec_of_the_wrong_kinds_is_refused(kwargs: dict, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        PolicySpec(**kwargs)


def test_policy_json_records_the_spec_and_the_loaders_give_it_back(model: PPO, tmp_path: Path) -> None:
    residual = PolicySpec(residual_on="lqr")
    directory = save_policy(tmp_path / "residual", model, None, ENV, spec=residual)
    assert read_metadata(directory)["residual_on"] == "lqr" and read_metadata(directory)["multiagent"] is None
    assert load_policy(directory).spec == residual
    assert TrainedPolicy(directory).spec == residual and TrainedPolicy(directory).residual_on == "lqr"

    decentralised = PolicySpec(multiagent={"reward": "team", "communication": {"hops": 1}})
    directory = save_policy(tmp_path / "shared", model, None, ENV, spec=decentralised)
    text = (directory / "policy.json").read_text()
    assert text.index('"reward"') < text.index('"communication"')  # the options' order, as given
    assert load_policy(directory).spec == decentralised
    assert TrainedPolicy(directory).multiagent == decentralised.multiagent

    plain = save_policy(tmp_path / "plain", model, None, ENV)
    assert load_policy(plain).spec == PolicySpec()
    metadata = json.loads((plain / "policy.json").read_text())
    assert (metadata["residual_on"], metadata["multiagent"]) == (None, None)
    # No spec and the default spec write the same metadata.
    default = policy_metadata(model, ENV, None, False, False, PolicySpec())
    assert policy_metadata(model, ENV, None, False, False) == default


def test_an_in_memory_policy_takes_a_spec(model: PPO) -> None:
    policy = TrainedPolicy.from_parts(model.policy, None, ENV, "ppo", PolicySpec(residual_on="lqr"))
    assert policy.spec == PolicySpec(residual_on="lqr")
    assert policy.metadata["residual_on"] == "lqr" and policy.multiagent is None
    assert TrainedPolicy.from_parts(model.policy, None, ENV, "ppo").spec == PolicySpec()
