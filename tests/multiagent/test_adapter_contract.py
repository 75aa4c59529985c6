"""One contract for both SB3 adapters: the single-agent ``SB3VecEnv`` and the multi-agent
``AgentVecEnv`` refuse the same inputs, with the same exception and a message that names the
argument, and accept the same ones.

The table below runs every bad input against both adapters (parametrised over adapter), and a
hypothesis property fuzzes ``set_attr``, ``get_attr``, ``env_method``, ``seed`` and
``step_async`` on both at once: each input must be accepted by both or refused by both, with
the same exception type.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

pytest.importorskip("stable_baselines3")

from stable_baselines3.common.monitor import Monitor  # noqa: E402

from tether_gym.envs.arguments import EnvArgumentError  # noqa: E402
from tether_gym.multiagent.sb3 import AgentVecEnv, make_agent_vec_env  # noqa: E402
from tether_gym.sb3 import BatchVecEnv, SB3VecEnv, make_sb3_vec_env  # noqa: E402

ENV_ID = "TetherTriangle-v0"
CLUSTERS = 2


def single() -> SB3VecEnv:
    return make_sb3_vec_env(ENV_ID, CLUSTERS, seed=0, max_episode_steps=50)


def multi() -> AgentVecEnv:
    return make_agent_vec_env(ENV_ID, CLUSTERS, seed=0, max_episode_steps=50)


ADAPTERS: dict[str, Callable[[], BatchVecEnv]] = {"SB3VecEnv": single, "AgentVecEnv": multi}


def action_shape(env: BatchVecEnv) -> tuple[int, ...]:
    return (env.num_envs, *env.action_space.shape)


def nominal_states(env: BatchVecEnv) -> np.ndarray:
    """(clusters, n, 3) nominal positions: valid exact reset states for either adapter."""
    cluster = env.get_attr("task", indices=0)[0].cluster
    return np.stack([cluster.positions] * CLUSTERS)


def pending(env: BatchVecEnv) -> None:
    env.step_async(np.zeros(action_shape(env)))
    env.step_async(np.zeros(action_shape(env)))


def closed(call: Callable[[BatchVecEnv], Any]) -> Callable[[BatchVecEnv], Any]:
    def use_after_close(env: BatchVecEnv) -> Any:
        env.close()
        env.close()  # a second close is allowed
        return call(env)

    return use_after_close


def options(value: Any) -> Callable[[BatchVecEnv], Any]:
    def reset_with(env: BatchVecEnv) -> Any:
        env.set_options(value(env) if callable(value) else value)
        return env.reset()

    return reset_with


#: (case, call, exception, a fragment the message must hold: the argument's name).
BAD: list[tuple[str, Callable[[BatchVecEnv], Any], type[BaseException], str]] = [
    (
        "set_attr max_episode_steps 0",
        lambda e: e.set_attr("max_episode_steps", 0),
        EnvArgumentError,
        "max_episode_steps",
    ),
    (
        "set_attr max_episode_steps -3",
        lambda e: e.set_attr("max_episode_steps", -3),
        EnvArgumentError,
        "max_episode_steps",
    ),
    (
        "set_attr max_episode_steps 2.0",
        lambda e: e.set_attr("max_episode_steps", 2.0),
        EnvArgumentError,
        "max_episode_steps",
    ),
    (
        "set_attr max_episode_steps True",
        lambda e: e.set_attr("max_episode_steps", True),
        EnvArgumentError,
        "max_episode_steps",
    ),
    (
        "set_attr max_episode_steps '9'",
        lambda e: e.set_attr("max_episode_steps", "9"),
        EnvArgumentError,
        "max_episode_steps",
    ),
    (
        "set_attr max_episode_steps nan",
        lambda e: e.set_attr("max_episode_steps", math.nan),
        EnvArgumentError,
        "max_episode_steps",
    ),
    ("set_attr misspelt", lambda e: e.set_attr("max_episod_steps", 5), AttributeError, "max_episod_steps"),
    ("set_attr task", lambda e: e.set_attr("task", None), AttributeError, "'task'"),
    ("set_attr private", lambda e: e.set_attr("_max_episode_steps", 0), AttributeError, "_max_episode_steps"),
    ("set_attr not a str", lambda e: e.set_attr(3, 5), TypeError, "attr_name"),
    ("set_attr some rows", lambda e: e.set_attr("max_episode_steps", 5, indices=[1]), EnvArgumentError, "indices"),
    ("get_attr missing", lambda e: e.get_attr("no_such_attribute"), AttributeError, "no_such_attribute"),
    ("get_attr private", lambda e: e.get_attr("_seeds"), AttributeError, "_seeds"),
    ("get_attr dunder", lambda e: e.get_attr("__class__"), AttributeError, "__class__"),
    ("get_attr not a str", lambda e: e.get_attr(None), TypeError, "attr_name"),
    ("indices out of range", lambda e: e.get_attr("task", indices=[99]), EnvArgumentError, "indices"),
    ("indices negative", lambda e: e.get_attr("task", indices=-1), EnvArgumentError, "indices"),
    ("indices float", lambda e: e.get_attr("task", indices=1.0), EnvArgumentError, "indices"),
    ("indices bool", lambda e: e.get_attr("task", indices=True), EnvArgumentError, "indices"),
    ("indices mask", lambda e: e.get_attr("task", indices=np.ones(e.num_envs, bool)), EnvArgumentError, "mask"),
    ("indices str", lambda e: e.get_attr("task", indices="0"), EnvArgumentError, "indices"),
    ("indices repeated", lambda e: e.get_attr("task", indices=[0, 0]), EnvArgumentError, "indices"),
    ("indices too many", lambda e: e.get_attr("task", indices=range(10**12)), EnvArgumentError, "indices"),
    ("env_is_wrapped indices", lambda e: e.env_is_wrapped(Monitor, indices=[99]), EnvArgumentError, "indices"),
    ("env_method reset", lambda e: e.env_method("reset"), AttributeError, "'reset'"),
    ("env_method step", lambda e: e.env_method("step", None), AttributeError, "'step'"),
    ("env_method private", lambda e: e.env_method("_step_next_step"), AttributeError, "_step_next_step"),
    ("env_method not a str", lambda e: e.env_method(b"set_difficulty", 0.5), TypeError, "method_name"),
    ("env_method no argument", lambda e: e.env_method("set_difficulty"), EnvArgumentError, "difficulty"),
    ("env_method two arguments", lambda e: e.env_method("set_difficulty", 0.5, 1), EnvArgumentError, "set_difficulty"),
    ("env_method bad keyword", lambda e: e.env_method("set_difficulty", level=0.5), EnvArgumentError, "set_difficulty"),
    ("env_method difficulty 2", lambda e: e.env_method("set_difficulty", 2.0), EnvArgumentError, "difficulty"),
    ("env_method difficulty nan", lambda e: e.env_method("set_difficulty", math.nan), EnvArgumentError, "difficulty"),
    (
        "env_method no rows, bad value",
        lambda e: e.env_method("set_difficulty", -1, indices=[]),
        EnvArgumentError,
        "difficulty",
    ),
    (
        "env_method bad indices",
        lambda e: e.env_method("set_difficulty", 0.5, indices=[7.0]),
        EnvArgumentError,
        "indices",
    ),
    ("seed -1", lambda e: e.seed(-1), EnvArgumentError, "seed"),
    ("seed 1.5", lambda e: e.seed(1.5), EnvArgumentError, "seed"),
    ("seed True", lambda e: e.seed(True), EnvArgumentError, "seed"),
    ("seed '3'", lambda e: e.seed("3"), EnvArgumentError, "seed"),
    ("set_options 3", lambda e: e.set_options(3), EnvArgumentError, "options"),
    ("set_options a list of 1", lambda e: e.set_options([{}]), EnvArgumentError, "options"),
    ("reset option unknown", options({"bogus": 1}), EnvArgumentError, "bogus"),
    ("reset option shape", options({"positions": np.zeros((1, 3))}), EnvArgumentError, "positions"),
    (
        "reset option nan",
        options(lambda e: {"velocities": np.full_like(nominal_states(e), np.nan)}),
        EnvArgumentError,
        "velocities",
    ),
    (
        "reset options differ",
        options(lambda e: [{"positions": nominal_states(e)}] + [{}] * (e.num_envs - 1)),
        EnvArgumentError,
        "same options",
    ),
    ("actions shape", lambda e: e.step_async(np.zeros((e.num_envs + 1, 3))), EnvArgumentError, "actions"),
    ("actions 1-D", lambda e: e.step_async(np.zeros(e.num_envs * 3)), EnvArgumentError, "actions"),
    ("actions nan", lambda e: e.step_async(np.full(action_shape(e), np.nan)), EnvArgumentError, "actions"),
    ("actions inf", lambda e: e.step_async(np.full(action_shape(e), -np.inf)), EnvArgumentError, "actions"),
    ("actions bool", lambda e: e.step_async(np.ones(action_shape(e), bool)), EnvArgumentError, "actions"),
    ("actions complex", lambda e: e.step_async(np.ones(action_shape(e), complex)), EnvArgumentError, "actions"),
    ("actions str", lambda e: e.step_async("zeros"), EnvArgumentError, "actions"),
    ("actions None", lambda e: e.step_async(None), EnvArgumentError, "actions"),
    ("step_wait first", lambda e: e.step_wait(), RuntimeError, "step_async"),
    ("step_async twice", pending, RuntimeError, "step_wait"),
    ("reset after close", closed(lambda e: e.reset()), RuntimeError, "closed"),
    ("step after close", closed(lambda e: e.step(np.zeros(action_shape(e)))), RuntimeError, "closed"),
    ("get_attr after close", closed(lambda e: e.get_attr("task")), RuntimeError, "closed"),
    ("set_attr after close", closed(lambda e: e.set_attr("max_episode_steps", 5)), RuntimeError, "closed"),
    ("env_method after close", closed(lambda e: e.env_method("set_difficulty", 0.5)), RuntimeError, "closed"),
    ("seed after close", closed(lambda e: e.seed(0)), RuntimeError, "closed"),
    # Every call but close, the rendering ones too (they warn and return nothing while open).
    ("set_options after close", closed(lambda e: e.set_options({})), RuntimeError, "closed"),
    ("env_is_wrapped after close", closed(lambda e: e.env_is_wrapped(gym.Wrapper)), RuntimeError, "closed"),
    ("render after close", closed(lambda e: e.render()), RuntimeError, "closed"),
    ("get_images after close", closed(lambda e: e.get_images()), RuntimeError, "closed"),
]


@pytest.fixture(scope="module")
def adapters() -> dict[str, BatchVecEnv]:
    """One of each, reset: the refusals below must leave them usable (a refused call changes nothing)."""
    made = {name: make() for name, make in ADAPTERS.items()}
    for env in made.values():
        env.reset()
    return made


@pytest.mark.parametrize("adapter", list(ADAPTERS))
@pytest.mark.parametrize(("case", "call", "error", "names"), BAD, ids=[case for case, *_ in BAD])
def test_both_adapters_refuse_the_same_input(
    adapter: str, case: str, call: Callable[[BatchVecEnv], Any], error: type[BaseException], names: str
) -> None:
    env = ADAPTERS[adapter]()
    env.reset()
    limit, difficulty = env.get_attr("max_episode_steps")[0], env.get_attr("task", indices=0)[0].difficulty
    with pytest.raises(error) as caught:
        call(env)
    assert type(caught.value) is error, f"{case}: {type(caught.value).__name__}: {caught.value}"
    assert names in str(caught.value), f"{case}: the message does not name {names!r}: {caught.value}"
    if "close" not in case:  # what the refused call would have changed is as it was
        assert env.get_attr("max_episode_steps") == [limit] * env.num_envs
        assert env.get_attr("task", indices=0)[0].difficulty == difficulty


@pytest.mark.parametrize("adapter", list(ADAPTERS))
def test_both_adapters_accept_the_same_input(adapter: str) -> None:
    env = ADAPTERS[adapter]()
    env.reset()
    everyone = list(range(env.num_envs))
    env.set_attr("max_episode_steps", 3, indices=everyone)
    assert env.get_attr("max_episode_steps", indices=np.array([0, 1])) == [3, 3]
    env.set_attr("max_episode_steps", np.int64(4))
    assert env.get_attr("max_episode_steps", indices=range(2)) == [4, 4]
    assert env.env_method("set_difficulty", 0.5, indices=[]) == []
    assert env.env_method("set_difficulty", difficulty=0.5, indices=1) == [None]
    assert env.get_attr("task", indices=0)[0].difficulty == 0.5
    assert env.has_attr("task") and not env.has_attr("no_such_attribute") and not env.has_attr("_seeds")
    # One row's spaces, as SB3's get_attr gives a sub-env's.
    assert env.get_attr("observation_space", indices=0) == [env.observation_space]
    assert env.get_attr("action_space", indices=[1]) == [env.action_space]
    # Out-of-bounds actions are clipped by the env, as the single-agent env clips them: accepted by both.
    _, rewards, dones, _ = env.step(np.full(action_shape(env), 50.0, dtype=np.float32))
    assert np.isfinite(rewards).all() and rewards.dtype == np.float32 and not dones.any()
    env.step(np.zeros(action_shape(env), dtype=np.int64))  # integer commands are numbers
    env.set_attr("max_episode_steps", None)  # no limit
    assert env.get_attr("max_episode_steps") == [None] * env.num_envs
    # Exact initial states through the reset options: the nominal shape at rest.
    nominal = nominal_states(env)
    env.set_options({"positions": nominal, "velocities": np.zeros_like(nominal)})
    env.reset()
    task = env.get_attr("task", indices=0)[0]
    np.testing.assert_array_equal(task.sim.velocities, 0.0)
    assert env.seed(7)[0] == 7
    env.close()


def test_one_implementation_of_the_contract() -> None:
    """Both adapters run BatchVecEnv's checks: neither overrides a method of the contract."""
    contract = [
        "seed",
        "set_options",
        "reset",
        "step_async",
        "step_wait",
        "get_attr",
        "set_attr",
        "env_method",
        "env_is_wrapped",
        "_get_indices",
        "render",
        "get_images",
        "close",
    ]
    for adapter in (SB3VecEnv, AgentVecEnv):
        assert issubclass(adapter, BatchVecEnv)
        overridden = [name for name in contract if name in vars(adapter)]
        assert not overridden, f"{adapter.__name__} overrides {overridden}"


