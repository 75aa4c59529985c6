"""The safe policy format: files that hold pickle payloads or name code are refused, numbers
must be finite, and a round trip gives bit-identical actions."""

from __future__ import annotations

import json
import pickle
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import torch
from stable_baselines3 import PPO

from agents.policies import TrainedPolicy
from agents.policies.codecs import MAX_JSON_BYTES, MAX_JSON_DEPTH, json_depth
from agents.policies.format import load_policy, load_tensors, save_policy, tensor_bytes
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


@pytest.mark.parametrize("name", ["policy.json", "normalization.json"])
def test_deeply_nested_or_huge_json_is_refused_before_it_is_parsed(
    sb3_model: tuple[PPO, object], tmp_path: Path, name: str
) -> None:
    """A few KB of brackets made the parser raise a bare RecursionError; a huge file would be read
    whole. Both are refused by name, quickly, in every JSON file of a policy directory."""
    model, venv = sb3_model
    directory = save_policy(tmp_path / "policy", model, venv, ENV)
    (directory / "MANIFEST.sha256").unlink()
    (directory / name).write_text("[" * 100_000 + "]" * 100_000)
    start = time.perf_counter()
    with pytest.raises(PolicyFormatError, match=f"{name} nests lists or objects more than {MAX_JSON_DEPTH} deep"):
        load_policy(directory)
    assert time.perf_counter() - start < 1.0
    (directory / name).write_bytes(b" " * (MAX_JSON_BYTES + 1))
    with pytest.raises(PolicyFormatError, match=f"{name} is .* bytes, more than a policy file can be"):
        load_policy(directory)


def test_json_depth_ignores_brackets_inside_strings() -> None:
    assert json_depth(b'{"a": [1, {"b": "[[[[\\"{{"}]}', 32) == 3
    assert json_depth(b"[" * 40, 32) == 33  # stops counting past the limit
    assert json_depth(b"3", 32) == 0


@pytest.mark.parametrize("value", [float("nan"), float("inf")])
def test_weights_that_are_not_finite_are_refused(sb3_model: tuple[PPO, object], tmp_path: Path, value: float) -> None:
    """NaN or infinite weights loaded and failed late inside torch, or saturated every action."""
    model, venv = sb3_model
    directory = save_policy(tmp_path / "policy", model, venv, ENV)
    weights = load_tensors((directory / "policy.safetensors").read_bytes(), directory / "policy.safetensors")
    name = sorted(weights)[0]
    weights[name].view(-1)[0] = value
    (directory / "policy.safetensors").write_bytes(tensor_bytes(weights))
    (directory / "MANIFEST.sha256").unlink()
    with pytest.raises(PolicyFormatError, match=f"tensor {name!r} has NaN or infinite entries"):
        load_policy(directory)


def test_a_file_listed_twice_in_the_manifest_is_refused(sb3_model: tuple[PPO, object], tmp_path: Path) -> None:
    """Only the last entry of a file listed twice was kept, so a wrong first hash went unseen."""
    model, venv = sb3_model
    directory = save_policy(tmp_path / "policy", model, venv, ENV)
    manifest = directory / "MANIFEST.sha256"
    line = next(line for line in manifest.read_text().splitlines() if line.endswith("policy.json"))
    manifest.write_text(f"{'0' * 64}  policy.json\n" + manifest.read_text())
    with pytest.raises(ChecksumError, match="policy.json is listed a second time"):
        load_policy(directory, require_manifest=True)
    assert line in manifest.read_text()


def test_an_oversized_manifest_is_refused_before_it_is_read(sb3_model: tuple[PPO, object], tmp_path: Path) -> None:
    """The manifest was the one policy file read whole whatever its size (a sparse 256 MB
    MANIFEST.sha256 cost 256 MB and seconds before its first line was checked)."""
    model, venv = sb3_model
    directory = save_policy(tmp_path / "policy", model, venv, ENV)
    with open(directory / "MANIFEST.sha256", "ab") as stream:
        stream.truncate(256 * 2**20)
    began = time.perf_counter()
    with pytest.raises(ChecksumError, match=r"MANIFEST.sha256 holds more than 65,536 bytes.*: restore it"):
        load_policy(directory)
    assert time.perf_counter() - began < 1.0


def test_zero_epsilon_with_a_zero_variance_is_refused(sb3_model: tuple[PPO, object], tmp_path: Path) -> None:
    """(x - mean) / sqrt(var + epsilon) with both zero is NaN for every observation."""
    model, venv = sb3_model
    directory = save_policy(tmp_path / "policy", model, venv, ENV)
    table = json.loads((directory / "normalization.json").read_text())
    table["epsilon"] = 0
    table["obs_rms"]["var"]["values"][0] = 0
    (directory / "normalization.json").write_text(json.dumps(table))
    (directory / "MANIFEST.sha256").unlink()
    with pytest.raises(PolicyFormatError, match="epsilon is 0 and a variance is 0"):
        load_policy(directory)


@pytest.mark.parametrize(
    ("change", "message"),
    [
        # One return statistic per key: any other shape broadcast against the batch of rewards.
        (
            lambda t: t["ret_rms"].update(
                mean={"shape": [3], "dtype": "float64", "values": [0.0] * 3},
                var={"shape": [3], "dtype": "float64", "values": [1.0] * 3},
            ),
            r"ret_rms.mean and ret_rms.var must have shape \[\]",
        ),
        (lambda t: t.update(gamma=1.5), r"gamma is a discount and must be in \(0, 1\]; got 1.5"),
    ],
)
def test_normalisation_statistics_no_normaliser_writes_are_refused(
    sb3_model: tuple[PPO, object], tmp_path: Path, change: Any, message: str
) -> None:
    model, venv = sb3_model
    directory = save_policy(tmp_path / "policy", model, venv, ENV)
    table = json.loads((directory / "normalization.json").read_text())
    change(table)
    (directory / "normalization.json").write_text(json.dumps(table))
    (directory / "MANIFEST.sha256").unlink()
    with pytest.raises(PolicyFormatError, match=rf"normalization.json: {message}"):
        load_policy(directory)
