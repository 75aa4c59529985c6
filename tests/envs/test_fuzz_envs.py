"""Property-based fuzzing of the environment layer: ``gym.make`` and ``gym.make_vec`` keyword
arguments, seeds, reset options, actions, ``set_difficulty`` and the SB3 adapter.

Every input ends in exactly one of two ways:

* a clear error: a ``ValueError`` or ``TypeError`` (the project's ``EnvArgumentError`` and
  ``ClusterError`` are ValueErrors) whose own message names the offending argument; an update
  that is refused (reset, step, set_difficulty) leaves the env exactly as it was;
* finite, correct behaviour: observations of the right shape and dtype, finite and inside the
  observation space, finite float rewards, bool flags, a known ``end_reason`` when terminated
  (``"running"`` otherwise), and no numpy or Gymnasium warning on the way.

Nothing else is allowed.  The hypothesis profile (tests/conftest.py) derandomises the examples,
so CI runs are reproducible; example counts keep the whole file to some tens of seconds.
"""

from __future__ import annotations

import math
import os
import warnings
from collections.abc import Callable, Mapping
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

import tether_gym as tg
from tests.helpers import assert_unchanged, env_state
from tether_gym.envs import END_REASONS, TaskConfig, TetherClusterEnv
from tether_gym.envs.task import RANDOMISABLE
from tether_gym.sb3 import make_sb3_vec_env
from tether_gym.simulator import UnstableSafetyFactorWarning

#: Property-based, with many generated examples per property: the fast suite (-m 'not slow') leaves them out.
pytestmark = pytest.mark.slow


def fuzz(examples: int) -> settings:
    """Settings of one property: ``examples`` examples (times ``TETHER_GYM_FUZZ_SCALE``, 1 in CI;
    raise it with the ``explore`` profile to hunt for new failures)."""
    scale = int(os.environ.get("TETHER_GYM_FUZZ_SCALE", "1"))
    return settings(
        max_examples=examples * scale,
        deadline=None,
        suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large, HealthCheck.filter_too_much],
    )


#: Small clusters only (3-5 satellites): the properties are about arguments, not size.
SMALL_IDS = [
    "TetherTetrahedron-v0",
    "TetherTriangle-v0",
    "TetherChain-v0",
    "TetherSpinningTriangle-v0",
    "TetherRadialChain-v0",
    # The hard track's: a delay line.
    "TetherDelayedTetrahedron-v0",
]

#: Gymnasium re-raises a TypeError from an env's constructor with every keyword argument appended
#: ("... was raised from the environment creator for ... with kwargs (...)"); that suffix would
#: name any argument, so only the message before it counts.
GYMNASIUM_SUFFIX = " was raised from the environment creator"

SPECIAL_FLOATS = [
    0.0,
    -0.0,
    5e-324,
    -5e-324,
    1e-300,
    1e-7,
    1.0,
    -1.0,
    0.5,
    1e7,
    1e300,
    1.7976931348623157e308,
    -1.7976931348623157e308,
    math.inf,
    -math.inf,
    math.nan,
]
special = st.sampled_from(SPECIAL_FLOATS)
junk = st.one_of(
    st.text(max_size=3),
    st.booleans(),
    st.none(),
    st.complex_numbers(max_magnitude=2, allow_nan=False),
    st.integers(-(10**30), 10**30),
    st.integers(-(10**400), 10**400),
    st.lists(st.integers(-2, 5), max_size=3),
    st.dictionaries(st.text(max_size=2), st.floats(0, 1), max_size=2),
    st.just(np.float32(0.5)),
    st.just(np.int64(2)),
)


def field(valid: st.SearchStrategy[Any]) -> st.SearchStrategy[Any]:
    """Mostly plausible values, sometimes special floats or junk."""
    return st.one_of(valid, valid, valid, special, junk)


def floats(low: float, high: float) -> st.SearchStrategy[float]:
    return st.floats(low, high, allow_nan=False, allow_infinity=False)


indices = st.one_of(
    st.none(),
    st.lists(st.integers(0, 4), min_size=1, max_size=4, unique=True),
    st.lists(st.integers(-1, 6), max_size=4),
    st.lists(floats(0, 3), min_size=1, max_size=2),
    hnp.arrays(np.int64, st.integers(1, 3), elements=st.integers(0, 3), unique=True),
)

