"""Property-based fuzzing of the multi-agent surfaces against the single-agent env's contract.

* The PettingZoo env's per-agent commands: any mix of good and bad commands either is refused
  with an :class:`~tether_gym.envs.EnvArgumentError` naming the agent, leaving the env as it
  was, or steps exactly as the single-agent env steps on the joint action (same bits).
* The SB3 adapters' reset options: any options are accepted by both ``SB3VecEnv`` and
  ``AgentVecEnv`` or refused by both with the same error, and a refused reset changes nothing.
"""

from __future__ import annotations

import math
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

pytest.importorskip("pettingzoo")
pytest.importorskip("stable_baselines3")

from tether_gym.envs.arguments import EnvArgumentError  # noqa: E402
from tether_gym.multiagent import parallel_env  # noqa: E402
from tether_gym.multiagent.sb3 import make_agent_vec_env  # noqa: E402
from tether_gym.sb3 import make_sb3_vec_env  # noqa: E402

#: Property-based: the fast suite (-m 'not slow') leaves these out.
pytestmark = pytest.mark.slow

ENV_ID = "TetherTriangle-v0"
FUZZ = settings(max_examples=120, deadline=None, suppress_health_check=[HealthCheck.too_slow])

SPECIAL = st.sampled_from([math.nan, math.inf, -math.inf, 1e300, -0.0])
JUNK = st.sampled_from([None, "up", b"x", {"x": 1}, [1, "a", 2], [[0.0, 0.0, 0.0]], True, 1j])


def command() -> st.SearchStrategy[Any]:
    """A (3,) thrust command, mostly good (inside and outside [-1, 1], as floats or ints), or not."""
    good = hnp.arrays(
        st.sampled_from([np.float32, np.float64, np.int64]), (3,), elements=st.integers(-2, 2)
    ) | hnp.arrays(np.float64, (3,), elements=st.floats(-5, 5))
    bad = st.one_of(
        st.tuples(hnp.arrays(np.float64, (3,), elements=st.floats(-1, 1)), st.integers(0, 2), SPECIAL).map(
            lambda drawn: np.where(np.arange(3) == drawn[1], drawn[2], drawn[0])
        ),
        hnp.arrays(st.sampled_from([np.float64, np.bool_, np.complex128]), hnp.array_shapes(max_dims=2, max_side=4)),
        st.lists(st.floats(-1, 1), min_size=2, max_size=4),
        JUNK,
    )
    return st.one_of(good, good, good, bad)


def single_accepts(value: Any) -> bool:
    """Whether the single-agent env's action check takes ``value`` as one thruster's command."""
    from tether_gym.envs.arguments import check_actions

    try:
        check_actions("action", value, (3,), "x, y, z")
    except EnvArgumentError:
        return False
    return True


PARALLEL = parallel_env(ENV_ID)
SINGLE = gym.make(ENV_ID)


@FUZZ
@given(commands=st.lists(command(), min_size=3, max_size=3), seed=st.integers(0, 3))
def test_parallel_env_commands_are_the_single_envs(commands: list[Any], seed: int) -> None:
    env, single = PARALLEL, SINGLE
    env.reset(seed=seed)
    single.reset(seed=seed)
    actions = dict(zip(env.possible_agents, commands, strict=True))
    before = (env.state(), env.task.sim.positions.copy(), env.batch.episode_steps.copy(), env.task.sim.time.copy())
    try:
        _, rewards, terminated, truncated, _ = env.step(actions)
    except EnvArgumentError as error:
        refused = [name for name, value in actions.items() if not single_accepts(value)]
        assert refused, f"every command passes the single env's check, yet: {error}"
        assert refused[0] in str(error), f"the message does not name {refused[0]}: {error}"
        after = (env.state(), env.task.sim.positions, env.batch.episode_steps, env.task.sim.time)
        for a, b in zip(before, after, strict=True):
            np.testing.assert_array_equal(a, b)  # a refused step changes nothing
        event("refused")
        return
    event("stepped")
    assert all(single_accepts(value) for value in commands)
    joint = np.concatenate([np.asarray(value, dtype=np.float64) for value in commands])
    observation, reward, single_terminated, single_truncated, _ = single.step(joint)
    np.testing.assert_array_equal(env.state(), observation)
    assert set(rewards.values()) == {reward}
    assert set(terminated.values()) == {single_terminated}
    assert set(truncated.values()) <= {single_truncated, False}  # the single env's time limit is its wrapper's


ADAPTERS = {
    "SB3VecEnv": make_sb3_vec_env(ENV_ID, 2, seed=0),
    "AgentVecEnv": make_agent_vec_env(ENV_ID, 2, seed=0),
}
NOMINAL = np.stack([PARALLEL.cluster.positions] * 2)


def state_option() -> st.SearchStrategy[Any]:
    """(clusters, n, 3) states near the nominal shape, far off, NaN, the wrong shape, or junk."""
    near = hnp.arrays(np.float64, NOMINAL.shape, elements=st.floats(-0.5, 0.5)).map(lambda d: NOMINAL + d)
    return st.one_of(
        near,
        near.map(lambda x: x * 1e6),
        hnp.arrays(np.float64, NOMINAL.shape, elements=st.one_of(st.floats(-1, 1), SPECIAL)),
        hnp.arrays(np.float64, hnp.array_shapes(max_dims=3, max_side=3)),
        st.none(),
        JUNK,
    )


OPTIONS = st.one_of(
    st.fixed_dictionaries({}, optional={"positions": state_option(), "velocities": state_option()}),
    st.dictionaries(st.sampled_from(["positions", "bogus", "seed"]), state_option(), max_size=2),
    st.lists(st.fixed_dictionaries({}, optional={"positions": state_option()}), min_size=1, max_size=3),
    JUNK,
)


@FUZZ
@given(options=OPTIONS)
def test_adapters_take_the_same_reset_options(options: Any) -> None:
    verdicts, messages = {}, {}
    for name, env in ADAPTERS.items():
        rows = options
        if isinstance(options, list) and len(options) == 2:
            rows = options * (env.num_envs // 2)  # a list of one dict per row, for either adapter
        positions = env.get_attr("task", indices=0)[0].sim.positions.copy()
        try:
            env.set_options(rows)
            env.reset()
        except (EnvArgumentError, TypeError) as error:
            # The same check gives the same words, but for the adapter's name and its number of rows.
            text = str(error).replace(name, "ADAPTER").replace(f"list of {env.num_envs} dicts", "list of N dicts")
            verdicts[name], messages[name] = type(error).__name__, text
            np.testing.assert_array_equal(env.get_attr("task", indices=0)[0].sim.positions, positions)
            env.set_options(None)
            continue
        verdicts[name] = "accepted"
    event(verdicts["SB3VecEnv"])
    assert len(set(verdicts.values())) == 1, f"{options!r}: {verdicts} {messages}"
    assert len(set(messages.values())) <= 1, messages
