"""Trust and care in the agents layer: model files that cannot run code, careful output files,
and errors that name the argument.

The crafted model directories hold real payloads: unpickling them writes a marker file (and
then returns the genuine object, so that a trusted load still works). A test first shows that
the payload fires when unpickled directly, so the tests that expect no marker can fail.
"""

from __future__ import annotations

import base64
import json
import operator
import os
import pickle
import shutil
import time
import warnings
import zipfile
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import torch
import yaml
from stable_baselines3 import PPO, SAC

import agents.compare
import agents.convert
import agents.evaluation.comparison
import agents.policies
import agents.policies.loaded
import agents.train
import agents.training.sb3
from agents.common.cli import REFERENCE_FILE
from agents.common.files import OutputError, OutputExistsError, atomic_write_text
from agents.evaluation.comparison import CompareConfig, compare
from agents.evaluation.rollout import rollout
from agents.policies import MODELS_DIR, OtherIdWarning, TrainedPolicy, make_controller, shipped_models
from agents.policies.conversion import ConvertConfig, convert
from agents.policies.format import load_policy, load_tensors, load_training_state, save_policy
from agents.policies.layout import ChecksumError, PolicyFormatError
from agents.policies.pickled import PickleNotTrustedError, PickleTrustWarning
from agents.policies.reference import reference_observations
from agents.training.config import TrainConfig
from agents.training.hyperparams import HyperparameterError, load_hyperparameters, validate_hyperparameters
from agents.training.sb3 import make_training_env, train
from tether_gym import ENV_IDS

ENV = "TetherTetrahedron-v0"
SHORT = {"max_episode_steps": 20}


# ---------------------------------------------------------------------------------------------
# Fixtures: a tiny SB3 model, its pickle-based files, and crafted copies with payloads
# ---------------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def sb3_model() -> tuple[PPO, object]:
    """A tiny PPO (256 steps) with VecNormalize statistics, in memory."""
    venv = make_training_env(ENV, 4, seed=0, normalize={"norm_obs": True, "norm_reward": True}, env_kwargs=SHORT)
    model = PPO(
        "MlpPolicy",
        venv,
        n_steps=64,
        batch_size=64,
        n_epochs=2,
        seed=0,
        device="cpu",
        policy_kwargs={"net_arch": [32, 32], "log_std_init": -1.0},
    )
    model.learn(256)
    return model, venv


