"""Baseline controllers, SB3 training, and the comparison command."""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import tether_gym
from agents.controllers.centralised import (
    LQRController,
    PassiveController,
    TensionAwareController,
    VelocityFeedbackController,
)
from agents.controllers.linear_model import LinearModel
from agents.controllers.registry import BASELINES, make_baseline
from agents.evaluation.comparison import CompareConfig, compare
from agents.policies import TrainedPolicy, make_controller
from agents.training.config import TrainConfig
from agents.training.hyperparams import load_hyperparameters
from agents.training.sb3 import make_training_env, train
from tether_gym.envs.contract import Scalar


@pytest.mark.parametrize("env_id", tether_gym.ENV_IDS)
@pytest.mark.parametrize("name", sorted(BASELINES))
def test_every_baseline_runs_on_every_id_single_and_vector(env_id: str, name: str) -> None:
    env = gym.make(env_id)
    controller = make_baseline(name, env)
    obs, _ = env.reset(seed=0)
    for _ in range(5):
        action, state = controller.predict(obs, deterministic=True)
        assert state is None
        assert action.shape == env.action_space.shape and action.dtype == np.float32
        assert env.action_space.contains(action)
        obs, *_ = env.step(action)
    envs = gym.make_vec(env_id, num_envs=3)
    vector_controller = make_baseline(name, envs)
    obs, _ = envs.reset(seed=0)
    for _ in range(5):
        actions, _ = vector_controller.predict(obs)
        assert actions.shape == envs.action_space.shape
        assert np.all(np.abs(actions) <= 1.0)
        obs, *_ = envs.step(actions)
    # A batch gives each row what that row alone gives.
    single_rows = np.stack([vector_controller.predict(row)[0] for row in obs])
    np.testing.assert_array_equal(single_rows, vector_controller.predict(obs)[0])


@pytest.mark.parametrize("env_id", tether_gym.ENV_IDS)
def test_lqr_closed_loop_is_stable_for_the_linear_model(env_id: str) -> None:
    controller = LQRController(gym.make(env_id))
    assert controller.closed_loop_eigenvalues(continuous=True).real.max() < 0
    assert np.abs(controller.closed_loop_eigenvalues(continuous=False)).max() < 1


def test_elastic_modes_exclude_rigid_motion() -> None:
    model = LinearModel(gym.make("TetherTetrahedron-v0").unwrapped.task)
    assert model.num_modes == 6  # 3n - 6
    np.testing.assert_allclose(np.sqrt(model.omega2)[[0, -1]], [np.sqrt(50.0), np.sqrt(200.0)], rtol=1e-4)
    chain = LinearModel(gym.make("TetherChain-v0").unwrapped.task)
    assert chain.num_modes == 3 * 5 - 5  # collinear: no rotation about the axis


def small_perturbation_energy(controller_class: type, steps: int = 30) -> np.ndarray:
    envs = gym.make_vec("TetherTetrahedron-v0", num_envs=8, initial_displacement=1e-4, initial_velocity=1e-4)
    controller = controller_class(envs)
    obs, _ = envs.reset(seed=3)
    start = envs.unwrapped.task.scalars[:, Scalar.VIBRATION_ENERGY].copy()
    for _ in range(steps):
        obs, _, terminated, _, infos = envs.step(controller.predict(obs)[0])
        assert not terminated.any()
    assert infos["slack_count"].max() == 0  # the linear regime: every cable stays taut
    return infos["vibration_energy"] / start


def test_lqr_and_velocity_feedback_beat_passive_on_small_perturbations() -> None:
    passive = small_perturbation_energy(PassiveController)
    assert np.all(passive > 0.5)
    for controller_class in (LQRController, VelocityFeedbackController):
        controlled = small_perturbation_energy(controller_class)
        assert np.all(controlled < 0.01 * passive)


