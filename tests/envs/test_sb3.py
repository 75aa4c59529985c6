"""The Stable-Baselines3 adapter (tether_gym.sb3): VecEnv contract, SB3 wrappers, PPO smoke run."""

from __future__ import annotations

import pickle
import warnings

import gymnasium as gym
import numpy as np
import pytest

pytest.importorskip("stable_baselines3")
pytest.importorskip("torch")

from gymnasium.vector import AutoresetMode, SyncVectorEnv  # noqa: E402
from stable_baselines3 import PPO  # noqa: E402
from stable_baselines3.common.monitor import Monitor  # noqa: E402
from stable_baselines3.common.vec_env import VecEnv, VecMonitor, VecNormalize  # noqa: E402

import tether_gym as tg  # noqa: E402
from tether_gym.envs import TetherClusterVectorEnv  # noqa: E402
from tether_gym.sb3 import SB3VecEnv, make_sb3_vec_env  # noqa: E402

ENV_ID = tg.DEFAULT_ENV_ID
OBS_SIZE = 30  # tetrahedron: 6 * 4 satellites + 6 cables
ACT_SIZE = 12  # 4 thrusters * 3 axes
#: With this max_deviation (m) and seed 0, the 8 sub-envs fail at different steps within 10 steps and
#: two reach the 10-step limit: a mix of terminations and truncations, ending at different times.
MIXED = dict(max_episode_steps=10, max_deviation=0.3)


def actions(num_envs: int, steps: int, seed: int = 0) -> np.ndarray:
    return np.random.default_rng(seed).uniform(-1, 1, (steps, num_envs, ACT_SIZE)).astype(np.float32)


# ---------------------------------------------------------------------------------------- contract
def test_adapter_is_an_sb3_vecenv_with_single_spaces() -> None:
    env = make_sb3_vec_env(ENV_ID, 4, seed=0)
    assert isinstance(env, VecEnv) and isinstance(env.venv, TetherClusterVectorEnv)
    assert env.num_envs == 4
    assert env.observation_space == env.venv.single_observation_space
    assert env.observation_space.shape == (OBS_SIZE,)
    assert env.action_space == env.venv.single_action_space
    assert env.action_space.shape == (ACT_SIZE,)
    assert env.metadata["autoreset_mode"] is AutoresetMode.SAME_STEP
    env.close()


def test_reset_and_step_shapes_dtypes_and_infos() -> None:
    env = make_sb3_vec_env(ENV_ID, 4, seed=0, max_episode_steps=5)
    obs = env.reset()
    assert isinstance(obs, np.ndarray) and obs.shape == (4, OBS_SIZE) and obs.dtype == np.float32
    assert len(env.reset_infos) == 4
    for info in env.reset_infos:
        assert isinstance(info["vibration_energy"], float) and info["vibration_energy"] > 0
        assert info["time"] == 0.0
        assert "end_reason" not in info  # a reset's info has no per-step keys
        assert "tensions" not in info  # array entries are left out
    for step, action in enumerate(actions(4, 5), start=1):
        obs, rewards, dones, infos = env.step(action)
        assert obs.shape == (4, OBS_SIZE) and obs.dtype == np.float32
        assert rewards.shape == (4,) and rewards.dtype == np.float32
        assert dones.shape == (4,) and dones.dtype == np.bool_
        assert isinstance(infos, list) and len(infos) == 4 and all(isinstance(i, dict) for i in infos)
        if step < 5:
            assert not dones.any()
            assert infos == [{}, {}, {}, {}]  # non-ended sub-envs get empty dicts (cheap steps)
    # step 5: the time limit ends every sub-env
    assert dones.all()
    for i, info in enumerate(infos):
        terminal = info["terminal_observation"]
        assert terminal.shape == (OBS_SIZE,) and terminal.dtype == np.float32
        assert not np.array_equal(terminal, obs[i])  # obs is the new episode's first observation
        assert info["TimeLimit.truncated"] is True
        assert info["end_reason"] == "running"
        assert isinstance(info["propellant_used"], float) and info["propellant_used"] > 0
        assert isinstance(info["vibration_energy"], float)
        assert isinstance(info["substeps"], int)
        assert info["time"] == pytest.approx(0.5)
        assert "tensions" not in info and "thrust" not in info
    # reset_infos were refreshed by the autoreset: the new episodes' reset infos only
    assert [info["time"] for info in env.reset_infos] == [0.0] * 4
    for info in env.reset_infos:
        assert "final_info" not in info and "end_reason" not in info and "terminal_observation" not in info
    env.close()


