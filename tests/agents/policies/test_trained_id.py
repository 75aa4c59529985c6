"""A trained policy runs on the id it was trained on, or on another only when the user opts in.

Ids of the same observation shape (the triangle and the spinning triangle, the hub and the
spinning hub) are different tasks: a policy of one used to run silently on the other.
"""

from __future__ import annotations

import json
import shutil
import warnings
from pathlib import Path

import gymnasium as gym
import pytest

import agents.compare
from agents.evaluation.benchmark import BenchmarkConfig, benchmark
from agents.evaluation.comparison import CompareConfig, compare
from agents.evaluation.rollout import rollout
from agents.policies import (
    MODELS_DIR,
    OtherIdError,
    OtherIdWarning,
    TrainedPolicy,
    env_id_of,
    make_controller,
    shipped_models,
)
from agents.policies.format import read_metadata, write_manifest
from agents.policies.layout import METADATA_FILE

TRIANGLE, SPINNING = "TetherTriangle-v0", "TetherSpinningTriangle-v0"
SHORT = {"max_episode_steps": 5}


def triangle_ppo() -> Path:
    return shipped_models(TRIANGLE)["ppo"]


def test_every_shipped_model_records_the_id_it_is_shipped_under() -> None:
    shipped = sorted(MODELS_DIR.glob(f"*/*/{METADATA_FILE}"))
    assert shipped
    for path in shipped:
        assert read_metadata(path.parent)["env_id"] == path.parent.parent.name, path


def test_env_id_of_reads_envs_vector_envs_and_wrappers() -> None:
    assert env_id_of(gym.make(SPINNING)) == SPINNING
    assert env_id_of(gym.make_vec(SPINNING, num_envs=2)) == SPINNING
    assert env_id_of(object()) is None


def test_a_policy_is_refused_on_another_id_of_the_same_shape() -> None:
    policy = TrainedPolicy(triangle_ppo())
    env = gym.make(SPINNING)
    assert env.observation_space.shape == policy.observation_shape  # the shapes alone cannot tell
    with pytest.raises(OtherIdError) as caught:
        policy.attach(env)
    message = str(caught.value)
    assert TRIANGLE in message and SPINNING in message
    assert "--allow-other-id" in message and "allow_other_id=True" in message
    assert (caught.value.trained, caught.value.running) == (TRIANGLE, SPINNING)
    with pytest.raises(OtherIdError):
        make_controller(str(triangle_ppo()), gym.make_vec(SPINNING, num_envs=1))
    with pytest.raises(OtherIdError):  # evaluate attaches the policy to its own env too
        rollout(policy, SPINNING, [0], env_kwargs=SHORT)


def test_the_opt_in_runs_it_with_a_warning_naming_both_ids() -> None:
    for policy, attach in (
        (TrainedPolicy(triangle_ppo(), allow_other_id=True), {}),
        (TrainedPolicy(triangle_ppo()), {"allow_other_id": True}),
    ):
        with pytest.warns(OtherIdWarning, match=f"trained on {TRIANGLE} and runs on {SPINNING}"):
            policy.attach(gym.make(SPINNING), **attach)
    with pytest.warns(OtherIdWarning):
        controller = make_controller(str(triangle_ppo()), gym.make_vec(SPINNING, num_envs=1), allow_other_id=True)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the opt-in is kept for later attaches, and warned about once
        record = rollout(controller, SPINNING, [0, 1], env_kwargs=SHORT)
    assert record.rewards.shape == (2, 5)


def test_its_own_id_runs_without_a_warning() -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        controller = make_controller("ppo", gym.make_vec(TRIANGLE, num_envs=1))
        rollout(controller, TRIANGLE, [0], env_kwargs=SHORT)


def test_a_policy_without_an_id_runs_with_a_warning(tmp_path: Path) -> None:
    """Files written before the id was recorded (env_id null) cannot be checked: they run, and say so."""
    copy = tmp_path / "old"
    shutil.copytree(triangle_ppo(), copy)
    metadata = json.loads((copy / METADATA_FILE).read_text())
    metadata["env_id"] = None
    (copy / METADATA_FILE).write_text(json.dumps(metadata))
    write_manifest(copy, [path.name for path in copy.iterdir()])
    policy = TrainedPolicy(copy)
    with pytest.warns(OtherIdWarning, match="records no env id"):
        policy.attach(gym.make(SPINNING))


def test_compare_refuses_another_id_unless_allowed(tmp_path: Path) -> None:
    arguments = ["--env", SPINNING, "--controllers", str(triangle_ppo()), "--episodes", "2", "--no-plots"]
    with pytest.raises(OtherIdError, match="--allow-other-id"):
        agents.compare.main([*arguments, "--out", str(tmp_path / "refused")])
    assert not (tmp_path / "refused" / "comparison.md").exists()
    with pytest.warns(OtherIdWarning, match=SPINNING):
        records, _ = compare(
            CompareConfig(
                SPINNING,
                [str(triangle_ppo())],
                episodes=2,
                out=tmp_path / "allowed",
                plots=False,
                env_kwargs=SHORT,
                allow_other_id=True,
            )
        )
    assert records[0].rewards.shape == (2, 5)
    assert agents.compare.build_parser().parse_args(["--allow-other-id"]).allow_other_id


def test_benchmark_runs_a_policy_on_its_own_id_only_unless_allowed(tmp_path: Path) -> None:
    settings = dict(
        env_ids=[TRIANGLE, SPINNING],
        controllers=[str(triangle_ppo())],
        episodes=2,
        plots=False,
        reference="lqr",
        bootstrap_reps=100,
        env_kwargs=SHORT,
    )
    results = benchmark(BenchmarkConfig(out=tmp_path / "own", **settings))
    assert str(triangle_ppo()) in results["per_id"][TRIANGLE]["controllers"]
    missing = results["per_id"][SPINNING]["missing"]
    assert missing == [
        {"controller": str(triangle_ppo()), "reason": f"trained on {TRIANGLE}; --allow-other-id runs it on other ids"}
    ]
    with pytest.warns(OtherIdWarning):
        results = benchmark(BenchmarkConfig(out=tmp_path / "allowed", allow_other_id=True, **settings))
    assert str(triangle_ppo()) in results["per_id"][SPINNING]["controllers"]