@pytest.mark.parametrize("env_id", ["TetherTetrahedron-v0", "TetherRadialChain-v0"])
def test_velocity_feedback_gain_rule_minimises_the_expected_vibration_energy(env_id: str) -> None:
    controller = VelocityFeedbackController(gym.make(env_id))
    cost = lambda gain: controller.model.expected_vibration_energy(controller.feedback_matrix(gain))  # noqa: E731
    best = cost(controller.gain)
    assert 0 < best < math.inf
    for factor in (0.5, 0.9, 1.1, 2.0):
        assert cost(factor * controller.gain) > best


@pytest.mark.slow
def test_expected_vibration_energy_matches_a_monte_carlo_average() -> None:
    """The Lyapunov formula against brute force: sampled initial states run through the sampled
    closed loop, the energy summed over 3000 intervals."""
    env = gym.make("TetherTetrahedron-v0")
    controller = VelocityFeedbackController(env)
    model = controller.model
    gain = controller.feedback_matrix(controller.gain)
    task = env.unwrapped.task
    rng = np.random.default_rng(0)
    count = 4000
    n = task.cluster.num_nodes
    displacement = task.config.initial_displacement * rng.standard_normal((count, n, 3))
    velocity = task.config.initial_velocity * rng.standard_normal((count, n, 3))
    state = model.modal_state(displacement, velocity)
    closed = model.Ad - model.Bd @ gain
    weight = model.energy_weight()
    total = np.zeros(count)
    for _ in range(3000):
        total += np.einsum("ki,ij,kj->k", state, weight, state) * model.interval
        state = state @ closed.T
    standard_error = total.std() / math.sqrt(count)
    assert abs(total.mean() - model.expected_vibration_energy(gain)) < 4 * standard_error


def test_tension_aware_struts_act_only_across_slack_cables() -> None:
    env = gym.make("TetherTetrahedron-v0")
    controller = TensionAwareController(env)
    task = env.unwrapped.task
    positions = controller.nominal_relative[None].copy()
    taut = np.zeros((1, task.cluster.num_cables))
    np.testing.assert_array_equal(controller.strut_forces(positions, taut), 0.0)
    slack = taut.copy()
    slack[0, 0] = -0.01  # cable 0 (satellites 0 and 1) is 1 cm short: slack
    force = controller.strut_forces(positions, slack)[0]
    apart = positions[0, 1] - positions[0, 0]
    assert np.dot(force[1], apart) > 0 > np.dot(force[0], apart)  # pushed apart along the cable
    np.testing.assert_allclose(np.linalg.norm(force[0]), controller.strut_stiffness * 0.01)
    np.testing.assert_array_equal(force[2:], 0.0)


def test_bad_input_gets_clear_errors() -> None:
    env = gym.make("TetherTetrahedron-v0")
    with pytest.raises(ValueError, match="unknown baseline"):
        make_baseline("pid", env)
    with pytest.raises(ValueError, match="unknown controller"):
        make_controller("no-such-model", env)
    controller = make_baseline("velocity_feedback", env)
    with pytest.raises(ValueError, match="shape"):
        controller.predict(np.zeros(5))
    with pytest.raises(ValueError, match="NaN"):
        controller.predict(np.full(env.observation_space.shape, np.nan))
    with pytest.raises(ValueError, match="observed"):
        make_baseline("lqr", gym.make("TetherTetrahedron-v0", observed_satellites=[0, 1]))
    with pytest.raises(TypeError, match="not a tether-gym environment"):
        make_baseline("passive", gym.make("CartPole-v1"))
    with pytest.raises(ValueError, match="gain"):
        VelocityFeedbackController(env, gain=-1.0)


def test_hyperparameter_files_cover_every_id() -> None:
    for algo in ("ppo", "sac"):
        for env_id in tether_gym.ENV_IDS:
            hyperparams = load_hyperparameters(algo, env_id)
            assert hyperparams["n_timesteps"] > 0 and hyperparams["n_envs"] >= 1


