"""The native vector env: equal to N single envs, independent sub-envs, Gymnasium's vector API."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode

import tether_gym as tg
from tether_gym.envs import TetherClusterVectorEnv


def test_make_vec_returns_the_native_vector_env() -> None:
    envs = gym.make_vec("TetherHub-v0", num_envs=3, max_thrust=2.0)
    assert isinstance(envs.unwrapped, TetherClusterVectorEnv)
    assert envs.metadata["autoreset_mode"] == AutoresetMode.NEXT_STEP  # Gymnasium's default
    assert envs.max_episode_steps == 300 and envs.num_envs == 3
    assert envs.observation_space.shape == (3, 54) and envs.action_space.shape == (3, 21)
    assert np.all(envs.task.max_thrust == 2.0)


#: Every disturbance and fault at once, in a spinning frame, with cables weak enough to break.
FAULTY = dict(
    max_episode_steps=40,
    impulse_magnitude=2.0,
    impulse_rate=0.5,
    periodic_amplitude=0.3,
    thrust_noise=0.2,
    thrust_delay=2,
    thruster_failure_probability=0.7,
    thruster_failure_window=(0.5, 3.0),
    cable_failure="continue",
    preset_kwargs={"breaking_load": 8.0},
    randomize={"axial_damping": 0.3},
    difficulty=0.8,
    max_deviation=1.0,
)


@pytest.mark.parametrize(
    ("env_id", "num_envs", "kwargs"),
    [
        (
            "TetherTetrahedron-v0",
            3,
            dict(max_episode_steps=40, observation_noise=0.01, randomize={"masses": 0.1}, max_deviation=1.0),
        ),
        # 20 uses the multi-threaded kernels
        (
            "TetherTetrahedron-v0",
            20,
            dict(max_episode_steps=40, observation_noise=0.01, randomize={"masses": 0.1}, max_deviation=1.0),
        ),
        ("TetherSpinningTriangle-v0", 20, FAULTY),
        # 128 (LANE_MIN_BATCH) runs the lane kernels: the tetrahedra in SIMD lanes, the spinning
        # triangles (turning frames) through the lane driver's pairs
        (
            "TetherTetrahedron-v0",
            128,
            dict(max_episode_steps=40, observation_noise=0.01, randomize={"masses": 0.1}, max_deviation=1.0),
        ),
        ("TetherSpinningTriangle-v0", 128, FAULTY),
        # The hard track's ids on their own settings: passive satellites, a delay line across resets.
        *[(env_id, 3, dict(max_episode_steps=40)) for env_id in tg.HARD_TRACK],
    ],
)
def test_vector_env_equals_single_envs_across_autoresets(env_id: str, num_envs: int, kwargs: dict) -> None:
    envs = gym.make_vec(env_id, num_envs=num_envs, autoreset_mode="same_step", **kwargs)
    singles = [gym.make(env_id, **kwargs) for _ in range(num_envs)]
    obs, infos = envs.reset(seed=10)
    for i, env in enumerate(singles):
        single_obs, single_info = env.reset(seed=10 + i)
        assert np.array_equal(obs[i], single_obs)
        assert infos["vibration_energy"][i] == single_info["vibration_energy"]
    rng = np.random.default_rng(0)
    ended = 0
    for _ in range(100):
        actions = rng.uniform(-1, 1, envs.action_space.shape).astype(np.float32)
        obs, rewards, terminated, truncated, infos = envs.step(actions)
        for i, env in enumerate(singles):
            s_obs, s_reward, s_term, s_trunc, s_info = env.step(actions[i])
            assert (s_reward, s_term, s_trunc) == (rewards[i], terminated[i], truncated[i])
            if s_term or s_trunc:
                ended += 1
                assert infos["_final_obs"][i] and np.array_equal(infos["final_obs"][i], s_obs)
                final = infos["final_info"]
                for key, value in s_info.items():
                    assert final["_" + key][i]
                    assert np.array_equal(final[key][i], value), key
                s_obs, s_info = env.reset()
                assert not infos["_substeps"][i]  # a fresh episode's info has no step keys
            else:
                for key, value in s_info.items():
                    assert np.array_equal(infos[key][i], value), key
            assert np.array_equal(obs[i], s_obs)
            assert infos["vibration_energy"][i] == s_info["vibration_energy"]
    assert ended >= 2 * num_envs  # time limits and failures both exercised


def test_an_ending_sub_env_resets_alone() -> None:
    envs = TetherClusterVectorEnv(num_envs=4, max_episode_steps=None, autoreset_mode="same_step")
    stretched = np.stack([envs.cluster.positions] * 4)
    stretched[2] *= 1.04  # cables 4 m too long: 2 kN > 1.5 kN breaking load at once
    envs.reset(seed=0, options={"positions": stretched})
    reference = TetherClusterVectorEnv(num_envs=4, max_episode_steps=None, autoreset_mode="same_step")
    reference.reset(seed=0, options={"positions": np.stack([envs.cluster.positions] * 4)})
    actions = np.zeros((4, 12))
    obs, _, terminated, truncated, infos = envs.step(actions)
    ref_obs, *_ = reference.step(actions)
    assert terminated.tolist() == [False, False, True, False] and not truncated.any()
    assert infos["final_info"]["end_reason"][2] == "cable_broken"
    for i in (0, 1, 3):
        assert np.array_equal(obs[i], ref_obs[i])
    for _ in range(10):
        obs, *_ = envs.step(actions)
        ref_obs, *_ = reference.step(actions)
    assert np.array_equal(obs[[0, 1, 3]], ref_obs[[0, 1, 3]])


def test_gymnasium_vector_checks() -> None:
    from gymnasium.utils.env_checker import data_equivalence

    envs = gym.make_vec("TetherTriangle-v0", num_envs=5)
    obs, infos = envs.reset(seed=1)
    assert envs.observation_space.contains(obs)
    assert obs.dtype == np.float32
    same, _ = envs.reset(seed=1)
    assert data_equivalence(obs, same)
    actions = envs.action_space.sample()
    obs, rewards, terminated, truncated, infos = envs.step(actions)
    assert envs.observation_space.contains(obs)
    assert rewards.shape == (5,) and rewards.dtype == np.float64
    assert terminated.dtype == np.bool_ and truncated.dtype == np.bool_
    for key in [k for k in infos if not k.startswith("_")]:
        assert infos[key].shape[0] == 5 and infos["_" + key].all()


def test_vector_env_errors() -> None:
    envs = TetherClusterVectorEnv(num_envs=2)
    envs.reset(seed=0)
    with pytest.raises(ValueError, match=r"actions must have shape \(2, 12\)"):
        envs.step(np.zeros((3, 12)))
    with pytest.raises(ValueError, match="actions contain NaN or inf"):
        envs.step(np.full((2, 12), np.inf))
    with pytest.raises(ValueError, match="list of 2 seeds"):
        envs.reset(seed=[1, 2, 3])
    with pytest.raises(ValueError, match=r"unknown reset option\(s\) \['mask'\]"):
        envs.reset(options={"mask": 1})
    with pytest.raises(ValueError, match="num_envs must be a whole number"):
        TetherClusterVectorEnv(num_envs=0)
    with pytest.raises(tg.ClusterError, match="unknown preset"):
        TetherClusterVectorEnv(num_envs=2, preset="blob")
