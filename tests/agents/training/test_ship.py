"""Shipping (agents.training.shipping, the command agents.ship): the shipped model is the best
candidate on the evaluation seeds, every run is recorded."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import gymnasium as gym
import pytest

import agents.training.shipping
from agents.common.files import OutputError
from agents.evaluation.rollout import rollout
from agents.policies import TrainedPolicy, make_controller, shipped_models
from agents.policies.format import verify_manifest
from agents.ship import main
from agents.training.config import TrainConfig
from agents.training.hyperparams import HyperparameterError, load_hyperparameters
from agents.training.sb3 import train
from agents.training.selection import evaluation_seeds
from agents.training.shipping import RunFileError, ship
from tether_gym import ENV_IDS, HARD_TRACK

ENV = "TetherTetrahedron-v0"
TINY = dict(
    timesteps=256,
    num_envs=4,
    overrides={"n_steps": 64, "batch_size": 64, "n_epochs": 1, "policy_kwargs": {"log_std_init": 0.0}},
    eval_freq=128,
    eval_episodes=2,
    checkpoint_freq=10_000,
    progress_bar=False,
)


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> list[Path]:
    out = tmp_path_factory.mktemp("runs")
    return [train(TrainConfig("ppo", ENV, seed=seed, out=out, **TINY)) for seed in (0, 1, 2)]


def _mean_on_evaluation_seeds(policy_dir: Path, episodes: int) -> float:
    policy = TrainedPolicy(policy_dir)
    return float(rollout(policy, ENV, evaluation_seeds(episodes)).rewards.sum(axis=1).mean())


@pytest.mark.slow
def test_ship_picks_the_best_run_on_the_evaluation_seeds(runs: list[Path], tmp_path: Path) -> None:
    records = ship(runs, tmp_path / "models", episodes=4)
    means = [_mean_on_evaluation_seeds(run / "best", 4) for run in runs]
    assert [r["mean_return"] for r in records] == pytest.approx(means, rel=1e-9)
    best = max(range(3), key=lambda i: means[i])
    assert [r["shipped"] for r in records] == [i == best for i in range(3)]
    shipped = tmp_path / "models" / ENV / "ppo"
    verify_manifest(shipped)
    assert sorted(p.name for p in shipped.iterdir()) == sorted(
        [
            "policy.json",
            "policy.safetensors",
            "normalization.json",
            "config.yml",
            "evaluations.json",
            "reference_actions.safetensors",
            "MANIFEST.sha256",
        ]
    )
    assert _mean_on_evaluation_seeds(shipped, 4) == pytest.approx(means[best], rel=1e-12)
    table = json.loads((tmp_path / "models" / "training_runs.json").read_text())
    assert sorted(entry["seed"] for entry in table["runs"]) == [0, 1, 2]
    bar = records[0]["bar"]
    assert bar == max(records[0]["baselines"], key=records[0]["baselines"].get)
    for record, run in zip(records, runs, strict=True):
        assert record["difference"] == pytest.approx(record["mean_return"] - record["bar_mean_return"], abs=1e-9)
        assert (
            record["wall_time_s"] > 0 and record["timesteps"] == TrainedPolicy(run / "best").metadata["num_timesteps"]
        )
    markdown = (tmp_path / "models" / "training_runs.md").read_text()
    assert markdown.count(f"| {ENV} | ppo |") == 3 + 1 and markdown.count("**yes**") == 1  # 3 runs, 1 shipped row
    # The shipped copy passed again beside the run it came from is one candidate, not two.
    again = ship([*runs, shipped], tmp_path / "models", episodes=4, force=True)
    assert len(again) == 3 and [r["shipped"] for r in again] == [i == best for i in range(3)]


@pytest.mark.slow
def test_the_shipped_reproduce_command_retrains_the_same_weights(runs: list[Path], tmp_path: Path) -> None:
    out = tmp_path / "models"
    (record,) = ship(runs[:1], out, episodes=2)
    command = record["reproduce"].split()
    assert command[:3] == ["python", "-m", "agents.train"]
    config = out / ENV / "ppo" / "config.yml"
    assert command[command.index("--hyperparams") + 1] == str(config)
    # The reproduce command holds whatever the YAML files say today: tiny settings no YAML has.
    again = train(
        TrainConfig(
            "ppo",
            ENV,
            seed=int(command[command.index("--seed") + 1]),
            out=tmp_path / "again",
            hyperparams_file=config,
            **{k: v for k, v in TINY.items() if k not in ("timesteps", "num_envs", "overrides")},
        )
    )
    assert (again / "policy.safetensors").read_bytes() == (runs[0] / "policy.safetensors").read_bytes()
    with pytest.raises(HyperparameterError, match="--env TetherTetrahedron-v0"):
        load_hyperparameters("ppo", "TetherChain-v0", config)
    with pytest.raises(HyperparameterError, match="--algo ppo"):
        load_hyperparameters("sac", ENV, config)


@pytest.mark.slow
def test_ship_refuses_to_replace_a_shipped_model_without_force(runs: list[Path], tmp_path: Path) -> None:
    out = tmp_path / "models"
    ship(runs[:1], out, episodes=2)
    before = (out / ENV / "ppo" / "policy.safetensors").read_bytes()
    with pytest.raises(OutputError, match="--force"):
        ship(runs[1:2], out, episodes=2)
    assert (out / ENV / "ppo" / "policy.safetensors").read_bytes() == before
    # The shipped model itself can stand again, beside a new run; the table keeps one row per candidate.
    ship([out / ENV / "ppo", runs[1]], out, episodes=2, force=True)
    assert len(json.loads((out / "training_runs.json").read_text())["runs"]) == 2


def test_ship_command_errors_are_clear(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError, match="holds no policy"):
        main([str(tmp_path), "--out", str(tmp_path / "models")])
    with pytest.raises(SystemExit):
        main([str(tmp_path), "--episodes", "1"])


@pytest.mark.slow
@pytest.mark.parametrize("env_id", list(ENV_IDS))
def test_every_id_ships_a_learned_model_that_beats_passive(env_id: str) -> None:
    """Every standard-track id ships one; a hard-track id may have none until it is trained, and
    every model it ships beats passive too."""
    models = shipped_models(env_id)
    if not models and env_id in HARD_TRACK:
        pytest.skip(f"{env_id} (hard track) ships no learned controller yet")
    assert models, f"{env_id} has no shipped learned controller in agents/models"
    env = gym.make(env_id)
    seeds = list(range(10_000, 10_008))
    passive = rollout(make_controller("passive", env), env_id, seeds).rewards.sum(axis=1)
    for name in models:
        verify_manifest(models[name])  # every file listed, each as shipped
        returns = rollout(make_controller(name, env), env_id, seeds).rewards.sum(axis=1)
        assert returns.mean() > passive.mean(), (name, returns.mean(), passive.mean())


@pytest.fixture
def no_rollouts(monkeypatch: pytest.MonkeyPatch) -> None:
    """Make any rollout of ship fail the test: what ship refuses, it refuses before any work."""
    monkeypatch.setattr(
        agents.training.shipping, "evaluate_candidates", lambda *a, **k: pytest.fail("rolled out before the refusal")
    )


@pytest.mark.slow
def test_ship_never_deletes_files_it_did_not_write(runs: list[Path], tmp_path: Path) -> None:
    out = tmp_path / "models"
    ship(runs[:1], out, episodes=2)
    target = out / ENV / "ppo"
    before = {p.name: p.read_bytes() for p in target.iterdir()}
    (target / "notes.txt").write_text("mine")
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(
            agents.training.shipping, "evaluate_candidates", lambda *a, **k: pytest.fail("rolled out before refusing")
        )
        for force in (False, True):
            with pytest.raises(OutputError, match=r"notes\.txt, which ship does not write"):
                ship(runs[1:2], out, episodes=2, force=force)
    assert (target / "notes.txt").read_text() == "mine"
    assert {p.name: p.read_bytes() for p in target.iterdir() if p.name != "notes.txt"} == before


@pytest.mark.slow
def test_ship_refuses_a_symlink_below_out_before_any_rollout(
    runs: list[Path], tmp_path: Path, no_rollouts: None
) -> None:
    out, elsewhere = tmp_path / "models", tmp_path / "elsewhere"
    elsewhere.mkdir()
    out.mkdir()
    (out / ENV).symlink_to(elsewhere)
    with pytest.raises(OutputError, match=rf"{ENV} is a symlink"):
        ship(runs[:1], out, episodes=2)
    (out / ENV).unlink()
    (out / "training_runs.md").symlink_to(elsewhere / "table.md")
    with pytest.raises(OutputError, match=r"training_runs\.md is a symlink"):
        ship(runs[:1], out, episodes=2)
    assert list(elsewhere.iterdir()) == []


@pytest.mark.slow
@pytest.mark.parametrize(
    ("table", "message"),
    [
        ("{", r"training_runs\.json is not valid JSON"),
        ('{"runs": {}}', r"training_runs\.json: runs must be a list"),
        ('{"runs": [{"env_id": 1}]}', r"training_runs\.json: runs\[0\]\.env_id must be a string"),
        ("[" * 5000 + "]" * 5000, r"training_runs\.json nests"),
    ],
)
def test_ship_refuses_a_malformed_runs_table_before_any_rollout(
    runs: list[Path], tmp_path: Path, table: str, message: str, no_rollouts: None
) -> None:
    out = tmp_path / "models"
    out.mkdir()
    (out / "training_runs.json").write_text(table)
    with pytest.raises(RunFileError, match=message):
        ship(runs[:1], out, episodes=2)


@pytest.mark.slow
@pytest.mark.parametrize(
    ("name", "text", "message"),
    [
        ("config.yml", "seed: [", r"config\.yml is not valid YAML"),
        ("config.yml", "seed: one\n", r"config\.yml: seed must be an integer"),
        ("config.yml", "- a list\n", r"config\.yml: the file must be a mapping"),
        ("best/evaluations.json", '{"first_beat": {"lqr": {"timesteps": "x"}}}', r"first_beat\.lqr\.wall_time_s"),
        ("best/evaluations.json", '{"training": []}', r"evaluations\.json: training must be an object"),
    ],
)
def test_ship_refuses_a_malformed_run_file_before_any_rollout(
    runs: list[Path], tmp_path: Path, name: str, text: str, message: str, no_rollouts: None
) -> None:
    run = tmp_path / "run"
    shutil.copytree(runs[0], run)
    (run / name).write_text(text)
    with pytest.raises(RunFileError, match=message):
        ship([run], tmp_path / "models", episodes=2)
    assert not (tmp_path / "models" / ENV).exists()


@pytest.mark.slow
def test_an_interrupted_install_leaves_the_shipped_model_whole(
    runs: list[Path], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    out = tmp_path / "models"
    ship(runs[:1], out, episodes=2)
    target = out / ENV / "ppo"
    before = {p.name: p.read_bytes() for p in target.iterdir()}

    def interrupted(*args: object) -> None:
        raise KeyboardInterrupt

    monkeypatch.setattr(agents.training.shipping, "_write_reference_actions", interrupted)
    with pytest.raises(KeyboardInterrupt):
        ship(runs[1:], out, episodes=2, force=True)
    verify_manifest(target)
    assert {p.name: p.read_bytes() for p in target.iterdir()} == before
    assert sorted(p.name for p in (out / ENV).iterdir()) == ["ppo"]  # no staging directory left
