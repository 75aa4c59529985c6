"""Careful output files: an atomic write keeps the old file when writing fails; a command's
claim on its output refuses a second command; no write goes through a symlink below the output
root; a multi-file save replaces its directory as a whole; and a command deletes only its own files."""

from __future__ import annotations

import errno
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from agents.common.files import (
    OutputBusyError,
    OutputError,
    atomic_directory,
    atomic_write_text,
    check_no_symlinks_between,
    claim_output_dir,
    holding_output_claims,
    holds_output_claims,
    make_dirs_below,
    prepare_output_dir,
    remove_written_files,
)
from agents.policies.format import verify_manifest, write_manifest


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


# ---------------------------------------------------------------------------------------------
# A command's exclusive claim on its output directory
# ---------------------------------------------------------------------------------------------

#: A second process that claims ``argv[1]`` as a command does, says so, and holds it until stdin closes.
HOLDER = """
import sys
from agents.common.files import claim_output_dir
claim_output_dir(sys.argv[1])
print("claimed", flush=True)
sys.stdin.read()
"""


def _holder(directory: Path) -> subprocess.Popen[str]:
    process = subprocess.Popen(
        [sys.executable, "-c", HOLDER, str(directory)],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
        cwd=Path(__file__).resolve().parents[3],
    )
    assert process.stdout is not None and process.stdout.readline().strip() == "claimed"
    return process


def _end(process: subprocess.Popen[str]) -> None:
    assert process.stdin is not None
    process.stdin.close()
    assert process.wait(timeout=60) == 0


def test_a_directory_another_process_claims_is_refused_until_it_ends(tmp_path: Path) -> None:
    holder = _holder(tmp_path)
    try:
        with pytest.raises(OutputBusyError, match=r"--out .* in use by another running command"):
            prepare_output_dir(tmp_path)
        with pytest.raises(OutputBusyError, match="DST"):
            claim_output_dir(tmp_path, argument="DST")
    finally:
        _end(holder)
    with holding_output_claims():
        prepare_output_dir(tmp_path)
        prepare_output_dir(tmp_path)  # this process's own claim again: no conflict
        # While this process holds it, another process is refused in turn.
        refused = subprocess.run(
            [sys.executable, "-c", HOLDER, str(tmp_path)], capture_output=True, text=True, input="", timeout=60
        )
        assert refused.returncode != 0 and "OutputBusyError" in refused.stderr
    _end(_holder(tmp_path))  # the scope released it: another process claims it at once
    assert sorted(p.name for p in tmp_path.iterdir()) == []  # the lock leaves no file behind


def test_a_decorated_command_releases_its_claims_on_error(tmp_path: Path) -> None:
    @holds_output_claims
    def command() -> None:
        prepare_output_dir(tmp_path)
        raise RuntimeError("failed midway")

    with pytest.raises(RuntimeError):
        command()
    _end(_holder(tmp_path))


# ---------------------------------------------------------------------------------------------
# Symlinks at every level below the output root
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize("depth", [0, 1, 2])
def test_a_symlink_at_any_level_below_the_root_is_refused(tmp_path: Path, depth: int) -> None:
    root, elsewhere = tmp_path / "out", tmp_path / "elsewhere"
    elsewhere.mkdir()
    parts = ["TetherChain-v0", "ppo_seed0", "best"]
    if depth == 0:
        root.symlink_to(elsewhere)
    else:
        (root / Path(*parts[: depth - 1])).mkdir(parents=True)
        (root / Path(*parts[:depth])).symlink_to(elsewhere)
    target = root / Path(*parts)
    with pytest.raises(OutputError, match=r"is a symlink .*refusing to write through it"):
        prepare_output_dir(target, root=root, claim=False)
    with pytest.raises(OutputError, match="symlink"):
        make_dirs_below(root, target)
    assert list(elsewhere.iterdir()) == []  # nothing was written through the link


def test_output_directories_are_made_below_the_root(tmp_path: Path) -> None:
    target = tmp_path / "out" / "a" / "b"
    assert prepare_output_dir(target, root=tmp_path / "out", claim=False) == target and target.is_dir()
    with pytest.raises(ValueError, match="not below"):
        check_no_symlinks_between(tmp_path / "out", tmp_path / "other")


# ---------------------------------------------------------------------------------------------
# Multi-file saves replace a directory as a whole
# ---------------------------------------------------------------------------------------------


def _save(directory: Path, version: str, fail_after: int | None = None) -> None:
    """A multi-file save with a manifest written last, as the policy saves are."""
    names = ["policy.json", "policy.safetensors", "normalization.json"]
    for index, name in enumerate(names):
        if fail_after is not None and index == fail_after:
            raise KeyboardInterrupt  # an interrupt midway through the save
        (directory / name).write_text(f"{name} {version}")
    write_manifest(directory, names)


