"""Bad arguments at the environment layer: every class of them gets a clear error naming the
argument, a refused update changes nothing, and a runaway step ends with a finite reward.

The property-based counterpart, over random inputs, is tests/envs/test_fuzz_envs.py.
"""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest

import tether_gym as tg
from tests.helpers import assert_unchanged, env_state
from tether_gym.envs import EnvArgumentError, TaskConfig, TetherClusterEnv, TetherClusterVectorEnv
from tether_gym.envs.task import (
    CONTROL_INTERVAL_RANGE,
    MAX_SPREAD,
    REWARD_LIMIT,
    SUBSTEP_HEADROOM,
    THRUST_RANGE,
    ClusterScales,
)
from tether_gym.sb3 import make_sb3_vec_env

ENV_ID = "TetherTetrahedron-v0"

#: Gymnasium re-raises a TypeError from an env's constructor with this suffix and every keyword
#: argument appended, which would name any parameter; the checks read the message before it.
GYMNASIUM_SUFFIX = " was raised from the environment creator"


def message(error: BaseException) -> str:
    return str(error).split(GYMNASIUM_SUFFIX)[0]


def assert_names(error: pytest.ExceptionInfo, *names: str) -> None:
    """The error is a ValueError/TypeError whose own message names every one of ``names``."""
    assert isinstance(error.value, (ValueError, TypeError)), type(error.value)
    text = message(error.value)
    for name in names:
        assert name in text, (name, text)


# ------------------------------------------------------------------ construction
BAD_KWARGS = [
    # strings where numbers are expected
    ({"control_interval": "0.1"}, "control_interval"),
    ({"initial_velocity": "fast"}, "initial_velocity"),
    ({"vibration_weight": "1"}, "vibration_weight"),
    ({"max_deviation": "x"}, "max_deviation"),
    ({"safety_factor": "a"}, "safety_factor"),
    ({"thruster_failure_probability": "x"}, "thruster_failure_probability"),
    ({"difficulty": "1"}, "difficulty"),
    ({"render_exaggeration": "big"}, "render_exaggeration"),
    ({"max_thrust": "1"}, "max_thrust"),
    ({"max_thrust": [1.0, "a", 1.0, 1.0]}, "max_thrust"),
    ({"randomize": {"masses": "x"}}, "randomize"),
    ({"thruster_failure_window": (0.0, "a")}, "thruster_failure_window"),
    # booleans where numbers or whole numbers are expected, and floats where whole numbers are
    ({"thrust_delay": True}, "thrust_delay"),
    ({"thrust_delay": 2.0}, "thrust_delay"),
    ({"difficulty": True}, "difficulty"),
    ({"max_thrust": False}, "max_thrust"),
    ({"thrusters": [True]}, "thrusters"),
    ({"thrusters": [0.0, 1.0]}, "thrusters"),
    ({"observed_satellites": [1.5]}, "observed_satellites"),
    ({"observe_tensions": "yes"}, "observe_tensions"),
    ({"observe_tensions": 1}, "observe_tensions"),
    # NaN, infinities, negative values
    ({"initial_displacement": math.nan}, "initial_displacement"),
    ({"control_interval": math.inf}, "control_interval"),
    ({"observation_noise": -1.0}, "observation_noise"),
    ({"periodic_amplitude": math.inf}, "periodic_amplitude"),
    ({"max_thrust": [1.0, math.nan, 1.0, 1.0]}, "max_thrust"),
    ({"randomize": {"EA": math.inf}}, "randomize"),
    ({"difficulty": math.nan}, "difficulty"),
    # wrong containers
    ({"randomize": [("masses", 0.1)]}, "randomize"),
    ({"randomize": {1: 0.1}}, "randomize"),
    ({"thrusters": "0"}, "thrusters"),
    ({"thrusters": {0: 1}}, "thrusters"),
    ({"thrusters": 3}, "thrusters"),
    ({"thrusters": []}, "thrusters"),
    ({"thrusters": [1, 1]}, "thrusters"),
    ({"thruster_failure_window": 5}, "thruster_failure_window"),
    ({"thruster_failure_window": (1.0, 2.0, 3.0)}, "thruster_failure_window"),
    ({"preset_kwargs": [1, 2]}, "preset_kwargs"),
    ({"preset_kwargs": "edge=3"}, "preset_kwargs"),
    ({"preset_kwargs": {3: 1.0}}, "preset_kwargs"),
    ({"preset": 3}, "preset"),
    ({"preset": ["tetrahedron"]}, "preset"),
    ({"thrust_limit": None}, "thrust_limit"),
    ({"cable_failure": ["terminate"]}, "cable_failure"),
    # magnitudes that cannot be simulated
    ({"initial_displacement": 1e200}, "initial_displacement"),
    ({"initial_displacement": 50.0}, "initial_displacement"),  # half the 100 m cable
    ({"initial_displacement": 1e-300}, "initial_displacement"),  # a reward scale of 1e-600 J
    ({"initial_velocity": 1e200}, "initial_velocity"),
    ({"initial_velocity": 1e4}, "initial_velocity"),
    ({"vibration_weight": 1e308}, "vibration_weight"),
    ({"failure_penalty": 1e300}, "failure_penalty"),
    ({"max_thrust": 1e308}, "max_thrust"),
    ({"max_thrust": 1e-320}, "max_thrust"),
    ({"control_interval": 1e9}, "control_interval"),
    ({"control_interval": 1e-320}, "control_interval"),
    ({"observation_noise": 1e300}, "observation_noise"),
    ({"impulse_magnitude": 1e300}, "impulse_magnitude"),
    ({"periodic_period": 1e-300, "periodic_amplitude": 1.0}, "periodic_period"),
    ({"thruster_failure_window": (0.0, 1e300)}, "thruster_failure_window"),
    ({"thrust_delay": 10**9}, "thrust_delay"),
    ({"randomize": {"masses": 0.99}}, "randomize"),
    ({"render_exaggeration": 0.0}, "render_exaggeration"),
    ({"safety_factor": 1e-300}, "control_interval"),  # the sub-step budget names the interval to lower
    ({"preset_kwargs": {"edge": "x"}}, "edge"),
    ({"cluster": "tetrahedron"}, "cluster"),
]


