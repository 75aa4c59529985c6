"""Disturbances, faults and the difficulty knob, as the env options of the damping task."""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest

import tether_gym  # noqa: F401  (registers the ids)


def run(env: gym.Env, actions: np.ndarray, seed: int = 0) -> list[dict]:
    """The infos of an episode driven by the given (T, action_size) actions."""
    _, info = env.reset(seed=seed)
    infos = [info]
    for action in actions:
        *_, info = env.step(action)
        infos.append(info)
    return infos


def test_an_impulse_is_one_kick_of_the_set_size_on_one_satellite() -> None:
    env = gym.make("TetherTetrahedron-v0", impulse_magnitude=3.0, impulse_rate=2.0)
    infos = run(env, np.zeros((40, 12)))
    forces = np.array([np.linalg.norm(info["disturbance"], axis=1) for info in infos[1:]])  # (T, n) N
    kicked = forces > 0
    # rate 2/s over 0.1 s intervals: P(kick) = 1 - e^-0.2 = 18 % per step; 40 steps see some.
    assert 2 <= kicked.any(axis=1).sum() <= 20
    assert np.all(kicked.sum(axis=1) <= 1)
    np.testing.assert_allclose(forces[kicked], 3.0 / 0.1, rtol=1e-12)  # the impulse over one interval
    assert np.all(infos[0]["disturbance"] == 0)


def test_periodic_force_has_the_set_amplitude_and_period() -> None:
    env = gym.make("TetherTetrahedron-v0", periodic_amplitude=0.4, periodic_period=2.0)
    infos = run(env, np.zeros((60, 12)))
    force = np.array([info["disturbance"] for info in infos[1:]])  # (T, n, 3)
    task = env.unwrapped.task
    midpoints = (np.arange(60) + 0.5) * 0.1
    expected = (
        0.4
        * np.sin(2 * math.pi * midpoints[:, None] / 2.0 + task.periodic_phase[0])[:, :, None]
        * task.periodic_direction[0]
    )
    np.testing.assert_allclose(force, expected, atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(task.periodic_direction[0], axis=1), 1.0)
    # Every satellite sees the full amplitude within a period.
    assert np.all(np.abs(np.linalg.norm(force[:20], axis=2)).max(axis=0) > 0.4 * math.cos(math.pi * 0.1 / 2.0) - 1e-12)


def test_thrust_noise_is_zero_mean_with_the_set_spread() -> None:
    env = gym.make("TetherTetrahedron-v0", thrust_noise=0.2, max_thrust=0.5)
    command = np.full(12, 0.5)  # 0.25 N per axis
    infos = run(env, np.tile(command, (200, 1)))
    error = np.array([info["thrust"] for info in infos[1:]]) - 0.25  # (T, n, 3) N
    assert abs(error.mean()) < 4 * 0.1 / math.sqrt(error.size)
    assert error.std() == pytest.approx(0.2 * 0.5, rel=0.1)
    # Propellant counts the command: the noise is an actuator error, not a choice.
    assert infos[-1]["propellant_used"] == pytest.approx(200 * 4 * 0.25 * math.sqrt(3) * 0.1, rel=1e-12)


def test_thrust_delay_applies_each_action_that_many_steps_later() -> None:
    env = gym.make("TetherTetrahedron-v0", thrust_delay=3)
    actions = np.random.default_rng(1).uniform(-1, 1, (10, 12))
    infos = run(env, actions)
    thrust = np.array([info["thrust"].ravel() for info in infos[1:]])  # max_thrust 1 N
    assert np.all(thrust[:3] == 0)
    np.testing.assert_array_equal(thrust[3:], actions[:-3])
    env.reset(seed=1)  # the queue empties at reset
    *_, info = env.step(actions[0])
    assert np.all(info["thrust"] == 0)


def test_a_failed_thruster_stops_at_its_failure_time_and_stays_failed() -> None:
    env = gym.make("TetherTetrahedron-v0", thruster_failure_probability=1.0, thruster_failure_window=(1.0, 2.0))
    infos = run(env, np.ones((40, 12)))
    task = env.unwrapped.task
    failed, when = int(task.failing_thruster[0]), float(task.failure_time[0])
    assert 1.0 <= when <= 2.0
    for info in infos[1:]:
        started = info["time"] - 0.1  # the thrusters' state is decided at the start of the interval
        broken = started >= when
        assert info["thruster_ok"][failed] == (not broken)
        assert np.all(info["thrust"][failed] == 0) == broken
        assert info["thruster_ok"].sum() >= 3
    env.reset(seed=5)
    assert env.unwrapped.task.thruster_ok.all()


def failure_free(env_id: str, seed: int) -> float:
    env = gym.make(env_id, thruster_failure_probability=0.3)
    env.reset(seed=seed)
    return float(env.unwrapped.task.failure_time[0])


def test_thruster_failures_happen_with_the_set_probability() -> None:
    failures = [math.isfinite(failure_free("TetherTriangle-v0", seed)) for seed in range(300)]
    assert np.mean(failures) == pytest.approx(0.3, abs=4 * math.sqrt(0.3 * 0.7 / 300))


