"""Training on Ray RLlib (agents.training.rllib, the command agents.train_rllib): one iteration
with the native vector env in the env runners, checkpoint and resume, the export to the policy
format (its actions equal RLlib's), the exported policy in agents.compare, and clear errors for bad
input; the same for the multi-agent run with one shared module (--multiagent).

These need the rllib extra (bash scripts/test_rllib.sh); without Ray they are skipped. They share
one local Ray instance of 2 CPUs, started and shut down by a session fixture."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
import yaml

ray = pytest.importorskip("ray", reason="the rllib extra is not installed (bash scripts/test_rllib.sh runs these)")

from agents import compare  # noqa: E402
from agents.policies import TrainedPolicy  # noqa: E402
from agents.policies.format import save_policy  # noqa: E402
from agents.policies.pickled import PickleNotTrustedError  # noqa: E402
from agents.policies.spec import PolicySpec  # noqa: E402
from agents.training.hyperparams import HyperparameterError  # noqa: E402
from agents.training.rllib import (  # noqa: E402
    ALGO,
    RayUnavailableError,
    RLlibConfig,
    build_config,
    export_policy,
    load_rllib_hyperparameters,
    make_multiagent_env,
    make_vessel,
    rllib_actions,
    train_rllib,
)
from tether_gym.envs import TetherClusterVectorEnv  # noqa: E402
from tether_gym.registration import ENV_IDS  # noqa: E402

pytestmark = [pytest.mark.rllib, pytest.mark.slow]

ROOT = Path(__file__).resolve().parents[3]
ENV_ID = "TetherTetrahedron-v0"
#: A run small enough for tests: 800 env steps per iteration, 8 envs per runner, 40-step episodes.
SMALL = {
    "n_timesteps": 800,
    "num_envs_per_env_runner": 8,
    "train_batch_size_per_learner": 800,
    "minibatch_size": 400,
    "num_epochs": 1,
    "fcnet_hiddens": [16, 16],
    "normalize_obs": True,
    "lr": "lin_1.0e-3",
    "env_kwargs": {"max_episode_steps": 40},
}


@pytest.fixture(scope="session")
def ray_instance() -> object:
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False, configure_logging=False)
    yield ray
    ray.shutdown()


@pytest.fixture(scope="module")
def small_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("hyperparams") / "small.yml"
    path.write_text(yaml.safe_dump({"default": SMALL}))
    return path


@pytest.fixture(scope="module")
def first_run(ray_instance: object, small_file: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """One iteration with one remote env runner, evaluated on 4 seeds and checkpointed."""
    out = tmp_path_factory.mktemp("runs")
    return train_rllib(
        RLlibConfig(
            ENV_ID,
            seed=3,
            out=out,
            num_env_runners=1,
            hyperparams_file=small_file,
            eval_freq=800,
            eval_episodes=4,
            checkpoint_freq=800,
            command="python -m agents.train_rllib --test",
        )
    )


def test_one_iteration_writes_the_run(first_run: Path) -> None:
    assert first_run.name == f"{ALGO}_seed3"
    config = yaml.safe_load((first_run / "config.yml").read_text())
    assert config["command"] == "python -m agents.train_rllib --test"
    assert config["algo"] == ALGO and config["num_env_runners"] == 1 and config["hyperparams"]["n_timesteps"] == 800
    assert list((first_run / "tensorboard").glob("rllib_ppo_1/events.out.tfevents.*"))
    assert (first_run / "checkpoints" / "iter_000001" / "rllib_checkpoint.json").is_file()
    evaluations = yaml.safe_load((first_run / "best" / "evaluations.json").read_text())
    assert evaluations["evaluations"][0]["timesteps"] == 800 and len(evaluations["evaluations"][0]["returns"]) == 4
    policy = TrainedPolicy(first_run)
    assert policy.metadata["num_timesteps"] == 800 and policy.normalizer is not None
    assert policy.metadata["provenance"]["trainer"] == "rllib"
    # The recorded config reproduces the run's hyperparameters.
    assert load_rllib_hyperparameters(ENV_ID, first_run / "config.yml") == config["hyperparams"]


def test_the_env_runners_step_the_native_vector_env_in_next_step_mode(ray_instance: object) -> None:
    algo = build_config(ENV_ID, SMALL, num_env_runners=1, envs_per_runner=3, seed=0).build_algo()
    try:
        found = algo.env_runner_group.foreach_env_runner(
            lambda runner: (
                type(runner.env.unwrapped).__name__,
                runner.env.unwrapped.metadata["autoreset_mode"].value,
                runner.env.unwrapped.num_envs,
            ),
            local_env_runner=False,
        )
    finally:
        algo.stop()
    assert found == [(TetherClusterVectorEnv.__name__, "NextStep", 3)]


def _exported_after_one_iteration(
    hyperparams: dict[str, Any], envs_per_runner: int, samples: Callable[[], np.ndarray]
) -> tuple[Any, np.ndarray, np.ndarray]:
    """One iteration sampled in the driver, exported: ``(vessel, observations, RLlib's actions on them)``."""
    algo = build_config(ENV_ID, hyperparams, num_env_runners=0, envs_per_runner=envs_per_runner, seed=1).build_algo()
    try:
        algo.train()
        vessel = make_vessel(ENV_ID, hyperparams, seed=1)
        export_policy(algo, vessel, hyperparams["train_batch_size_per_learner"])
        observations = samples()
        expected = rllib_actions(algo, observations)
    finally:
        algo.stop()
    assert np.abs(expected).max() > 0.01  # not a trivially zero policy
    return vessel, observations, expected


def _vector_observations() -> np.ndarray:
    """Observations the env gives (the statistics matter there), and wider random ones (clipping)."""
    envs = gym.make_vec(ENV_ID, num_envs=16)
    observations, _ = envs.reset(seed=5)
    stepped, *_ = envs.step(np.random.default_rng(0).uniform(-1, 1, envs.action_space.shape))
    wide = np.random.default_rng(1).normal(0, 3, observations.shape)
    return np.concatenate([observations, stepped, wide]).astype(np.float32)


def test_the_exported_policy_acts_as_the_rllib_module(ray_instance: object, tmp_path: Path) -> None:
    vessel, samples, expected = _exported_after_one_iteration(SMALL, 8, _vector_observations)
    save_policy(tmp_path, vessel, vessel.get_vec_normalize_env(), ENV_ID)
    loaded = TrainedPolicy(tmp_path)
    actions, _ = loaded.predict(samples, deterministic=True)
    np.testing.assert_allclose(actions, expected, rtol=0, atol=1e-6)


def test_the_exported_policy_runs_in_compare(first_run: Path, tmp_path: Path) -> None:
    records, summaries = compare.main(
        ["--controllers", "lqr", str(first_run), "--episodes", "2", "--no-plots", "--out", str(tmp_path / "cmp")]
    )
    assert [record.name for record in records] == ["lqr", str(first_run)]
    assert np.isfinite(records[1].rewards.sum())
    assert (tmp_path / "cmp" / "comparison.md").is_file()


def test_resume_continues_from_the_checkpoint(first_run: Path, small_file: Path) -> None:
    checkpoint = first_run / "checkpoints" / "iter_000001"
    with pytest.raises(PickleNotTrustedError, match="--trust-pickle"):
        train_rllib(
            RLlibConfig(ENV_ID, seed=3, out=first_run.parents[1], hyperparams_file=small_file, resume=checkpoint)
        )
    run = train_rllib(
        RLlibConfig(
            ENV_ID,
            seed=3,
            out=first_run.parents[1],
            timesteps=1600,
            hyperparams_file=small_file,
            resume=first_run,  # a run directory: its latest checkpoint
            trust_pickle=True,
            force=True,
            eval_freq=10**6,
            eval_episodes=2,
        )
    )
    assert (run / "checkpoints" / "iter_000002" / "rllib_checkpoint.json").is_file()
    assert TrainedPolicy(run).metadata["num_timesteps"] == 1600
    assert yaml.safe_load((run / "config.yml").read_text())["resumed_from"] == str(checkpoint)


def test_bad_arguments_fail_before_training(ray_instance: object, small_file: Path, tmp_path: Path) -> None:
    def run(**kwargs: object) -> Path:
        return train_rllib(RLlibConfig(out=tmp_path, hyperparams_file=small_file, **kwargs))  # type: ignore[arg-type]

    with pytest.raises(ValueError, match="unknown env id 'TetherNothing-v0'"):
        run(env_id="TetherNothing-v0")
    with pytest.raises(ValueError, match="num_env_runners must be an integer >= 0"):
        run(num_env_runners=-1)
    with pytest.raises(ValueError, match="envs_per_runner must be an integer >= 1"):
        run(envs_per_runner=0)
    with pytest.raises(ValueError, match="envs_per_runner must be at most"):
        run(envs_per_runner=10**9)
    # More runners than the 2 CPUs of the Ray instance: an error, not a wait for ever.
    with pytest.raises(RayUnavailableError, match="--num-env-runners 5 needs 5 CPUs"):
        run(num_env_runners=5)
    with pytest.raises(HyperparameterError, match="unknown key 'learning_rate'"):
        bad = tmp_path / "bad.yml"
        bad.write_text(yaml.safe_dump({"default": {**SMALL, "learning_rate": 0.1}}))
        train_rllib(RLlibConfig(out=tmp_path, hyperparams_file=bad))
    assert sorted(ENV_IDS)  # the ids exist


def _command(*arguments: str) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.run(
        [sys.executable, "-m", "agents.train_rllib", *arguments],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
    )


def test_an_unreachable_address_fails_fast(tmp_path: Path) -> None:
    started = time.perf_counter()
    result = _command("--address", "127.0.0.1:1", "--out", str(tmp_path))
    assert result.returncode == 1
    assert "--address 127.0.0.1:1: no Ray head node answers there" in result.stderr
    assert "ray start --head" in result.stderr
    assert time.perf_counter() - started < 60


def test_the_command_joins_a_running_cluster_by_address(ray_instance: object, small_file: Path, tmp_path: Path) -> None:
    """This session's Ray instance stands in for a cluster: the command joins it as a second driver."""
    address = ray.get_runtime_context().gcs_address
    result = _command(
        "--address", address, "--hyperparams", str(small_file), "--out", str(tmp_path), "--eval-episodes", "2"
    )
    assert result.returncode == 0, result.stderr[-3000:]
    run = tmp_path / ENV_ID / f"{ALGO}_seed0"
    assert yaml.safe_load((run / "config.yml").read_text())["address"] == address
    assert TrainedPolicy(run).metadata["num_timesteps"] == 800


def test_the_command_line_rejects_bad_counts_and_ids(tmp_path: Path) -> None:
    for arguments, message in (
        (["--num-env-runners", "-1"], "--num-env-runners"),
        (["--envs-per-runner", "0"], "--envs-per-runner"),
        (["--env", "TetherNothing-v0"], "invalid choice: 'TetherNothing-v0'"),
    ):
        result = _command(*arguments, "--out", str(tmp_path))
        assert result.returncode == 2 and message in result.stderr, result.stderr


# ---------------------------------------------------------------------------------------------
# Multi-agent: one shared module for every satellite (agents.train_rllib --multiagent)
# ---------------------------------------------------------------------------------------------

#: A small multi-agent run: 200 env steps (x 4 agents) per iteration, one env per runner.
SMALL_MULTIAGENT = {
    **SMALL,
    "multiagent": {"reward": "shares"},
    "n_timesteps": 200,
    "num_envs_per_env_runner": 1,
    "train_batch_size_per_learner": 200,
    "minibatch_size": 100,
    "normalize_obs": False,
}


def _local_observations(multiagent: dict[str, object]) -> np.ndarray:
    """(B, local obs) observations of the agents after a reset and a random step, and wider random ones."""
    from tether_gym.multiagent import parallel_env

    env = parallel_env(ENV_ID, **multiagent)
    first, _ = env.reset(seed=5)
    rng = np.random.default_rng(0)
    stepped, *_ = env.step({agent: rng.uniform(-1, 1, 3) for agent in env.agents})
    rows = np.stack([*first.values(), *stepped.values()])
    return np.concatenate([rows, rng.normal(0, 3, rows.shape)]).astype(np.float32)


@pytest.fixture(scope="module")
def multiagent_run(ray_instance: object, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """One iteration of the shared-policy PPO, sampled in the driver, evaluated on 2 seeds."""
    path = tmp_path_factory.mktemp("hyperparams") / "multiagent.yml"
    path.write_text(yaml.safe_dump({ENV_ID: SMALL_MULTIAGENT}))
    return train_rllib(
        RLlibConfig(
            ENV_ID, seed=2, out=tmp_path_factory.mktemp("runs"), hyperparams_file=path, eval_freq=200, eval_episodes=2
        )
    )


def test_one_multiagent_iteration_trains_the_shared_module(multiagent_run: Path) -> None:
    assert multiagent_run.name == f"{ALGO}_multiagent_seed2"
    config = yaml.safe_load((multiagent_run / "config.yml").read_text())
    assert config["hyperparams"]["multiagent"] == {"reward": "shares"}
    policy = TrainedPolicy(multiagent_run)
    assert policy.multiagent == {"reward": "shares"} and policy.metadata["num_timesteps"] == 200
    assert policy.observation_size == _local_observations({}).shape[1] and policy.normalizer is None
    assert (multiagent_run / "best" / "evaluations.json").is_file()


def test_every_agent_maps_to_the_one_shared_module(ray_instance: object) -> None:
    algo = build_config(ENV_ID, SMALL_MULTIAGENT, num_env_runners=0, envs_per_runner=1, seed=0).build_algo()
    try:
        agents = list(make_multiagent_env({"env_id": ENV_ID}).get_agent_ids())
        mapped = {algo.config.policy_mapping_fn(agent, None) for agent in agents}
        modules = set(algo.env_runner.module.keys())
    finally:
        algo.stop()
    assert len(agents) == 4 and mapped == {"shared"} and modules == {"shared"}


def test_the_exported_multiagent_policy_acts_as_the_shared_module(ray_instance: object, tmp_path: Path) -> None:
    options = SMALL_MULTIAGENT["multiagent"]
    vessel, samples, expected = _exported_after_one_iteration(SMALL_MULTIAGENT, 1, lambda: _local_observations(options))
    save_policy(tmp_path, vessel, None, ENV_ID, spec=PolicySpec(multiagent=options))
    loaded = TrainedPolicy(tmp_path)
    actions, _ = loaded.policy.predict(samples, deterministic=True)
    np.testing.assert_allclose(actions, expected, rtol=0, atol=1e-6)


def test_the_exported_multiagent_policy_runs_in_compare(multiagent_run: Path, tmp_path: Path) -> None:
    records, _ = compare.main(
        [
            "--controllers",
            "local_velocity_feedback",
            str(multiagent_run),
            "--episodes",
            "2",
            "--no-plots",
            "--out",
            str(tmp_path / "cmp"),
        ]
    )
    assert [record.name for record in records] == ["local_velocity_feedback", str(multiagent_run)]
    assert np.isfinite(records[1].rewards.sum())


def test_bad_multiagent_options_fail_before_training(ray_instance: object, tmp_path: Path) -> None:
    def run(entry: dict[str, object]) -> Path:
        path = tmp_path / "bad.yml"
        path.write_text(yaml.safe_dump({ENV_ID: {**SMALL_MULTIAGENT, **entry}}))
        return train_rllib(RLlibConfig(ENV_ID, out=tmp_path, hyperparams_file=path))

    with pytest.raises(HyperparameterError, match="unknown key 'rewards'.*reward"):
        run({"multiagent": {"rewards": "shares"}})
    with pytest.raises(HyperparameterError, match="'multiagent'.*'sharez'"):
        run({"multiagent": {"reward": "sharez"}})
    with pytest.raises(HyperparameterError, match="'normalize_obs' must be false with 'multiagent'"):
        run({"normalize_obs": True})
    with pytest.raises(HyperparameterError, match="'num_envs_per_env_runner' must be 1 with 'multiagent'"):
        run({"num_envs_per_env_runner": 4})
    assert not list(tmp_path.glob(f"{ENV_ID}/*"))  # nothing was written