@pytest.mark.parametrize(("kwargs", "name"), BAD_KWARGS, ids=[str(k) for k, _ in BAD_KWARGS])
def test_every_bad_keyword_argument_gets_an_error_naming_it(kwargs: dict, name: str) -> None:
    with pytest.raises((ValueError, TypeError)) as error:
        gym.make(ENV_ID, **kwargs)
    assert_names(error, name)
    if "render" in name:  # the vector env does not render
        return
    with pytest.raises((ValueError, TypeError)) as error:
        gym.make_vec(ENV_ID, num_envs=2, **kwargs)
    assert_names(error, name)


@pytest.mark.parametrize("render_mode", [["human"], 3, "ascii"])
def test_a_bad_render_mode_is_named(render_mode: object) -> None:
    # Directly: gym.make itself calls str methods on render_mode (an AttributeError for a list).
    with pytest.raises(EnvArgumentError, match="render_mode"):
        TetherClusterEnv(render_mode=render_mode)  # type: ignore[arg-type]


def test_a_huge_integer_preset_parameter_gets_a_named_error() -> None:
    with pytest.raises((ValueError, TypeError)) as error:
        gym.make(ENV_ID, preset_kwargs={"mass": 10**400})
    assert_names(error, "mass")


def test_settings_are_normalised_to_plain_values() -> None:
    config = TaskConfig(
        thrusters=np.array([0, 2]),
        max_thrust=[np.float32(2.0), 1],
        thruster_failure_window=[1, 2],
        randomize={"masses": np.float64(0.2)},
        thrust_delay=np.int64(3),
        observe_tensions=np.bool_(True),
    )
    assert config.thrusters == (0, 2) and type(config.thrusters[0]) is int
    assert config.max_thrust == (2.0, 1.0) and all(type(v) is float for v in config.max_thrust)
    assert config.thruster_failure_window == (1.0, 2.0)
    assert config.randomize == {"masses": 0.2} and type(config.randomize["masses"]) is float
    assert config.thrust_delay == 3 and type(config.thrust_delay) is int
    assert config.observe_tensions is True
    # max_deviation = inf means "never end on the deviation".
    assert TaskConfig(max_deviation=math.inf).max_deviation == math.inf


