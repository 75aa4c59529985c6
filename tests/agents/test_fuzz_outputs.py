"""Property-based fuzzing of what the commands write and the run files ship reads.

* Output paths: any layout below an output root (real directories, files, symlinks to elsewhere
  or back inside, at any level) either is refused with an ``OutputError``, or the command's
  directory is made below the root through real directories only, and nothing is written
  elsewhere.
* Multi-file saves: whatever a directory holds and wherever a save is interrupted, the directory
  afterwards is exactly the old one (interrupted) or the new save plus what the command did not
  write (done); a file the command did not write is never lost.
* Run files: any ``training_runs.json``, ``config.yml`` or ``evaluations.json`` is either refused
  with a :class:`RunFileError` that names the file, or everything ship writes from it is written
  without error.
"""

from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path
from typing import Any

import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from agents.common.files import OutputError, atomic_directory, prepare_output_dir
from agents.training import shipping
from agents.training.shipping import RunFileError, read_runs_table, reproduce_command

#: Property-based, with many generated examples per property: the fast suite (-m 'not slow') leaves them out.
pytestmark = pytest.mark.slow

FUZZ = settings(max_examples=200, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow])

#: What stands at one level of an output path: nothing, a real directory, a file, a symlink to a
#: directory outside the root, or a symlink to a directory inside it.
KINDS = ("absent", "directory", "file", "link out", "link in")


def _tree(root: Path) -> dict[str, Any]:
    """Everything below ``root`` (not following symlinks): relative path -> file bytes, link target or None."""
    found: dict[str, Any] = {}
    for base, directories, files in os.walk(root, followlinks=False):
        for name in directories + files:
            path = Path(base) / name
            key = str(path.relative_to(root))
            found[key] = os.readlink(path) if path.is_symlink() else (path.read_bytes() if path.is_file() else None)
    return found


@FUZZ
@given(levels=st.lists(st.sampled_from(KINDS), min_size=1, max_size=4))
def test_an_output_below_the_root_is_made_through_real_directories_or_refused(levels: list[str]) -> None:
    with tempfile.TemporaryDirectory() as scratch:
        root, outside, inside = Path(scratch) / "out", Path(scratch) / "outside", Path(scratch) / "out" / "inside"
        outside.mkdir()
        inside.mkdir(parents=True)
        target = root
        for index, kind in enumerate(levels):
            target = target / f"level{index}"
            if kind == "absent" or not target.parent.is_dir() or target.parent.is_symlink():
                continue
            if kind == "directory":
                target.mkdir()
            elif kind == "file":
                target.write_text("a file")
            else:
                target.symlink_to(outside if kind == "link out" else inside)
        outside_before = _tree(outside)
        try:
            made = prepare_output_dir(target, root=root, claim=False)
        except OutputError as error:
            assert str(target.relative_to(root).parts[0]) in str(error) or "out" in str(error)
        else:
            assert made == target and target.is_dir()
            current = root
            for part in target.relative_to(root).parts:
                current = current / part
                assert not current.is_symlink(), f"{current} is a symlink the output went through"
        assert _tree(outside) == outside_before, "something was written outside the output root"


NAMES = ("policy.json", "policy.safetensors", "normalization.json", "MANIFEST.sha256", "evaluations.json", "notes.txt")
OURS = NAMES[:4]


@FUZZ
@given(
    old=st.one_of(st.none(), st.dictionaries(st.sampled_from(NAMES), st.binary(max_size=8), max_size=6)),
    new=st.dictionaries(st.sampled_from(OURS), st.binary(max_size=8), min_size=1, max_size=4),
    interrupt_after=st.one_of(st.none(), st.integers(0, 3)),
    others=st.sampled_from(["carry", "refuse"]),
)
def test_a_directory_save_is_whole_or_absent_and_loses_no_foreign_file(
    old: dict[str, bytes] | None, new: dict[str, bytes], interrupt_after: int | None, others: str
) -> None:
    with tempfile.TemporaryDirectory() as scratch:
        target = Path(scratch) / "best"
        if old is not None:
            target.mkdir()
            for name, data in old.items():
                (target / name).write_bytes(data)
        before = _tree(Path(scratch))
        foreign = {name: data for name, data in (old or {}).items() if name not in OURS}
        try:
            with atomic_directory(target, ours=OURS, others=others) as staging:
                for index, (name, data) in enumerate(new.items()):
                    if index == interrupt_after:
                        raise KeyboardInterrupt
                    (staging / name).write_bytes(data)
        except KeyboardInterrupt:
            assert _tree(Path(scratch)) == before, "an interrupted save changed the directory"
            return
        except OutputError as error:
            assert others == "refuse" and foreign, error
            assert _tree(Path(scratch)) == before, "a refused save changed the directory"
            return
        if interrupt_after is not None and interrupt_after < len(new):
            pytest.fail("the interrupt did not propagate")
        after = {p.name: p.read_bytes() for p in target.iterdir()}
        assert after == {**foreign, **new}, "the directory is not the new save plus the files it did not write"
        assert sorted(p.name for p in Path(scratch).iterdir()) == ["best"], "a staging directory was left behind"