#: Plausible values of every TaskConfig field: inside or near its range (the edges included), but
#: not all valid for every cluster or in every combination.
PLAUSIBLE: dict[str, st.SearchStrategy[Any]] = {
    "control_interval": st.one_of(floats(1e-4, 1.0), st.sampled_from([1e-4, 0.05, 0.1, 0.5, 5.0])),
    "thrusters": indices,
    "max_thrust": st.one_of(floats(1e-9, 1e6), st.lists(floats(1e-3, 10), min_size=1, max_size=5)),
    "thrust_limit": st.sampled_from(["per_axis", "magnitude"]),
    "thrust_mode": st.sampled_from(["continuous", "on_off"]),
    "initial_displacement": st.one_of(floats(0, 12), st.sampled_from([0.0, 1e-7, 10.0])),
    "initial_velocity": st.one_of(floats(0, 200), st.sampled_from([0.0, 1e-6, 173.0])),
    "vibration_weight": floats(0, 1e6),
    "propellant_weight": floats(0, 1e6),
    "slack_weight": floats(0, 1e6),
    "failure_penalty": floats(0, 1e6),
    "max_deviation": st.one_of(st.none(), floats(1e-3, 1e4), st.just(math.inf)),
    "observe_tensions": st.booleans(),
    "observe_commands": st.booleans(),
    "observation_noise": floats(0, 1e4),
    "observed_satellites": indices,
    "randomize": st.dictionaries(st.sampled_from(RANDOMISABLE), floats(0, 0.95), max_size=3),
    "safety_factor": floats(1e-3, 1.0),
    "allow_unstable_safety_factor": st.booleans(),
    "impulse_magnitude": floats(0, 1e3),
    "impulse_rate": floats(0, 1e3),
    "periodic_amplitude": floats(0, 1e3),
    "periodic_period": floats(1e-3, 1e3),
    "thrust_noise": floats(0, 10),
    "thrust_delay": st.integers(0, 5),
    "thruster_failure_probability": floats(0, 1),
    "thruster_failure_window": st.tuples(floats(0, 5), floats(0, 5)),
    "cable_failure": st.sampled_from(["terminate", "continue"]),
    "difficulty": floats(0, 1),
}
#: Any value of every TaskConfig field: mostly plausible, sometimes special floats or junk.
TASK_FIELDS = {name: field(valid) for name, valid in PLAUSIBLE.items()}
assert set(PLAUSIBLE) == set(TaskConfig.__dataclass_fields__), "fuzz every TaskConfig field"

#: Overrides of the presets' parameters (some presets lack some of them: that is an error too).
PRESET_KWARGS = st.one_of(
    st.none(),
    st.fixed_dictionaries(
        {},
        optional={
            "EA": field(floats(1e2, 1e6)),
            "N0": field(floats(0, 10)),
            "mass": field(floats(0.1, 100)),
            "breaking_load": field(st.one_of(floats(1, 1e4), st.just(math.inf))),
            "damping_rate": field(floats(0, 10)),
            "edge": field(floats(1, 1e3)),
            "n": field(st.integers(-1, 6)),
            "spin_rate": field(floats(1e-3, 1)),
        },
    ),
    junk,
)

task_kwargs = st.fixed_dictionaries({}, optional=TASK_FIELDS)


# ------------------------------------------------------------------ the two outcomes
#: Settings whose range depends on the cluster: with another cluster than the id's own, their
#: defaults may be the offending argument (e.g. 0.1 m/s is too fast for 30 000 t satellites).
CLUSTER_DEPENDENT = {"initial_displacement", "initial_velocity", "control_interval", "safety_factor"}


def names_of(kwargs: Mapping[str, Any]) -> set[str]:
    """The argument names an error about ``kwargs`` may name: the keys, the preset's parameters
    inside ``preset_kwargs``, and with another cluster the cluster-dependent settings."""
    names = set(kwargs)
    inner = kwargs.get("preset_kwargs")
    if isinstance(inner, Mapping):
        names |= {key for key in inner if isinstance(key, str)}
    if inner or "preset" in kwargs or "cluster" in kwargs:
        names |= CLUSTER_DEPENDENT
    return names


