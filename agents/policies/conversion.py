"""Converting a pickle-based SB3 model to the safe policy format: the library part of
``python -m agents.convert`` (:mod:`agents.convert`, whose docstring describes what it does).

:func:`convert` takes a :class:`ConvertConfig`; it unpickles the source only with
``trust_pickle``, writes the safe format into a scratch directory, checks there that the
converted policy's actions are bit-identical to the original's (:mod:`.reference`), and only
then moves the files into the destination.
"""

from __future__ import annotations

import dataclasses
import shutil
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from tether_gym._optional import needs_extra

from ..common.checks import MAX_CHECK_OBSERVATIONS, check_int
from ..common.cli import REFERENCE_FILE
from ..common.files import (
    atomic_directory,
    atomic_write_bytes,
    check_output_files,
    holds_output_claims,
    prepare_output_dir,
)
from .format import save_policy, sha256_hex, tensor_bytes, write_manifest
from .layout import MANIFEST_FILE, POLICY_FILES, PolicyFormatError
from .loaded import check_actions_fit
from .pickled import is_pickle_model, load_pickled_model, refuse_untrusted, sb3_model_file
from .reference import reference_observations, safe_actions, sb3_actions, trajectory_observations

with needs_extra("train", "converting SB3 models"):
    import torch

__all__ = ["ConvertConfig", "convert"]


@dataclasses.dataclass(frozen=True)
class ConvertConfig:
    """What to convert, and how (the options of ``python -m agents.convert``)."""

    source: Path
    """``SRC``: an SB3 run directory (``model.zip`` and ``vecnormalize.pkl``, or with ``best``
    ``best/best_model.zip``) or a model ``.zip`` (its statistics are found next to it)."""
    destination: Path
    """``DST``: the directory for the safe format (may be ``source``'s directory)."""
    trust_pickle: bool = False
    """Required: converting unpickles ``source``, which runs any code a crafted file contains."""
    best: bool = False
    """Convert the run directory's ``best/best_model.zip`` instead of its ``model.zip``."""
    algo: str | None = None
    """The algorithm (``ppo``, ``sac``, ``td3``), if ``source`` has no ``config.yml`` (else each is tried)."""
    env_id: str | None = None
    """The env id the model was trained on, if ``source`` has no ``config.yml`` (recorded in ``destination``)."""
    training_state: bool = False
    """Keep the optimizer states, so that ``agents.train --resume`` continues training."""
    check_observations: int = 512
    """Observations (at least 16) on which the converted actions must be bit-identical to the original's."""
    reference: bool = False
    """Keep those observations and actions in ``destination``'s ``reference_actions.safetensors``."""
    force: bool = False
    """Replace an earlier conversion in ``destination``."""

    def __post_init__(self) -> None:
        object.__setattr__(self, "source", Path(self.source))
        object.__setattr__(self, "destination", Path(self.destination))
        object.__setattr__(
            self,
            "check_observations",
            check_int("check_observations", self.check_observations, 16, MAX_CHECK_OBSERVATIONS),
        )


@holds_output_claims
def convert(config: ConvertConfig) -> Path:
    """Convert the pickle-based SB3 model ``config.source`` to the safe format in
    ``config.destination`` (see :mod:`agents.convert`); returns the destination.

    Raises :class:`agents.policies.pickled.PickleNotTrustedError` without ``trust_pickle`` (before
    reading anything), :class:`agents.common.files.OutputError` for an unusable or symlinked
    destination, :class:`agents.common.files.OutputExistsError` if it holds an earlier conversion
    and not ``force``, and :class:`agents.policies.layout.PolicyFormatError` if the converted
    policy's actions differ from the original's."""
    source, destination = config.source, config.destination
    if not source.exists():
        raise FileNotFoundError(f"SRC {source} does not exist")
    if not is_pickle_model(source):
        raise ValueError(
            f"SRC {source} is not a pickle-based SB3 model (a .zip, or a directory holding model.zip); "
            f"a directory with policy.json is already in the safe format"
        )
    if not config.trust_pickle:
        refuse_untrusted(source, opt_in="--trust-pickle")
    model_file = sb3_model_file(source, config.best)
    config_file = next(
        (d / "config.yml" for d in (model_file.parent, model_file.parent.parent) if (d / "config.yml").is_file()), None
    )
    prepare_output_dir(destination, argument="DST")
    copy_config = config_file is not None and config_file.resolve() != (destination / "config.yml").resolve()
    outputs = [*POLICY_FILES, REFERENCE_FILE] + (["config.yml"] if copy_config else [])
    check_output_files(destination, outputs, force=config.force, argument="DST", what="an earlier conversion")

    model, normalizer, run_config, files = load_pickled_model(
        source, trust_pickle=True, best=config.best, algo=config.algo
    )
    env_id = _checked_env_id(config.env_id, run_config.get("env_id"))
    provenance = {
        "converted_from": [{"file": f.name, "sha256": sha256_hex(f.read_bytes())} for f in files],
        "seed": run_config.get("seed"),
        "command": run_config.get("command"),
    }
    rng = np.random.default_rng(0)
    env_kwargs = (run_config.get("hyperparams") or {}).get("env_kwargs")
    if env_id is not None:
        _check_fits_env(model, env_id, env_kwargs, files[0])
    rollout = (
        trajectory_observations(lambda obs: sb3_actions(model, normalizer, obs), env_id, env_kwargs)
        if env_id is not None
        else None
    )
    mean, var = (normalizer.obs_rms.mean, normalizer.obs_rms.var) if normalizer is not None else (0.0, 1.0)
    observations = reference_observations(config.check_observations, model.observation_space, mean, var, rng, rollout)
    expected = sb3_actions(model, normalizer, observations)

    # The conversion lands as a whole: written into a new directory that then replaces DST, so an
    # interrupt leaves an earlier conversion whole. Files of DST the conversion does not write (SRC's
    # own, when DST is SRC's directory) are carried over; its own stale ones are dropped.
    with atomic_directory(destination, ours=[*outputs, "config.yml"]) as staging:
        names = _write_checked(
            staging, model, normalizer, env_id, provenance, config.training_state, observations, expected
        )
        if config_file is not None:
            atomic_write_bytes(staging / "config.yml", config_file.read_bytes())
            names.append("config.yml")
        if config.reference:
            _write_reference(staging, observations, expected, provenance)
            names.append(REFERENCE_FILE)
        write_manifest(staging, names)
    print(
        f"converted {', '.join(str(f) for f in files)} -> {destination} "
        f"({len(observations)} observations checked: identical actions)"
    )
    return destination


