"""The PettingZoo env: API and seed tests, identity with the single-agent env, locality,
communication and its delay, reward shares, and bad input."""

from __future__ import annotations

import warnings

import gymnasium as gym
import numpy as np
import pytest
from pettingzoo.test import parallel_api_test, parallel_seed_test

import tether_gym
from tether_gym.envs.arguments import EnvArgumentError
from tether_gym.envs.contract import REWARD_TERM_KEYS
from tether_gym.multiagent import parallel_env


@pytest.mark.parametrize("env_id", tether_gym.ENV_IDS)
def test_pettingzoo_api_and_seed_tests_pass(env_id: str) -> None:
    env = parallel_env(env_id, communication={"hops": 1, "delay": 1}, reward="shares")
    with warnings.catch_warnings():
        # The API test resets with options={"options": 1}, which the env warns about and ignores.
        warnings.filterwarnings("ignore", message="reset options")
        parallel_api_test(env, num_cycles=60)
    parallel_seed_test(lambda: parallel_env(env_id, local_observation_noise=0.1), num_cycles=20)


def test_unknown_id_lists_the_ids() -> None:
    with pytest.raises(ValueError, match="unknown env id 'TetherCube-v0'.*TetherTetrahedron-v0"):
        parallel_env("TetherCube-v0")


def test_agents_are_the_thruster_satellites() -> None:
    env = parallel_env("TetherHub-v0", thrusters=[6, 0, 3])
    assert env.possible_agents == ["satellite_6", "satellite_0", "satellite_3"]
    env.reset(seed=0)
    env.step({"satellite_6": [1.0, 0.0, 0.0], "satellite_0": [0.0, 0.0, 0.0], "satellite_3": [0.0, -1.0, 0.0]})
    thrust = env.task.thrust[0] / env.task.max_thrust[0]
    np.testing.assert_array_equal(thrust[6], [1.0, 0.0, 0.0])
    np.testing.assert_array_equal(thrust[3], [0.0, -1.0, 0.0])
    assert not thrust[[0, 1, 2, 4, 5]].any()


def rollout_both(env_id: str, seed: int, steps: int, **kwargs: object) -> int:
    """Step the single- and the multi-agent env with the same random joint actions; assert
    bit-identity; return the steps taken."""
    single = gym.make(env_id, **kwargs)
    multi = parallel_env(env_id, **kwargs)
    obs, info = single.reset(seed=seed)
    _, infos = multi.reset(seed=seed)
    assert np.array_equal(obs, multi.state()) and multi.state_space.contains(multi.state())
    rng = np.random.default_rng(seed)
    names = multi.possible_agents
    for step in range(steps):
        action = rng.uniform(-1.2, 1.2, single.action_space.shape).astype(np.float32)
        obs, reward, terminated, truncated, info = single.step(action)
        _, rewards, terminations, truncations, infos = multi.step(
            {name: action[3 * k : 3 * k + 3] for k, name in enumerate(names)}
        )
        assert np.array_equal(obs, multi.state())
        assert set(rewards) == set(names) and all(r == reward for r in rewards.values())
        assert all(t == terminated for t in terminations.values())
        assert all(t == truncated for t in truncations.values())
        assert infos[names[0]]["vibration_energy"] == info["vibration_energy"]
        if terminated or truncated:
            assert multi.agents == []
            return step + 1
    return steps


@pytest.mark.parametrize("env_id", ["TetherTetrahedron-v0", "TetherHub-v0", "TetherRadialChain-v0"])
def test_team_reward_is_bit_identical_to_the_single_agent_env(env_id: str) -> None:
    assert rollout_both(env_id, seed=5, steps=10_000) == gym.spec(env_id).max_episode_steps  # truncation too
    # Draws of the task (disturbances, thrust noise, global observation noise) come in the same order.
    perturbed = {"observation_noise": 0.1, "thrust_noise": 0.2, "impulse_magnitude": 0.05, "impulse_rate": 2.0}
    rollout_both(env_id, seed=6, steps=50, **perturbed)


def test_termination_is_identical() -> None:
    # Large thrust on the default id ends in a failure; both envs say so on the same step.
    steps = rollout_both("TetherTetrahedron-v0", seed=1, steps=300, max_deviation=0.05)
    assert steps < 300


