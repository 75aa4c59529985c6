"""Run directories: an earlier run is kept without --force, a run resumes from its own directory,
and a checkpoint that does not fit is refused."""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

import pytest

import agents.compare
import agents.convert
import agents.evaluation.comparison
import agents.policies
import agents.policies.loaded
import agents.train
import agents.training.callbacks
import agents.training.sb3
from agents.common.files import OutputError, OutputExistsError
from agents.policies import TrainedPolicy, shipped_models
from agents.policies.format import save_policy, verify_manifest
from agents.policies.layout import PolicyFormatError
from agents.policies.spec import PolicySpec
from agents.training.config import TrainConfig
from agents.training.sb3 import train
from tests.agents.helpers import ENV

TINY = dict(
    timesteps=256,
    num_envs=4,
    overrides={"n_steps": 64, "batch_size": 64, "n_epochs": 1},
    eval_freq=128,
    eval_episodes=2,
    progress_bar=False,
)


@pytest.mark.slow
def test_train_refuses_to_overwrite_a_run_without_force(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    run = train(TrainConfig("ppo", ENV, seed=3, out=tmp_path, checkpoint_freq=128, **TINY))
    assert sorted(p.name for p in (run / "checkpoints").iterdir()) == ["ppo_128_steps", "ppo_256_steps"]
    config = (run / "config.yml").read_text()
    with monkeypatch.context() as patch:
        patch.setattr(
            agents.training.sb3, "make_training_env", lambda *a, **k: pytest.fail("env built before the refusal")
        )
        with pytest.raises(OutputExistsError, match=r"already holds a run .*--force"):
            train(TrainConfig("ppo", ENV, seed=3, out=tmp_path, checkpoint_freq=128, **TINY))
    assert (run / "config.yml").read_text() == config
    # Another seed: another run directory.
    train(TrainConfig("ppo", ENV, seed=4, out=tmp_path, checkpoint_freq=128, **TINY))
    # --force replaces the run: the earlier checkpoints go, new ones come.
    train(TrainConfig("ppo", ENV, seed=3, out=tmp_path, checkpoint_freq=10_000, force=True, **TINY))
    assert not (run / "checkpoints").exists() or not any((run / "checkpoints").iterdir())
    assert TrainedPolicy(run).metadata["num_timesteps"] == 256
    # A symlink anywhere in the run directory is refused, even with --force.
    (run / "best" / "evaluations.json").unlink()
    (run / "best" / "evaluations.json").symlink_to(tmp_path / "elsewhere.json")
    with pytest.raises(OutputError, match="symlink"):
        train(TrainConfig("ppo", ENV, seed=3, out=tmp_path, force=True, **TINY))


@pytest.mark.slow
def test_train_resumes_from_its_own_directory_with_force(tmp_path: Path) -> None:
    run = train(TrainConfig("ppo", ENV, seed=0, out=tmp_path, checkpoint_freq=128, **TINY))
    checkpoint = run / "checkpoints" / "ppo_128_steps"
    with pytest.raises(OutputExistsError):
        train(TrainConfig("ppo", ENV, seed=0, out=tmp_path, resume=checkpoint, **TINY))
    train(TrainConfig("ppo", ENV, seed=0, out=tmp_path, resume=checkpoint, force=True, checkpoint_freq=10_000, **TINY))
    assert TrainedPolicy(run).metadata["num_timesteps"] == 128 + 256
    assert checkpoint.is_dir() and not (run / "checkpoints" / "ppo_256_steps").exists()


@pytest.mark.slow
def test_resume_refuses_a_checkpoint_that_does_not_fit(tmp_path: Path) -> None:
    run = train(TrainConfig("ppo", ENV, seed=0, out=tmp_path / "a", checkpoint_freq=10_000, **TINY))
    overrides = {**TINY["overrides"], "policy_kwargs": {"net_arch": [16], "activation_fn": "relu"}}
    with pytest.raises(PolicyFormatError, match="net_arch.*resume with the run's hyperparameters"):
        train(TrainConfig("ppo", ENV, seed=0, out=tmp_path / "b", resume=run, **{**TINY, "overrides": overrides}))
    with pytest.raises(PolicyFormatError, match="--algo ppo"):
        train(TrainConfig("sac", ENV, seed=0, out=tmp_path / "c", resume=run, **{**TINY, "overrides": {}}))
    with pytest.raises(PolicyFormatError, match="inference only"):
        train(TrainConfig("ppo", ENV, seed=0, out=tmp_path / "d", resume=shipped_models(ENV)["ppo"], **TINY))


@pytest.mark.slow
def test_two_training_commands_on_the_same_output_cannot_both_write_it(tmp_path: Path) -> None:
    """Two agents.train processes on the same --out, env, algorithm and seed, started 0.3 s apart:
    one trains, the other is refused (the directory's claim while the first runs, or the earlier
    run once it is done) and writes nothing; the run directory holds the winner's run."""
    hyperparams = tmp_path / "tiny.yml"
    hyperparams.write_text(
        f"{ENV}:\n  n_timesteps: 512\n  n_envs: 2\n  policy: MlpPolicy\n  n_steps: 64\n  batch_size: 64\n"
        "  n_epochs: 1\n"
    )
    out = tmp_path / "runs"

    def start() -> subprocess.Popen[str]:
        arguments = ["--env", ENV, "--out", str(out), "--hyperparams", str(hyperparams), "--no-progress"]
        arguments += ["--eval-freq", "256", "--eval-episodes", "2", "--checkpoint-freq", "100000"]
        return subprocess.Popen(
            [sys.executable, "-m", "agents.train", *arguments],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            cwd=Path(__file__).resolve().parents[3],
        )

    first = start()
    time.sleep(0.3)
    second = start()
    results = [process.communicate(timeout=600) for process in (first, second)]
    codes = [first.returncode, second.returncode]
    assert sorted(codes) == [0, 1], (codes, results)
    refused = results[codes.index(1)][1]
    assert "in use by another running command" in refused or "already holds a run" in refused, refused
    assert "Traceback" not in refused
    run = out / ENV / "ppo_seed0"
    assert TrainedPolicy(run).metadata["num_timesteps"] == 512
    verify_manifest(run / "best", strict=False)


@pytest.mark.slow
def test_a_symlink_below_out_is_refused_before_any_work(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    out, elsewhere = tmp_path / "runs", tmp_path / "elsewhere"
    out.mkdir()
    elsewhere.mkdir()
    (out / ENV).symlink_to(elsewhere)  # out/<id> -> elsewhere
    monkeypatch.setattr(
        agents.training.sb3, "make_training_env", lambda *a, **k: pytest.fail("env built before the refusal")
    )
    with pytest.raises(OutputError, match=rf"{ENV} is a symlink .*refusing to write through it"):
        train(TrainConfig("ppo", ENV, seed=0, out=out, **TINY))
    assert list(elsewhere.iterdir()) == []


@pytest.mark.slow
def test_an_interrupted_best_save_leaves_best_verifying(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    run = train(TrainConfig("ppo", ENV, seed=5, out=tmp_path, checkpoint_freq=10_000, **TINY))
    before = {p.name: p.read_bytes() for p in (run / "best").iterdir()}
    real_save = agents.training.callbacks.save_policy

    def save_then_interrupt(directory: Path, *args: object, **kwargs: object) -> None:
        real_save(directory, *args, **kwargs)
        (Path(directory) / "policy.json").write_text("{}")  # a half-replaced directory, if it were in place
        raise KeyboardInterrupt

    monkeypatch.setattr(agents.training.callbacks, "save_policy", save_then_interrupt)
    # Resumed from best/ itself, which --force therefore keeps; its first new best is interrupted.
    resumed = TrainConfig(
        "ppo", ENV, seed=5, out=tmp_path, checkpoint_freq=10_000, force=True, resume=run / "best", **TINY
    )
    with pytest.raises(KeyboardInterrupt):
        train(resumed)
    verify_manifest(run / "best", strict=False)
    assert {p.name: p.read_bytes() for p in (run / "best").iterdir()} == before
    assert not [p for p in run.iterdir() if p.name.startswith(".best.")]  # no staging directory left


@pytest.mark.parametrize(
    ("spec", "normalized", "message"),
    [
        (
            PolicySpec(residual_on="lqr"),
            True,
            r"policy.json records residual_on: lqr, the run's hyperparameters None: the checkpoint's outputs are "
            r"corrections to lqr's actions",
        ),
        (PolicySpec(multiagent={}), True, r"policy.json records multiagent: \{\}, the run's hyperparameters None"),
        (PolicySpec(), False, r"policy.json records normalization: false, but the run's hyperparameters' 'normalize'"),
    ],
)
def test_resume_refuses_a_checkpoint_whose_weights_mean_something_else_before_any_work(
    sb3_model: tuple[object, object],
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    spec: PolicySpec,
    normalized: bool,
    message: str,
) -> None:
    """A checkpoint trained with residual_on: lqr, resumed with plain hyperparameters, continued
    silently, and its corrections became absolute thrust. Every recorded setting that changes
    what the weights mean is checked against the run's, naming the file and the entry, before
    an env is built."""
    model, venv = sb3_model
    checkpoint = save_policy(
        tmp_path / "checkpoint", model, venv if normalized else None, ENV, training_state=True, spec=spec
    )
    monkeypatch.setattr(agents.training.sb3, "make_training_env", lambda *a, **k: pytest.fail("env built"))
    with pytest.raises(PolicyFormatError, match=message) as raised:
        train(TrainConfig("ppo", ENV, seed=0, out=tmp_path / "out", resume=checkpoint, **TINY))
    assert "resume with the run's hyperparameters" in str(raised.value)
    assert not (tmp_path / "out").exists() or not any((tmp_path / "out").rglob("config.yml"))