@pytest.fixture(scope="module")
def sb3_run(sb3_model: tuple[PPO, object], tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The tiny model as SB3 writes it: model.zip + vecnormalize.pkl (+ config.yml)."""
    model, venv = sb3_model
    run = tmp_path_factory.mktemp("sb3_run")
    model.save(run / "model.zip")
    venv.save(str(run / "vecnormalize.pkl"))
    (run / "config.yml").write_text(yaml.safe_dump({"algo": "ppo", "env_id": ENV, "seed": 0}))
    return run


def payload(marker: Path, genuine: bytes) -> bytes:
    """Pickle bytes that write ``marker`` when unpickled, then return ``pickle.loads(genuine)``."""
    code = (
        f"(__import__('pathlib').Path({str(marker)!r}).write_text('pwned'), __import__('pickle').loads({genuine!r}))[1]"
    )

    class Payload:
        def __reduce__(self) -> tuple:
            return (eval, (code,))

    return pickle.dumps(Payload())


def crafted_zip(source: Path, target: Path, marker: Path) -> None:
    """A copy of an SB3 model zip whose cloudpickled ``policy_class`` field carries a payload."""
    with zipfile.ZipFile(source) as archive:
        members = {name: archive.read(name) for name in archive.namelist()}
    data = json.loads(members["data"])
    genuine = base64.b64decode(data["policy_class"][":serialized:"])
    data["policy_class"][":serialized:"] = base64.b64encode(payload(marker, genuine)).decode()
    members["data"] = json.dumps(data).encode()
    with zipfile.ZipFile(target, "w") as archive:
        for name, content in members.items():
            archive.writestr(name, content)


@pytest.fixture(params=["vecnormalize.pkl", "model.zip"])
def crafted(request: pytest.FixtureRequest, sb3_run: Path, tmp_path: Path) -> tuple[Path, Path]:
    """(run directory, marker): a copy of the SB3 run with a payload in one of its two files."""
    run, marker = tmp_path / "crafted", tmp_path / "marker"
    shutil.copytree(sb3_run, run)
    if request.param == "vecnormalize.pkl":
        (run / "vecnormalize.pkl").write_bytes(payload(marker, (sb3_run / "vecnormalize.pkl").read_bytes()))
    else:
        crafted_zip(sb3_run / "model.zip", run / "model.zip", marker)
    return run, marker


def test_the_payloads_are_real(crafted: tuple[Path, Path]) -> None:
    """Unpickled directly, each crafted file runs its code (and still gives the genuine object)."""
    run, marker = crafted
    from stable_baselines3.common.save_util import load_from_zip_file
    from stable_baselines3.common.vec_env import VecNormalize

    normalizer = pickle.loads((run / "vecnormalize.pkl").read_bytes())
    data, _, _ = load_from_zip_file(run / "model.zip")
    assert marker.read_text() == "pwned"
    assert isinstance(normalizer, VecNormalize) and data["policy_class"].__name__ == "ActorCriticPolicy"


def test_no_loader_or_command_unpickles_without_the_opt_in(crafted: tuple[Path, Path], tmp_path: Path) -> None:
    run, marker = crafted
    env = gym.make_vec(ENV, num_envs=1)
    attempts = [
        lambda: TrainedPolicy(run),
        lambda: TrainedPolicy(run / "model.zip"),
        lambda: make_controller(str(run), env),
        lambda: agents.compare.main(
            ["--controllers", "passive", str(run), "--episodes", "2", "--out", str(tmp_path / "compare")]
        ),
        lambda: agents.train.main(
            [
                "--resume",
                str(run / "model.zip"),
                "--out",
                str(tmp_path / "runs"),
                "--timesteps",
                "64",
                "--n-envs",
                "4",
                "--no-progress",
            ]
        ),
        lambda: agents.train.main(["--resume", str(run), "--out", str(tmp_path / "runs"), "--timesteps", "64"]),
        lambda: agents.convert.main([str(run), str(tmp_path / "converted")]),
    ]
    for attempt in attempts:
        with pytest.raises(PickleNotTrustedError, match="arbitrary code") as error:
            attempt()
        assert "--trust-pickle" in str(error.value) and "agents.convert" in str(error.value)
    assert not marker.exists()
    assert not (tmp_path / "compare" / "comparison.md").exists()
    assert not (tmp_path / "runs").exists()  # refused before the run directory was made


def test_opting_in_loads_pickle_files_with_a_warning(crafted: tuple[Path, Path], tmp_path: Path) -> None:
    """With the opt-in, every path loads the crafted files -- and so runs their code, which is
    what the warning is about."""
    run, marker = crafted
    env = gym.make_vec(ENV, num_envs=1)
    attempts = [
        lambda: TrainedPolicy(run, trust_pickle=True).predict(np.zeros((2, 30), dtype=np.float32)),
        lambda: make_controller(str(run), env, trust_pickle=True),
        lambda: agents.compare.main(
            [
                "--controllers",
                "passive",
                str(run),
                "--episodes",
                "2",
                "--no-plots",
                "--trust-pickle",
                "--out",
                str(tmp_path / "compare"),
            ]
        ),
        lambda: agents.train.main(
            [
                "--resume",
                str(run / "model.zip"),
                "--trust-pickle",
                "--out",
                str(tmp_path / "runs"),
                "--timesteps",
                "64",
                "--n-envs",
                "4",
                "--no-progress",
                "--eval-freq",
                "100000",
                "--checkpoint-freq",
                "100000",
                "--eval-episodes",
                "2",
            ]
        ),
        lambda: agents.convert.main([str(run), str(tmp_path / "converted"), "--trust-pickle"]),
    ]
    for attempt in attempts:
        with pytest.warns(PickleTrustWarning, match="runs any code"):
            attempt()
        assert marker.exists()
        marker.unlink()
    assert f"| {run} |" in (tmp_path / "compare" / "comparison.md").read_text()
    resumed = TrainedPolicy(tmp_path / "runs" / ENV / "ppo_seed0")
    assert resumed.metadata["num_timesteps"] == 512  # 256 in the zip + one rollout of 4 x 64, counted on
    TrainedPolicy(tmp_path / "converted")  # the converted copy loads without the opt-in
    assert not marker.exists()


def test_safe_files_that_hold_pickle_payloads_are_rejected(sb3_model: tuple[PPO, object], tmp_path: Path) -> None:
    model, venv = sb3_model
    marker = tmp_path / "marker"
    for name in ("policy.json", "policy.safetensors", "normalization.json"):
        directory = save_policy(tmp_path / name, model, venv, ENV)
        (directory / name).write_bytes(payload(marker, pickle.dumps(None)))
        with pytest.raises(ChecksumError, match=name):  # the manifest catches the change first
            TrainedPolicy(directory)
        (directory / "MANIFEST.sha256").unlink()
        with pytest.raises(PolicyFormatError, match=name):  # and the parsers reject it anyway
            TrainedPolicy(directory)
    assert not marker.exists()


@pytest.mark.parametrize(
    ("key", "value", "message"),
    [
        ("algo", "evil", "algorithm 'evil'"),
        ("policy", "builtins.eval", "policy 'builtins.eval'"),
        ("policy_kwargs", {"activation_fn": "os.system"}, "activation_fn"),
        ("policy_kwargs", {"features_extractor_class": "subprocess.Popen"}, "features_extractor_class"),
        ("policy_kwargs", {"__init__": 1}, "__init__"),
    ],
)
def test_policy_metadata_cannot_name_arbitrary_code(
    sb3_model: tuple[PPO, object], tmp_path: Path, key: str, value: object, message: str
) -> None:
    model, venv = sb3_model
    directory = save_policy(tmp_path / "policy", model, venv, ENV)
    metadata = json.loads((directory / "policy.json").read_text())
    metadata[key] = value
    (directory / "policy.json").write_text(json.dumps(metadata))
    (directory / "MANIFEST.sha256").unlink()
    with pytest.raises(PolicyFormatError, match=message):
        load_policy(directory)


def test_policy_metadata_numbers_must_be_finite(sb3_model: tuple[PPO, object], tmp_path: Path) -> None:
    model, venv = sb3_model
    directory = save_policy(tmp_path / "policy", model, venv, ENV)
    text = (directory / "policy.json").read_text()
    assert '"log_std_init": -1.0' in text
    (directory / "policy.json").write_text(text.replace('"log_std_init": -1.0', '"log_std_init": -1e999'))
    (directory / "MANIFEST.sha256").unlink()
    with pytest.raises(PolicyFormatError, match="overflows"):
        load_policy(directory)


# ---------------------------------------------------------------------------------------------
# The safe format: round trips, conversion, the shipped models and their checksums
# ---------------------------------------------------------------------------------------------


def sb3_actions(model: object, normalizer: object, observations: np.ndarray) -> np.ndarray:
    """The SB3 pipeline: VecNormalize.normalize_obs, then model.predict(deterministic=True)."""
    return model.predict(normalizer.normalize_obs(observations).astype(np.float32), deterministic=True)[0]


def test_safe_round_trip_gives_bit_identical_actions(sb3_model: tuple[PPO, object], tmp_path: Path) -> None:
    model, venv = sb3_model
    observations = reference_observations(
        4000, model.observation_space, venv.obs_rms.mean, venv.obs_rms.var, np.random.default_rng(1)
    )
    directory = save_policy(tmp_path / "policy", model, venv, ENV)
    rng_state = torch.random.get_rng_state()
    policy = TrainedPolicy(directory)
    assert torch.equal(rng_state, torch.random.get_rng_state())  # loading draws no random numbers of the caller's
    assert policy.predict(observations)[0].tobytes() == sb3_actions(model, venv, observations).tobytes()
    for row in observations[:20]:  # one observation at a time too (torch may round a batch differently)
        assert policy.predict(row)[0].tobytes() == sb3_actions(model, venv, row).tobytes()


def test_sac_round_trip_and_resume_state(tmp_path: Path) -> None:
    venv = make_training_env(ENV, 2, seed=0, normalize={"norm_obs": True, "norm_reward": False}, env_kwargs=SHORT)
    kwargs = dict(
        learning_starts=20,
        batch_size=16,
        gradient_steps=1,
        buffer_size=1000,
        seed=0,
        device="cpu",
        policy_kwargs={"net_arch": [16, 16]},
    )
    model = SAC("MlpPolicy", venv, **kwargs)
    model.learn(60)
    directory = save_policy(tmp_path / "sac", model, venv, ENV, training_state=True)
    observations = reference_observations(
        500, model.observation_space, venv.obs_rms.mean, venv.obs_rms.var, np.random.default_rng(2)
    )
    assert (
        TrainedPolicy(directory).predict(observations)[0].tobytes() == sb3_actions(model, venv, observations).tobytes()
    )
    fresh_venv = make_training_env(ENV, 2, seed=5, normalize={"norm_obs": True, "norm_reward": False}, env_kwargs=SHORT)
    fresh = SAC("MlpPolicy", fresh_venv, **kwargs)
    load_training_state(fresh, directory, fresh_venv)
    assert fresh.num_timesteps == model.num_timesteps
    assert torch.equal(fresh.log_ent_coef, model.log_ent_coef)
    for name in ("actor.optimizer", "critic.optimizer", "ent_coef_optimizer"):
        ours, theirs = (operator.attrgetter(name)(m).state_dict() for m in (fresh, model))
        assert ours["param_groups"] == theirs["param_groups"]
        for index, entries in theirs["state"].items():
            for key, value in entries.items():
                assert torch.equal(ours["state"][index][key], value), (name, index, key)
    np.testing.assert_array_equal(fresh_venv.obs_rms.mean, venv.obs_rms.mean)


def test_a_saved_optimizer_with_another_number_of_param_groups_is_refused(tmp_path: Path) -> None:
    """Extra saved param groups must not be dropped quietly: the optimizer would resume with
    settings that are not the ones it was saved with."""
    from agents.policies.sb3_state import _restore_optimizer

    optimizer = torch.optim.Adam(torch.nn.Linear(2, 1).parameters())
    group = {
        key: list(v) if isinstance(v, tuple) else v for key, v in optimizer.state_dict()["param_groups"][0].items()
    }
    _restore_optimizer(optimizer, {"param_groups": [group]}, {}, "actor.optimizer", tmp_path)  # the fitting case loads
    for groups in ([group, dict(group)], []):
        with pytest.raises(PolicyFormatError, match=f"has {len(groups)} param groups; this model's optimizer has 1"):
            _restore_optimizer(optimizer, {"param_groups": groups}, {}, "actor.optimizer", tmp_path)


def test_converter_output_matches_sb3_load(sb3_run: Path, tmp_path: Path) -> None:
    target = tmp_path / "converted"
    with pytest.warns(PickleTrustWarning):
        convert(ConvertConfig(sb3_run, target, trust_pickle=True, reference=True))
    assert sorted(p.name for p in target.iterdir()) == sorted(
        ["MANIFEST.sha256", "config.yml", "normalization.json", "policy.json", "policy.safetensors", REFERENCE_FILE]
    )
    loaded = PPO.load(sb3_run / "model.zip", device="cpu")
    with open(sb3_run / "vecnormalize.pkl", "rb") as stream:
        normalizer = pickle.load(stream)
    observations = reference_observations(
        3000, loaded.observation_space, normalizer.obs_rms.mean, normalizer.obs_rms.var, np.random.default_rng(3)
    )
    actions = TrainedPolicy(target).predict(observations)[0]
    assert actions.tobytes() == sb3_actions(loaded, normalizer, observations).tobytes()
    with pytest.raises(OutputExistsError, match="--force"):
        convert(ConvertConfig(sb3_run, target, trust_pickle=True))
    with pytest.warns(PickleTrustWarning):
        # No --reference this time: its file goes.
        convert(ConvertConfig(sb3_run, target, trust_pickle=True, force=True))
    assert not (target / REFERENCE_FILE).exists()
    TrainedPolicy(target)


def test_converter_refuses_an_env_that_contradicts_the_run(sb3_run: Path, tmp_path: Path) -> None:
    """The converted policy.json records the id the policy runs on: --env cannot relabel a run."""
    other = next(env_id for env_id in ENV_IDS if env_id != ENV)
    with pytest.warns(PickleTrustWarning), pytest.raises(ValueError, match=f"--env {other} differs .*{ENV}"):
        convert(ConvertConfig(sb3_run, tmp_path / "relabelled", trust_pickle=True, env_id=other))
    assert not (tmp_path / "relabelled" / "policy.json").exists()


SHIPPED = [(env_id, name) for env_id in ENV_IDS for name in shipped_models(env_id)]


@pytest.mark.parametrize(("env_id", "name"), SHIPPED)
def test_shipped_models_give_their_reference_actions(env_id: str, name: str) -> None:
    """The observations and actions recorded when the model was shipped (by agents.ship, or from
    the pickle-based original, PPO.load + VecNormalize, by agents.convert), against the shipped
    safe policy.

    Recorded on another machine, the actions may differ in the last bit where torch picks other
    vector kernels, so the comparison allows 1e-6 of full thrust; a wrong weight, layer order or
    normaliser moves them by orders of magnitude more.  Within one process the safe loader is
    checked bit for bit against PPO.load (test_converter_output_matches_sb3_load)."""
    directory = shipped_models(env_id)[name]
    reference = load_tensors((directory / REFERENCE_FILE).read_bytes(), directory / REFERENCE_FILE)
    observations, expected = reference["observations"].numpy(), reference["actions"].numpy()
    assert observations.shape[0] >= 512 and np.isfinite(observations).all()
    policy = TrainedPolicy(directory)
    normalized = policy.normalizer.normalize_obs(observations).astype(np.float32) if policy.normalizer else observations
    actions = policy.policy.predict(normalized, deterministic=True)[0]  # the network's part (residual policies too)
    assert actions.dtype == expected.dtype
    np.testing.assert_allclose(actions, expected, rtol=0, atol=1e-6)
    assert not list(directory.glob("*.zip")) and not list(directory.glob("*.pkl"))


@pytest.fixture
def fake_models_dir(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """A copy of the shipped models, standing in for agents/models."""
    root = tmp_path / "models"
    shutil.copytree(MODELS_DIR, root)
    monkeypatch.setattr(agents.policies.loaded, "MODELS_DIR", root.resolve())
    return root / ENV / "ppo"


def test_a_corrupted_shipped_model_is_a_clear_error(fake_models_dir: Path) -> None:
    env = gym.make_vec(ENV, num_envs=1)
    make_controller("ppo", env)  # intact: loads
    weights = bytearray((fake_models_dir / "policy.safetensors").read_bytes())
    weights[-1] ^= 0x01  # one bit of one weight
    (fake_models_dir / "policy.safetensors").write_bytes(bytes(weights))
    with pytest.raises(ChecksumError, match=r"policy\.safetensors: SHA-256 .* does not match MANIFEST\.sha256"):
        make_controller("ppo", env)


def test_shipped_models_need_an_exact_manifest(fake_models_dir: Path) -> None:
    (fake_models_dir / "model.zip").write_bytes(b"not listed")
    with pytest.raises(ChecksumError, match="files not listed: .'model.zip'."):
        TrainedPolicy(fake_models_dir)
    (fake_models_dir / "model.zip").unlink()
    (fake_models_dir / "MANIFEST.sha256").unlink()
    assert "ppo" not in agents.policies.shipped_models(ENV)  # not offered without its manifest
    with pytest.raises(ChecksumError, match="no MANIFEST.sha256"):
        TrainedPolicy(fake_models_dir)


# ---------------------------------------------------------------------------------------------
# Careful commands
# ---------------------------------------------------------------------------------------------


@pytest.fixture
def no_work(monkeypatch: pytest.MonkeyPatch) -> None:
    """Make any rollout, controller load or env build fail the test: a refusal must come first."""

    def forbidden(*args: object, **kwargs: object) -> None:
        raise AssertionError("work started before the outputs were checked")

    monkeypatch.setattr(agents.evaluation.comparison, "rollout", forbidden)
    monkeypatch.setattr(agents.evaluation.comparison, "make_controller", forbidden)
    monkeypatch.setattr(agents.training.sb3, "make_training_env", forbidden)


def bad_outputs(tmp_path: Path) -> dict[str, Path]:
    file = tmp_path / "a_file"
    file.write_text("keep me")
    real = tmp_path / "real"
    real.mkdir()
    link = tmp_path / "link"
    link.symlink_to(real, target_is_directory=True)
    return {"is a file": file, "inside .* which is a file": file / "sub", "symlink": link}


def test_compare_refuses_a_bad_out_before_any_work(tmp_path: Path, no_work: None) -> None:
    for message, out in bad_outputs(tmp_path).items():
        start = time.perf_counter()
        with pytest.raises(OutputError, match=message):
            agents.compare.main(["--out", str(out), "--episodes", "2"])
        assert time.perf_counter() - start < 0.5, message
    assert (tmp_path / "a_file").read_text() == "keep me" and not any((tmp_path / "real").iterdir())
    if Path("/proc/self").is_dir():  # a directory nobody can create files in, even root
        with pytest.raises(OutputError, match="cannot be created|not writable"):
            agents.compare.main(["--out", "/proc/self/tether-gym-out"])


def test_compare_refuses_to_overwrite_and_to_follow_symlinks(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    out = tmp_path / "compare"
    kwargs = dict(env_id=ENV, controllers=["passive", "lqr"], episodes=2, plots=False, env_kwargs=SHORT)
    compare(CompareConfig(out=out, **kwargs))
    first = (out / "comparison.csv").read_text()
    monkeypatch.setattr(
        agents.evaluation.comparison, "rollout", lambda *a, **k: pytest.fail("rollout before the refusal")
    )
    with pytest.raises(OutputExistsError, match="comparison.md, comparison.csv .*--force"):
        compare(CompareConfig(out=out, **kwargs))
    monkeypatch.undo()
    compare(CompareConfig(out=out, force=True, **kwargs))
    assert (out / "comparison.csv").read_text() == first  # same seeds: same numbers
    assert not [p for p in out.iterdir() if p.name.startswith(".")]  # no temporary files left
    outside = tmp_path / "outside.md"
    outside.write_text("not yours")
    (out / "comparison.md").unlink()
    (out / "comparison.md").symlink_to(outside)
    with pytest.raises(OutputError, match="symlink"):
        compare(CompareConfig(out=out, force=True, **kwargs))
    assert outside.read_text() == "not yours" and (out / "comparison.md").is_symlink()


def test_atomic_write_keeps_the_old_file_when_writing_fails(tmp_path: Path) -> None:
    from agents.common.files import atomic_write

    target = tmp_path / "table.md"
    atomic_write_text(target, "old")
    with pytest.raises(RuntimeError):
        with atomic_write(target) as temporary:
            temporary.write_text("half")
            raise RuntimeError("disk full")
    assert target.read_text() == "old" and sorted(p.name for p in tmp_path.iterdir()) == ["table.md"]
    umask = os.umask(0)
    os.umask(umask)
    assert target.stat().st_mode & 0o777 == 0o666 & ~umask  # the mode a plain open() would give


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


# ---------------------------------------------------------------------------------------------
# Errors that name the key or the argument
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("default: {n_envs: 4}", "'n_timesteps' is missing"),
        ("default: {n_timesteps: 1e6}", r"'n_timesteps' must be an integer; got the text '1e6' \(YAML reads"),
        ("default: {n_timesteps: 1000, n_steps: lots}", "'n_steps' must be an integer; got the text 'lots'"),
        ("default: {n_timesteps: 1000, n_steps: 12.5}", "'n_steps' must be an integer; got 12.5"),
        (
            "default: {n_timesteps: 1000, learning_rat: 0.001}",
            "unknown key 'learning_rat' .did you mean 'learning_rate'",
        ),
        ("default: {n_timesteps: 1000, learning_rate: lin_fast}", "'learning_rate' must be a positive number or 'lin_"),
        ("default: {n_timesteps: 1000, gamma: 1.5}", r"'gamma' must be in \(0, 1\]"),
        ("default: {n_timesteps: 1000, n_epochs: true}", "'n_epochs' must be an integer, not true"),
        ("default: {n_timesteps: 1000, seed: 3}", "'seed' cannot be set in a hyperparameter file: use --seed"),
        ("default: {n_timesteps: 1000, policy: TransformerPolicy}", "'policy' must be one of"),
        (
            "default: {n_timesteps: 1000, policy_kwargs: {activation_fn: sigmoid}}",
            "'policy_kwargs.activation_fn' must be",
        ),
        (
            "default: {n_timesteps: 1000, policy_kwargs: {net_arch: [64, wide]}}",
            "'policy_kwargs.net_arch' must be a list",
        ),
        (
            "default: {n_timesteps: 1000, policy_kwargs: {netarch: [64]}}",
            "unknown key 'netarch' .did you mean 'net_arch'",
        ),
        ("default: {n_timesteps: 1000, normalize: {clip_ob: 5}}", "unknown key 'clip_ob'"),
        ("default: {n_timesteps: 1000, curriculum: {start: 0.2}}", "'curriculum' must be a mapping with exactly"),
        ("default: {n_timesteps: 1000, rollout_buffer_class: RolloutBuffer}", "'rollout_buffer_class' cannot be set"),
        (
            "default: {n_timesteps: 1000, policy_kwargs: {optimizer_kwargs: {eps: 1e-5}}}",
            "'policy_kwargs.optimizer_kwargs.eps' is the text '1e-5', not a number",
        ),
        ("default: [1, 2]", "entry 'default': must be a mapping"),
        ("TetherChain-v0: {n_timesteps: 5}", "no entry for 'TetherTetrahedron-v0' and no 'default'"),
        ("default: {n_timesteps: [1000", "not valid YAML"),
    ],
)
def test_hyperparameter_errors_name_the_key(tmp_path: Path, text: str, message: str) -> None:
    file = tmp_path / "ppo.yml"
    file.write_text(text)
    with pytest.raises(HyperparameterError, match=message):
        train(TrainConfig("ppo", ENV, out=tmp_path / "runs", hyperparams_file=file))
    assert not (tmp_path / "runs").exists()  # refused before anything was written


def test_ppo_schedules_are_unknown_keys_for_sac_and_td3() -> None:
    """SAC and TD3 take no clip_range: accepting it would fail later, inside SB3's constructor."""
    for algo in ("sac", "td3"):
        for key in ("clip_range", "clip_range_vf"):
            with pytest.raises(HyperparameterError, match=f"unknown key '{key}'; {algo}"):
                validate_hyperparameters(algo, {"n_timesteps": 100, key: 0.2})
    assert validate_hyperparameters("ppo", {"n_timesteps": 100, "clip_range": 0.2})["clip_range"] == 0.2


def test_hyperparameter_file_that_is_not_utf8(tmp_path: Path) -> None:
    file = tmp_path / "ppo.yml"
    file.write_bytes(b"default: {n_timesteps: \xff}")
    with pytest.raises(HyperparameterError, match="not UTF-8"):
        load_hyperparameters("ppo", ENV, file)


def _quietly_on_another_id(model: Path) -> None:
    """make_controller(model) on ENV with the other-id opt-in, its warning expected and silenced."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", OtherIdWarning)
        make_controller(str(model), gym.make_vec(ENV, num_envs=1), allow_other_id=True)


def test_bad_arguments_name_the_argument(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "out"
    cases = [
        (lambda: compare(CompareConfig(ENV, episodes=-3, out=out)), "episodes must be an integer >= 2"),
        (lambda: compare(CompareConfig(ENV, seed=-1, out=out)), "seed must be an integer >= 0"),
        (lambda: compare(CompareConfig(ENV, seed=1.5, out=out)), "seed must be an integer"),
        (lambda: compare(CompareConfig("Nope-v0", out=out)), "unknown env id 'Nope-v0'"),
        (
            lambda: compare(CompareConfig(ENV, controllers=["passive", "nope"], out=out, episodes=2)),
            "unknown controller 'nope'",
        ),
        (lambda: compare(CompareConfig(ENV, controllers=["lqr", "lqr"], out=out)), r"\['lqr'\] more than once"),
        (lambda: compare(CompareConfig(ENV, controllers=[], out=out)), "at least one controller"),
        (lambda: compare(CompareConfig(ENV, satellite=9, out=out, episodes=2)), r"satellite must be in 0\.\.3"),
        (
            lambda: rollout(make_controller("passive", gym.make_vec(ENV, num_envs=1)), ENV, [1.5]),
            r"seeds must be non-negative integers; got \[1\.5\]",
        ),
        (lambda: train(TrainConfig("ppo", ENV, seed=-1, out=out)), "seed must be an integer >= 0"),
        (lambda: train(TrainConfig("ppo", ENV, eval_episodes=0, out=out)), "eval_episodes must be an integer >= 1"),
        (lambda: train(TrainConfig("ppo", ENV, timesteps=0, out=out)), "timesteps must be an integer >= 1"),
        (lambda: train(TrainConfig("a2c", ENV, out=out)), "unknown algorithm 'a2c'"),
        (lambda: train(TrainConfig("ppo", "Nope-v0", out=out)), "unknown env id 'Nope-v0'"),
        (
            lambda: make_controller(
                str(shipped_models("TetherSpinningTriangle-v0")["ppo"]), gym.make_vec(ENV, num_envs=1)
            ),
            "trained on TetherSpinningTriangle-v0, not TetherTetrahedron-v0: .*--allow-other-id",
        ),
        (
            lambda: _quietly_on_another_id(shipped_models("TetherSpinningTriangle-v0")["ppo"]),
            "takes observations of shape .21,., but TetherTetrahedron-v0 gives .30,.",
        ),
    ]
    shipped = TrainedPolicy(shipped_models(ENV)["ppo"])
    cases += [
        (lambda: shipped.predict(np.full(30, np.nan)), "NaN"),
        (lambda: shipped.predict(np.zeros(29)), r"shape \(30,\) or \(N, 30\)"),
    ]
    for attempt, message in cases:
        with pytest.raises(ValueError, match=message):
            attempt()
    with pytest.raises(FileNotFoundError, match="has no best/ directory"):
        TrainedPolicy(shipped_models(ENV)["ppo"], best=True)
    with pytest.raises(FileNotFoundError, match="no trained policy at"):
        TrainedPolicy(tmp_path / "nowhere")
    for main, argv, argument in [
        (agents.compare.main, ["--episodes", "-3"], "--episodes"),
        (agents.compare.main, ["--env", "Nope-v0"], "--env"),
        (agents.train.main, ["--seed", "x"], "--seed"),
        (agents.train.main, ["--timesteps", "0"], "--timesteps"),
        (agents.convert.main, ["a", "b", "--check-observations", "3"], "--check-observations"),
    ]:
        with pytest.raises(SystemExit) as exit_info:
            main(argv)
        assert exit_info.value.code == 2 and argument in capsys.readouterr().err
