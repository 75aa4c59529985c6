"""Property-based fuzzing of the YAML files the agents read (hyperparameters, settings, a run's
``config.yml``), all through :func:`agents.common.settings.read_yaml`.

* A key given twice in any mapping, at any depth, is refused naming the file and the key (PyYAML
  keeps the last one silently).
* Any mutation of the project's own hyperparameter files (bytes replaced, inserted or cut, aliases
  nested) is read or refused with the caller's error type, within a second: never a
  RecursionError, a structure that contains itself, or an expansion without bound.
"""

from __future__ import annotations

import json
import tempfile
import time
from pathlib import Path
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from agents.common.data import HYPERPARAMS_DIR
from agents.common.reading import MAX_YAML_FLOW_DEPTH, MAX_YAML_NODES, read_yaml

#: Property-based, with many generated examples per property: the fast suite (-m 'not slow') leaves them out.
pytestmark = pytest.mark.slow

FUZZ = settings(max_examples=150, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow])

#: Prefixed, so that no key is one of YAML 1.1's booleans (y, no, on) and two keys read as one.
keys = st.text(alphabet="abcdefghijklmnopqrstuvwxyz_", min_size=1, max_size=6).map(lambda text: f"k_{text}")
values = st.recursive(
    st.none() | st.booleans() | st.integers(-1000, 1000) | keys,
    lambda children: st.lists(children, max_size=3) | st.dictionaries(keys, children, min_size=1, max_size=3),
    max_leaves=10,
)


class FileError(ValueError):
    """The caller's error type, to check that read_yaml raises the one it is given."""


def flow(value: Any, target: list[Any] | None, key: str, here: list[Any]) -> str:
    """``value`` as YAML flow text, the mapping at path ``target`` giving ``key`` a second time."""
    if isinstance(value, dict):
        entries = [f"{k}: {flow(v, target, key, [*here, k])}" for k, v in value.items()]
        if here == target:
            entries.append(f"{key}: 0")
        return "{" + ", ".join(entries) + "}"
    if isinstance(value, list):
        return "[" + ", ".join(flow(v, target, key, [*here, i]) for i, v in enumerate(value)) + "]"
    return json.dumps(value)


def mappings(value: Any, here: list[Any]) -> list[list[Any]]:
    found = [here] if isinstance(value, dict) else []
    items = value.items() if isinstance(value, dict) else enumerate(value) if isinstance(value, list) else ()
    for k, v in items:
        found += mappings(v, [*here, k])
    return found


@FUZZ
@given(value=st.dictionaries(keys, values, min_size=1, max_size=4), data=st.data())
def test_a_key_given_twice_in_any_mapping_is_refused(value: dict[str, Any], data: st.DataObject) -> None:
    target = data.draw(st.sampled_from(mappings(value, [])))
    table = value
    for step in target:
        table = table[step]
    key = data.draw(st.sampled_from(sorted(table)))
    with tempfile.TemporaryDirectory() as scratch:
        file = Path(scratch) / "settings.yml"
        file.write_text(flow(value, None, key, []), encoding="utf-8")
        assert read_yaml(file) == value  # the same text without the second key reads as it is
        file.write_text(flow(value, target, key, []), encoding="utf-8")
        with pytest.raises(FileError, match=rf"settings.yml .*the key '{key}' appears twice"):
            read_yaml(file, FileError)


SOURCES = sorted(HYPERPARAMS_DIR.glob("*.yml"))
PATCHES = st.binary(max_size=12) | st.sampled_from(
    [b"[" * 3000, b"*ppo_default", b"&a [*a]", b"\n  <<: *nothing", b"\xef\xbb\xbf", b"\xff", b": : :", b"\t"]
)


@FUZZ
@given(source=st.sampled_from(SOURCES), data=st.data())
def test_a_mutated_settings_file_is_read_or_refused_with_the_callers_error(source: Path, data: st.DataObject) -> None:
    raw = source.read_bytes()
    start = data.draw(st.integers(0, len(raw)))
    end = data.draw(st.integers(start, min(len(raw), start + 40)))
    mutated = raw[:start] + data.draw(PATCHES) + raw[end:]
    with tempfile.TemporaryDirectory() as scratch:
        file = Path(scratch) / source.name
        file.write_bytes(mutated)
        began = time.perf_counter()
        try:
            table = read_yaml(file, FileError)
        except FileError as error:
            assert str(file) in str(error)
        else:
            json.dumps(table)  # plain data, no structure that contains itself
        assert time.perf_counter() - began < 1.0


