"""DAgger (agents.training.dagger, the command agents.dagger): the teacher's labels on the teacher's
and then the student's states, a run end to end whose saved student loads and acts as the one in
memory, selection on the evaluation seeds only, determinism, and bad settings refused by name.

A tiny planner (3 samples over 2 steps) and episodes of 40 steps keep it to seconds."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
import yaml
from gymnasium.vector import AutoresetMode
from hypothesis import given, settings
from hypothesis import strategies as st

from agents.common.reading import json_hooks
from agents.controllers.mpc import MPCController, MPCSettings
from agents.controllers.registry import make_baseline
from agents.evaluation.ceiling import load_ceiling_settings
from agents.policies import TrainedPolicy
from agents.policies.format import read_metadata
from agents.policies.loaded import make_controller
from agents.training import dagger
from agents.training.dagger import (
    SEEDS_PER_RUN,
    TRAINING_SEEDS_START,
    DAggerSettings,
    build_student,
    collect,
    fit_student,
    load_dagger_settings,
    observation_statistics,
    save_student,
    student_controller,
    teacher_of,
    train_dagger,
    training_seeds,
)
from agents.training.selection import EVAL_SEEDS_START

ENV_ID = "TetherTetrahedron-v0"  # it has ceiling settings, so train_dagger finds a teacher by default
LAW = "local_tension_aware"  # the tiny teacher's prior
SHORT = {"max_episode_steps": 40}
TEACHER = MPCSettings(samples=3, horizon=2, knots=1, noise=0.3, prior=LAW)
TINY = DAggerSettings(
    residual_on=LAW,
    iterations=2,
    episodes=2,
    epochs=3,
    batch_size=32,
    eval_episodes=2,
    net_arch=(8, 8),
    validation_every=2,  # the second episode of each iteration held out for early stopping
)


def teacher_rollout(seeds: list[int]) -> tuple[np.ndarray, np.ndarray]:
    """The observations (N, O) a pure teacher's episodes visit and its actions (N, A), stepped here
    independently of :func:`collect`."""
    envs = gym.make_vec(ENV_ID, num_envs=len(seeds), autoreset_mode=AutoresetMode.SAME_STEP, **SHORT)
    teacher = MPCController(envs, TEACHER)
    observation, _ = envs.reset(seed=seeds)
    alive = np.ones(len(seeds), dtype=bool)
    states, actions = [], []
    while alive.any():
        action, _ = teacher.predict(observation)
        states.append(observation[alive].copy())
        actions.append(action[alive])
        observation, _, terminated, truncated, _ = envs.step(action)
        alive &= ~(terminated | truncated)
    envs.close()
    return np.concatenate(states), np.concatenate(actions)


def law_actions(observations: np.ndarray) -> np.ndarray:
    env = gym.make(ENV_ID)
    actions, _ = make_baseline(LAW, env).predict(observations)
    env.close()
    return actions


def trained_student(seed: int = 0) -> tuple[Any, Any]:
    """A small student fitted a little on random targets, and its statistics."""
    rng = np.random.default_rng(seed)
    states, _ = teacher_rollout([7])
    statistics = observation_statistics(states)
    model = build_student(ENV_ID, (8, 8), seed)
    targets = rng.uniform(-0.5, 0.5, (len(states), 12)).astype(np.float32)
    fit_student(model.policy, statistics.normalize_obs(states).astype(np.float32), targets, 3, 1e-2, 16, seed)
    return model, statistics


def test_iteration_zero_labels_the_teachers_own_states_with_teacher_minus_law() -> None:
    seeds = [200_000, 200_001]
    data = collect(ENV_ID, seeds, TEACHER, LAW, None, 1.0, np.random.default_rng(0), SHORT)
    states, actions = teacher_rollout(seeds)
    np.testing.assert_array_equal(data.observations, states.astype(np.float32))
    np.testing.assert_array_equal(data.teacher_actions, actions)
    np.testing.assert_array_equal(data.law_actions, law_actions(states))
    np.testing.assert_array_equal(data.targets, np.clip(actions - law_actions(states), -1, 1))
    assert len(data.observations) == 2 * SHORT["max_episode_steps"] and np.abs(data.targets).max() > 0
    assert data.teacher_steps == 2 * SHORT["max_episode_steps"] and data.teacher_seconds > 0


def test_a_later_iteration_labels_the_students_states() -> None:
    """With beta 0 the student acts: the states are those of the student's own episodes (not the
    teacher's), and the teacher labels each of them with the action it would take there."""
    seeds = [200_002, 200_003]
    model, statistics = trained_student()
    student = student_controller(model, statistics, ENV_ID, LAW)
    data = collect(ENV_ID, seeds, TEACHER, LAW, student, 0.0, np.random.default_rng(0), SHORT)

    envs = gym.make_vec(ENV_ID, num_envs=2, autoreset_mode=AutoresetMode.SAME_STEP, **SHORT)
    teacher = MPCController(envs, TEACHER)
    student.attach(envs)
    observation, _ = envs.reset(seed=seeds)
    states, labels = [], []
    for _ in range(SHORT["max_episode_steps"]):
        labels.append(teacher.predict(observation)[0])
        states.append(observation.copy())
        observation, *_ = envs.step(student.predict(observation)[0])
    envs.close()
    # Step by step, every episode of the batch at each step (all run to the end here).
    np.testing.assert_array_equal(data.observations, np.concatenate(states))
    np.testing.assert_array_equal(data.teacher_actions, np.concatenate(labels))
    teachers_own, _ = teacher_rollout(seeds)
    assert not np.array_equal(data.observations, teachers_own)