def _check_fits_env(model: Any, env_id: str, env_kwargs: Any, source: Path) -> None:
    """Refuse a model whose observations or actions do not fit ``env_id``'s, before it runs there."""
    import gymnasium as gym

    env = gym.make(env_id, **dict(env_kwargs or {}))
    try:
        shape = tuple(env.observation_space.shape or ())
        if tuple(model.observation_space.shape) != shape:
            raise ValueError(
                f"{source} takes observations of shape {tuple(model.observation_space.shape)}, but {env_id} gives "
                f"{shape}: pass --env with the id it was trained on"
            )
        check_actions_fit(model.action_space, env, str(source), entry=f"{source.name}: action_space")
    finally:
        env.close()


def _checked_env_id(given: str | None, recorded: str | None) -> str | None:
    """The id the converted policy records: ``--env`` (``given``) or the one SRC's ``config.yml``
    records, which must agree, and a tether-gym id."""
    if given is not None and recorded is not None and given != recorded:
        raise ValueError(
            f"--env {given} differs from the id SRC's config.yml records ({recorded}): the converted policy would "
            "carry the wrong id; leave out --env"
        )
    env_id = given or recorded
    if env_id is not None:
        import tether_gym

        if env_id not in tether_gym.ENV_IDS:
            raise ValueError(f"--env {env_id!r} is not a tether-gym id; ids are {list(tether_gym.ENV_IDS)}")
    return env_id


def _write_checked(
    destination: Path,
    model: Any,
    normalizer: Any,
    env_id: str | None,
    provenance: dict[str, Any],
    training_state: bool,
    observations: np.ndarray,
    expected: np.ndarray,
) -> list[str]:
    """Write ``model`` in the safe format into a scratch directory next to ``destination``, check
    there that its actions on ``observations`` are ``expected`` to the bit, then move the files
    in; returns their names (the manifest is written later, over every file)."""
    scratch = Path(tempfile.mkdtemp(dir=destination, prefix=".convert-"))
    try:
        save_policy(scratch, model, normalizer, env_id, provenance, training_state=training_state)
        actual = safe_actions(scratch, observations)
        if actual.dtype != expected.dtype or actual.tobytes() != expected.tobytes():
            worst = float(np.max(np.abs(actual.astype(np.float64) - expected)))
            raise PolicyFormatError(
                f"the converted policy's actions differ from the original's (largest difference {worst:.3g}); "
                f"nothing was written to {destination}"
            )
        names = [path.name for path in scratch.iterdir() if path.name != MANIFEST_FILE]
        for name in names:
            shutil.move(str(scratch / name), str(destination / name))  # same file system: a rename
    finally:
        shutil.rmtree(scratch, ignore_errors=True)
    return names


def _write_reference(
    destination: Path, observations: np.ndarray, expected: np.ndarray, provenance: dict[str, Any]
) -> None:
    """``reference_actions.safetensors``: the checked observations and the original's actions."""
    atomic_write_bytes(
        destination / REFERENCE_FILE,
        tensor_bytes(
            {"observations": torch.from_numpy(observations), "actions": torch.from_numpy(np.asarray(expected))},
            metadata={
                "source": ", ".join(
                    f"{entry['file']} sha256 {entry['sha256']}" for entry in provenance["converted_from"]
                ),
                "pipeline": "VecNormalize.normalize_obs, then <Algorithm>.predict(deterministic=True)",
            },
        ),
    )