def test_terminal_observation_exactly_for_ended_envs() -> None:
    env = make_sb3_vec_env(ENV_ID, 8, seed=0, **MIXED)
    raw = gym.make_vec(ENV_ID, num_envs=8, autoreset_mode="same_step", **MIXED)
    env.reset()
    raw.reset(seed=0)
    zero = np.zeros((8, ACT_SIZE), np.float32)
    seen_terminated = seen_truncated = 0
    ended_steps = set()
    for step in range(12):
        obs, rewards, dones, infos = env.step(zero)
        _, _, terminated, truncated, raw_infos = raw.step(zero)
        np.testing.assert_array_equal(dones, terminated | truncated)
        for i, info in enumerate(infos):
            assert ("terminal_observation" in info) == bool(dones[i])
            assert ("TimeLimit.truncated" in info) == bool(dones[i])
            if dones[i]:
                ended_steps.add(step)
                np.testing.assert_array_equal(info["terminal_observation"], raw_infos["final_obs"][i])
                assert info["TimeLimit.truncated"] == bool(truncated[i] and not terminated[i])
                assert info["end_reason"] == raw_infos["final_info"]["end_reason"][i]
                if terminated[i]:
                    seen_terminated += 1
                    assert info["end_reason"] == "formation_lost"
                else:
                    seen_truncated += 1
                    assert info["end_reason"] == "running"
            else:
                assert info == {}
    assert seen_terminated > 0 and seen_truncated > 0 and len(ended_steps) > 2
    env.close()


def test_failure_on_the_last_step_is_not_a_time_limit_truncation() -> None:
    # seed 0, max_deviation 0.3: sub-env 3 loses the formation on step 4, the time limit's step
    env = make_sb3_vec_env(ENV_ID, 8, seed=0, max_episode_steps=4, max_deviation=0.3)
    raw = gym.make_vec(ENV_ID, num_envs=8, autoreset_mode="same_step", max_episode_steps=4, max_deviation=0.3)
    env.reset()
    raw.reset(seed=0)
    zero = np.zeros((8, ACT_SIZE), np.float32)
    for _ in range(4):
        _, _, dones, infos = env.step(zero)
        _, _, terminated, truncated, _ = raw.step(zero)
    assert dones.all() and truncated.all() and terminated.any() and not terminated.all()
    for i, info in enumerate(infos):
        assert info["TimeLimit.truncated"] is (not terminated[i])
        assert (info["end_reason"] == "formation_lost") is bool(terminated[i])


def test_trajectories_equal_the_raw_vector_env() -> None:
    env = make_sb3_vec_env(ENV_ID, 6, seed=11, max_episode_steps=4)
    raw = gym.make_vec(ENV_ID, num_envs=6, autoreset_mode="same_step", max_episode_steps=4)
    obs = env.reset()
    raw_obs, raw_infos = raw.reset(seed=11)
    np.testing.assert_array_equal(obs, raw_obs)
    for i in range(6):
        assert env.reset_infos[i]["vibration_energy"] == raw_infos["vibration_energy"][i]
    for action in actions(6, 10, seed=3):
        obs, rewards, dones, infos = env.step(action)
        raw_obs, raw_rewards, terminated, truncated, raw_infos = raw.step(action)
        np.testing.assert_array_equal(obs, raw_obs)
        np.testing.assert_array_equal(rewards, raw_rewards.astype(np.float32))
        np.testing.assert_array_equal(dones, terminated | truncated)
        assert env.vector_infos is not None and env.vector_infos.keys() == raw_infos.keys()
        for i in np.flatnonzero(dones):
            np.testing.assert_array_equal(infos[i]["terminal_observation"], raw_infos["final_obs"][i])
            assert infos[i]["vibration_energy"] == raw_infos["final_info"]["vibration_energy"][i]
            assert env.reset_infos[i]["vibration_energy"] == raw_infos["vibration_energy"][i]
    env.close()