@pytest.fixture(scope="module")
def trained_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A few hundred PPO steps, with a checkpoint, through the project's own training script."""
    out = tmp_path_factory.mktemp("runs")
    return train(
        TrainConfig(
            "ppo",
            "TetherTetrahedron-v0",
            seed=0,
            out=out,
            timesteps=512,
            num_envs=4,
            overrides={"n_steps": 64, "batch_size": 64},
            eval_freq=256,
            eval_episodes=2,
            checkpoint_freq=256,
            progress_bar=False,
        )
    )


def _check_evaluations(run: Path) -> None:
    """best/evaluations.json: every evaluation on the same seeds, paired against the best baseline
    rolled out on those seeds, and the best/ policy is the one with the best mean return."""
    from agents.evaluation.rollout import rollout
    from agents.training.selection import evaluation_seeds

    log = json.loads((run / "best" / "evaluations.json").read_text())
    seeds = evaluation_seeds(2)
    assert log["seeds"] == [seeds[0], seeds[-1]] and log["bar"] == max(log["baselines"], key=log["baselines"].get)
    assert [entry["timesteps"] for entry in log["evaluations"]] == [256, 512]
    assert (
        log["training"]["timesteps"] == 512 and log["training"]["wall_time_s"] >= log["evaluations"][-1]["wall_time_s"]
    )
    env = gym.make("TetherTetrahedron-v0")
    bar = rollout(make_controller(log["bar"], env), "TetherTetrahedron-v0", seeds).rewards.sum(axis=1)
    assert bar.mean() == pytest.approx(log["baselines"][log["bar"]], rel=1e-12)
    for entry in log["evaluations"]:
        assert entry["difference_vs_bar"] == pytest.approx(np.mean(np.array(entry["returns"]) - bar), rel=1e-9)
        assert entry["difference_low"] < entry["difference_vs_bar"] < entry["difference_high"]
    best = TrainedPolicy(run, best=True)
    best.attach(env)
    returns = rollout(best, "TetherTetrahedron-v0", seeds).rewards.sum(axis=1)
    assert returns.mean() == pytest.approx(log["best_mean_return"], rel=1e-6)
    assert log["best_mean_return"] == max(entry["mean_return"] for entry in log["evaluations"])
    for name, beat in log["first_beat"].items():
        first = next(entry for entry in log["evaluations"] if entry["mean_return"] > log["baselines"][name])
        assert beat == {"timesteps": first["timesteps"], "wall_time_s": first["wall_time_s"]}
    assert set(log["first_beat"]) == {
        name
        for name, value in log["baselines"].items()
        if any(entry["mean_return"] > value for entry in log["evaluations"])
    }


@pytest.mark.slow
def test_training_smoke_writes_everything(trained_run: Path) -> None:
    safe = (
        "policy.json",
        "policy.safetensors",
        "normalization.json",
        "training.safetensors",
        "training.json",
        "MANIFEST.sha256",
    )
    for name in ("config.yml", *safe, *(f"best/{name}" for name in safe), "best/evaluations.json"):
        assert (trained_run / name).is_file(), name
    assert any((trained_run / "tensorboard").rglob("events.out.tfevents.*"))
    _check_evaluations(trained_run)
    assert sorted(p.name for p in (trained_run / "checkpoints").iterdir()) == ["ppo_256_steps", "ppo_512_steps"]
    for checkpoint in (trained_run / "checkpoints").iterdir():
        assert sorted(p.name for p in checkpoint.iterdir()) == sorted(safe)
    # Nothing the project writes is a pickle.
    assert not [p for p in trained_run.rglob("*") if p.suffix in (".zip", ".pkl", ".pt", ".pth")]
    policy = TrainedPolicy(trained_run)
    obs = np.zeros((3,) + gym.make("TetherTetrahedron-v0").observation_space.shape, dtype=np.float32)
    actions, _ = policy.predict(obs)
    assert actions.shape == (3, 12)
    assert TrainedPolicy(trained_run, best=True).metadata["num_timesteps"] in (256, 512)


