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
import errno
import functools
import glob
import os
import shutil
import tempfile
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path
from typing import Any, TypeVar, cast

from tether_gym._optional import require

__all__ = [
    "OutputBusyError",
    "OutputError",
    "OutputExistsError",
    "atomic_directory",
    "atomic_write",
    "atomic_write_bytes",
    "atomic_write_text",
    "check_no_symlinks_between",
    "check_no_symlinks_inside",
    "check_output_files",
    "claim_output_dir",
    "holding_output_claims",
    "holds_output_claims",
    "make_dirs_below",
    "prepare_output_dir",
    "prepare_table_outputs",
    "release_output_dir",
    "remove_written_files",
]


class OutputError(ValueError):
    """An output path that a command cannot or must not write: a file where a directory is
    needed, a path inside a file, an unwritable directory, or a symlink."""


class OutputExistsError(OutputError):
    """An output that an earlier run wrote, which a command replaces only with ``--force``."""


def prepare_output_dir(
    path: str | Path, argument: str = "--out", root: str | Path | None = None, claim: bool = True
) -> Path:
    """Check that ``path`` can hold a command's outputs, create it (with its parents), prove it
    writable by creating and removing a probe file, and (with ``claim``) take the command's
    exclusive claim on it (:func:`claim_output_dir`). Returns the path.

    ``root`` is the output root the user named (``--out``) when ``path`` lies below it: every
    component from ``root`` down to ``path`` must then be a real directory, not a symlink.

    Raises :class:`OutputError`, naming ``argument``, if ``path`` (or a component below ``root``)
    is a symlink, an existing file, inside a file, or cannot be created or written, and
    :class:`OutputBusyError` if another running command holds it."""
    if isinstance(path, str) and not path.strip():
        # Path("") is the current directory: an unset variable would have written the outputs there.
        raise OutputError(f"{argument} is empty ({path!r}): pass a directory path")
    if "\x00" in str(path):
        raise OutputError(f"{argument} {str(path)!r} holds a NUL character, which no path can: pass a directory path")
    path = Path(path)
    if root is not None:
        check_no_symlinks_between(root, path, argument)
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
        if root is not None:
            Path(root).mkdir(parents=True, exist_ok=True)
            make_dirs_below(root, path, argument)
        else:
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
    if claim:
        claim_output_dir(path, argument)
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


class OutputBusyError(OutputError):
    """An output directory that another running command holds (:func:`claim_output_dir`)."""


#: Directories this process holds an exclusive lock on (real path -> open descriptor), and the
#: stack of :func:`holding_output_claims` scopes that release the claims made inside them.
_claims: dict[str, int] = {}
_claim_scopes: list[list[str]] = []


def claim_output_dir(directory: str | Path, argument: str = "--out") -> Path:
    """Take an exclusive lock (``flock``) on the existing directory ``directory`` for as long as
    this process runs the command that writes it, so that a second command on the same output,
    started while the first runs, is refused instead of overwriting it. The lock lives on the
    directory itself (no lock file is left behind) and the kernel drops it when the process ends,
    however it ends. Claiming a directory this process holds already is a no-op.

    Inside :func:`holding_output_claims` the lock is released when the scope ends; otherwise at
    process exit. Raises :class:`OutputBusyError` naming ``argument`` when another process holds it."""
    directory = Path(directory)
    key = os.path.realpath(directory)
    if key in _claims:
        return directory
    try:
        import fcntl
    except ImportError:  # no flock (Windows): the checks for an earlier result still apply
        return directory
    try:
        descriptor = os.open(directory, os.O_RDONLY | getattr(os, "O_DIRECTORY", 0))
    except OSError as error:
        raise OutputError(
            f"{argument} {directory} cannot be opened to claim it for this command ({error.strerror}): "
            f"pass a directory you can read and write"
        ) from error
    try:
        fcntl.flock(descriptor, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError as error:
        os.close(descriptor)
        if error.errno not in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES):
            # Not another holder: a file system without locks (NFS without lockd: ENOLCK) or another
            # failure, which "in use by another command" would have misreported.
            raise OutputError(
                f"{argument} {directory} cannot be locked for this command ({error.strerror or error}): its file "
                f"system does not support locks, so a second command could write it at the same time; pass an "
                f"{argument} on a local file system"
            ) from error
        raise OutputBusyError(
            f"{argument} {directory} is in use by another running command (it holds the directory's lock): "
            f"wait for that command to end, or pass another {argument}"
        ) from error
    _claims[key] = descriptor
    if _claim_scopes:
        _claim_scopes[-1].append(key)
    return directory


