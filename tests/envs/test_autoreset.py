"""The native vector env's two autoreset modes: each equal to N single envs to the bit, next-step
equal to Gymnasium's own SyncVectorEnv, the mode chosen through gym.make_vec and checked."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode, SyncVectorEnv

from tether_gym.envs import EnvArgumentError, TetherClusterVectorEnv
from tether_gym.sb3 import SB3VecEnv

from .test_vector_env import FAULTY as FAULTY_CASE

#: Short episodes (many truncations), observation noise and randomised masses (each sub-env's
#: generator must draw exactly as a single env's does around every reset).
NOISY = dict(max_episode_steps=7, observation_noise=0.01, randomize={"masses": 0.1}, max_deviation=1.0)
#: test_vector_env's faulty case (every disturbance and fault, cables that break), with shorter
#: episodes, faults early and a tight deviation limit: truncations and terminations.
FAULTY = dict(FAULTY_CASE, max_episode_steps=9, thruster_failure_window=(0.1, 0.5), max_deviation=0.1)
CASES = [
    ("TetherTetrahedron-v0", 3, NOISY),
    ("TetherTetrahedron-v0", 20, NOISY),  # 20 uses the multi-threaded kernels
    ("TetherSpinningTriangle-v0", 6, FAULTY),
]
STEPS = 40


def _actions(rng: np.random.Generator, envs: gym.vector.VectorEnv) -> np.ndarray:
    return rng.uniform(-1, 1, envs.action_space.shape).astype(np.float32)


def _assert_info_row(infos: dict[str, Any], i: int, single_info: dict[str, Any]) -> None:
    """Sub-env i of the vector infos holds exactly ``single_info``'s keys and values."""
    present = {key for key in infos if not key.startswith(("_", "final_")) and infos["_" + key][i]}
    assert present == set(single_info), (i, present ^ set(single_info))
    for key, value in single_info.items():
        assert np.array_equal(infos[key][i], value), key


def _vector_and_singles(
    env_id: str, num_envs: int, kwargs: dict, mode: Any, expected: AutoresetMode
) -> tuple[gym.vector.VectorEnv, list[gym.Env]]:
    """The vector env in ``mode`` and N single envs, reset with seed 10 (sub-env i: 10 + i) and
    checked equal at the start."""
    envs = gym.make_vec(env_id, num_envs=num_envs, autoreset_mode=mode, **kwargs)
    assert envs.metadata["autoreset_mode"] is expected
    singles = [gym.make(env_id, **kwargs) for _ in range(num_envs)]
    obs, _ = envs.reset(seed=10)
    for i, env in enumerate(singles):
        assert np.array_equal(obs[i], env.reset(seed=10 + i)[0])
    return envs, singles


@pytest.mark.parametrize(("env_id", "num_envs", "kwargs"), CASES)
def test_same_step_equals_single_envs(env_id: str, num_envs: int, kwargs: dict) -> None:
    envs, singles = _vector_and_singles(env_id, num_envs, kwargs, "same_step", AutoresetMode.SAME_STEP)
    rng = np.random.default_rng(0)
    ended = 0
    for _ in range(STEPS):
        actions = _actions(rng, envs)
        obs, rewards, terminated, truncated, infos = envs.step(actions)
        for i, env in enumerate(singles):
            s_obs, s_reward, s_term, s_trunc, s_info = env.step(actions[i])
            assert (s_reward, s_term, s_trunc) == (rewards[i], terminated[i], truncated[i])
            if s_term or s_trunc:
                ended += 1
                assert np.array_equal(infos["final_obs"][i], s_obs)
                _assert_info_row(infos["final_info"], i, s_info)
                s_obs, s_info = env.reset()
            _assert_info_row(infos, i, s_info)
            assert np.array_equal(obs[i], s_obs)
    assert ended >= num_envs  # the loop went through episode ends


@pytest.mark.parametrize(("env_id", "num_envs", "kwargs"), CASES)
def test_next_step_equals_single_envs(env_id: str, num_envs: int, kwargs: dict) -> None:
    envs, singles = _vector_and_singles(env_id, num_envs, kwargs, AutoresetMode.NEXT_STEP, AutoresetMode.NEXT_STEP)
    rng = np.random.default_rng(0)
    ended_last = np.zeros(num_envs, dtype=bool)
    resets = terminations = 0
    for _ in range(STEPS):
        actions = _actions(rng, envs)
        obs, rewards, terminated, truncated, infos = envs.step(actions)
        assert "final_obs" not in infos and "final_info" not in infos
        for i, env in enumerate(singles):
            if ended_last[i]:  # the step after an end: the reset, whatever the action
                resets += 1
                s_obs, s_info = env.reset()
                s_reward, s_term, s_trunc = 0.0, False, False
            else:
                s_obs, s_reward, s_term, s_trunc, s_info = env.step(actions[i])
                terminations += s_term
            assert (s_reward, s_term, s_trunc) == (rewards[i], terminated[i], truncated[i])
            assert np.array_equal(obs[i], s_obs)
            _assert_info_row(infos, i, s_info)
        ended_last = terminated | truncated
    assert resets >= num_envs
    if kwargs is FAULTY:
        assert terminations > 0  # the case covers terminations, not only truncations