def chain_observations(velocity_of: dict[int, np.ndarray], **kwargs: object) -> dict[str, np.ndarray]:
    env = parallel_env("TetherChain-v0", **kwargs)
    cluster = env.cluster
    velocities = np.zeros((cluster.num_nodes, 3))
    for node, value in velocity_of.items():
        velocities[node] = value
    observations, _ = env.reset(seed=0, options={"positions": cluster.positions, "velocities": velocities})
    return observations


def test_observations_are_local() -> None:
    # Chain 0-1-2-3-4: satellite 4's motion is seen by its neighbour 3 only.
    still = chain_observations({})
    moving = chain_observations({4: np.array([0.0, 0.01, 0.0])})
    changed = {name for name in still if not np.array_equal(still[name], moving[name])}
    assert changed == {"satellite_3", "satellite_4"}
    # With one hop of communication, satellite 2 hears satellite 3, which sees satellite 4.
    still = chain_observations({}, communication={"hops": 1})
    moving = chain_observations({4: np.array([0.0, 0.01, 0.0])}, communication={"hops": 1})
    changed = {name for name in still if not np.array_equal(still[name], moving[name])}
    assert changed == {"satellite_2", "satellite_3", "satellite_4"}


def test_padding_and_layout() -> None:
    env = parallel_env("TetherHub-v0")
    observations, _ = env.reset(seed=0)
    layout = env.layout
    assert layout.slots == 6  # the hub meets six cables; a rim satellite three
    present = layout.cable_field(observations["satellite_1"], "present")[:, 0]
    np.testing.assert_array_equal(present, [1, 1, 1, 0, 0, 0])
    assert not observations["satellite_1"][layout.cables].reshape(6, -1)[3:].any()
    assert layout.cable_field(observations["satellite_0"], "present").all()
    directions = layout.cable_field(observations["satellite_1"], "direction")[:3]
    np.testing.assert_allclose(np.linalg.norm(directions, axis=-1), 1.0, rtol=1e-6)


@pytest.mark.parametrize("delay", [0, 3])
def test_messages_are_the_partners_measurements_delay_steps_late(delay: int) -> None:
    env = parallel_env("TetherTriangle-v0", communication={"hops": 1, "delay": delay})
    layout = env.layout
    history = []
    observations, _ = env.reset(seed=2)
    rng = np.random.default_rng(0)
    for step in range(12):
        history.append({name: obs[layout.own].copy() for name, obs in observations.items()})
        # Satellite 0 hears 1 then 2 (agent order); its message slot 0 is satellite 1's measurements.
        present, message = layout.message(observations["satellite_0"], 0)
        assert present == 1.0
        sent = history[max(step - delay, 0)]["satellite_1"]  # before the first step: the reset's
        np.testing.assert_array_equal(message, sent)
        observations, *_ = env.step({name: rng.uniform(-1, 1, 3) for name in env.agents})


def test_local_noise_is_seeded_and_leaves_the_state_alone() -> None:
    def first(seed: int, noise: float) -> tuple[np.ndarray, np.ndarray]:
        env = parallel_env("TetherTetrahedron-v0", local_observation_noise=noise)
        observations, _ = env.reset(seed=seed)
        observations, *_ = env.step({name: np.zeros(3) for name in env.agents})
        return observations["satellite_0"], env.state()

    clean, state = first(0, 0.0)
    noisy, noisy_state = first(0, 0.5)
    again, _ = first(0, 0.5)
    other, _ = first(1, 0.5)
    np.testing.assert_array_equal(noisy, again)
    assert not np.array_equal(noisy, clean) and not np.array_equal(noisy, other)
    np.testing.assert_array_equal(state, noisy_state)
    # The present flags and the padding carry no noise.
    env = parallel_env("TetherHub-v0", local_observation_noise=0.5)
    observations, _ = env.reset(seed=0)
    slots = observations["satellite_1"][env.layout.cables].reshape(6, -1)
    np.testing.assert_array_equal(slots[:, 0], [1, 1, 1, 0, 0, 0])
    assert not slots[3:].any()