def test_the_saved_student_loads_and_acts_as_the_one_in_memory_to_the_bit(tmp_path: Path) -> None:
    model, statistics = trained_student()
    in_memory = student_controller(model, statistics, ENV_ID, LAW)
    save_student(tmp_path / "student", model, ENV_ID, LAW, statistics, 80, {"seed": 0})
    envs = gym.make_vec(ENV_ID, num_envs=4)
    loaded = make_controller(str(tmp_path / "student"), envs)
    in_memory.attach(envs)
    assert isinstance(loaded, TrainedPolicy) and loaded.algo == "dagger" and loaded.residual_on == LAW
    observation, _ = envs.reset(seed=[1, 2, 3, 4])
    for _ in range(5):
        expected, _ = in_memory.predict(observation)
        actual, _ = loaded.predict(observation)
        np.testing.assert_array_equal(actual, expected)
        assert not np.array_equal(actual, law_actions(observation))  # the network adds its part
        observation, *_ = envs.step(actual)
    envs.close()
    metadata = read_metadata(tmp_path / "student")
    assert metadata["policy_kwargs"]["net_arch"] == {"pi": [8, 8], "vf": []}


def test_early_stopping_keeps_the_epoch_best_on_the_held_out_states() -> None:
    rng = np.random.default_rng(2)
    features = rng.normal(size=(320, 30)).astype(np.float32)
    targets = np.tanh(features[:, :12] * 0.5).astype(np.float32)
    fitted, held = slice(0, 256), slice(256, 320)
    # Held-out states that follow the same rule: the fit helps there, and the best epoch is kept.
    model = build_student(ENV_ID, (16,), 0)
    fit = fit_student(model.policy, features[fitted], targets[fitted], 30, 1e-2, 32, 0, (features[held], targets[held]))
    assert fit.validation_loss is not None and fit.validation_loss_before is not None
    assert 0 < fit.epochs_kept <= 30 and fit.validation_loss < 0.5 * fit.validation_loss_before
    assert fit.validation_loss == pytest.approx(dagger.student_loss(model.policy, features[held], targets[held]))
    # Held-out states that contradict the fitted ones: no epoch improves on them, so the weights
    # before the fit are kept, to the bit.
    model = build_student(ENV_ID, (16,), 0)
    start = [p.detach().numpy().copy() for p in model.policy.action_net.parameters()]
    fit = fit_student(
        model.policy, features[fitted], targets[fitted], 10, 1e-2, 32, 0, (features[fitted], -targets[fitted])
    )
    assert fit.epochs_kept == 0 and fit.validation_loss == fit.validation_loss_before
    assert all(
        np.array_equal(a, p.detach().numpy()) for a, p in zip(start, model.policy.action_net.parameters(), strict=True)
    )
    with pytest.raises(ValueError, match="validation must be"):
        fit_student(model.policy, features, targets, 1, 1e-2, 32, 0, (features[:, 1:], targets))
    assert dagger.held_out_rows(np.array([0, 1, 2, 3, 4, 5, 9, 9]), 5).tolist() == [0, 0, 0, 0, 1, 0, 1, 1]
    assert not dagger.held_out_rows(np.arange(10), 0).any()