def test_a_cluster_with_preset_kwargs_is_refused_rather_than_ignoring_them() -> None:
    with pytest.raises(EnvArgumentError, match="preset_kwargs"):
        TetherClusterEnv(cluster=tg.make_cluster("chain"), preset_kwargs={"n": 3})
    TetherClusterEnv(cluster=tg.make_cluster("chain"), preset_kwargs={})


def test_the_sub_step_budget_names_the_longest_control_interval_and_it_is_accepted() -> None:
    cluster = tg.make_cluster("tetrahedron")
    scales = ClusterScales.of(cluster)
    safety = 1e-6
    longest = scales.max_substeps // SUBSTEP_HEADROOM * safety * min(scales.critical_step, scales.damping_step)
    with pytest.raises(
        EnvArgumentError, match=r"control_interval=1 s needs about .* lower control_interval to at most"
    ) as error:
        TetherClusterEnv(safety_factor=safety, control_interval=1.0)
    assert f"{longest:.3g} s" in str(error.value)
    TaskConfig(safety_factor=safety, control_interval=0.99 * longest).validate(cluster)
    # The worst randomised cluster (light, stiff) needs smaller sub-steps still.
    with pytest.raises(EnvArgumentError, match="control_interval"):
        TaskConfig(safety_factor=safety, control_interval=0.99 * longest, randomize={"masses": 0.5}).validate(cluster)


def test_the_damping_time_scale_counts_in_the_sub_step_budget() -> None:
    heavy = tg.make_cluster("tetrahedron", damping_rate=1e5)  # 2 m / c = 20 us
    scales = ClusterScales.of(heavy)
    assert scales.damping_step == pytest.approx(2e-5)
    with pytest.raises(EnvArgumentError, match="control_interval"):
        TetherClusterEnv(cluster=heavy, control_interval=CONTROL_INTERVAL_RANGE[1])


def test_a_cluster_too_stiff_for_any_interval_is_named_as_such() -> None:
    with pytest.raises(EnvArgumentError, match="too stiff or too light"):
        TetherClusterEnv(safety_factor=1e-12, control_interval=CONTROL_INTERVAL_RANGE[0])


def test_limits_are_generous_enough_for_the_edges_of_their_ranges() -> None:
    """The ends of every range build and step finitely."""
    scales = ClusterScales.of(tg.make_cluster("tetrahedron"))
    edge = {
        "max_thrust": THRUST_RANGE[1],
        "initial_displacement": scales.displacement_limit,
        "initial_velocity": scales.speed_limit,
        "vibration_weight": 1e6,
        "failure_penalty": 1e6,
        "randomize": {"masses": MAX_SPREAD, "EA": MAX_SPREAD},
        "max_deviation": math.inf,
    }
    env = gym.make(ENV_ID, **edge)
    env.reset(seed=0)
    for _ in range(5):
        obs, reward, terminated, _, info = env.step(np.ones(12))
        assert np.isfinite(obs).all() and math.isfinite(reward)
        if terminated:
            assert info["end_reason"] in tg.envs.END_REASONS[1:]
            break
    env = gym.make(
        ENV_ID,
        max_thrust=THRUST_RANGE[0],
        initial_displacement=0.0,
        initial_velocity=0.0,
        control_interval=CONTROL_INTERVAL_RANGE[0],
    )
    env.reset(seed=0)
    obs, reward, *_ = env.step(np.ones(12))
    assert np.isfinite(obs).all() and math.isfinite(reward)


# ------------------------------------------------------------------ seeds, options, actions
@pytest.mark.parametrize("seed", [1.5, "3", True, -1, [1], np.float64(2.0)])
def test_bad_seeds_are_named(seed: object) -> None:
    env = TetherClusterEnv()
    with pytest.raises(EnvArgumentError, match="seed"):
        env.reset(seed=seed)


@pytest.mark.parametrize(
    "seed", [1.5, "abc", True, -1, [0, 1.0], [0, "1"], [0, -1], [0], np.zeros((2, 1), int), {0: 1}]
)
def test_bad_vector_seeds_are_named(seed: object) -> None:
    envs = TetherClusterVectorEnv(num_envs=2)
    with pytest.raises(EnvArgumentError, match="seed"):
        envs.reset(seed=seed)