@pytest.mark.parametrize("env_id", ["TetherTetrahedron-v0", "TetherHub-v0"])
def test_reward_shares_add_up_to_the_team_reward(env_id: str) -> None:
    team = parallel_env(env_id)
    shares = parallel_env(env_id, reward="shares", slack_weight=1.0, max_deviation=0.08)
    team.reset(seed=4)
    shares.reset(seed=4)
    rng = np.random.default_rng(4)
    unequal = 0
    for _ in range(300):
        actions = {name: rng.uniform(-1, 1, 3) for name in team.agents}
        _, rewards, terminations, truncations, infos = shares.step(actions)
        info = infos[shares.possible_agents[0]]
        total = sum(info[key] for key in REWARD_TERM_KEYS)
        np.testing.assert_allclose(sum(rewards.values()), total, rtol=1e-12, atol=1e-12)
        unequal += len(set(rewards.values())) > 1
        if any(terminations.values()) or any(truncations.values()):
            break
    assert unequal > 0  # shares, not copies


def test_bad_input_gets_a_clear_error() -> None:
    env = parallel_env("TetherTriangle-v0")
    with pytest.raises(EnvArgumentError, match="call reset"):
        env.step({name: np.zeros(3) for name in env.possible_agents})
    env.reset(seed=0)
    good = {name: np.zeros(3) for name in env.agents}
    with pytest.raises(EnvArgumentError, match=r"unknown agent\(s\).*'satellite_9'.*the agents are"):
        env.step({**good, "satellite_9": np.zeros(3)})
    with pytest.raises(EnvArgumentError, match=r"no action for agent\(s\) \['satellite_2'\]"):
        env.step({name: good[name] for name in ["satellite_0", "satellite_1"]})
    with pytest.raises(EnvArgumentError, match=r"action of satellite_1 must have shape \(3,\)"):
        env.step({**good, "satellite_1": np.zeros(4)})
    with pytest.raises(EnvArgumentError, match="action of satellite_0 contains NaN"):
        env.step({**good, "satellite_0": [np.nan, 0, 0]})
    with pytest.raises(EnvArgumentError, match="action of satellite_0 must be"):
        env.step({**good, "satellite_0": "up"})
    with pytest.raises(EnvArgumentError, match="actions must be a dict"):
        env.step([np.zeros(3)] * 3)
    assert env.task.sim.time[0] == 0.0 and env.batch.episode_steps[0] == 0  # the refused steps changed nothing
    with pytest.raises(EnvArgumentError, match="unknown agent"):
        env.observation_space("hub")
    with pytest.raises(EnvArgumentError, match="unknown agent"):
        env.action_space(["satellite_0"])  # not a name at all: refused by name, not a bare TypeError
    for options, message in (
        ({"communication": {"hops": 0}}, r"communication\['hops'\] must be a whole number"),
        ({"communication": {"hops": 1, "range": 2.0}}, "exactly one of 'hops'"),
        ({"communication": {"hop": 1}}, "unknown communication key"),
        ({"communication": 1}, "communication must be None"),
        ({"communication": {"range": 5.0, "delay": -1}}, r"communication\['delay'\]"),
        ({"reward": "mine"}, "reward must be one of 'team' or 'shares'"),
        ({"local_observation_noise": -1.0}, "local_observation_noise must be"),
        ({"render_mode": "human"}, "render_mode must be None"),
        ({"control_interval": -1.0}, "control_interval"),
    ):
        with pytest.raises(EnvArgumentError, match=message):
            parallel_env("TetherTriangle-v0", **options)
    with pytest.raises(TypeError, match="unknown argument"):
        parallel_env("TetherTriangle-v0", colour="red")
    with pytest.raises(EnvArgumentError, match="seed must be"):
        env.reset(seed=-1)
    with pytest.warns(UserWarning, match=r"reset options \['colour'\] .* ignored"):
        env.reset(seed=0, options={"colour": 1})


def test_communication_graphs() -> None:
    # Hub: spokes and rim are 100 m; across the wheel 173 m and 200 m.
    def partners(communication: dict) -> list[set[int]]:
        graph = parallel_env("TetherHub-v0", communication=communication).batch.graph
        return [{int(graph.nodes[p]) for p in row if p >= 0} for row in graph.partners]

    assert partners({"range": 150.0}) == partners({"hops": 1})
    assert partners({"hops": 1})[0] == {1, 2, 3, 4, 5, 6} and partners({"hops": 1})[1] == {0, 2, 6}
    assert partners({"range": 180.0})[1] == {0, 2, 3, 5, 6}
    assert partners({"hops": 2})[1] == {0, 2, 3, 4, 5, 6}
    assert parallel_env("TetherHub-v0", communication={"range": 50.0}).layout.partners == 0