@FUZZ
@given(depth=st.integers(1, 9), width=st.integers(2, 12))
def test_nested_aliases_are_refused_before_they_expand(depth: int, width: int) -> None:
    """A few lines of nested aliases expand to width ** depth entries for whatever walks them."""
    lines = ["a0: &a0 [1, 1]"]
    lines += [f"a{i}: &a{i} [{', '.join([f'*a{i - 1}'] * width)}]" for i in range(1, depth + 1)]
    with tempfile.TemporaryDirectory() as scratch:
        file = Path(scratch) / "laughs.yml"
        file.write_text("\n".join(lines) + "\n", encoding="utf-8")
        sizes = [3]  # a0: the list and its two numbers
        for _ in range(depth):
            sizes.append(1 + width * sizes[-1])
        expanded = 1 + sum(1 + size for size in sizes)  # the root mapping, and each key with its value
        if expanded > MAX_YAML_NODES:
            with pytest.raises(FileError, match=f"laughs.yml .*expands to more than {MAX_YAML_NODES:,} entries"):
                read_yaml(file, FileError)
        else:
            assert len(json.loads(json.dumps(read_yaml(file, FileError)))) == depth + 1


@pytest.mark.parametrize("kind", ["fifo", "device", "directory", "large"])
def test_a_file_that_is_not_a_bounded_regular_file_is_refused_before_it_is_read(tmp_path: Path, kind: str) -> None:
    """A FIFO blocked the read, /dev/zero never ended, a large file was read whole before its size
    was checked: read_bounded refuses each after reading at most limit + 1 bytes."""
    import os

    from agents.common.reading import read_bounded

    file = tmp_path / "settings.yml"
    if kind == "fifo":
        os.mkfifo(file)
    elif kind == "device":
        file = Path("/dev/zero")
    elif kind == "directory":
        file.mkdir()
    else:
        with open(file, "wb") as stream:
            stream.truncate(2**30)  # sparse: 1 GiB that costs no disk
    began = time.perf_counter()
    message = "is not a regular file" if kind != "large" else "holds more than 1,024 bytes"
    with pytest.raises(FileError, match=f"{file.name} {message}.*: restore it"):
        read_bounded(file, 1024, FileError, "restore it")
    assert time.perf_counter() - began < 1.0


def test_a_mapping_of_many_keys_is_read_in_linear_time(tmp_path: Path) -> None:
    """The duplicate check compared each key with every earlier one: 40 000 keys (under 1 MB)
    cost about a billion comparisons, 50 s. Ten times the keys now cost about ten times the time
    (a ratio, not a duration: the parser itself is pure Python and the machine may be busy)."""

    def seconds(count: int) -> float:
        file = tmp_path / f"many{count}.yml"
        file.write_text("".join(f"k{i}: {i}\n" for i in range(count)), encoding="utf-8")
        began = time.perf_counter()
        assert len(read_yaml(file)) == count
        return time.perf_counter() - began

    # The least of three runs each: one pause of a shared machine (GC, another process) must not
    # decide the ratio. Linear reading gives about 10, and up to 16 has been measured on a loaded
    # machine (CI, 2026-12-03); the quadratic check took 50 s for the large file, a ratio in the
    # hundreds. 50 tells the two apart without failing on a busy machine's noise.
    small, large = (min(seconds(count) for _ in range(3)) for count in (4_000, 40_000))
    assert large < 50 * small, (small, large)


@pytest.mark.parametrize(("opening", "depth"), [(b"[", 3000), (b"{a: ", 3000), (b"[{x: ", 6000)])
def test_deeply_nested_flow_collections_are_refused_before_the_scanner_runs(
    tmp_path: Path, opening: bytes, depth: int
) -> None:
    """PyYAML's scanner checks every open flow level at every token: 3 000 nested ``[`` took over
    a second to refuse, on an idle core, where the cap refuses them in well under a millisecond."""
    file = tmp_path / "deep.yml"
    file.write_bytes(opening * 3000 + b"\nalgo: ppo\n")
    began = time.perf_counter()
    with pytest.raises(
        FileError, match=rf"deep\.yml nests \[ \] or {{ }} {depth} deep \(at most {MAX_YAML_FLOW_DEPTH}"
    ):
        read_yaml(file, FileError)
    assert time.perf_counter() - began < 0.1
    # The cap leaves room: the depth it allows still reads.
    file.write_bytes(b"x: " + b"[" * MAX_YAML_FLOW_DEPTH + b"]" * MAX_YAML_FLOW_DEPTH + b"\n")
    expected: list[Any] = []
    for _ in range(MAX_YAML_FLOW_DEPTH - 1):
        expected = [expected]
    assert read_yaml(file, FileError) == {"x": expected}
