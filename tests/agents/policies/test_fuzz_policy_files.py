"""Property-based fuzzing of every file of a policy directory, through every reader of it.

Each file format a policy directory holds (:data:`FORMATS`: ``policy.json``,
``normalization.json``, ``training.json``, ``MANIFEST.sha256`` and the safetensors files) is
mutated -- a JSON entry replaced by another value or removed, a safetensors header edited, bytes
flipped, inserted or cut -- and read by each reader that reads it (:data:`READERS`). Every
mutation ends in exactly one of two ways: the directory loads, or the reader raises the format's
own :class:`~agents.policies.layout.PolicyFormatError` (a ChecksumError is one), within a second
and 100 MB of peak memory.
Nothing else (a RecursionError, a KeyError or TypeError from inside, a torch or safetensors
error, an OverflowError) is allowed.

A new file format or reader is fuzzed from the day it lands: :func:`test_every_format_and_reader_is_fuzzed`
fails while a file of the layout has no row in :data:`FORMATS`, or a function of agents/policies
that parses a policy file is not one of :data:`READERS`.
"""

from __future__ import annotations

import ast
import json
import resource
import shutil
import struct
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from stable_baselines3 import PPO

from agents.common.cli import REFERENCE_FILE
from agents.policies.format import load_policy, load_training_state, save_policy, verify_manifest, write_manifest
from agents.policies.layout import (
    MANIFEST_FILE,
    METADATA_FILE,
    NORMALIZATION_FILE,
    POLICY_FILES,
    TRAINING_META_FILE,
    TRAINING_STATE_FILE,
    WEIGHTS_FILE,
    PolicyFormatError,
)
from agents.training.sb3 import make_training_env

#: Property-based, with many generated examples per property: the fast suite (-m 'not slow') leaves them out.
pytestmark = pytest.mark.slow

POLICIES = Path(__file__).resolve().parents[3] / "agents" / "policies"
TRIANGLE = "TetherTriangle-v0"
NORMALIZE = {"norm_obs": True, "norm_reward": False}
FUZZ = settings(
    max_examples=60,
    deadline=None,
    derandomize=True,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow, HealthCheck.data_too_large],
)


def tiny_model(seed: int) -> tuple[PPO, Any]:
    venv = make_training_env(TRIANGLE, 1, seed=seed, normalize=NORMALIZE, env_kwargs={"max_episode_steps": 20})
    model = PPO("MlpPolicy", venv, n_steps=16, batch_size=16, device="cpu", policy_kwargs={"net_arch": [4]}, seed=seed)
    return model, venv


def read_policy(directory: Path) -> None:
    load_policy(directory)


def read_shipped(directory: Path) -> None:
    """The shipped models' path: the manifest required and verified, then the policy loaded."""
    verify_manifest(directory)
    load_policy(directory, require_manifest=True)


def read_training_state(directory: Path) -> None:
    model, venv = tiny_model(seed=1)
    load_training_state(model, directory, venv)


#: The readers of a policy directory, and the functions of agents/policies each goes through
#: (module.qualified name) where a file is parsed.
READERS: dict[str, tuple[Callable[[Path], None], set[str]]] = {
    "load_policy": (
        read_policy,
        {"format.load_policy", "format.read_metadata", "normalization.NormalizationStatistics.from_json"},
    ),
    "shipped": (read_shipped, {"format.verify_manifest", "format._VerifiedReader.__init__"}),
    "load_training_state": (read_training_state, {"format.load_training_state"}),
}

#: Every file of a policy directory: its kind (how it is mutated) and the readers that read it.
FORMATS: dict[str, tuple[str, tuple[str, ...]]] = {
    METADATA_FILE: ("json", ("load_policy", "load_training_state")),
    NORMALIZATION_FILE: ("json", ("load_policy", "load_training_state")),
    TRAINING_META_FILE: ("json", ("load_training_state",)),
    WEIGHTS_FILE: ("safetensors", ("load_policy", "load_training_state")),
    TRAINING_STATE_FILE: ("safetensors", ("load_training_state",)),
    MANIFEST_FILE: ("manifest", ("shipped",)),
    # Read by the tests of the shipped models only (load_tensors), which the safetensors rows cover.
    REFERENCE_FILE: ("safetensors", ()),
}
CASES = [(name, reader) for name, (_, readers) in FORMATS.items() for reader in readers]


