"""Careful output files for the agents' commands: check before working, never overwrite an
earlier result unasked, never write through a symlink, and never leave a half-written file.

Every command (``agents.compare``, ``agents.train``, ``agents.convert``) checks its output
directory with :func:`prepare_output_dir` and the files it is about to write with
:func:`check_output_files` *before* it does any work, so that a bad ``--out`` fails in
milliseconds instead of after every rollout. The files themselves are written with
:func:`atomic_write`: a temporary file in the same directory, then ``os.replace``, so a reader
sees either the old file or the new one, and a symlink at the target is replaced (never
followed) -- but the checks refuse symlinked outputs explicitly before that.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from collections.abc import Iterable, Iterator
from pathlib import Path

from tether_gym._optional import require

__all__ = [
    "OutputError",
    "OutputExistsError",
    "atomic_write",
    "atomic_write_bytes",
    "atomic_write_text",
    "check_no_symlinks_inside",
    "check_output_files",
    "prepare_output_dir",
    "prepare_table_outputs",
]


class OutputError(ValueError):
    """An output path that a command cannot or must not write: a file where a directory is
    needed, a path inside a file, an unwritable directory, or a symlink."""


class OutputExistsError(OutputError):
    """An output that an earlier run wrote, which a command replaces only with ``--force``."""


def prepare_output_dir(path: str | Path, argument: str = "--out") -> Path:
    """Check that ``path`` can hold a command's outputs, create it (with its parents), and
    prove it writable by creating and removing a probe file. Returns the path.

    Raises :class:`OutputError`, naming ``argument``, if ``path`` is a symlink, an existing
    file, inside a file, or cannot be created or written."""
    path = Path(path)
    if path.is_symlink():
        raise OutputError(
            f"{argument} {path} is a symlink (to {os.readlink(path)}); refusing to write through it: "
            f"pass the real directory instead"
        )
    if path.exists() and not path.is_dir():
        raise OutputError(f"{argument} {path} is a file, not a directory: pass a directory path")
    for parent in path.parents:
        if parent.exists():
            if not parent.is_dir():
                raise OutputError(
                    f"{argument} {path} is inside {parent}, which is a file, not a directory: pass a directory path"
                )
            break
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as error:
        raise OutputError(
            f"{argument} {path} cannot be created ({error.strerror}): pass a writable directory"
        ) from error
    try:
        with tempfile.TemporaryFile(dir=path, prefix=".write-probe-"):
            pass
    except OSError as error:
        raise OutputError(f"{argument} {path} is not writable ({error.strerror}): pass a writable directory") from error
    return path


def check_output_files(
    directory: Path, names: Iterable[str], force: bool, argument: str = "--out", what: str = "an earlier run"
) -> None:
    """Refuse to write ``directory / name`` for any of ``names`` that is a symlink (always) or a
    directory (always), or that exists already unless ``force``.

    Raises :class:`OutputError` or :class:`OutputExistsError` naming the files, ``argument`` and
    the fix."""
    existing = []
    for name in names:
        target = directory / name
        if target.is_symlink():
            raise OutputError(
                f"{target} is a symlink (to {os.readlink(target)}); refusing to write through it: "
                f"remove it or pass another {argument}"
            )
        if target.is_dir():
            raise OutputError(
                f"{target} is a directory where a file will be written: remove it or pass another {argument}"
            )
        if target.exists():
            existing.append(target.name)
    if existing and not force:
        raise OutputExistsError(
            f"{directory} already holds {', '.join(existing)} from {what}: pass --force to replace "
            f"{'them' if len(existing) > 1 else 'it'}, or another {argument}"
        )


def check_no_symlinks_inside(directory: Path, argument: str = "--out") -> None:
    """Refuse a directory tree that contains a symlink anywhere below it (not followed), so that
    no library writing into it (TensorBoard, SB3's evaluation log) can be led elsewhere."""
    for root, dirnames, filenames in os.walk(directory, followlinks=False):
        for name in dirnames + filenames:
            if os.path.islink(os.path.join(root, name)):
                link = Path(root) / name
                raise OutputError(
                    f"{link} is a symlink (to {os.readlink(link)}); refusing to write into a run directory "
                    f"that holds symlinks: remove it or pass another {argument}"
                )


def _umask() -> int:
    """The process's file-creation mask (read by setting and restoring it)."""
    mask = os.umask(0)
    os.umask(mask)
    return mask


@contextlib.contextmanager
def atomic_write(path: str | Path) -> Iterator[Path]:
    """Yield a temporary path in ``path``'s directory, with the same suffix, for a writer to
    fill; on success move it onto ``path`` with ``os.replace`` (atomic, and a symlink at
    ``path`` is replaced, not followed); on failure remove it and leave ``path`` untouched.

    Refuses (``OutputError``) when ``path`` is a symlink, so that a symlink planted after the
    command's checks is still not silently replaced."""
    path = Path(path)
    if path.is_symlink():
        raise OutputError(f"{path} is a symlink (to {os.readlink(path)}); refusing to write through it")
    descriptor, temporary = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=path.suffix)
    os.close(descriptor)
    temporary_path = Path(temporary)
    try:
        yield temporary_path
        os.chmod(temporary_path, 0o666 & ~_umask())  # mkstemp makes 0600; give the usual mode
        with open(temporary_path, "rb+") as stream:
            os.fsync(stream.fileno())
        if path.is_symlink():
            raise OutputError(f"{path} became a symlink while it was being written; refusing to replace it")
        os.replace(temporary_path, path)
    except BaseException:
        temporary_path.unlink(missing_ok=True)
        raise


def atomic_write_bytes(path: str | Path, data: bytes) -> None:
    """Write ``data`` to ``path`` atomically (see :func:`atomic_write`)."""
    with atomic_write(path) as temporary:
        temporary.write_bytes(data)


def atomic_write_text(path: str | Path, text: str) -> None:
    """Write ``text`` (UTF-8) to ``path`` atomically (see :func:`atomic_write`)."""
    atomic_write_bytes(path, text.encode("utf-8"))


def prepare_table_outputs(
    out: str | Path, tables: Iterable[str], plots: Iterable[str], with_plots: bool, force: bool, what: str
) -> Path:
    """Everything a table-and-plots command (comparison, benchmark) checks before any work:
    matplotlib is there when plots are asked for, ``out`` is a usable directory (``--out``), and
    none of its ``tables`` (and ``plots``) would overwrite ``what`` without ``force`` or write
    through a symlink. Returns the directory."""
    if with_plots:  # checked now, not after every rollout
        require("matplotlib", "plots", "the plots (or pass --no-plots; plots=False in Python)")
    directory = prepare_output_dir(out, argument="--out")
    check_output_files(
        directory, tuple(tables) + (tuple(plots) if with_plots else ()), force=force, argument="--out", what=what
    )
    return directory