@pytest.mark.parametrize("mode", ["terminate", "continue"])
def test_a_cable_past_its_breaking_load_breaks_for_the_rest_of_the_episode(mode: str) -> None:
    env = gym.make("TetherTriangle-v0", preset_kwargs={"breaking_load": 3.0}, cable_failure=mode, max_deviation=50.0)
    env.reset(seed=0)
    broken_at = None
    for step in range(300):
        _, _, terminated, _, info = env.step(np.ones(9))
        if broken_at is None and info["broken_cables"].any():
            broken_at = step
            cables = info["broken_cables"].copy()
            assert np.any(info["peak_tension"][cables] > 3.0)
            if mode == "terminate":
                assert terminated and info["end_reason"] == "cable_broken"
                break
            assert info["end_reason"] != "cable_broken"
        if broken_at is not None:
            assert np.all(info["broken_cables"][cables])  # stays broken
            assert np.all(info["tensions"][cables] == 0)
            assert abs(info["energy_residual"]) < 1e-2 * max(info["dissipated_energy"], 1.0)
        if terminated:
            break
    assert broken_at is not None
    _, info = env.reset(seed=1)
    assert not info["broken_cables"].any()


def test_a_cluster_with_every_cable_broken_drifts_on_without_crashing() -> None:
    env = gym.make(
        "TetherSpinningTriangle-v0", preset_kwargs={"breaking_load": 0.5}, cable_failure="continue", max_deviation=1e6
    )
    env.reset(seed=0)
    for _ in range(100):
        obs, reward, terminated, _, info = env.step(np.zeros(9))
        assert np.isfinite(obs).all() and math.isfinite(reward) and not terminated
    assert info["broken_cables"].all() and np.all(info["tensions"] == 0)


FAULTS = dict(
    impulse_magnitude=1.0,
    impulse_rate=0.5,
    periodic_amplitude=0.2,
    thrust_noise=0.1,
    thrust_delay=1,
    thruster_failure_probability=0.5,
    randomize={"masses": 0.1, "EA": 0.1},
    cable_failure="continue",
)


def test_faulty_episodes_are_bit_identical_for_the_same_seed() -> None:
    actions = np.random.default_rng(2).uniform(-1, 1, (50, 9))
    first = run(gym.make("TetherSpinningTriangle-v0", **FAULTS), actions, seed=7)
    second = run(gym.make("TetherSpinningTriangle-v0", **FAULTS), actions, seed=7)
    for a, b in zip(first, second, strict=True):
        for key in a:
            assert np.array_equal(a[key], b[key]), key
    other = run(gym.make("TetherSpinningTriangle-v0", **FAULTS), actions, seed=8)
    assert not np.array_equal(first[-1]["tensions"], other[-1]["tensions"])


def test_difficulty_scales_initial_conditions_and_randomisation_together() -> None:
    kwargs = dict(randomize={"masses": 0.2})
    full = gym.make("TetherTetrahedron-v0", **kwargs)
    half = gym.make("TetherTetrahedron-v0", difficulty=0.5, **kwargs)
    nominal = full.unwrapped.cluster
    full.reset(seed=3)
    half.reset(seed=3)
    deviation = lambda env: env.unwrapped.task.sim.positions[0] - nominal.positions  # noqa: E731
    spread = lambda env: env.unwrapped.task.sim.masses[0] / nominal.masses - 1  # noqa: E731
    np.testing.assert_allclose(deviation(half), 0.5 * deviation(full), atol=1e-12)
    np.testing.assert_allclose(spread(half), 0.5 * spread(full), atol=1e-12)
    # Velocities scale too, up to the rigid rotation removed about the (differently) displaced shape.
    np.testing.assert_allclose(
        half.unwrapped.task.sim.velocities, 0.5 * full.unwrapped.task.sim.velocities, rtol=0, atol=1e-3 * 0.1
    )
    # The observation units and the reward's energy scale do not move with the difficulty.
    assert half.unwrapped.task.energy_scale == full.unwrapped.task.energy_scale
    assert half.unwrapped.task.length_scale == full.unwrapped.task.length_scale
    half.unwrapped.set_difficulty(0.0)
    obs, info = half.reset(seed=4)
    assert np.abs(obs).max() < 1e-9 and info["vibration_energy"] == pytest.approx(0.0, abs=1e-12)
    np.testing.assert_array_equal(half.unwrapped.task.sim.masses[0], nominal.masses)


def test_vector_env_difficulty_reaches_every_sub_env() -> None:
    envs = gym.make_vec("TetherTetrahedron-v0", num_envs=4)
    envs.unwrapped.set_difficulty(0.0)
    obs, _ = envs.reset(seed=0)
    assert np.abs(obs).max() < 1e-9


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        (dict(thrust_delay=-1), "thrust_delay"),
        (dict(thrust_delay=1.5), "thrust_delay"),
        (dict(cable_failure="explode"), "cable_failure"),
        (dict(difficulty=2.0), "difficulty"),
        (dict(thruster_failure_probability=1.5), "thruster_failure_probability"),
        (dict(thruster_failure_window=(5.0, 1.0)), "thruster_failure_window"),
        (dict(impulse_magnitude=-1.0), "impulse_magnitude"),
        (dict(periodic_period=0.0), "periodic_period"),
        (dict(thrust_noise=math.nan), "thrust_noise"),
        (dict(randomize={"spin": 0.1}), "randomize"),
    ],
)
def test_bad_fault_options_get_clear_errors(kwargs: dict, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        gym.make("TetherTetrahedron-v0", **kwargs)


def test_set_difficulty_rejects_values_outside_0_1() -> None:
    env = gym.make("TetherTetrahedron-v0")
    with pytest.raises(ValueError, match="difficulty"):
        env.unwrapped.set_difficulty(-0.1)
