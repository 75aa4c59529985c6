"""Run directories of the trainers: ``<out>/<env>/<algo>_seed<seed>/``, checked before any work
(usable, no symlinks inside, no earlier run unless ``--force``), an earlier run's files cleared
when it is replaced, and what ``--resume`` names checked against the run to be trained."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from ..common.files import (
    OutputError,
    OutputExistsError,
    atomic_directory,
    check_no_symlinks_inside,
    prepare_output_dir,
    remove_written_files,
)
from ..policies.format import check_resumable, is_policy_dir, read_metadata, save_policy
from ..policies.layout import METADATA_FILE, POLICY_FILES
from ..policies.normalization import NormalizationStatistics
from ..policies.pickled import is_pickle_model, normalization_file_of, refuse_untrusted, sb3_model_file
from ..policies.spec import PolicySpec
from .selection import EVALUATIONS_FILE

__all__ = [
    "LEGACY_BEST_FILES",
    "LEGACY_RUN_FILES",
    "clear_earlier_run",
    "earlier_run_files",
    "prepare_run_dir",
    "resume_source",
    "save_residual_policy",
]

#: Files an earlier run of agents.train may have left (this format and the pickle-based one).
LEGACY_RUN_FILES = ("model.zip", "vecnormalize.pkl")
LEGACY_BEST_FILES = ("best_model.zip", "vecnormalize.pkl", "evaluations.npz")


def earlier_run_files(run: Path) -> list[str]:
    """What an earlier run left in ``run`` (relative names), empty for a new run directory."""
    found = [name for name in ("config.yml", METADATA_FILE, *LEGACY_RUN_FILES) if (run / name).exists()]
    for sub in ("best", "checkpoints"):
        if (run / sub).is_dir() and any((run / sub).iterdir()):
            found.append(f"{sub}/")
    return found


def prepare_run_dir(out: str | Path, env_id: str, algo: str, seed: int, force: bool) -> Path:
    """The run directory ``out/env_id/algo_seed<seed>`` (``algo`` may carry a suffix, e.g.
    ``ppo_multiagent``), checked before any work: usable, no symlink on the way from ``out`` to
    it nor inside it, claimed by this command (a second command on it is refused while this one
    runs: :func:`agents.common.files.claim_output_dir`), and no earlier run unless ``force``.
    The claim comes before the check for an earlier run, so two runs started together cannot
    both find the directory empty."""
    out = Path(out)
    if out.is_symlink():
        raise OutputError(f"--out {out} is a symlink; refusing to write through it: pass the real directory")
    run = prepare_output_dir(out / env_id / f"{algo}_seed{seed}", argument="--out", root=out)
    check_no_symlinks_inside(run)
    earlier = earlier_run_files(run)
    if earlier and not force:
        raise OutputExistsError(
            f"{run} already holds a run ({', '.join(earlier)}) with the same --out, env, algorithm and seed: pass "
            f"--force to replace it (its models, best/ and checkpoints/ are deleted; TensorBoard logs are kept), "
            f"or choose another --seed or --out"
        )
    return run


def clear_earlier_run(run: Path, algo: str, keep: set[Path]) -> None:
    """Delete what an earlier run wrote (models, best/, checkpoints/), except the paths in
    ``keep`` (the checkpoint being resumed), by the file names the trainers write: any other
    file there is kept (and its directory with it). TensorBoard logs stay: SB3 numbers each
    run's subdirectory, so they do not mix."""
    keep = {path.resolve() for path in keep}

    def remove(path: Path) -> None:
        if path.resolve() in keep or not (path.exists() or path.is_symlink()):
            return
        if path.is_dir() and not path.is_symlink():
            remove_written_files(path, (*POLICY_FILES, "config.yml", EVALUATIONS_FILE))
        else:
            path.unlink()

    if run.resolve() not in keep:
        for name in (*POLICY_FILES, *LEGACY_RUN_FILES):
            remove(run / name)
    best = run / "best"
    if best.is_dir() and best.resolve() not in keep:
        remove_written_files(best, (*POLICY_FILES, EVALUATIONS_FILE, *LEGACY_BEST_FILES))
    checkpoints = run / "checkpoints"
    if checkpoints.is_dir():
        for entry in checkpoints.iterdir():
            ours = (entry.is_dir() and (entry / METADATA_FILE).is_file()) or (
                entry.suffix in (".zip", ".pkl") and entry.name.startswith(f"{algo}_")
            )
            if ours:
                remove(entry)


def resume_source(
    resume: str | Path,
    trust_pickle: bool,
    algo: str,
    env_id: str,
    spec: PolicySpec | None = None,
    normalize: bool | None = None,
) -> tuple[str, Path, set[Path]]:
    """What ``--resume`` names: ``("safe", policy directory, paths)`` or ``("pickle", model .zip,
    paths)``, checked before any work: PickleNotTrustedError for a pickle without the opt-in,
    PolicyFormatError for a safe checkpoint of another algorithm or env, without training state,
    or recorded with other settings than the run's (``spec``: ``residual_on`` and ``multiagent``;
    ``normalize``: whether observations are normalised), when those are given."""
    path = Path(resume)
    if not path.exists():
        raise FileNotFoundError(
            f"--resume {path} does not exist: pass a checkpoint directory "
            f"(<run>/checkpoints/<algo>_<steps>_steps), <run>/best or a run directory"
        )
    if is_policy_dir(path):
        check_resumable(read_metadata(path), algo, f"--resume {path}", env_id, spec=spec, normalize=normalize)
        return "safe", path, {path}
    if is_pickle_model(path):
        if not trust_pickle:
            refuse_untrusted(path, opt_in="--trust-pickle")
        model_file = sb3_model_file(path)
        statistics = normalization_file_of(model_file)
        return "pickle", model_file, {model_file} | ({statistics} if statistics else set())
    raise FileNotFoundError(
        f"--resume {path} holds no checkpoint: pass a directory with {METADATA_FILE} "
        f"(or, with --trust-pickle, an SB3 .zip)"
    )


def save_residual_policy(
    directory: Path,
    model: Any,
    statistics: NormalizationStatistics,
    env_id: str,
    provenance: dict[str, Any],
    residual_on: str,
    algo: str,
    extra_files: tuple[str, ...] = (),
    whole_directory: bool = False,
) -> Path:
    """Write ``model``'s policy, a residual on the baseline ``residual_on``, in the safe format
    as ``algo`` (the trainers without an SB3 run of their own: ``ars``, ``dagger``). With
    ``whole_directory`` (``best/``), the save replaces ``directory`` as a whole, so an interrupt
    never leaves it half-written."""
    spec = PolicySpec(residual_on=residual_on)
    if not whole_directory:
        return save_policy(
            directory, model, statistics, env_id, provenance, extra_files=extra_files, spec=spec, algo=algo
        )
    directory.parent.mkdir(parents=True, exist_ok=True)
    with atomic_directory(directory, ours=POLICY_FILES) as staging:
        save_policy(staging, model, statistics, env_id, provenance, extra_files=extra_files, spec=spec, algo=algo)
    return directory
