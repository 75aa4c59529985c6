"""Pickle-based Stable-Baselines3 files (``model.zip``, ``vecnormalize.pkl``), behind an opt-in.

An SB3 ``.zip`` stores some of its fields cloudpickled, and ``VecNormalize.save`` writes a plain
pickle. Unpickling runs whatever code the file names, so a crafted model file runs code the moment
it is loaded. tether-gym's own format (:mod:`agents.policies.format`) has no such step; these files
are read only when the caller passes ``trust_pickle=True`` (``--trust-pickle`` on the command
line), and then with a :class:`PickleTrustWarning`. This is the only module of the project that
unpickles anything.
"""

from __future__ import annotations

import pickle
import warnings
from pathlib import Path
from typing import Any

from tether_gym._optional import needs_extra

with needs_extra("train", "loading pickle-based SB3 models"):
    from stable_baselines3.common.base_class import BaseAlgorithm
    from stable_baselines3.common.vec_env import VecEnv, VecNormalize

from ..common.commands import program
from ..common.reading import read_yaml
from .format import ALGORITHMS
from .layout import METADATA_FILE

__all__ = [
    "PickleNotTrustedError",
    "PickleTrustWarning",
    "is_pickle_model",
    "load_pickled_model",
    "normalization_file_of",
    "refuse_untrusted",
    "sb3_model_file",
]

#: File names of pickle-based models inside a run directory.
PICKLE_MODEL_NAMES = ("model.zip", "best_model.zip")


class PickleNotTrustedError(ValueError):
    """A pickle-based model file that the caller has not opted in to load."""


class PickleTrustWarning(UserWarning):
    """Emitted whenever a pickle-based file is loaded after the caller opted in."""


def is_pickle_model(path: str | Path) -> bool:
    """Whether ``path`` is an SB3 ``.zip`` / ``.pkl`` file, or a directory holding ``model.zip`` or
    ``best/best_model.zip`` but no safe ``policy.json``."""
    path = Path(path)
    if path.is_file():
        return path.suffix in (".zip", ".pkl")
    if path.is_dir() and not (path / METADATA_FILE).is_file():
        return (
            any((path / name).is_file() for name in PICKLE_MODEL_NAMES) or (path / "best" / "best_model.zip").is_file()
        )
    return False


def refuse_untrusted(path: str | Path, opt_in: str = "--trust-pickle (trust_pickle=True in Python)") -> None:
    """Raise :class:`PickleNotTrustedError`: why ``path`` is not loaded, and the two ways on."""
    raise PickleNotTrustedError(
        f"{path} is a pickle-based Stable-Baselines3 model (model .zip / vecnormalize.pkl). Loading it unpickles "
        f"data, and a crafted file runs arbitrary code the moment it is loaded, so tether-gym loads pickle files "
        f"only if you opt in. If you trust where it came from, either convert it once to the safe format: "
        f"{program('convert')} {path} NEW_DIR --trust-pickle, and use NEW_DIR; or pass {opt_in} to load it "
        f"as it is."
    )


def _warn(files: list[Path]) -> None:
    warnings.warn(
        f"loading pickle-based files {[str(f) for f in files]} because you passed --trust-pickle: unpickling runs "
        f"any code a crafted file contains. Do this only for files you made yourself or fully trust, and prefer "
        f"the safe format ({program('convert')}).",
        PickleTrustWarning,
        stacklevel=3,
    )


def sb3_model_file(path: str | Path, best: bool = False) -> Path:
    """The SB3 model ``.zip`` of ``path``: the file itself, or a run directory's ``model.zip``
    (``best/best_model.zip`` with ``best``)."""
    path = Path(path)
    if path.is_dir():
        candidates = (
            [path / "best" / "best_model.zip", path / "best_model.zip"]
            if best
            else [path / "model.zip", path / "best_model.zip"]
        )
        for candidate in candidates:
            if candidate.is_file():
                return candidate
        raise FileNotFoundError(f"{path} holds no {'best_model.zip' if best else 'model.zip'}")
    if path.suffix == ".pkl":
        raise ValueError(f"{path} holds normalisation statistics, not a model: pass the model .zip or its directory")
    if not path.is_file():
        raise FileNotFoundError(f"no model at {path}")
    return path