# ------------------------------------------------------------------ the property: same verdicts
#: The names the adapters take come up often, so that accepted calls are fuzzed too.
USED = st.sampled_from(["max_episode_steps", "set_difficulty"])
NAMES = st.one_of(
    USED,
    USED,
    st.sampled_from(
        [
            "max_episode_steps",
            "task",
            "num_envs",
            "render_mode",
            "cluster",
            "set_difficulty",
            "reset",
            "step",
            "close",
            "_seeds",
            "_actions",
            "__dict__",
            "",
            "max_episode_steps ",
        ]
    ),
    st.text(max_size=6),
    st.integers(-2, 2),
    st.none(),
)
VALUES = st.one_of(
    st.integers(1, 100),
    st.floats(0, 1),
    st.integers(-3, 2**63),
    st.floats(allow_nan=True, allow_infinity=True),
    st.booleans(),
    st.none(),
    st.text(max_size=3),
    st.lists(st.integers(0, 3), max_size=3),
)
#: Rows valid for both adapters (0, 1: SB3VecEnv has 2 rows, AgentVecEnv 6) or for neither.
ROWS = st.sampled_from([-2, -1, 0, 1, 6, 7, 100])
#: ``ALL_ROWS`` stands for every row of the adapter at hand; a drawn list never holds both 0 and
#: 1, which would be every row of one adapter and only some of the other's.
ALL_ROWS = "every row"
INDICES = st.one_of(
    st.none(),
    st.none(),
    st.just(ALL_ROWS),
    ROWS,
    st.lists(ROWS, max_size=3).filter(lambda rows: not {0, 1} <= set(rows)),
    st.floats(-1, 3),
    st.booleans(),
    st.text(max_size=2),
    st.just(np.array([True, False])),
)