@pytest.mark.parametrize("fail_after", [0, 1, 2])
def test_an_interrupted_directory_save_leaves_the_old_one_verifying(tmp_path: Path, fail_after: int) -> None:
    best = tmp_path / "best"
    with atomic_directory(best) as staging:
        _save(staging, "old")
    verify_manifest(best)
    with pytest.raises(KeyboardInterrupt), atomic_directory(best) as staging:
        _save(staging, "new", fail_after=fail_after)
    verify_manifest(best)
    assert (best / "policy.json").read_text() == "policy.json old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["best"]  # no staging directory left behind


def test_an_interrupt_between_the_renames_puts_the_old_directory_back(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    best = tmp_path / "best"
    with atomic_directory(best) as staging:
        _save(staging, "old")
    real_replace, calls = os.replace, []

    def replace(source: Any, destination: Any) -> None:
        if Path(source).name.startswith(".best.new-"):  # the new directory's rename into place
            calls.append(destination)
            raise KeyboardInterrupt
        real_replace(source, destination)

    monkeypatch.setattr(os, "replace", replace)
    with pytest.raises(KeyboardInterrupt), atomic_directory(best) as staging:
        _save(staging, "new")
    monkeypatch.undo()
    verify_manifest(best)
    assert (best / "policy.json").read_text() == "policy.json old" and calls == [best]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["best"]


def test_a_directory_save_replaces_its_own_files_and_keeps_the_others(tmp_path: Path) -> None:
    best = tmp_path / "best"
    best.mkdir()
    (best / "evaluations.json").write_text("{}")  # not the save's: carried over
    (best / "training.json").write_text("stale")  # the save's own, not written this time: dropped
    ours = ("policy.json", "policy.safetensors", "normalization.json", "MANIFEST.sha256", "training.json")
    with atomic_directory(best, ours=ours) as staging:
        _save(staging, "new")
    assert sorted(p.name for p in best.iterdir()) == [
        "MANIFEST.sha256",
        "evaluations.json",
        "normalization.json",
        "policy.json",
        "policy.safetensors",
    ]
    assert (best / "evaluations.json").read_text() == "{}"
    # Where the manifest must list every file, a file the command does not write is refused before any work.
    (best / "notes.txt").write_text("mine")
    with pytest.raises(OutputError, match=r"notes\.txt, which this command does not write"):
        with atomic_directory(best, ours=ours, others="refuse"):
            pytest.fail("the writer ran before the refusal")
    assert (best / "notes.txt").read_text() == "mine"


def test_removing_a_commands_files_keeps_everything_else(tmp_path: Path) -> None:
    (tmp_path / "policy.json").write_text("{}")
    (tmp_path / "notes.txt").write_text("mine")
    assert remove_written_files(tmp_path, ["policy.json", "MANIFEST.sha256"]) == ["notes.txt"]
    assert (tmp_path / "notes.txt").read_text() == "mine" and not (tmp_path / "policy.json").exists()
    (tmp_path / "notes.txt").unlink()
    assert remove_written_files(tmp_path, ["policy.json"]) == [] and not tmp_path.exists()


def test_a_directory_that_cannot_be_opened_is_refused_by_name(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    def unreadable(*args: Any, **kwargs: Any) -> int:
        raise PermissionError(13, "Permission denied")  # a directory with write but no read permission

    monkeypatch.setattr(os, "open", unreadable)
    with pytest.raises(OutputError, match="--out .*cannot be opened to claim it .*Permission denied"):
        claim_output_dir(tmp_path)


KILLED_BETWEEN_THE_RENAMES = """
import os, sys
from pathlib import Path
from agents.common.files import atomic_directory
best = Path(sys.argv[1])
real_replace = os.replace
def replace(source, destination):
    if Path(source).name.startswith(".best.new-"):
        os._exit(9)  # killed outright: no except, no finally runs
    real_replace(source, destination)
os.replace = replace
with atomic_directory(best) as staging:
    (staging / "policy.json").write_text("new")
"""


def test_a_save_killed_between_the_renames_is_refused_next_time_naming_where_the_old_one_is(tmp_path: Path) -> None:
    """Killed outright between its two renames, a save left best/ missing and its old contents
    hidden in .best.old-*; the next save made a new best/ and buried them. It is refused now,
    naming both and the fix, and once the old directory is back a save works and leaves no
    leftover."""
    best = tmp_path / "best"
    best.mkdir()
    (best / "policy.json").write_text("old")
    (best / "notes.txt").write_text("the user's")
    root = Path(__file__).resolve().parents[3]
    killed = subprocess.run(
        [sys.executable, "-c", KILLED_BETWEEN_THE_RENAMES, str(best)], cwd=root, capture_output=True, check=False
    )
    assert killed.returncode == 9, killed.stderr
    assert not best.exists()
    (aside,) = tmp_path.glob(".best.old-*")
    with pytest.raises(OutputError, match=rf"best is missing, and .*{aside.name} holds what it held .*mv "):
        with atomic_directory(best) as staging:
            (staging / "policy.json").write_text("newer")
    assert not best.exists() and aside.is_dir()  # nothing written, nothing removed
    os.replace(aside, best)  # the fix the message gives
    with atomic_directory(best) as staging:
        (staging / "policy.json").write_text("newer")
    assert (best / "policy.json").read_text() == "newer" and (best / "notes.txt").read_text() == "the user's"
    # Killed after the new directory landed: the superseded copy beside it is removed by the next save.
    (tmp_path / ".best.old-superseded").mkdir()
    with atomic_directory(best) as staging:
        (staging / "policy.json").write_text("newest")
    assert not list(tmp_path.glob(".best.old-*"))


@pytest.mark.parametrize(
    ("code", "busy"), [(errno.EWOULDBLOCK, True), (errno.ENOLCK, False), (errno.EOPNOTSUPP, False)]
)
def test_a_lock_that_fails_for_another_reason_than_a_holder_is_not_reported_as_busy(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, code: int, busy: bool
) -> None:
    """On a file system without locks (NFS without lockd) flock raises ENOLCK: that was reported as
    'in use by another running command', sending the user to wait for a command that does not exist."""
    import fcntl

    def flock(descriptor: int, operation: int) -> None:
        raise OSError(code, os.strerror(code))

    monkeypatch.setattr(fcntl, "flock", flock)
    with holding_output_claims():
        with pytest.raises(OutputError) as raised:
            claim_output_dir(tmp_path, argument="--out")
    assert isinstance(raised.value, OutputBusyError) == busy
    assert "--out" in str(raised.value)
    if not busy:
        assert "cannot be locked" in str(raised.value) and "local file system" in str(raised.value)


HOLD_A_RUN = """
import sys, time
from agents.common.files import claim_output_dir
claim_output_dir(sys.argv[1])
print("claimed", flush=True)
time.sleep(60)
"""


def test_a_directory_save_is_refused_around_a_directory_another_command_holds(tmp_path: Path) -> None:
    """A conversion whose DST was the parent of a running training's run directory swapped the
    parent: the training kept its lock on the old run directory (removed after the swap), and a
    second training could claim the new one. Directories carried into the new one are held for
    the swap, and one another command holds is refused before the writer runs."""
    runs = tmp_path / "runs"
    (runs / "TetherChain-v0" / "ppo_seed0").mkdir(parents=True)
    (runs / "TetherChain-v0" / "ppo_seed0" / "config.yml").write_text("seed: 0\n")
    root = Path(__file__).resolve().parents[3]
    holder = subprocess.Popen(
        [sys.executable, "-c", HOLD_A_RUN, str(runs / "TetherChain-v0" / "ppo_seed0")],
        cwd=root,
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        assert holder.stdout is not None and holder.stdout.readline().strip() == "claimed"
        wrote = []
        with pytest.raises(OutputBusyError, match=r"ppo_seed0 is in use by another running command, and .*runs would"):
            with atomic_directory(runs) as staging:
                wrote.append(staging)
        assert not wrote  # refused before the writer ran
        assert (runs / "TetherChain-v0" / "ppo_seed0" / "config.yml").read_text() == "seed: 0\n"
    finally:
        holder.kill()
        holder.wait()
    with atomic_directory(runs) as staging:  # the holder gone, the save carries the run over
        (staging / "policy.json").write_text("{}")
    assert (runs / "TetherChain-v0" / "ppo_seed0" / "config.yml").read_text() == "seed: 0\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["runs"]


@pytest.mark.parametrize(("path", "message"), [("", "is empty"), ("   ", "is empty"), ("out\x00dir", "NUL character")])
def test_an_empty_or_nul_output_path_is_refused_by_name(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, path: str, message: str
) -> None:
    """Path("") is the current directory: out="" (an unset variable) wrote a command's outputs there;
    a NUL raised a bare ValueError from the path functions."""
    monkeypatch.chdir(tmp_path)
    with holding_output_claims(), pytest.raises(OutputError, match=f"--out .*{message}"):
        prepare_output_dir(path)
    assert not list(tmp_path.iterdir())