@pytest.mark.slow
def test_training_resumes_from_a_checkpoint(trained_run: Path, tmp_path: Path) -> None:
    run = train(
        TrainConfig(
            "ppo",
            "TetherTetrahedron-v0",
            seed=0,
            out=tmp_path,
            timesteps=256,
            num_envs=4,
            overrides={"n_steps": 64, "batch_size": 64},
            resume=trained_run / "checkpoints" / "ppo_256_steps",
            eval_freq=10_000,
            eval_episodes=2,
            checkpoint_freq=10_000,
            progress_bar=False,
        )
    )
    assert TrainedPolicy(run).metadata["num_timesteps"] == 512  # 256 from the checkpoint + 256 more


def test_curriculum_raises_the_training_difficulty_on_schedule(tmp_path: Path) -> None:
    from stable_baselines3 import PPO

    from agents.controllers.base import task_of
    from agents.training.callbacks import DifficultyCurriculum

    schedule = DifficultyCurriculum(0.2, 0.5, 1000)
    assert [schedule.difficulty_at(t) for t in (0, 250, 500, 900)] == pytest.approx([0.2, 0.6, 1.0, 1.0])
    venv = make_training_env("TetherSpinningTriangle-v0", 4, seed=0, normalize=False)
    model = PPO("MlpPolicy", venv, n_steps=32, batch_size=64, n_epochs=1, device="cpu")
    model.learn(256, callback=DifficultyCurriculum(0.0, 1.0, 512))
    assert task_of(venv).difficulty == pytest.approx(0.5, abs=0.02)
    with pytest.raises(ValueError, match="curriculum"):
        DifficultyCurriculum(1.5, 0.5, 1000)


@pytest.mark.slow
def test_sac_training_smoke(tmp_path: Path) -> None:
    run = train(
        TrainConfig(
            "sac",
            "TetherTetrahedron-v0",
            seed=0,
            out=tmp_path,
            timesteps=200,
            num_envs=2,
            overrides={"learning_starts": 50, "batch_size": 32, "gradient_steps": 1},
            eval_freq=10_000,
            eval_episodes=2,
            checkpoint_freq=10_000,
            progress_bar=False,
        )
    )
    assert TrainedPolicy(run).algo == "sac"


@pytest.mark.slow
def test_comparison_loads_a_trained_model_and_is_reproducible(trained_run: Path, tmp_path: Path) -> None:
    controllers = ["passive", "velocity_feedback", "lqr", "tension_aware", str(trained_run)]
    kwargs = dict(
        env_id="TetherTetrahedron-v0",
        controllers=controllers,
        episodes=3,
        seed=123,
        env_kwargs={"max_episode_steps": 40},
    )
    records, summaries = compare(CompareConfig(out=tmp_path / "a", **kwargs))
    assert [r.name for r in records[:4]] == ["passive", "velocity_feedback", "lqr", "tension_aware"]
    table = (tmp_path / "a" / "comparison.md").read_text()
    for record in records:
        assert f"| {record.name} |" in table
    for name in ("energy.png", "displacement.png", "comparison.csv"):
        assert (tmp_path / "a" / name).stat().st_size > 0
    compare(CompareConfig(out=tmp_path / "b", plots=False, **kwargs))
    rows_a = list(csv.reader(open(tmp_path / "a" / "comparison.csv")))
    rows_b = list(csv.reader(open(tmp_path / "b" / "comparison.csv")))
    assert rows_a == rows_b and len(rows_a) == 1 + len(controllers)
    # Scripted control beats doing nothing even over 4 s.
    energy = {r.name: np.nanmean(r.energy[:, -1] / r.energy[:, 0]) for r in records}
    assert energy["velocity_feedback"] < energy["passive"]