#: JSON values, the strange ones included: nesting, wrong types, huge and negative numbers.
json_values = st.recursive(
    st.one_of(
        st.none(),
        st.booleans(),
        st.integers(-(10**20), 10**20),
        st.floats(allow_nan=False, allow_infinity=False),
        st.text(max_size=8),
    ),
    lambda children: st.one_of(
        st.lists(children, max_size=3), st.dictionaries(st.text(max_size=6), children, max_size=3)
    ),
    max_leaves=12,
)
#: A ``first_beat`` record: per baseline (the names the tables look up among them), when training first beat it.
first_beats = st.dictionaries(
    st.one_of(st.sampled_from(["lqr", "velocity_feedback"]), st.text(max_size=4)),
    st.one_of(st.none(), json_values, st.dictionaries(st.sampled_from(["wall_time_s", "timesteps"]), json_values)),
    max_size=3,
)
ENTRY_KEYS = [*shipping._ENTRY_KEYS, "wall_time_s", "seeds", "shipped", "residual_on", "command", "first_beat", "seed"]


def _entry(draw_values: dict[str, Any], **more: Any) -> dict[str, Any]:
    """A well-formed runs-table entry, with ``draw_values`` and ``more`` replacing some of its values."""
    entry = {
        "env_id": "TetherTetrahedron-v0",
        "algo": "ppo",
        "seed": 0,
        "timesteps": 1000,
        "wall_time_s": 1.5,
        "mean_return": -10.0,
        "bar": "lqr",
        "bar_mean_return": -12.0,
        "difference": 2.0,
        "difference_low": 1.0,
        "difference_high": 3.0,
        "first_beat": {"lqr": {"wall_time_s": 3.0, "timesteps": 500}},
        "seeds": [1_000_000, 1_000_001],
        "shipped": True,
        "residual_on": None,
        "command": "python -m agents.train",
    }
    entry.update(draw_values)
    entry.update(more)
    return entry


@FUZZ
@given(
    table=st.one_of(
        json_values,
        st.builds(
            lambda entries: {"command": None, "runs": entries},
            st.lists(
                st.builds(
                    _entry,
                    st.dictionaries(st.sampled_from(ENTRY_KEYS), json_values, max_size=3),
                    first_beat=st.one_of(json_values, first_beats),
                ),
                max_size=3,
            ),
        ),
    )
)
def test_a_runs_table_is_refused_by_name_or_merged(table: Any) -> None:
    with tempfile.TemporaryDirectory() as scratch:
        out = Path(scratch)
        (out / "training_runs.json").write_text(json.dumps(table))
        try:
            entries = read_runs_table(out)
        except RunFileError as error:
            assert "training_runs.json" in str(error)
            return
        shipping._markdown(entries or [_entry({})])  # everything ship writes from the table


@FUZZ
@given(
    config=st.one_of(json_values, st.dictionaries(st.sampled_from(["seed", "command", "hyperparams"]), json_values)),
    log=st.one_of(
        json_values,
        st.dictionaries(st.sampled_from(["training", "first_beat", "evaluations"]), json_values),
        st.builds(lambda beat: {"first_beat": beat}, first_beats),
    ),
)
def test_run_files_are_refused_by_name_or_read(config: Any, log: Any) -> None:
    with tempfile.TemporaryDirectory() as scratch:
        run = Path(scratch)
        (run / "best").mkdir()
        (run / "config.yml").write_text(yaml.safe_dump(config))
        (run / "best" / "evaluations.json").write_text(json.dumps(log))
        try:
            read_config = shipping._config(run, run / "best")
            read_log = shipping._training_log(run, run / "best")
        except RunFileError as error:
            assert "config.yml" in str(error) or "evaluations.json" in str(error)
            return
        candidate = _entry(
            {
                "seed": read_config.get("seed"),
                "command": read_config.get("command"),
                "wall_time_s": ((read_log or {}).get("training") or {}).get("wall_time_s"),
                "first_beat": (read_log or {}).get("first_beat"),
            }
        )
        reproduce_command(candidate, "models")
        shipping._markdown([candidate])