def assert_clear_error(error: BaseException, names: set[str]) -> None:
    """Outcome (a): a ValueError/TypeError whose own message names one of ``names``."""
    assert isinstance(error, (ValueError, TypeError)), f"{type(error).__name__}: {error}"
    text = str(error).split(GYMNASIUM_SUFFIX)[0]
    if "sub-steps" in text:  # the sub-step budget: control_interval against safety_factor and the cluster
        names = names | {"control_interval", "safety_factor"}
    assert any(name in text for name in names), f"the message names none of {sorted(names)}: {text}"
    event("clear error")


def assert_step_ok(space: gym.Space, obs: Any, reward: Any, terminated: Any, truncated: Any, info: dict) -> None:
    """Outcome (b) for one single-env step."""
    event("stepped")
    assert isinstance(obs, np.ndarray) and obs.dtype == np.float32 and np.isfinite(obs).all()
    assert space.contains(obs)
    assert type(reward) is float and math.isfinite(reward)
    assert type(terminated) is bool and type(truncated) is bool
    assert info["end_reason"] in (END_REASONS[1:] if terminated else ("running",))


def assert_reset_ok(space: gym.Space, obs: Any, info: dict) -> None:
    assert isinstance(obs, np.ndarray) and obs.dtype == np.float32 and np.isfinite(obs).all()
    assert space.contains(obs)
    assert math.isfinite(info["vibration_energy"]) and math.isfinite(info["time"])


