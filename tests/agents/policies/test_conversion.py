"""agents.policies.conversion: ConvertConfig's checks, made when it is built (the conversion
itself is tested end to end in tests/agents/test_agents_safety.py)."""

from __future__ import annotations

import pickle
import shutil
from pathlib import Path

import numpy as np
import pytest
from stable_baselines3 import PPO

from agents.common.cli import REFERENCE_FILE
from agents.common.files import OutputExistsError
from agents.convert import build_parser
from agents.policies import TrainedPolicy
from agents.policies.conversion import ConvertConfig, convert
from agents.policies.format import verify_manifest
from agents.policies.pickled import PickleTrustWarning
from agents.policies.reference import reference_observations
from tests.agents.helpers import ENV, sb3_actions
from tether_gym import ENV_IDS


def test_the_config_takes_paths_as_text_and_keeps_them_as_paths() -> None:
    config = ConvertConfig("runs/a", "converted/a")
    assert config.source == Path("runs/a") and config.destination == Path("converted/a")
    assert (config.check_observations, config.trust_pickle, config.force) == (512, False, False)


@pytest.mark.parametrize("count", [15, 0, True, 512.0, "512"])
def test_too_few_or_non_integer_check_observations_are_refused(count: object) -> None:
    with pytest.raises(ValueError, match=r"check_observations must be an integer in 16\.\.100000"):
        ConvertConfig("a", "b", check_observations=count)  # type: ignore[arg-type]


def test_the_command_line_defaults_are_the_configs(tmp_path: Path) -> None:
    args = build_parser().parse_args(["SRC", "DST"])
    assert args.check_observations == ConvertConfig("SRC", "DST").check_observations
    with pytest.raises(FileNotFoundError, match="SRC .* does not exist"):
        convert(ConvertConfig(tmp_path / "nowhere", tmp_path / "out", trust_pickle=True))
    assert not (tmp_path / "out").exists()  # refused before anything was written


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


def test_converter_refuses_a_model_that_does_not_fit_the_id_before_it_runs_there(sb3_run: Path, tmp_path: Path) -> None:
    """A run that records no id, converted with --env of another shape, failed inside SB3's
    predict on the first trajectory step; it is refused naming the model file and the id."""
    import shutil

    import yaml

    run = tmp_path / "run"
    shutil.copytree(sb3_run, run)
    (run / "config.yml").write_text(yaml.safe_dump({"algo": "ppo", "seed": 0}))
    with (
        pytest.warns(PickleTrustWarning),
        pytest.raises(
            ValueError, match=r"model.zip takes observations of shape \(30,\), but TetherTriangle-v0 gives \(21,\)"
        ),
    ):
        convert(ConvertConfig(run, tmp_path / "converted", trust_pickle=True, env_id="TetherTriangle-v0"))
    assert not (tmp_path / "converted" / "policy.json").exists()


def test_an_interrupted_conversion_leaves_the_earlier_one_whole_and_keeps_srcs_files(
    sb3_run: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A conversion lands as a whole directory: interrupted at its last step, DST is the earlier
    conversion, verifying; converted into SRC's own directory, SRC's files stay."""
    import agents.policies.conversion

    target = tmp_path / "converted"
    with pytest.warns(PickleTrustWarning):
        convert(ConvertConfig(sb3_run, target, trust_pickle=True, reference=True))
    before = {p.name: p.read_bytes() for p in target.iterdir()}

    def interrupted(*args: object, **kwargs: object) -> None:
        raise KeyboardInterrupt

    with monkeypatch.context() as patch:
        patch.setattr(agents.policies.conversion, "write_manifest", interrupted)
        with pytest.warns(PickleTrustWarning), pytest.raises(KeyboardInterrupt):
            # Another conversion of the same run: more files (the training state), other reference observations.
            again = dict(force=True, reference=True, training_state=True, check_observations=16)
            convert(ConvertConfig(sb3_run, target, trust_pickle=True, **again))
    verify_manifest(target)
    assert {p.name: p.read_bytes() for p in target.iterdir()} == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["converted"]  # no staging directory left
    # Into SRC's own directory: every file of SRC is still there, unchanged, beside the conversion.
    source = tmp_path / "run"
    shutil.copytree(sb3_run, source)
    originals = {p.name: p.read_bytes() for p in source.iterdir() if p.is_file()}
    with pytest.warns(PickleTrustWarning):
        convert(ConvertConfig(source, source, trust_pickle=True))
    assert {name: (source / name).read_bytes() for name in originals} == originals
    verify_manifest(source, strict=False)