def test_fitting_lowers_the_error_and_depends_on_the_seed() -> None:
    rng = np.random.default_rng(1)
    features = rng.normal(size=(256, 30)).astype(np.float32)
    targets = np.tanh(features[:, :12] * 0.5).astype(np.float32)
    model = build_student(ENV_ID, (16,), 0)
    before = fit_student(model.policy, features, targets, 0, 1e-2, 32, 0)
    after = fit_student(model.policy, features, targets, 30, 1e-2, 32, 0)
    assert after.loss < 0.25 * before.loss and (before.epochs_kept, after.epochs_kept) == (0, 30)
    assert after.validation_loss is None and after.validation_loss_before is None
    weights = []
    for seed in (1, 2):
        other = build_student(ENV_ID, (16,), 0)
        fit_student(other.policy, features, targets, 2, 1e-2, 32, seed)
        weights.append(other.policy.action_net.weight.detach().numpy().copy())
    assert not np.array_equal(*weights)
    with pytest.raises(ValueError, match="rows alike"):
        fit_student(model.policy, features, targets[:10], 1, 1e-2, 32, 0)
    with pytest.raises(ValueError, match="takes 30 observation values and gives 12 actions; got features of 29"):
        fit_student(model.policy, features[:, 1:], targets, 1, 1e-2, 32, 0)


@pytest.fixture(scope="module")
def run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return train_dagger(
        ENV_ID, 3, tmp_path_factory.mktemp("a"), TINY, teacher=TEACHER, progress=False, env_kwargs=SHORT
    )


def test_a_run_aggregates_the_data_selects_on_the_evaluation_seeds_and_records_its_compute(run: Path) -> None:
    # Read as agents.ship reads it: strict JSON, no NaN.
    log = json.loads((run / "best" / "evaluations.json").read_text(), **json_hooks())
    history = log["evaluations"]
    assert [entry["iteration"] for entry in history] == [0, 1] and [e["beta"] for e in history] == [1.0, 0.0]
    assert history[1]["states"] == 2 * history[0]["states"] == 4 * SHORT["max_episode_steps"]
    assert all(entry["target_variance"] > 0 and entry["loss"] >= 0 for entry in history)
    assert history[0]["loss_on_new_states"] is None and history[1]["loss_on_new_states"] > 0
    # validation_every 2: the second episode of each iteration is held out of the fits.
    assert [entry["validation_states"] for entry in history] == [SHORT["max_episode_steps"] * k for k in (1, 2)]
    assert all(entry["validation_loss"] <= entry["validation_loss_before"] for entry in history)
    assert all(0 <= entry["epochs_kept"] <= TINY.epochs for entry in history)
    assert log["seeds"] == [EVAL_SEEDS_START, EVAL_SEEDS_START + 1]
    config = yaml.safe_load((run / "config.yml").read_text())
    assert config["training_seeds"] == [TRAINING_SEEDS_START + 3 * SEEDS_PER_RUN, TRAINING_SEEDS_START + 3 * 800 + 3]
    assert config["teacher"]["samples"] == 3 and config["hyperparams"]["net_arch"] == [8, 8]
    assert load_dagger_settings(None, run / "config.yml") == TINY
    # best/ holds the best evaluation (or the law itself when no iteration beat it): rerun it.
    law_mean = log["baselines"][LAW]
    best_mean = max([law_mean] + [entry["mean_return"] for entry in history])
    assert log["best_mean_return"] == pytest.approx(best_mean)
    envs = gym.make_vec(ENV_ID, num_envs=2, **SHORT)
    best = make_controller(str(run / "best"), envs)
    envs.close()
    from agents.training.selection import episode_returns

    again = episode_returns(best, ENV_ID, [EVAL_SEEDS_START, EVAL_SEEDS_START + 1], SHORT)
    assert again.mean() == pytest.approx(best_mean)
    compute = log["training"]["compute"]
    assert compute["teacher_seconds_per_step"] > 0 and compute["student_single_seconds_per_step"] > 0
    assert compute["speedup_network_single"] == pytest.approx(
        compute["teacher_seconds_per_step"] / compute["network_single_seconds_per_step"]
    )
    assert read_metadata(run)["algo"] == "dagger"
    with np.load(run / dagger.DATASET_FILE, allow_pickle=False) as data:
        assert data["observations"].shape == (history[1]["states"], 30) and data["targets"].shape[1] == 12
        assert np.bincount(data["iteration"]).tolist() == [2 * SHORT["max_episode_steps"]] * 2
        assert np.bincount(data["episode"]).tolist() == [SHORT["max_episode_steps"]] * 4
        assert data["held_out"].tolist() == (data["episode"] % 2 == 1).tolist()