def test_numpy_integer_seeds_are_accepted_and_equal_to_python_ints() -> None:
    a, _ = TetherClusterEnv().reset(seed=np.int64(7))
    b, _ = TetherClusterEnv().reset(seed=7)
    assert np.array_equal(a, b)
    c, _ = TetherClusterVectorEnv(num_envs=2).reset(seed=np.array([7, 8]))
    d, _ = TetherClusterVectorEnv(num_envs=2).reset(seed=7)
    assert np.array_equal(c, d) and np.array_equal(c[0], a)


N = 4  # satellites of the tetrahedron
BAD_OPTIONS = [
    ("positions", np.full((N, 3), np.nan), "NaN or inf"),
    ("positions", np.full((N, 3), np.inf), "NaN or inf"),
    ("velocities", np.full((N, 3), -np.inf), "NaN or inf"),
    ("positions", np.zeros(3), "must be an"),
    ("positions", [["a", 1, 2]] * N, "real numbers"),
    ("positions", [[1, 2]] * 3 + [[1, 2, 3]], "array of numbers"),  # ragged
    ("velocities", np.ones((N, 3), dtype=complex), "real numbers"),
    ("velocities", np.ones((N, 3), dtype=bool), "real numbers"),
    ("velocities", "fast", "must be an"),
    ("positions", 1e300 * np.ones((N, 3)), "within"),
    ("positions", np.zeros((N, 3)), "on top of each other"),  # every satellite at one point
    ("velocities", 1e5 * np.ones((N, 3)), "limit"),
    ("velocities", np.full((N, 3), 10**400, dtype=object), "too large"),
]


@pytest.mark.parametrize(
    ("key", "value", "why"), BAD_OPTIONS, ids=[f"{k}-{w}-{i}" for i, (k, _, w) in enumerate(BAD_OPTIONS)]
)
def test_bad_reset_options_are_named_and_change_nothing(key: str, value: object, why: str) -> None:
    env = gym.make(ENV_ID)
    env.reset(seed=0)
    for _ in range(3):
        env.step(np.full(12, 0.5))
    before = env_state(env.unwrapped)
    with pytest.raises(EnvArgumentError, match=why) as error:
        env.reset(seed=99, options={key: value})
    assert_names(error, key)
    assert_unchanged(before, env_state(env.unwrapped))


@pytest.mark.parametrize("options", ["positions", ["positions"], 3, {"speed": 1}, {1: 2}])
def test_options_that_are_not_a_dict_of_known_keys_are_refused(options: object) -> None:
    env = TetherClusterEnv()
    with pytest.raises(EnvArgumentError, match="option"):
        env.reset(options=options)  # type: ignore[arg-type]


BAD_ACTIONS = [
    ("a" * 12, "action"),
    (["a"] * 12, "real numbers"),
    ([None] * 12, "real numbers"),
    (np.ones(12, dtype=complex), "real numbers"),
    (np.ones(12, dtype=bool), "real numbers"),
    ([[1.0, 2.0], [1.0]], "action"),
    ({"x": 1}, "action"),
    (np.zeros((1, 12)), "shape"),
    (np.full(12, np.inf), "NaN or inf"),
    (np.full(12, 1e4000, dtype=np.longdouble), "NaN or inf"),
]


@pytest.mark.parametrize(("action", "why"), BAD_ACTIONS, ids=[f"{w}-{i}" for i, (_, w) in enumerate(BAD_ACTIONS)])
def test_bad_actions_are_named_and_change_nothing(action: object, why: str) -> None:
    env = gym.make(ENV_ID)
    env.reset(seed=0)
    before = env_state(env.unwrapped)
    with pytest.raises(EnvArgumentError, match=why) as error:
        env.step(action)
    assert_names(error, "action")
    assert_unchanged(before, env_state(env.unwrapped))


def test_actions_of_any_real_dtype_act_alike_and_huge_ones_are_clipped() -> None:
    results = []
    for action in (
        np.ones(12, np.float32),
        np.ones(12, np.int8),
        [1] * 12,
        np.ones(12, np.float16),
        np.full(12, 1e300),
    ):
        env = TetherClusterEnv()
        env.reset(seed=0)
        results.append(env.step(action)[:2])
    for obs, reward in results[1:]:
        assert np.array_equal(obs, results[0][0]) and reward == results[0][1]