def quietly(call: Callable[[], Any]) -> Any:
    """``call()``, failing on any warning (numpy overflow, Gymnasium's checker on NaN or on an
    observation outside its space) instead of letting it pass; except the one a safety factor
    above the stable range gives when ``allow_unstable_safety_factor=True`` asked for it."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        warnings.filterwarnings("ignore", category=UnstableSafetyFactorWarning)
        return call()


def rollout(env: gym.Env, seed: int, steps: int, data: st.DataObject) -> None:
    obs, info = quietly(lambda: env.reset(seed=seed))
    assert_reset_ok(env.observation_space, obs, info)
    for _ in range(steps):
        action = data.draw(hnp.arrays(np.float32, env.action_space.shape, elements=floats(-2, 2)), label="action")
        obs, reward, terminated, truncated, info = quietly(lambda action=action: env.step(action))
        assert_step_ok(env.observation_space, obs, reward, terminated, truncated, info)
        if terminated or truncated:
            break


# ------------------------------------------------------------------ gym.make
@fuzz(250)
@given(env_id=st.sampled_from(SMALL_IDS), kwargs=task_kwargs, data=st.data())
def test_make_with_any_task_arguments(env_id: str, kwargs: dict, data: st.DataObject) -> None:
    make_and_roll_out(env_id, kwargs, data)


@fuzz(250)
@given(env_id=st.sampled_from(SMALL_IDS), kwargs=st.fixed_dictionaries({}, optional=PLAUSIBLE), data=st.data())
def test_make_with_plausible_task_arguments(env_id: str, kwargs: dict, data: st.DataObject) -> None:
    """The same, with values near their ranges: mostly accepted, so the rollouts are exercised."""
    make_and_roll_out(env_id, kwargs, data)


def make_and_roll_out(env_id: str, kwargs: dict, data: st.DataObject) -> None:
    try:
        env = quietly(lambda: gym.make(env_id, **kwargs))
    except Exception as error:  # noqa: BLE001 - the property is about which exceptions
        assert_clear_error(error, names_of(kwargs))
        return
    rollout(env, seed=0, steps=3, data=data)


@fuzz(120)
@given(
    env_id=st.sampled_from(SMALL_IDS),
    preset_kwargs=PRESET_KWARGS,
    extra=st.fixed_dictionaries(
        {},
        optional={
            "render_exaggeration": field(floats(1e-3, 1e6)),
            "render_mode": st.sampled_from([None, "rgb_array", "ascii", 3]),
            "preset": field(st.sampled_from(tg.preset_names())),
            "control_interval": TASK_FIELDS["control_interval"],
        },
    ),
    data=st.data(),
)
def test_make_with_any_preset_arguments(env_id: str, preset_kwargs: Any, extra: dict, data: st.DataObject) -> None:
    kwargs = dict(extra, preset_kwargs=preset_kwargs)

    def make() -> gym.Env:
        if kwargs.get("render_mode") in (None, "rgb_array"):
            return gym.make(env_id, **kwargs)
        # gym.make itself warns about, or trips over, a render mode the env does not list
        return TetherClusterEnv(**{**gym.spec(env_id).kwargs, **kwargs})

    try:
        env = quietly(make)
    except Exception as error:  # noqa: BLE001
        assert_clear_error(error, names_of(kwargs) | {"preset"})
        return
    rollout(env, seed=1, steps=2, data=data)


# ------------------------------------------------------------------ gym.make_vec and SB3
num_envs = st.one_of(st.integers(1, 4), st.integers(-2, 0), st.just(2.0), st.just(True), st.text(max_size=1))
vector_seeds = st.one_of(
    st.none(),
    st.integers(0, 2**40),
    st.integers(-3, -1),
    floats(0, 3),
    st.booleans(),
    st.text(max_size=2),
    st.lists(st.one_of(st.none(), st.integers(-1, 9), floats(0, 2)), max_size=4),
)


@fuzz(120)
@given(
    env_id=st.sampled_from(SMALL_IDS),
    kwargs=st.fixed_dictionaries(
        {},
        optional={
            key: PLAUSIBLE[key]
            for key in (
                "control_interval",
                "max_thrust",
                "thrusters",
                "initial_velocity",
                "randomize",
                "observation_noise",
                "impulse_magnitude",
                "thrust_delay",
                "observe_commands",
                "difficulty",
                "max_deviation",
                "thrust_noise",
            )
        },
    ),
    count=num_envs,
    seed=vector_seeds,
    data=st.data(),
)
def test_make_vec_with_any_arguments_and_seeds(
    env_id: str, kwargs: dict, count: Any, seed: Any, data: st.DataObject
) -> None:
    try:
        envs = quietly(lambda: gym.make_vec(env_id, num_envs=count, **kwargs))
    except Exception as error:  # noqa: BLE001
        assert_clear_error(error, names_of(kwargs) | {"num_envs"})
        return
    try:
        obs, infos = quietly(lambda: envs.reset(seed=seed))
    except Exception as error:  # noqa: BLE001
        assert_clear_error(error, {"seed"})
        return
    assert obs.dtype == np.float32 and np.isfinite(obs).all() and envs.observation_space.contains(obs)
    event("vector stepped")
    for _ in range(3):
        actions = data.draw(hnp.arrays(np.float64, envs.action_space.shape, elements=floats(-3, 3)), label="actions")
        obs, rewards, terminated, truncated, infos = quietly(lambda actions=actions: envs.step(actions))
        assert obs.dtype == np.float32 and np.isfinite(obs).all() and envs.observation_space.contains(obs)
        assert rewards.dtype == np.float64 and rewards.shape == (count,) and np.isfinite(rewards).all()
        assert terminated.dtype == np.bool_ and truncated.dtype == np.bool_
        # Next-step autoreset (the default): the step that ends an episode returns its last
        # observation and info as they are; the next one resets it.
        for i in np.flatnonzero(terminated):
            assert infos["end_reason"][i] in END_REASONS[1:]


@fuzz(60)
@given(
    seed=st.one_of(
        st.none(),
        st.integers(0, 2**40),
        st.integers(-3, -1),
        floats(0, 3),
        st.booleans(),
        st.text(max_size=2),
    ),
    data=st.data(),
)
def test_sb3_adapter_with_any_seed(seed: Any, data: st.DataObject) -> None:
    env = SB3
    try:
        env.seed(seed)
    except Exception as error:  # noqa: BLE001
        assert_clear_error(error, {"seed"})
        return
    obs = quietly(env.reset)
    assert np.isfinite(obs).all()
    actions = data.draw(hnp.arrays(np.float32, (2, 12), elements=floats(-3, 3)), label="actions")
    env.step_async(actions)
    obs, rewards, dones, infos = quietly(env.step_wait)
    assert rewards.dtype == np.float32 and np.isfinite(rewards).all() and np.isfinite(obs).all()
    for i in np.flatnonzero(dones):
        assert infos[i]["end_reason"] in END_REASONS[1:] or infos[i]["TimeLimit.truncated"]


SB3 = make_sb3_vec_env("TetherTetrahedron-v0", 2, seed=0)


# ------------------------------------------------------------------ actions, reset options, difficulty
#: One env per shape of action space, built once: the properties below are about one call each.
ENVS = {
    "all": gym.make("TetherTetrahedron-v0"),
    "two thrusters, magnitude": gym.make(
        "TetherTetrahedron-v0", thrusters=[1, 3], thrust_limit="magnitude", max_thrust=[2.0, 0.5]
    ),
    "faults": gym.make(
        "TetherTriangle-v0",
        thrust_delay=1,
        thrust_noise=0.1,
        impulse_magnitude=1.0,
        observation_noise=0.01,
        cable_failure="continue",
    ),
}
for _env in ENVS.values():
    _env.reset(seed=0)


def action_like(size: int) -> st.SearchStrategy[Any]:
    """Arrays of every dtype and many shapes (the right one often), lists, scalars and junk."""
    dtypes = st.sampled_from(
        [
            np.float64,
            np.float32,
            np.float16,
            np.int8,
            np.int64,
            np.uint8,
            np.bool_,
            np.complex128,
            np.longdouble,
        ]
    )
    shapes = st.one_of(st.just((size,)), hnp.array_shapes(min_dims=0, max_dims=3, max_side=size + 1))
    arrays = st.one_of(
        hnp.arrays(st.just(np.float64), st.just((size,)), elements=st.one_of(floats(-1e300, 1e300), special)),
        hnp.arrays(dtypes, shapes),
    )
    lists = st.lists(st.one_of(floats(-2, 2), special, junk), min_size=size - 1, max_size=size + 1)
    return st.one_of(arrays, arrays, lists, special, junk)


@fuzz(300)
@given(name=st.sampled_from(list(ENVS)), data=st.data())
def test_step_with_any_action(name: str, data: st.DataObject) -> None:
    env = ENVS[name]
    action = data.draw(action_like(env.action_space.shape[0]), label="action")
    before = env_state(env)
    try:
        result = quietly(lambda: env.step(action))
    except Exception as error:  # noqa: BLE001
        assert_clear_error(error, {"action"})
        assert_unchanged(before, env_state(env))
        return
    assert_step_ok(env.observation_space, *result)
    if result[2] or result[3]:
        env.reset(seed=0)


def state_like(shape: tuple[int, ...], nominal: np.ndarray | None) -> st.SearchStrategy[Any]:
    """Exact initial positions (near ``nominal``) or velocities: plausible, special, wrong
    shapes, wrong dtypes, junk."""
    offsets = hnp.arrays(np.float64, shape, elements=st.one_of(floats(-5, 5), floats(-1e4, 1e4), special))
    near = offsets.map(lambda x: x + nominal) if nominal is not None else offsets
    return st.one_of(
        near,
        near,
        near,
        hnp.arrays(np.float64, hnp.array_shapes(max_dims=3, max_side=5)),
        hnp.arrays(st.sampled_from([np.int64, np.bool_, np.complex128, object]), shape, elements=st.integers(0, 1)),
        near.map(lambda x: x.tolist()),
        special,
        junk,
    )


def reset_options(
    nominal: np.ndarray, unknown_key: str, unknown_values: st.SearchStrategy[Any]
) -> st.SearchStrategy[Any]:
    """Reset options: none, junk, or a dict with any of exact positions/velocities shaped like
    ``nominal`` and a key the env does not know."""
    return st.one_of(
        st.none(),
        junk,
        st.fixed_dictionaries(
            {},
            optional={
                "positions": state_like(nominal.shape, nominal),
                "velocities": state_like(nominal.shape, None),
                unknown_key: unknown_values,
            },
        ),
    )


@fuzz(250)
@given(
    name=st.sampled_from(list(ENVS)),
    seed=st.one_of(
        st.none(),
        st.integers(0, 2**64),
        st.integers(-2, -1),
        floats(0, 2),
        st.text(max_size=1),
        st.booleans(),
    ),
    data=st.data(),
)
def test_reset_with_any_options_and_seed(name: str, seed: Any, data: st.DataObject) -> None:
    env = ENVS[name]
    nominal = env.unwrapped.cluster.positions
    options = data.draw(reset_options(nominal, "speed", st.floats()), label="options")
    before = env_state(env)
    try:
        obs, info = quietly(lambda: env.reset(seed=seed, options=options))
    except Exception as error:  # noqa: BLE001
        assert_clear_error(error, {"seed", "options", "option", "positions", "velocities"})
        assert_unchanged(before, env_state(env))
        return
    assert_reset_ok(env.observation_space, obs, info)
    if isinstance(options, Mapping) and options.get("positions") is not None:
        assert np.array_equal(env.unwrapped.task.sim.positions[0], np.asarray(options["positions"], dtype=float))
    rollout_from_here(env, data)


def rollout_from_here(env: gym.Env, data: st.DataObject) -> None:
    for _ in range(2):
        action = data.draw(hnp.arrays(np.float32, env.action_space.shape, elements=floats(-1, 1)), label="action")
        result = quietly(lambda action=action: env.step(action))
        assert_step_ok(env.observation_space, *result)
        if result[2] or result[3]:
            env.reset(seed=0)
            return


@fuzz(100)
@given(name=st.sampled_from(list(ENVS)), difficulty=st.one_of(floats(-0.5, 1.5), special, junk))
def test_set_difficulty_with_any_value(name: str, difficulty: Any) -> None:
    env = ENVS[name]
    before = env_state(env)
    try:
        env.unwrapped.set_difficulty(difficulty)
    except Exception as error:  # noqa: BLE001
        assert_clear_error(error, {"difficulty"})
        assert_unchanged(before, env_state(env))
        return
    assert env.unwrapped.task.difficulty == float(difficulty)
    obs, info = quietly(lambda: env.reset(seed=0))
    assert_reset_ok(env.observation_space, obs, info)
    env.unwrapped.set_difficulty(1.0)


VECTOR = gym.make_vec("TetherTriangle-v0", num_envs=3, randomize={"masses": 0.1}, thrust_delay=1)
VECTOR.reset(seed=0)


@fuzz(150)
@given(data=st.data())
def test_vector_step_with_any_actions(data: st.DataObject) -> None:
    envs = VECTOR
    shape = envs.action_space.shape
    actions = data.draw(
        st.one_of(
            hnp.arrays(np.float64, shape, elements=st.one_of(floats(-1e300, 1e300), special)),
            hnp.arrays(
                st.sampled_from([np.float32, np.int16, np.bool_, np.complex64, object]),
                st.one_of(st.just(shape), hnp.array_shapes(max_dims=3, max_side=10)),
                elements=st.integers(0, 1),
            ),
            st.lists(
                st.lists(st.one_of(floats(-2, 2), special, junk), min_size=8, max_size=10),
                min_size=2,
                max_size=4,
            ),
            special,
            junk,
        ),
        label="actions",
    )
    before = env_state(envs)
    try:
        obs, rewards, terminated, truncated, _ = quietly(lambda: envs.step(actions))
    except Exception as error:  # noqa: BLE001
        assert_clear_error(error, {"actions"})
        assert_unchanged(before, env_state(envs))
        return
    assert obs.dtype == np.float32 and np.isfinite(obs).all() and envs.observation_space.contains(obs)
    assert np.isfinite(rewards).all() and terminated.dtype == np.bool_ and truncated.dtype == np.bool_


@fuzz(150)
@given(seed=vector_seeds, data=st.data())
def test_vector_reset_with_any_options_and_seeds(seed: Any, data: st.DataObject) -> None:
    envs = VECTOR
    nominal = np.broadcast_to(envs.unwrapped.cluster.positions, (3, 3, 3))
    options = data.draw(reset_options(nominal, "mask", st.booleans()), label="options")
    before = env_state(envs)
    try:
        obs, infos = quietly(lambda: envs.reset(seed=seed, options=options))
    except Exception as error:  # noqa: BLE001
        assert_clear_error(error, {"seed", "options", "option", "positions", "velocities"})
        assert_unchanged(before, env_state(envs))
        return
    assert obs.dtype == np.float32 and np.isfinite(obs).all() and envs.observation_space.contains(obs)
    assert np.isfinite(infos["vibration_energy"]).all()


@pytest.mark.parametrize("env_id", SMALL_IDS)
def test_the_registered_ids_pass_their_own_checks(env_id: str) -> None:
    """The defaults sit inside every range (a guard against limits drawn too tight)."""
    spec = gym.spec(env_id)
    cluster = tg.make_cluster(spec.kwargs["preset"])
    TaskConfig(**{k: v for k, v in spec.kwargs.items() if k != "preset"}).validate(cluster)


@fuzz(40)
@given(preset=st.sampled_from(["tetrahedron", "chain", "triangle"]), data=st.data())
def test_commands_act_only_on_thrusters_and_only_after_their_delay(preset: str, data: st.DataObject) -> None:
    """Whichever satellites carry thrusters and however late they act (the hard track's kinds of
    id): a satellite without a thruster never gets thrust, and a command in flight reaches
    nothing observed before it acts, ``thrust_delay`` intervals after it is given."""
    satellites = tg.make_cluster(preset).num_satellites
    thrusters = data.draw(
        st.lists(st.integers(0, satellites - 1), min_size=1, max_size=satellites, unique=True), label="thrusters"
    )
    delay = data.draw(st.integers(0, 3), label="thrust_delay")
    changed = data.draw(st.integers(0, 4), label="changed step")
    seed = data.draw(st.integers(0, 2**32 - 1), label="seed")
    passive = [i for i in range(satellites) if i not in thrusters]
    rng = np.random.default_rng(seed)
    # At least half the full scale per axis, so that flipping a command shows in float32.
    actions = rng.choice([-1.0, 1.0], (changed + 1, 3 * len(thrusters))) * rng.uniform(0.5, 1.0, (changed + 1, 1))
    actions = np.concatenate([actions, np.zeros((delay + 2, 3 * len(thrusters)))]).astype(np.float32)
    runs = []
    for flip in (False, True):
        env = TetherClusterEnv(preset=preset, thrusters=thrusters, thrust_delay=delay)
        observations = [env.reset(seed=seed)[0]]
        for step, action in enumerate(actions):
            obs, _, terminated, _, info = env.step(-action if flip and step == changed else action)
            assert not terminated and np.all(info["thrust"][passive] == 0.0)
            observations.append(obs)
        runs.append(observations)
    first_different = next(k for k, (a, b) in enumerate(zip(*runs, strict=True)) if not np.array_equal(a, b))
    assert first_different == changed + delay + 1


# ---------------------------------------------------------------------- task snapshots
@fuzz(150)
@given(
    env_id=st.sampled_from(SMALL_IDS),
    data=st.data(),
    value=st.one_of(special, st.integers(-(2**40), 2**40)),
)
def test_task_restore_refuses_out_of_range_arrays_and_changes_nothing(
    env_id: str, data: st.DataObject, value: Any
) -> None:
    import dataclasses

    from tether_gym.envs.task import TASK_STATE_FIELDS

    env = gym.make(env_id)
    env.reset(seed=0)
    env.step(np.zeros(env.action_space.shape, dtype=np.float32))
    task = env.unwrapped.task  # type: ignore[attr-defined]
    state = task.snapshot()
    task.restore(state)  # every real snapshot restores
    name = data.draw(st.sampled_from([n for n in TASK_STATE_FIELDS if state.arrays[n].size]))
    poisoned = state.arrays[name].copy()
    try:
        poisoned.flat[0] = value
    except (TypeError, ValueError, OverflowError):
        return
    arrays = dict(state.arrays)
    arrays[name] = poisoned
    env.step(np.full(env.action_space.shape, 0.5, dtype=np.float32))
    before = env_state(env)
    try:
        task.restore(dataclasses.replace(state, arrays=arrays))
    except ValueError as error:
        assert f"state.arrays[{name!r}]" in str(error)
        assert_unchanged(before, env_state(env))
        return
    # Accepted: then it was a value the task can hold, and the next step is finite.
    observation, reward, _, _, info = env.step(np.zeros(env.action_space.shape, dtype=np.float32))
    assert np.isfinite(observation).all() and math.isfinite(reward)
    assert info["propellant_used"] >= 0 and info["simulator_status"] in (0, 1, 2, 3)


@fuzz(60)
@given(rows=st.lists(st.integers(-1, 3), min_size=1, max_size=4))
def test_task_reset_refuses_bad_rows_before_any_generator_draws(rows: list[int]) -> None:
    venv = gym.make_vec("TetherTetrahedron-v0", num_envs=3)
    venv.reset(seed=0)
    task = venv.unwrapped.task  # type: ignore[attr-defined]
    rngs = [np.random.default_rng(k) for k in range(len(rows))]
    before = env_state(venv), [rng.bit_generator.state for rng in rngs]
    try:
        task.reset(rngs, np.asarray(rows))
    except ValueError as error:
        assert "indices" in str(error)
        assert len(set(rows)) < len(rows) or not all(0 <= r < 3 for r in rows)
        assert_unchanged(before[0], env_state(venv))
        assert [rng.bit_generator.state for rng in rngs] == before[1]
        return
    assert len(set(rows)) == len(rows) and all(0 <= r < 3 for r in rows)