def rollout(env: SB3VecEnv, steps: int = 20) -> tuple[np.ndarray, np.ndarray]:
    observations, rewards = [env.reset()], []
    for action in actions(env.num_envs, steps, seed=5):
        obs, reward, _, _ = env.step(action)
        observations.append(obs)
        rewards.append(reward)
    return np.array(observations), np.array(rewards)


def test_seeding_is_reproducible() -> None:
    a = make_sb3_vec_env(ENV_ID, 3, seed=42, max_episode_steps=8)
    b = make_sb3_vec_env(ENV_ID, 3, seed=42, max_episode_steps=8)
    obs_a, rew_a = rollout(a)
    obs_b, rew_b = rollout(b)
    np.testing.assert_array_equal(obs_a, obs_b)
    np.testing.assert_array_equal(rew_a, rew_b)
    # another seed gives other episodes; sub-envs differ from each other (seed + i)
    obs_c, _ = rollout(make_sb3_vec_env(ENV_ID, 3, seed=43, max_episode_steps=8))
    assert not np.array_equal(obs_a[0], obs_c[0])
    assert not np.array_equal(obs_a[0, 0], obs_a[0, 1])
    # sub-env i gets seed + i: seed 43's sub-env 0 is seed 42's sub-env 1
    np.testing.assert_array_equal(obs_c[0, 0], obs_a[0, 1])
    # seed() returns the scheduled seeds; they are used by one reset only
    assert a.seed(42) == [42, 43, 44]
    first = a.reset()
    np.testing.assert_array_equal(first, obs_a[0])
    assert a._seeds == [None, None, None]
    assert not np.array_equal(a.reset(), first)  # generators continue
    # seed(None) draws a random base seed
    seeds = a.seed()
    assert len(seeds) == 3 and seeds[1] == seeds[0] + 1


def test_reset_options_batch_level() -> None:
    env = make_sb3_vec_env(ENV_ID, 2, seed=0)
    nominal = env.venv.cluster.positions
    positions = np.stack([nominal, nominal])  # (N, n, 3)
    env.set_options({"positions": positions, "velocities": np.zeros_like(positions)})
    obs = env.reset()
    np.testing.assert_allclose(obs[:, :24], 0.0, atol=1e-6)  # no displacement, no velocity
    assert env._options == [{}, {}]  # used once
    assert np.abs(env.reset()[:, :24]).max() > 1e-3
    env.set_options([{"positions": positions}, {}])
    with pytest.raises(ValueError, match="same options for every row"):
        env.reset()


def test_step_wait_without_step_async() -> None:
    env = make_sb3_vec_env(ENV_ID, 2, seed=0)
    env.reset()
    with pytest.raises(RuntimeError, match="step_async"):
        env.step_wait()


# ---------------------------------------------------------------------------------------- wrappers
def test_vec_monitor_reports_episodes() -> None:
    env = VecMonitor(make_sb3_vec_env(ENV_ID, 3, seed=0, max_episode_steps=5))
    env.reset()
    total = np.zeros(3)
    for action in actions(3, 5):
        _, rewards, dones, infos = env.step(action)
        total += rewards
    assert dones.all()
    for i, info in enumerate(infos):
        assert info["episode"]["l"] == 5
        assert info["episode"]["r"] == pytest.approx(total[i], rel=1e-5)
        assert "terminal_observation" in info


def normalised(env: VecNormalize, raw: np.ndarray) -> np.ndarray:
    """VecNormalize's observation formula, with ``env``'s statistics."""
    scaled = (raw - env.obs_rms.mean) / np.sqrt(env.obs_rms.var + env.epsilon)
    return np.clip(scaled, -env.clip_obs, env.clip_obs)