def test_a_refused_reset_leaves_the_generator_as_it_was() -> None:
    """After a refused reset(seed=..., options=bad), the next reset() continues the old
    generator: the episode equals that of an env which never saw the refused call."""
    env, twin = TetherClusterEnv(), TetherClusterEnv()
    env.reset(seed=1)
    twin.reset(seed=1)
    with pytest.raises(EnvArgumentError):
        env.reset(seed=2, options={"positions": np.nan})
    assert np.array_equal(env.reset()[0], twin.reset()[0])


def test_a_refused_vector_reset_changes_nothing() -> None:
    envs = TetherClusterVectorEnv(num_envs=3, randomize={"masses": 0.2})
    envs.reset(seed=0)
    envs.step(np.full((3, 12), 0.3))
    before = env_state(envs)
    good = np.stack([envs.cluster.positions] * 3)
    bad_positions = good.copy()
    bad_positions[2, 0] = np.nan
    for seed, options in (
        ([5, 6, 1.5], None),
        ([5, 6, -7], None),
        (5, {"positions": bad_positions}),
        (5, {"positions": good, "velocities": np.ones((2, 4, 3))}),
        (5, {"positions": good, "mask": 1}),
    ):
        with pytest.raises(EnvArgumentError):
            envs.reset(seed=seed, options=options)
        assert_unchanged(before, env_state(envs))


@pytest.mark.parametrize("difficulty", [-0.1, 1.5, math.nan, "0.5", True, None, [0.5]])
def test_a_refused_difficulty_keeps_the_old_one(difficulty: object) -> None:
    env = gym.make(ENV_ID, difficulty=0.7)
    envs = gym.make_vec(ENV_ID, num_envs=2, difficulty=0.7)
    for target in (env.unwrapped, envs.unwrapped):
        with pytest.raises(EnvArgumentError, match="difficulty"):
            target.set_difficulty(difficulty)
        assert target.task.difficulty == 0.7
    env.unwrapped.set_difficulty(np.float32(0.25))
    assert env.unwrapped.task.difficulty == 0.25 and type(env.unwrapped.task.difficulty) is float


@pytest.mark.parametrize(
    ("kwargs", "name"),
    [
        ({"num_envs": True}, "num_envs"),
        ({"num_envs": 2.0}, "num_envs"),
        ({"num_envs": 10**9}, "num_envs"),
        ({"num_envs": "2"}, "num_envs"),
        ({"num_envs": 2, "max_episode_steps": True}, "max_episode_steps"),
        ({"num_envs": 2, "max_episode_steps": 1.5}, "max_episode_steps"),
    ],
)
def test_bad_vector_sizes_are_named(kwargs: dict, name: str) -> None:
    with pytest.raises(EnvArgumentError, match=name):
        TetherClusterVectorEnv(**kwargs)


def test_the_vector_env_refuses_a_render_mode_and_a_bad_time_limit_set_later() -> None:
    with pytest.raises(EnvArgumentError, match="render_mode must be None"):
        gym.make_vec(ENV_ID, num_envs=2, render_mode="rgb_array")
    env = make_sb3_vec_env(ENV_ID, 2, seed=0)
    for steps in ("10", 0, 2.5, True):
        with pytest.raises(EnvArgumentError, match="max_episode_steps"):
            env.set_attr("max_episode_steps", steps)
    env.set_attr("max_episode_steps", 2)
    env.reset()
    for expected in (False, True):
        env.step_async(np.zeros((2, 12), np.float32))
        assert env.step_wait()[2].all() == expected


def test_a_delay_line_too_long_for_memory_is_refused_by_name() -> None:
    with pytest.raises(EnvArgumentError, match="lower thrust_delay or num_envs"):
        TetherClusterVectorEnv(num_envs=100_000, thrust_delay=1000)


def test_validate_needs_a_cluster() -> None:
    with pytest.raises(TypeError, match="cluster must be a tether_gym.Cluster"):
        TaskConfig().validate("tetrahedron")  # type: ignore[arg-type]