def verdict(call: Callable[[], Any]) -> str:
    """``"accepted"`` or the name of the exception type; anything but a clear refusal fails."""
    try:
        call()
    except (EnvArgumentError, AttributeError, TypeError, RuntimeError) as error:
        assert str(error), "an error without a message"
        return type(error).__name__
    return "accepted"


ACTION_FORMS = st.sampled_from(["right", "right", "right", "list", "extra row", "flat", "scalar", "no rows"])
ELEMENTS = st.one_of(st.floats(-60, 60), st.floats(-1, 1), st.sampled_from([math.nan, math.inf, -math.inf, 1e300]))


def actions_for(env: BatchVecEnv, form: str, value: float, dtype: Any) -> Any:
    shape = action_shape(env)
    if form == "extra row":
        shape = (shape[0] + 1, *shape[1:])
    elif form == "flat":
        shape = (int(np.prod(shape)),)
    elif form == "scalar":
        return value
    elif form == "no rows":
        shape = (0, *shape[1:])
    array = np.full(shape, value, dtype=dtype) if np.isfinite(value) or dtype != np.int64 else np.zeros(shape, dtype)
    return array.tolist() if form == "list" else array


@pytest.mark.slow
@settings(max_examples=500, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    call=st.sampled_from(["set_attr", "get_attr", "env_method", "seed", "step"]),
    name=NAMES,
    value=VALUES,
    indices=INDICES,
    form=ACTION_FORMS,
    element=ELEMENTS,
    dtype=st.sampled_from([np.float32, np.float32, np.float64, np.int64, np.bool_, np.complex64]),
)
def test_both_adapters_give_the_same_verdict(
    adapters: dict[str, BatchVecEnv],
    call: str,
    name: Any,
    value: Any,
    indices: Any,
    form: str,
    element: float,
    dtype: Any,
) -> None:
    verdicts = {}
    drawn = indices
    for adapter, env in adapters.items():
        indices = list(range(env.num_envs)) if drawn is ALL_ROWS else drawn
        env.set_attr("max_episode_steps", 50)
        task = env.get_attr("task", indices=0)[0]
        before = (env.get_attr("max_episode_steps", indices=0), task.difficulty, task.sim.time.copy(), list(env._seeds))
        if call == "set_attr":
            verdicts[adapter] = verdict(lambda env=env, rows=indices: env.set_attr(name, value, indices=rows))
        elif call == "get_attr":
            verdicts[adapter] = verdict(lambda env=env, rows=indices: env.get_attr(name, indices=rows))
        elif call == "env_method":
            verdicts[adapter] = verdict(lambda env=env, rows=indices: env.env_method(name, value, indices=rows))
        elif call == "seed":
            verdicts[adapter] = verdict(lambda env=env: env.seed(value))
        else:
            with np.errstate(invalid="ignore", over="ignore"):
                actions = actions_for(env, form, element, dtype)
            verdicts[adapter] = verdict(lambda env=env, actions=actions: env.step(actions))
        if verdicts[adapter] != "accepted":  # a refused call changed nothing
            after = (env.get_attr("max_episode_steps", indices=0), task.difficulty, task.sim.time, env._seeds)
            assert after[:2] == before[:2] and after[3] == before[3], f"{call}: {before} -> {after}"
            np.testing.assert_array_equal(after[2], before[2])
        env.env_method("set_difficulty", 1.0)
    assert len(set(verdicts.values())) == 1, f"{call}({name!r}, {value!r}, indices={drawn!r}): {verdicts}"
    event(f"{call}: {verdicts['SB3VecEnv']}")