def test_vec_normalize_normalises_and_pickles(tmp_path) -> None:
    env = VecNormalize(make_sb3_vec_env(ENV_ID, 4, seed=0, max_episode_steps=5), gamma=0.99)
    raw_obs = env.venv.reset()
    obs = env.reset()
    assert obs.shape == raw_obs.shape and obs.dtype == np.float32
    for action in actions(4, 30):
        obs, rewards, dones, infos = env.step(action)
        raw = env.get_original_obs()
        assert not np.allclose(obs, raw)
        np.testing.assert_allclose(obs, normalised(env, raw), rtol=1e-4, atol=1e-4)
        for i in np.flatnonzero(dones):
            assert infos[i]["terminal_observation"].shape == (OBS_SIZE,)  # normalised by VecNormalize too
    assert env.obs_rms.count > 100
    assert np.abs(env.obs_rms.mean).max() > 0
    # save / load through pickle
    path = tmp_path / "vecnormalize.pkl"
    env.save(str(path))
    loaded = VecNormalize.load(str(path), make_sb3_vec_env(ENV_ID, 4, seed=0, max_episode_steps=5))
    np.testing.assert_array_equal(loaded.obs_rms.mean, env.obs_rms.mean)
    np.testing.assert_array_equal(loaded.obs_rms.var, env.obs_rms.var)
    np.testing.assert_array_equal(loaded.ret_rms.var, env.ret_rms.var)
    clone = pickle.loads(pickle.dumps(env))  # VecNormalize drops its venv when pickled
    np.testing.assert_array_equal(clone.obs_rms.mean, env.obs_rms.mean)
    loaded.training = False
    first = loaded.reset()
    np.testing.assert_allclose(first, normalised(env, loaded.get_original_obs()), rtol=1e-5, atol=1e-5)


def test_ppo_smoke(tmp_path) -> None:
    env = make_sb3_vec_env(ENV_ID, 8, seed=0, max_episode_steps=20)
    model = PPO("MlpPolicy", env, n_steps=32, batch_size=64, n_epochs=1, device="cpu", seed=0, verbose=0)
    model.learn(total_timesteps=512)
    assert model.num_timesteps == 512
    assert len(model.ep_info_buffer) == 0  # no Monitor: SB3 finds no "episode" infos
    path = tmp_path / "ppo.zip"
    model.save(path)
    loaded = PPO.load(path, device="cpu")
    obs = env.reset()
    action, _ = model.predict(obs, deterministic=True)
    assert action.shape == (8, ACT_SIZE) and np.all(np.abs(action) <= 1.0)
    loaded_action, _ = loaded.predict(obs, deterministic=True)
    np.testing.assert_allclose(loaded_action, action, rtol=1e-6, atol=1e-6)
    env.step(action)
    env.close()


def test_ppo_with_vec_monitor_collects_episode_stats() -> None:
    env = VecMonitor(make_sb3_vec_env(ENV_ID, 8, seed=0, max_episode_steps=16))
    model = PPO("MlpPolicy", env, n_steps=16, batch_size=64, n_epochs=1, device="cpu", seed=0)
    model.learn(total_timesteps=128)
    assert len(model.ep_info_buffer) == 8
    assert all(ep["l"] == 16 for ep in model.ep_info_buffer)


# ------------------------------------------------------------------------- the batch as one object
def test_get_attr_set_attr_env_method_env_is_wrapped() -> None:
    env = make_sb3_vec_env(ENV_ID, 4, seed=0, max_episode_steps=5)
    venv = env.venv
    assert env.get_attr("max_episode_steps") == [5, 5, 5, 5]
    tasks = env.get_attr("task", indices=[0, 2])
    assert len(tasks) == 2 and tasks[0] is venv.task and tasks[1] is venv.task
    assert env.get_attr("num_envs", indices=3) == [4]
    with pytest.raises(AttributeError):
        env.get_attr("no_such_attribute")
    assert env.has_attr("cluster") and not env.has_attr("no_such_attribute")

    env.set_attr("max_episode_steps", 3)  # shared by all sub-envs
    assert venv.max_episode_steps == 3
    env.reset()
    for _ in range(3):
        _, _, dones, _ = env.step(np.zeros((4, ACT_SIZE), np.float32))
    assert dones.all()
    env.set_attr("max_episode_steps", 4, indices=[0, 1, 2, 3])
    assert venv.max_episode_steps == 4
    with pytest.raises(ValueError, match="whole batch"):
        env.set_attr("max_episode_steps", 7, indices=[1])
    assert venv.max_episode_steps == 4

    calls = []
    venv.set_difficulty = lambda difficulty: calls.append(difficulty) or difficulty * 2  # counts the calls
    assert env.env_method("set_difficulty", 0.25, indices=[0, 1]) == [0.5, 0.5]
    assert calls == [0.25]  # called once for the batch, not once per index
    assert env.env_method("set_difficulty", difficulty=0.5) == [1.0] * 4 and calls == [0.25, 0.5]
    assert env.env_method("set_difficulty", 1.0, indices=[]) == [] and calls == [0.25, 0.5]
    with pytest.raises(AttributeError, match="env_method cannot call 'probe'"):
        env.env_method("probe", 1)  # only the batch methods of BatchVecEnv.CALLABLE

    assert env.env_is_wrapped(Monitor) == [False] * 4
    assert env.env_is_wrapped(gym.wrappers.TimeLimit, indices=2) == [False]
    env.close()