@pytest.fixture(scope="module")
def base_directory(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A valid checkpoint directory (normalisation, training state), without a manifest."""
    model, venv = tiny_model(seed=0)
    model.learn(32)
    directory = save_policy(tmp_path_factory.mktemp("fuzz") / "policy", model, venv, TRIANGLE, training_state=True)
    (directory / MANIFEST_FILE).unlink()
    return directory


json_values = st.recursive(
    st.none()
    | st.booleans()
    | st.integers(-(10**30), 10**400)
    | st.floats(allow_nan=False, allow_infinity=False)
    | st.sampled_from(["", "nan", "inf", "-inf", "Box", "float64", "MlpPolicy", "ppo", "lqr", "0.001", "1e6"])
    | st.sampled_from([0, -1, 1, 2**31, 2**63, 10**400, -(10**400), 1e308, -1e-308, 0.5, [], {}, [4096] * 16])
    | st.text(max_size=8),
    lambda children: st.lists(children, max_size=4) | st.dictionaries(st.text(max_size=6), children, max_size=4),
    max_leaves=12,
)


def mutate_json(data: st.DataObject, value: Any) -> Any:
    """``value`` with one entry somewhere inside replaced, removed or added."""
    if isinstance(value, (dict, list)) and value and data.draw(st.integers(0, 3)) > 0:
        keys = list(value) if isinstance(value, dict) else list(range(len(value)))
        key = data.draw(st.sampled_from(keys))
        copy = dict(value) if isinstance(value, dict) else list(value)
        action = data.draw(st.sampled_from(["descend", "descend", "remove", "replace"]))
        if action == "remove":
            del copy[key]
        elif action == "replace":
            copy[key] = data.draw(json_values)
        else:
            copy[key] = mutate_json(data, copy[key])
        return copy
    if isinstance(value, dict) and data.draw(st.booleans()):
        return {**value, data.draw(st.text(max_size=8)): data.draw(json_values)}
    return data.draw(json_values)


def mutate_bytes(data: st.DataObject, raw: bytes) -> bytes:
    """``raw`` with a stretch replaced, inserted or cut."""
    start = data.draw(st.integers(0, len(raw)))
    end = data.draw(st.integers(start, min(len(raw), start + 64)))
    action = data.draw(st.sampled_from(["replace", "insert", "cut", "truncate"]))
    if action == "truncate":
        return raw[:start]
    if action == "cut":
        return raw[:start] + raw[end:]
    patch = data.draw(st.binary(min_size=1, max_size=16) | st.sampled_from([b"[" * 5000, b"\x00" * 8, b"1e999"]))
    return raw[:start] + patch + (raw[end:] if action == "replace" else raw[start:])


def mutate_safetensors(data: st.DataObject, raw: bytes) -> bytes:
    """A safetensors file with its JSON header edited (shapes, dtypes, offsets, names), or its bytes."""
    if data.draw(st.booleans()):
        return mutate_bytes(data, raw)
    (length,) = struct.unpack("<Q", raw[:8])
    header = json.loads(raw[8 : 8 + length])
    text = json.dumps(mutate_json(data, header)).encode()
    return struct.pack("<Q", len(text)) + text + raw[8 + length :]


def mutate_manifest(data: st.DataObject, raw: bytes) -> bytes:
    lines = raw.decode().splitlines()
    action = data.draw(st.sampled_from(["duplicate", "drop", "edit", "add", "bytes"]))
    if action == "bytes" or not lines:
        return mutate_bytes(data, raw)
    index = data.draw(st.integers(0, len(lines) - 1))
    if action == "duplicate":
        lines.insert(index, lines[index])
    elif action == "drop":
        del lines[index]
    elif action == "edit":
        lines[index] = data.draw(st.sampled_from(["", "0" * 64 + "  ..", "0" * 64 + "  policy.json", "x"]))
    else:
        lines.append(data.draw(st.text(max_size=80).filter(lambda line: "\n" not in line and "\r" not in line)))
    return ("\n".join(lines) + "\n").encode()


MUTATORS = {"json": None, "safetensors": mutate_safetensors, "manifest": mutate_manifest}


@pytest.mark.parametrize(("name", "reader"), CASES)
@FUZZ
@given(data=st.data())
def test_a_mutated_policy_file_loads_or_is_refused_by_name(
    base_directory: Path, name: str, reader: str, data: st.DataObject
) -> None:
    kind, _ = FORMATS[name]
    read, _ = READERS[reader]
    with tempfile.TemporaryDirectory() as scratch:
        directory = Path(scratch) / "policy"
        shutil.copytree(base_directory, directory)
        if kind == "manifest":
            write_manifest(directory, [path.name for path in directory.iterdir()])
        raw = (directory / name).read_bytes()
        if kind == "json":
            if data.draw(st.booleans()):
                mutated = json.dumps(mutate_json(data, json.loads(raw))).encode()
            else:
                mutated = mutate_bytes(data, raw)
        else:
            mutated = MUTATORS[kind](data, raw)
        (directory / name).write_bytes(mutated)
        peak, start = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss, time.perf_counter()
        try:
            read(directory)
        except PolicyFormatError as error:
            assert str(error), "an error without a message"
        assert time.perf_counter() - start < 1.0
        # The process's peak resident memory (KiB) rises by under 100 MB for any mutation.
        assert resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - peak < 100 * 1024


def parsing_functions() -> set[str]:
    """The functions of agents/policies (module.qualified name) that parse a policy file: call
    parse_json, load_tensors, read_manifest or from_json, or build a _VerifiedReader."""
    parsers = {"parse_json", "load_tensors", "read_manifest", "_VerifiedReader", "from_json"}
    found = set()
    for path in sorted(POLICIES.glob("*.py")):
        tree = ast.parse(path.read_text(encoding="utf-8"))

        def visit(node: ast.AST, scope: list[str], module: str = path.stem) -> None:
            for child in ast.iter_child_nodes(node):
                if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
                    visit(child, [*scope, child.name])
                    continue
                if isinstance(child, ast.Call) and scope:
                    function = child.func
                    called = function.attr if isinstance(function, ast.Attribute) else getattr(function, "id", "")
                    if called in parsers:
                        found.add(f"{module}.{'.'.join(scope)}")
                visit(child, scope)

        visit(tree, [])
    # The parsers themselves, and the writers' own checks of what they wrote.
    return found - {"codecs.parse_json", "format.load_tensors", "format.read_manifest"}


def test_every_format_and_reader_is_fuzzed() -> None:
    """A file the layout names without a row in FORMATS, or a parsing function that no reader in
    READERS goes through, fails here: add it to the tables, and the property above fuzzes it."""
    missing_files = sorted(set(POLICY_FILES) - set(FORMATS))
    assert not missing_files, f"policy files without a fuzz row in FORMATS: {missing_files}"
    covered = set().union(*(functions for _, functions in READERS.values()))
    unfuzzed = sorted(parsing_functions() - covered)
    assert not unfuzzed, f"functions that parse policy files but are in no READERS row: {unfuzzed}"
    assert covered <= parsing_functions(), sorted(covered - parsing_functions())
    assert {reader for _, (_, readers) in FORMATS.items() for reader in readers} == set(READERS)


def objects_in(value: Any, path: tuple[Any, ...] = ()) -> list[tuple[Any, ...]]:
    """The paths of every non-empty JSON object inside ``value``."""
    found = [path] if isinstance(value, dict) and value else []
    items = value.items() if isinstance(value, dict) else enumerate(value) if isinstance(value, list) else ()
    for key, item in items:
        found += objects_in(item, (*path, key))
    return found


def dump_with_a_key_twice(
    value: Any, target: tuple[Any, ...], key: str, second: Any, here: tuple[Any, ...] = ()
) -> str:
    """``value`` as JSON text in which the object at ``target`` gives ``key`` twice: first its own
    entry, then ``second``."""
    if isinstance(value, dict):
        entries = [
            f"{json.dumps(k)}: {dump_with_a_key_twice(v, target, key, second, (*here, k))}" for k, v in value.items()
        ]
        if here == target:
            entries.append(f"{json.dumps(key)}: {json.dumps(second)}")
        return "{" + ", ".join(entries) + "}"
    if isinstance(value, list):
        return (
            "["
            + ", ".join(dump_with_a_key_twice(v, target, key, second, (*here, i)) for i, v in enumerate(value))
            + "]"
        )
    return json.dumps(value)


JSON_CASES = [(name, reader) for name, reader in CASES if FORMATS[name][0] == "json"]


@pytest.mark.parametrize(("name", "reader"), JSON_CASES)
@settings(FUZZ, max_examples=25)
@given(data=st.data())
def test_a_key_given_twice_in_any_json_object_is_refused(
    base_directory: Path, name: str, reader: str, data: st.DataObject
) -> None:
    """The "file listed twice" class for every JSON file: ``json`` keeps the last of two entries
    with the same key silently, so a file could say two things about one entry (the same value
    twice included) and be read as the second. Every reader refuses it, naming the file."""
    read, _ = READERS[reader]
    with tempfile.TemporaryDirectory() as scratch:
        directory = Path(scratch) / "policy"
        shutil.copytree(base_directory, directory)
        value = json.loads((directory / name).read_bytes())
        target = data.draw(st.sampled_from(objects_in(value)))
        table = value
        for step in target:
            table = table[step]
        key = data.draw(st.sampled_from(sorted(table)))
        second = data.draw(st.just(table[key]) | st.sampled_from([None, True, 0, 1.5, "ppo", [], {}, [0.0]]))
        (directory / name).write_text(dump_with_a_key_twice(value, target, key, second), encoding="utf-8")
        with pytest.raises(PolicyFormatError, match=rf"{name}.*appears twice"):
            read(directory)


@pytest.fixture(scope="module")
def captured_state() -> tuple[dict[str, Any], dict[str, Any]]:
    """A trained tiny model's optimizer state, as training.safetensors and training.json hold it."""
    from agents.policies.sb3_state import capture_training_state

    model, _ = tiny_model(seed=0)
    model.learn(32)
    tensors, meta = capture_training_state(model)
    return tensors, json.loads(json.dumps(meta))


@settings(FUZZ, max_examples=80)
@given(
    key=st.sampled_from(["lr", "eps", "weight_decay", "betas.0", "betas.1"]),
    value=st.floats(-2.0, 2.0, allow_nan=False) | st.sampled_from([0.0, 1.0, 0.999999, 1e-300, 1e300, -0.0]),
    moment=st.sampled_from(["exp_avg", "exp_avg_sq", "step"]),
    scale=st.sampled_from([None, -1.0, 0.5, 2.5, -3.0]),
)
def test_a_resumed_optimizer_state_is_what_the_optimizer_itself_accepts(
    captured_state: tuple[dict[str, Any], dict[str, Any]], key: str, value: float, moment: str, scale: float | None
) -> None:
    """Differential: a param group setting is restored exactly when the optimizer's own
    constructor accepts it (Adam refuses betas outside [0, 1), negative rates and epsilons), and a
    per-parameter entry exactly when an optimizer step could have written it (averages of squares
    >= 0, steps whole and >= 0); otherwise the refusal names training.json or training.safetensors."""
    import torch

    from agents.policies.sb3_state import restore_training_state

    tensors, meta = captured_state
    meta = json.loads(json.dumps(meta))
    group = meta["optimizers"]["policy.optimizer"]["param_groups"][0]
    name, _, index = key.partition(".")
    settings_ = {k: v for k, v in group.items() if k not in ("params",)}
    if index:
        group[name][int(index)] = value
    else:
        group[name] = value
    tensors = dict(tensors)
    target = f"policy.optimizer/state/0/{moment}"
    if scale is not None:
        tensors[target] = tensors[target] * scale if moment != "step" else torch.tensor(float(tensors[target]) * scale)
    try:
        torch.optim.Adam([torch.nn.Parameter(torch.zeros(1))], **{**settings_, name: group[name]})
        accepted = True
    except ValueError:
        accepted = False
    written = tensors[target]
    if moment == "step":
        accepted = accepted and float(written) >= 0 and float(written) == round(float(written))
    elif moment == "exp_avg_sq":
        accepted = accepted and bool((written >= 0).all())
    model, _ = tiny_model(seed=1)
    try:
        restore_training_state(model, meta, tensors, "ppo", Path("training.json"), Path("training.safetensors"))
    except PolicyFormatError as error:
        assert not accepted, f"refused what the optimizer accepts: {error}"
        assert "training.json" in str(error) or "training.safetensors" in str(error)
    else:
        assert accepted, f"restored {key}={value}, {moment} x {scale}, which the optimizer would not have"