# ------------------------------------------------------------------ every batch surface, made the same way
def _parallel(num_envs: int = 1, **kwargs: Any) -> Any:
    from tether_gym.multiagent import parallel_env

    return parallel_env(ENV_ID, **kwargs)


SURFACES: dict[str, Callable[..., Any]] = {
    "gym.make_vec": lambda num_envs=2, **kwargs: gym.make_vec(ENV_ID, num_envs=num_envs, **kwargs),
    "make_sb3_vec_env": lambda num_envs=2, **kwargs: make_sb3_vec_env(ENV_ID, num_envs, **kwargs),
    "make_agent_vec_env": lambda num_envs=2, **kwargs: make_agent_vec_env(ENV_ID, num_envs, **kwargs),
    "parallel_env": _parallel,
}
#: Arguments every batch surface refuses by name, with the same check.
BAD_MAKE = [
    {"max_episode_steps": 0},
    {"max_episode_steps": -2},
    {"max_episode_steps": 2.5},
    {"max_episode_steps": True},
    {"max_episode_steps": "5"},
    {"max_episode_steps": 2**70},
    {"num_envs": 0},
    {"num_envs": 2.0},
    {"num_envs": True},
    {"num_envs": 10**9},
    {"render_mode": "rgb_array"},
]


#: The PettingZoo env is one cluster: it has no num_envs.
MAKE_CASES = [
    (surface, kwargs)
    for surface in SURFACES
    for kwargs in BAD_MAKE
    if surface != "parallel_env" or "num_envs" not in kwargs
]