def test_render_is_not_supported() -> None:
    env = make_sb3_vec_env(ENV_ID, 2, seed=0)
    with pytest.warns(UserWarning, match="does not render"):
        assert env.render("rgb_array") is None
    with pytest.warns(UserWarning, match="does not render"):
        assert env.get_images() == [None, None]


def test_close_closes_the_vector_env() -> None:
    env = make_sb3_vec_env(ENV_ID, 2, seed=0)
    assert not env.venv.closed
    env.close()
    assert env.venv.closed


# ------------------------------------------------------------------------------ other vector envs
def sync(autoreset_mode: AutoresetMode, n: int = 2, steps: int | None = None) -> SyncVectorEnv:
    kwargs = {} if steps is None else {"max_episode_steps": steps}
    fns = [lambda: gym.make(ENV_ID, **kwargs) for _ in range(n)]
    return SyncVectorEnv(fns, autoreset_mode=autoreset_mode)


def test_rejects_next_step_autoreset() -> None:
    with pytest.raises(ValueError, match="same-step autoreset"):
        SB3VecEnv(sync(AutoresetMode.NEXT_STEP))
    with pytest.raises(ValueError, match="same-step autoreset"):
        SB3VecEnv(sync(AutoresetMode.DISABLED))
    with pytest.raises(ValueError, match="same-step autoreset"):
        SB3VecEnv(gym.make_vec(ENV_ID, num_envs=2))  # the native env's default is next-step, as Gymnasium's
    with pytest.raises(ValueError, match="same-step autoreset"):
        make_sb3_vec_env(ENV_ID, 2, autoreset_mode="next_step")  # an explicit mode is passed on as given


def test_make_sb3_vec_env_asks_for_same_step() -> None:
    """The adapter's builder asks for same-step itself, natively and for Gymnasium's vector envs."""
    assert make_sb3_vec_env(ENV_ID, 2).venv.metadata["autoreset_mode"] is AutoresetMode.SAME_STEP
    for mode in ("sync", "async"):
        env = make_sb3_vec_env(ENV_ID, 2, seed=0, vectorization_mode=mode)
        try:
            assert env.venv.metadata["autoreset_mode"] is AutoresetMode.SAME_STEP
            np.testing.assert_array_equal(env.reset(), make_sb3_vec_env(ENV_ID, 2, seed=0).reset())
        finally:
            env.close()


def test_rejects_a_single_env() -> None:
    with pytest.raises(TypeError, match="VectorEnv"):
        SB3VecEnv(gym.make(ENV_ID))  # type: ignore[arg-type]


def test_works_over_a_same_step_sync_vector_env() -> None:
    env = SB3VecEnv(sync(AutoresetMode.SAME_STEP, n=2, steps=3))
    env.seed(0)
    obs = env.reset()
    np.testing.assert_array_equal(obs, gym.make_vec(ENV_ID, num_envs=2).reset(seed=0)[0])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for _ in range(3):
            obs, rewards, dones, infos = env.step(np.zeros((2, ACT_SIZE), np.float32))
    assert dones.all()
    for info in infos:
        assert info["TimeLimit.truncated"] is True and info["end_reason"] == "running"
        assert info["terminal_observation"].shape == (OBS_SIZE,)
    # The limits live in each sub-env's TimeLimit: setting one on the SyncVectorEnv object would
    # do nothing, so it is refused instead of silently making a new attribute.
    with pytest.raises(AttributeError, match="SyncVectorEnv has no attribute 'max_episode_steps'"):
        env.set_attr("max_episode_steps", 5)
    with pytest.raises(AttributeError, match="SyncVectorEnv has no method 'set_difficulty'"):
        env.env_method("set_difficulty", 0.5)
    env.close()