def test_bad_vector_actions_are_named() -> None:
    envs = TetherClusterVectorEnv(num_envs=2)
    envs.reset(seed=0)
    for actions, why in (
        ("x", "actions"),
        ([["a"] * 12] * 2, "real numbers"),
        (np.ones((2, 12), complex), "real numbers"),
        (np.zeros(24), "shape"),
        (np.full((2, 12), np.nan), "NaN or inf"),
    ):
        with pytest.raises(EnvArgumentError, match=why) as error:
            envs.step(actions)
        assert_names(error, "actions")


def test_sb3_seeds_are_checked() -> None:
    env = make_sb3_vec_env(ENV_ID, 2, seed=0)
    for seed in (1.5, "1", True, -3):
        with pytest.raises(ValueError, match="seed"):
            env.seed(seed)  # type: ignore[arg-type]
    assert env.seed(np.int64(4)) == [4, 5]


# ------------------------------------------------------------------ runaway steps
def runaway(task: tg.envs.DampingTask, how: str) -> None:
    """Make the next step's vibration reward run away: beyond REWARD_LIMIT but finite (caught by
    the env layer), or infinite (caught by the task kernel)."""
    task.weights[0] = {"huge": 1e300, "infinite": math.inf}[how]


@pytest.mark.parametrize("how", ["huge", "infinite"])
def test_a_runaway_reward_ends_the_episode_as_diverged_with_a_finite_reward(how: str) -> None:
    env = gym.make(ENV_ID)
    env.reset(seed=0)
    runaway(env.unwrapped.task, how)
    obs, reward, terminated, _, info = env.step(np.zeros(12))
    assert terminated and info["end_reason"] == "numerics_diverged"
    assert math.isfinite(reward) and abs(reward) <= REWARD_LIMIT and np.isfinite(obs).all()
    assert env.observation_space.contains(obs)
    assert info["reward_vibration"] == 0.0 and info["reward_failure"] == -100.0
    assert reward == pytest.approx(
        sum(info[k] for k in ("reward_vibration", "reward_propellant", "reward_slack", "reward_failure")),
        rel=1e-12,
    )


@pytest.mark.parametrize("how", ["huge", "infinite"])
def test_vector_and_sb3_runaways_end_with_finite_rewards(how: str) -> None:
    envs = gym.make_vec(ENV_ID, num_envs=3, autoreset_mode="same_step")
    envs.reset(seed=0)
    single = gym.make(ENV_ID)
    single.reset(seed=1)
    task = envs.unwrapped.task
    for t in (task, single.unwrapped.task):
        runaway(t, how)
    obs, rewards, terminated, _, infos = envs.step(np.zeros((3, 12)))
    s_obs, s_reward, s_terminated, _, s_info = single.step(np.zeros(12))
    assert terminated.all() and np.isfinite(rewards).all() and np.isfinite(obs).all()
    assert s_terminated and s_info["end_reason"] == "numerics_diverged"
    assert list(infos["final_info"]["end_reason"]) == ["numerics_diverged"] * 3
    # Bit-identical to the single env seeded alike.
    assert rewards[1] == s_reward and np.array_equal(infos["final_obs"][1], s_obs)

    sb3 = make_sb3_vec_env(ENV_ID, 3, seed=0)
    sb3.reset()
    runaway(sb3.venv.unwrapped.task, how)
    sb3.step_async(np.zeros((3, 12), np.float32))
    obs, rewards, dones, infos = sb3.step_wait()
    assert dones.all() and rewards.dtype == np.float32 and np.isfinite(rewards).all() and np.isfinite(obs).all()
    assert [info["end_reason"] for info in infos] == ["numerics_diverged"] * 3
    assert all(np.isfinite(info["terminal_observation"]).all() for info in infos)


def test_sb3_refuses_rewards_that_are_not_finite_in_float32() -> None:
    """A foreign vector env returning a reward beyond float32 gets an error, not a silent inf."""

    class Loud(TetherClusterVectorEnv):
        def step(self, actions):  # type: ignore[no-untyped-def]
            obs, rewards, terminated, truncated, infos = super().step(actions)
            return obs, rewards + 1e39, terminated, truncated, infos

    from tether_gym.sb3 import SB3VecEnv

    env = SB3VecEnv(Loud(num_envs=2, autoreset_mode="same_step"))
    env.reset()
    env.step_async(np.zeros((2, 12), np.float32))
    with pytest.raises(ValueError, match="not finite in float32"):
        env.step_wait()