def release_output_dir(directory: str | Path) -> None:
    """Release this process's claim on ``directory`` (:func:`claim_output_dir`), if it holds one."""
    descriptor = _claims.pop(os.path.realpath(directory), None)
    if descriptor is not None:
        os.close(descriptor)  # closing the only descriptor of the lock releases it


@contextlib.contextmanager
def holding_output_claims() -> Iterator[None]:
    """Release, when the block ends, the output claims made inside it: a command's function,
    called from Python, leaves no directory locked after it returns."""
    _claim_scopes.append([])
    try:
        yield
    finally:
        for key in _claim_scopes.pop():
            descriptor = _claims.pop(key, None)
            if descriptor is not None:
                os.close(descriptor)


F = TypeVar("F", bound=Callable[..., Any])


def holds_output_claims(function: F) -> F:
    """Decorate a command's top-level function with :func:`holding_output_claims`."""

    @functools.wraps(function)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        with holding_output_claims():
            return function(*args, **kwargs)

    return cast(F, wrapper)


def check_no_symlinks_between(root: str | Path, target: str | Path, argument: str = "--out") -> None:
    """Refuse (``OutputError`` naming the link and ``argument``) when ``root`` or any existing path
    component below it on the way to ``target`` (``target`` included) is a symlink: a command
    writes only through real directories from its output root down, so that ``out/<id> ->
    elsewhere`` cannot lead it elsewhere. ``target`` must be ``root`` or lie below it. Components
    above ``root`` are the user's choice and are not checked."""
    root, target = Path(root), Path(target)
    try:
        parts = target.relative_to(root).parts
    except ValueError:
        raise ValueError(f"{target} is not below the output root {root}") from None
    current = root
    for part in ("", *parts):
        current = current / part if part else current
        if current.is_symlink():
            raise OutputError(
                f"{current} is a symlink (to {os.readlink(current)}); refusing to write through it "
                f"(below {argument} {root}): remove it or pass another {argument}"
            )
        if not current.exists():
            return  # nothing below a missing component exists yet


def make_dirs_below(root: str | Path, target: str | Path, argument: str = "--out") -> Path:
    """Create ``target`` and its missing parents up from ``root``, one component at a time, each
    checked not to be a symlink (:func:`check_no_symlinks_between`) before and after it is made."""
    root, target = Path(root), Path(target)
    check_no_symlinks_between(root, target, argument)
    current = root
    for part in ("", *target.relative_to(root).parts):
        current = current / part if part else current
        if current.exists() and not current.is_dir():
            raise OutputError(f"{current} is a file where a directory is needed: remove it or pass another {argument}")
        current.mkdir(exist_ok=True)
    check_no_symlinks_between(root, target, argument)
    return target


@contextlib.contextmanager
def atomic_directory(target: str | Path, ours: Iterable[str] = (), others: str = "carry") -> Iterator[Path]:
    """Yield a new, empty sibling directory of ``target`` for a writer to fill with a whole
    multi-file save; on success, put it in place of ``target`` as a whole: the old directory is
    renamed aside, the new one renamed to ``target``, and the old one removed. A reader sees the
    old complete directory or the new complete one, never a mix of the two (between the two
    renames, for an instant, neither). On failure or interrupt the new directory is removed and
    ``target`` is left as it was.

    ``ours`` names the files the command writes there: one of them in the old directory that the
    writer did not write again is stale and dropped. Files a command did not write are never
    deleted: with ``others="carry"`` whatever else the old directory holds is carried into the new
    one (hard-linked, or copied); with ``others="refuse"`` it is refused with :class:`OutputError`
    before the writer runs (for a directory whose manifest must list exactly its files).
    Refuses a symlinked ``target``."""
    if others not in ("carry", "refuse"):
        raise ValueError(f"others must be 'carry' or 'refuse'; got {others!r}")
    target = Path(target)
    if target.is_symlink():
        raise OutputError(f"{target} is a symlink (to {os.readlink(target)}); refusing to write through it")
    known = set(ours)
    if others == "refuse" and target.is_dir():
        foreign = sorted(path.name for path in target.iterdir() if path.name not in known or not path.is_file())
        if foreign:
            raise OutputError(
                f"{target} holds {', '.join(foreign)}, which this command does not write: move "
                f"{'them' if len(foreign) > 1 else 'it'} away first (files a command did not write are never deleted)"
            )
    _recover_from_a_killed_swap(target)
    # Directories carried into the new one are held for the swap: a command running in one of them
    # (a training whose run directory lies below a conversion's DST) would keep its lock on the old
    # directory, removed after the swap, while a second command could claim the new one.
    held = _hold_subdirectories(target) if others == "carry" else []
    staging = Path(tempfile.mkdtemp(dir=target.parent, prefix=f".{target.name}.new-"))
    aside: Path | None = None
    try:
        yield staging
        if others == "carry" and target.is_dir():
            written = {path.name for path in staging.iterdir()}
            for old in target.iterdir():
                if old.name not in written and old.name not in known:
                    _carry(old, staging / old.name)
        os.chmod(staging, 0o777 & ~_umask())  # mkdtemp makes 0700; give the usual mode
        if target.is_symlink():
            raise OutputError(f"{target} became a symlink while it was being written; refusing to replace it")
        if target.exists():
            aside = Path(tempfile.mkdtemp(dir=target.parent, prefix=f".{target.name}.old-"))
            os.replace(target, aside)  # onto the empty directory mkdtemp made
        os.replace(staging, target)
    except BaseException:
        if aside is not None and not target.exists():
            os.replace(aside, target)  # interrupted between the renames: the old directory goes back
            aside = None
        shutil.rmtree(staging, ignore_errors=True)
        if aside is not None:
            shutil.rmtree(aside, ignore_errors=True)
        raise
    finally:
        for descriptor in held:
            os.close(descriptor)
    if aside is not None:
        shutil.rmtree(aside, ignore_errors=True)