@pytest.mark.parametrize(("surface", "kwargs"), MAKE_CASES, ids=[f"{s}-{k}" for s, k in MAKE_CASES])
def test_every_batch_surface_refuses_the_same_arguments(surface: str, kwargs: dict[str, Any]) -> None:
    with pytest.raises(EnvArgumentError) as caught:
        SURFACES[surface](**kwargs)
    (name,) = kwargs
    assert f"{name} must be" in str(caught.value)


@pytest.mark.parametrize("surface", list(SURFACES))
def test_minus_one_is_no_episode_limit_everywhere(surface: str) -> None:
    """``max_episode_steps=-1`` is ``gym.make``'s "no limit"; every batch surface reads it so."""
    env = SURFACES[surface](max_episode_steps=-1)
    limit = env.get_attr("max_episode_steps")[0] if isinstance(env, BatchVecEnv) else env.max_episode_steps
    assert limit is None


@pytest.mark.parametrize("kwargs", BAD_MAKE[:-1], ids=[str(k) for k in BAD_MAKE[:-1]])
def test_one_check_gives_one_message(kwargs: dict[str, Any]) -> None:
    """The surfaces do not only refuse alike: one check refuses, so the message is the same."""
    messages = set()
    for surface, _ in (case for case in MAKE_CASES if case[1] is kwargs):
        with pytest.raises(EnvArgumentError) as caught:
            SURFACES[surface](**kwargs)
        messages.add(str(caught.value))
    assert len(messages) == 1, messages