def normalization_file_of(model_file: Path) -> Path | None:
    """The ``VecNormalize`` statistics saved with an SB3 model: ``<prefix>_vecnormalize_<steps>_steps.pkl``
    next to ``<prefix>_<steps>_steps.zip`` (CheckpointCallback's names), else ``vecnormalize.pkl`` in
    the same directory; None if there are none."""
    stem = model_file.stem
    if stem.endswith("_steps") and stem.count("_") >= 2:
        prefix, steps = stem[: -len("_steps")].rsplit("_", 1)
        candidate = model_file.with_name(f"{prefix}_vecnormalize_{steps}_steps.pkl")
        if candidate.is_file():
            return candidate
    candidate = model_file.with_name("vecnormalize.pkl")
    return candidate if candidate.is_file() else None


def run_config(model_file: Path) -> dict[str, Any]:
    """The ``config.yml`` of the run a model file belongs to (read with
    :func:`~agents.common.reading.read_yaml`), or {}."""
    for directory in (model_file.parent, model_file.parent.parent):
        config_file = directory / "config.yml"
        if config_file.is_file():
            config = read_yaml(config_file)
            return config if isinstance(config, dict) else {}
    return {}


def load_pickled_model(
    path: str | Path,
    trust_pickle: bool,
    best: bool = False,
    algo: str | None = None,
    env: VecEnv | None = None,
    **load_kwargs: Any,
) -> tuple[BaseAlgorithm, VecNormalize | None, dict[str, Any], list[Path]]:
    """Load an SB3 model and its ``VecNormalize`` statistics by unpickling them -- only with
    ``trust_pickle`` (otherwise :class:`PickleNotTrustedError`, before any file is opened).

    Returns ``(model, normalizer or None, the run's config.yml or {}, the files loaded)``. The
    algorithm comes from ``algo``, else the run's ``config.yml``, else each one is tried. With
    ``env`` (to resume training), the statistics wrap ``env`` and the model is attached to them.
    ``load_kwargs`` go to ``<Algorithm>.load``."""
    if not trust_pickle:
        refuse_untrusted(path)
    model_file = sb3_model_file(path, best)
    statistics = normalization_file_of(model_file)
    files = [model_file] + ([statistics] if statistics is not None else [])
    _warn(files)
    config = run_config(model_file)
    algo = algo or config.get("algo")
    load_kwargs.setdefault("device", "cpu")
    normalizer = None
    if statistics is not None:
        with open(statistics, "rb") as stream:
            normalizer = pickle.load(stream)  # a VecNormalize without its venv
        if not isinstance(normalizer, VecNormalize):
            raise ValueError(f"{statistics} holds a {type(normalizer).__name__}, not VecNormalize statistics")
        if env is not None:
            normalizer.set_venv(env)
            env = normalizer
    if env is not None:
        load_kwargs["env"] = env
    if algo is None:
        for candidate, cls in ALGORITHMS.items():
            try:
                model = cls.load(str(model_file), **load_kwargs)
                algo = candidate
                break
            except Exception:  # noqa: BLE001 - the wrong class fails in several ways
                continue
        else:
            raise ValueError(f"{model_file} is not a model of any of {sorted(ALGORITHMS)}")
    else:
        if algo not in ALGORITHMS:
            raise ValueError(f"algorithm {algo!r} (of {model_file}) is not one of {sorted(ALGORITHMS)}")
        model = ALGORITHMS[algo].load(str(model_file), **load_kwargs)
    return model, normalizer, {**config, "algo": algo}, files