def _hold_subdirectories(target: Path) -> list[int]:
    """Take the lock of :func:`claim_output_dir` on every directory below ``target`` (not
    following symlinks), except those this process claims already, and return their descriptors;
    :class:`OutputBusyError` naming the first that another running command holds (none is then
    held)."""
    try:
        import fcntl
    except ImportError:  # no flock (Windows)
        return []
    held: list[int] = []
    if not target.is_dir() or target.is_symlink():
        return held
    for root, dirnames, _ in os.walk(target, followlinks=False):
        for name in dirnames:
            directory = os.path.join(root, name)
            if os.path.islink(directory) or os.path.realpath(directory) in _claims:
                continue
            try:
                descriptor = os.open(directory, os.O_RDONLY | getattr(os, "O_DIRECTORY", 0))
            except OSError:
                continue  # unreadable: nothing can hold it through this process's eyes, and it is carried as is
            try:
                fcntl.flock(descriptor, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError as error:
                os.close(descriptor)
                if error.errno not in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES):
                    continue  # no locks on this file system: claim_output_dir refuses those outputs itself
                for other in held:
                    os.close(other)
                raise OutputBusyError(
                    f"{directory} is in use by another running command, and {target} would be replaced around "
                    f"it: wait for that command to end, or write elsewhere"
                ) from error
            held.append(descriptor)
    return held


def _recover_from_a_killed_swap(target: Path) -> None:
    """Deal with what a save killed outright (SIGKILL, power loss: no ``except`` ran) between its
    two renames left: ``target`` missing and its old contents hidden in ``.<name>.old-*`` beside it
    (refused, naming both and the fix: a new save would bury them); or, killed after the new
    directory landed, a superseded ``.old-*`` copy (removed: what it held that the command did not
    write was carried into the new directory before the swap)."""
    leftovers = sorted(target.parent.glob(f".{glob.escape(target.name)}.old-*"))
    if not leftovers:
        return
    if not target.exists():
        raise OutputError(
            f"{target} is missing, and {leftovers[0]} holds what it held before a save was killed between its "
            f"two renames: move it back (mv {leftovers[0]} {target}) or remove it, then run again"
        )
    for leftover in leftovers:
        if leftover.is_dir() and not leftover.is_symlink():
            shutil.rmtree(leftover, ignore_errors=True)


def _carry(source: Path, destination: Path) -> None:
    """Bring ``source`` (a file, directory or symlink of a directory being replaced) into the new
    directory unchanged: a hard link where the file system allows, else a copy."""
    if source.is_symlink():
        os.symlink(os.readlink(source), destination)
    elif source.is_dir():
        shutil.copytree(source, destination, symlinks=True, copy_function=_link_or_copy)
    else:
        _link_or_copy(source, destination)


def _link_or_copy(source: str | Path, destination: str | Path) -> None:
    try:
        os.link(source, destination)
    except OSError:
        shutil.copy2(source, destination)


def remove_written_files(directory: Path, names: Iterable[str]) -> list[str]:
    """Delete the files ``names`` (what a command itself writes) from ``directory``, and the
    directory too once it is empty; anything else in it is kept. Symlinks among ``names`` are
    unlinked, never followed. Returns the names of what was kept."""
    for name in names:
        path = directory / name
        if path.is_symlink() or path.is_file():
            path.unlink()
    kept = sorted(path.name for path in directory.iterdir())
    if not kept:
        directory.rmdir()
    return kept