def test_selection_evaluates_on_the_evaluation_seeds_only(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    seen: list[list[int]] = []
    through = dagger.episode_returns

    def spy(controller: Any, env_id: str, seeds: list[int], env_kwargs: Any = None) -> np.ndarray:
        seen.append(list(seeds))
        return through(controller, env_id, seeds, env_kwargs)

    rolled: list[list[int]] = []
    collect_through = dagger.collect

    def collect_spy(env_id: str, seeds: Any, *args: Any) -> Any:
        rolled.append(list(seeds))
        return collect_through(env_id, seeds, *args)

    monkeypatch.setattr(dagger, "episode_returns", spy)
    monkeypatch.setattr(dagger, "collect", collect_spy)
    # residual_on null: the teacher's prior, recorded by name.
    one = DAggerSettings(residual_on=None, iterations=2, episodes=1, epochs=1, eval_episodes=2, net_arch=(4,))
    run = train_dagger(ENV_ID, 999, tmp_path, one, teacher=TEACHER, progress=False, env_kwargs=SHORT)
    assert yaml.safe_load((run / "config.yml").read_text())["hyperparams"]["residual_on"] == TEACHER.prior
    assert read_metadata(run)["residual_on"] == TEACHER.prior
    assert seen == [[EVAL_SEEDS_START, EVAL_SEEDS_START + 1]] * 2
    assert rolled == [training_seeds(999, 0, 1), training_seeds(999, 1, 1)] == [[999_200], [999_201]]
    assert max(max(seeds) for seeds in rolled) < EVAL_SEEDS_START


def test_the_same_seed_trains_the_same_bits(run: Path, tmp_path: Path) -> None:
    again = train_dagger(ENV_ID, 3, tmp_path, TINY, teacher=TEACHER, progress=False, env_kwargs=SHORT)
    for name in ("policy.safetensors", "normalization.json", "best/policy.safetensors"):
        assert (again / name).read_bytes() == (run / name).read_bytes(), name
    first, second = (json.loads((r / "best" / "evaluations.json").read_text()) for r in (run, again))
    assert [e["returns"] for e in first["evaluations"]] == [e["returns"] for e in second["evaluations"]]


@pytest.mark.parametrize(
    ("overrides", "message"),
    [
        ({"residual_on": "oracle"}, "residual_on must be one of"),
        ({"iterations": 0}, "iterations must be an integer in 1..800"),
        ({"episodes": True}, "episodes must be an integer"),
        ({"eval_episodes": 1}, "eval_episodes must be an integer in 2.."),
        ({"iterations": 100, "episodes": 9}, "iterations x episodes .* must be <= 800"),
        ({"beta_decay": 1.0}, r"beta_decay must be a number in \[0, 1\)"),
        ({"learning_rate": float("nan")}, "learning_rate must be a number"),
        ({"net_arch": []}, "net_arch must be a list of 1 to 16"),
        ({"net_arch": [64, 0]}, "net_arch entry must be an integer in 1..4096"),
        ({"net_arch": "64"}, "net_arch must be a list"),
        ({"validation_every": 1}, "validation_every must be 0 .off. or at least 2"),
        ({"validation_every": -1}, "validation_every must be an integer in 0..800"),
        ({"teacher_samples": 0}, "teacher_samples must be an integer in 1..100000"),
        ({"teacher_samples": 1.5}, "teacher_samples must be an integer"),
    ],
)
def test_bad_settings_are_named(overrides: dict[str, Any], message: str) -> None:
    with pytest.raises(ValueError, match=message):
        DAggerSettings(**overrides)


def test_teacher_samples_change_only_the_teachers_samples() -> None:
    ceiling = load_ceiling_settings(ENV_ID)
    assert teacher_of(ENV_ID, DAggerSettings()) == ceiling
    cheaper = teacher_of(ENV_ID, DAggerSettings(teacher_samples=16))
    assert cheaper.samples == 16 != ceiling.samples
    assert dataclasses.replace(cheaper, samples=ceiling.samples) == ceiling


def test_settings_files_and_runs_without_a_teacher_are_refused(tmp_path: Path) -> None:
    assert load_dagger_settings("TetherHub-v0", iterations=3).iterations == 3
    bad = tmp_path / "dagger.yml"
    bad.write_text("default: {iterationz: 3}\n")
    with pytest.raises(ValueError, match="unknown DAgger setting.*iterationz"):
        load_dagger_settings("TetherHub-v0", bad)
    with pytest.raises(ValueError, match="no ceiling settings for 'TetherBeadedChain-v0'"):
        train_dagger("TetherBeadedChain-v0", 1, tmp_path, TINY, progress=False)
    assert not (tmp_path / "TetherBeadedChain-v0").exists()  # refused before any work
    without_prior = MPCSettings(samples=3, horizon=2, knots=1)
    with pytest.raises(ValueError, match="residual_on is null .* plans without a prior: name the law"):
        train_dagger(ENV_ID, 1, tmp_path, DAggerSettings(), teacher=without_prior, progress=False)
    with pytest.raises(ValueError, match="needs a student"):
        collect(ENV_ID, [1], TEACHER, LAW, None, 0.5, np.random.default_rng(0))
    with pytest.raises(ValueError, match="seed must be an integer in 0..999"):
        train_dagger(ENV_ID, 1000, tmp_path, TINY, teacher=TEACHER, progress=False)


@settings(max_examples=60, deadline=None)
@given(
    st.fixed_dictionaries(
        {},
        optional={
            "iterations": st.one_of(st.integers(-5, 900), st.floats(), st.booleans()),
            "episodes": st.one_of(st.integers(-5, 200_000), st.none()),
            "beta_decay": st.one_of(st.floats(allow_nan=True), st.integers(-2, 2), st.text(max_size=3)),
            "net_arch": st.one_of(st.lists(st.integers(-2, 5000), max_size=18), st.integers(), st.text(max_size=3)),
            "learning_rate": st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.booleans()),
            "batch_size": st.one_of(st.integers(-3, 10), st.floats()),
        },
    )
)
def test_settings_are_valid_or_refused_by_name(values: dict[str, Any]) -> None:
    """Any settings either build valid settings or are refused with a ValueError naming the setting."""
    try:
        built = DAggerSettings(**values)
    except ValueError as error:
        assert "dagger setting" in str(error)
        return
    assert 1 <= built.iterations * built.episodes <= SEEDS_PER_RUN and 0 <= built.beta_decay < 1
    assert all(isinstance(size, int) and size >= 1 for size in built.net_arch) and built.learning_rate > 0