@pytest.mark.parametrize(("env_id", "num_envs", "kwargs"), CASES)
def test_next_step_equals_gymnasium_sync_vector_env(env_id: str, num_envs: int, kwargs: dict) -> None:
    """Gymnasium's SyncVectorEnv over the same single envs, in its next-step mode: the same
    observations, rewards and flags to the bit (dtypes too), and the same infos."""
    ours = gym.make_vec(
        env_id, num_envs=num_envs, vectorization_mode="vector_entry_point", autoreset_mode="NextStep", **kwargs
    )
    theirs = SyncVectorEnv(
        [lambda: gym.make(env_id, **kwargs) for _ in range(num_envs)], autoreset_mode=AutoresetMode.NEXT_STEP
    )
    assert ours.metadata["autoreset_mode"] == theirs.metadata["autoreset_mode"]
    obs, _ = ours.reset(seed=3)
    ref_obs, _ = theirs.reset(seed=3)
    assert np.array_equal(obs, ref_obs)
    rng = np.random.default_rng(1)
    ends = 0
    for _ in range(STEPS):
        actions = _actions(rng, ours)
        result, reference = ours.step(actions), theirs.step(actions)
        for mine, ref in zip(result[:4], reference[:4], strict=True):
            assert mine.dtype == ref.dtype and np.array_equal(mine, ref)
        infos, ref_infos = result[4], reference[4]
        assert set(infos) == set(ref_infos)
        for key in (k for k in ref_infos if not k.startswith("_")):
            mask = ref_infos["_" + key]
            assert np.array_equal(infos["_" + key], mask), key
            assert np.array_equal(infos[key][mask], ref_infos[key][mask]), key
        ends += int(np.sum(result[2] | result[3]))
    assert ends >= num_envs


def test_reset_clears_a_pending_autoreset() -> None:
    envs = gym.make_vec("TetherTetrahedron-v0", num_envs=2, autoreset_mode="next_step", max_episode_steps=1)
    envs.reset(seed=0)
    _, _, _, truncated, _ = envs.step(np.zeros(envs.action_space.shape, np.float32))
    assert truncated.all()
    envs.reset(seed=0)
    # A real step (not an autoreset): it ends the one-step episodes again.
    _, rewards, _, truncated, infos = envs.step(np.zeros(envs.action_space.shape, np.float32))
    assert truncated.all() and infos["_substeps"].all() and np.all(rewards != 0.0)


def test_modes_are_per_instance_and_parsed() -> None:
    same_step = gym.make_vec("TetherHub-v0", num_envs=2, autoreset_mode="SAME_STEP")
    default = gym.make_vec("TetherHub-v0", num_envs=2)
    assert same_step.metadata["autoreset_mode"] is AutoresetMode.SAME_STEP
    # Gymnasium's own default, which its vector wrappers assume.
    assert default.metadata["autoreset_mode"] is AutoresetMode.NEXT_STEP
    assert TetherClusterVectorEnv.metadata["autoreset_mode"] is AutoresetMode.NEXT_STEP
    for spelling in ("NextStep", "nextstep", "next_step", AutoresetMode.NEXT_STEP):
        assert TetherClusterVectorEnv(1, autoreset_mode=spelling).metadata["autoreset_mode"] is AutoresetMode.NEXT_STEP
    for spelling in ("SameStep", "same_step", AutoresetMode.SAME_STEP):
        assert TetherClusterVectorEnv(1, autoreset_mode=spelling).metadata["autoreset_mode"] is AutoresetMode.SAME_STEP


@pytest.mark.parametrize(
    ("mode", "message"),
    [
        ("bogus", "autoreset_mode must be"),
        (1, "autoreset_mode must be"),
        (None, "autoreset_mode must be"),
        (AutoresetMode.DISABLED, "DISABLED is not supported"),
        ("Disabled", "DISABLED is not supported"),
    ],
)
def test_bad_autoreset_mode(mode: Any, message: str) -> None:
    with pytest.raises(EnvArgumentError, match=message):
        gym.make_vec("TetherTetrahedron-v0", num_envs=2, autoreset_mode=mode)


def test_sb3_adapter_refuses_next_step() -> None:
    envs = gym.make_vec("TetherTetrahedron-v0", num_envs=2, autoreset_mode="next_step")
    with pytest.raises(ValueError, match="same-step autoreset"):
        SB3VecEnv(envs)
