"""The safe policy format: files that hold pickle payloads or name code are refused, numbers
must be finite, and a round trip gives bit-identical actions."""

from __future__ import annotations

import json
import pickle
from pathlib import Path

import numpy as np
import pytest
import torch
from stable_baselines3 import PPO

from agents.policies import TrainedPolicy
from agents.policies.format import load_policy, save_policy
from agents.policies.layout import ChecksumError, PolicyFormatError
from agents.policies.reference import reference_observations
from tests.agents.helpers import ENV, payload, sb3_actions


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