def test_the_engine_checks_its_own_seeds() -> None:
    """AgentBatch.reset, the public engine under both multi-agent surfaces, checks its seeds
    before it changes a generator, as the envs above it do."""
    from tether_gym.multiagent import AgentBatch, env_arguments

    kwargs, steps = env_arguments(ENV_ID)
    batch = AgentBatch(2, kwargs, steps)
    batch.reset(np.arange(2), [0, 1])
    states = [rng.bit_generator.state for rng in batch.rngs]
    for seeds, message in (([0, -1], r"seed\[1\] must be"), ([0, 1.5], r"seed\[1\] must be"), ([0], "one seed")):
        with pytest.raises(EnvArgumentError, match=message):
            batch.reset(np.arange(2), seeds)
        assert [rng.bit_generator.state for rng in batch.rngs] == states
    with pytest.raises(EnvArgumentError, match="seed must be"):
        batch.reset(np.arange(1), [True])


def test_local_sensors_check_what_the_engine_checks() -> None:
    """LocalSensors, made directly over a single-agent vector env's task (the decentralised
    controllers do), refuses what AgentBatch refuses, with the same messages."""
    from tether_gym.multiagent import LocalSensors, parallel_env

    task = gym.make_vec(ENV_ID, num_envs=2).unwrapped.task
    for kwargs in ({"communication": {"hops": 0}}, {"communication": 3}, {"local_observation_noise": -1.0}):
        with pytest.raises(EnvArgumentError) as direct:
            LocalSensors(task, **kwargs)
        with pytest.raises(EnvArgumentError) as engine:
            parallel_env(ENV_ID, **kwargs)
        assert str(direct.value) == str(engine.value)
    assert LocalSensors(task, {"hops": 1}).layout == parallel_env(ENV_ID, communication={"hops": 1}).layout


def test_reset_options_give_both_adapters_the_same_clusters() -> None:
    """The same exact initial state through set_options puts the same bits in both batches, and
    AgentVecEnv reports each row's reset info as SB3VecEnv reports each sub-env's."""
    envs = {name: make() for name, make in ADAPTERS.items()}
    nominal = nominal_states(envs["SB3VecEnv"])
    offsets = np.random.default_rng(0).normal(0.0, 0.05, nominal.shape)
    for env in envs.values():
        env.seed(3)
        env.set_options({"positions": nominal + offsets, "velocities": 0.01 * offsets})
        env.reset()
    single, multi = (env.get_attr("task", indices=0)[0].sim for env in envs.values())
    np.testing.assert_array_equal(single.positions, multi.positions)
    np.testing.assert_array_equal(single.velocities, multi.velocities)
    agents = envs["AgentVecEnv"].num_envs // CLUSTERS
    for row, info in enumerate(envs["AgentVecEnv"].reset_infos):
        expected = envs["SB3VecEnv"].reset_infos[row // agents]
        assert info.keys() == expected.keys() and info["vibration_energy"] == expected["vibration_energy"]


@pytest.mark.parametrize("adapter", list(ADAPTERS))
def test_refused_reset_options_say_how_to_drop_them(adapter: str) -> None:
    env = ADAPTERS[adapter]()
    env.reset()
    nominal = nominal_states(env)
    env.set_options({"positions": np.full_like(nominal, np.nan)})
    for _ in range(2):  # they stay scheduled, so a second reset is refused the same way
        with pytest.raises(EnvArgumentError, match=r"stay scheduled: .*set_options\(None\) to drop them"):
            env.reset()
    env.set_options(None)
    observations = env.reset()
    assert np.isfinite(observations).all()
    env.close()
