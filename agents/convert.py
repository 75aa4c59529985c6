"""Convert a pickle-based SB3 model to the safe policy format:
``python -m agents.convert SRC DST --trust-pickle``.

``SRC`` is an SB3 run directory (``model.zip`` and ``vecnormalize.pkl``, or with ``--best``
``best/best_model.zip``) or a model ``.zip`` (its statistics are found next to it). Converting
unpickles ``SRC``, which runs any code a crafted file contains, so it needs ``--trust-pickle``:
convert only files you made or trust. The result, ``DST``, holds ``policy.json``,
``policy.safetensors``, ``normalization.json``, the run's ``config.yml`` (provenance) and a
``MANIFEST.sha256``, and loads without unpickling anything.

Before writing, the converter loads the converted policy back and checks that its actions are
bit-identical to the SB3 original's on ``--check-observations`` observations (env observations
along the original's own trajectories, and draws around the normalisation statistics).
``--reference`` also keeps those observations and actions in ``DST/reference_actions.safetensors``
so that tests can check the shipped policy against the original long after the pickle files are
gone. ``--training-state`` keeps the optimizer states, so that ``agents.train --resume DST``
continues training.
"""

from __future__ import annotations

if __name__ == "__main__":  # --help and bad options answered before the slow imports below
    from .common.cli import parse_before_imports

    parse_before_imports("convert")

import argparse
import shutil
import sys
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from tether_gym._optional import needs_extra

from .common import cli
from .common.cli import REFERENCE_FILE
from .common.commands import program
from .common.files import OutputError, atomic_write_bytes, check_output_files, prepare_output_dir
from .pickled import (
    PickleNotTrustedError,
    is_pickle_model,
    load_pickled_model,
    refuse_untrusted,
    sb3_model_file,
)
from .safe_format import (
    MANIFEST_FILE,
    POLICY_FILES,
    PolicyFormatError,
    load_policy,
    reference_observations,
    save_policy,
    tensor_bytes,
    write_manifest,
)

with needs_extra("train", "converting SB3 models"):
    import torch

__all__ = ["REFERENCE_FILE", "convert", "main"]


def _original_actions(model: Any, normalizer: Any, observations: np.ndarray) -> np.ndarray:
    """The SB3 pipeline the pickle-based files were used with: ``VecNormalize.normalize_obs``,
    then ``model.predict(deterministic=True)``."""
    obs = observations.astype(np.float32)
    if normalizer is not None:
        obs = normalizer.normalize_obs(obs).astype(np.float32)
    return model.predict(obs, deterministic=True)[0]


def _safe_actions(directory: Path, observations: np.ndarray) -> np.ndarray:
    loaded = load_policy(directory)
    obs = observations.astype(np.float32)
    if loaded.normalizer is not None:
        obs = loaded.normalizer.normalize_obs(obs).astype(np.float32)
    return loaded.policy.predict(obs, deterministic=True)[0]


def trajectory_observations(
    act: Callable[[np.ndarray], np.ndarray], env_id: str, env_kwargs: dict[str, Any] | None = None
) -> Callable[[int], np.ndarray]:
    """A function ``n -> (n, obs_dim)`` env observations along the trajectories of ``act`` (a batch
    of observations -> a batch of actions), 8 episodes in parallel, seeds 0-7."""
    import gymnasium as gym
    from gymnasium.vector import AutoresetMode

    import tether_gym  # noqa: F401 - registers the ids

    def observations(count: int) -> np.ndarray:
        envs = gym.make_vec(env_id, num_envs=8, **{"autoreset_mode": AutoresetMode.SAME_STEP, **dict(env_kwargs or {})})
        try:
            obs, _ = envs.reset(seed=list(range(8)))
            rows = [obs]
            while sum(len(r) for r in rows) < count:
                obs, *_ = envs.step(act(obs))
                rows.append(obs)
        finally:
            envs.close()
        return np.concatenate(rows)[:count]

    return observations


def convert(
    source: str | Path,
    destination: str | Path,
    trust_pickle: bool = False,
    best: bool = False,
    algo: str | None = None,
    env_id: str | None = None,
    training_state: bool = False,
    check_observations: int = 512,
    reference: bool = False,
    force: bool = False,
) -> Path:
    """Convert the pickle-based SB3 model ``source`` to the safe format in ``destination`` (see
    the module docstring); returns ``destination``.

    Raises :class:`agents.pickled.PickleNotTrustedError` without ``trust_pickle`` (before reading
    anything), :class:`agents.common.files.OutputError` for an unusable or symlinked ``destination``,
    :class:`agents.common.files.OutputExistsError` if it holds an earlier conversion and not ``force``,
    and :class:`agents.safe_format.PolicyFormatError` if the converted policy's actions differ
    from the original's."""
    source, destination = Path(source), Path(destination)
    if not source.exists():
        raise FileNotFoundError(f"SRC {source} does not exist")
    if not is_pickle_model(source):
        raise ValueError(
            f"SRC {source} is not a pickle-based SB3 model (a .zip, or a directory holding model.zip); "
            f"a directory with policy.json is already in the safe format"
        )
    if isinstance(check_observations, bool) or not isinstance(check_observations, int) or check_observations < 16:
        raise ValueError(f"check_observations must be an integer >= 16; got {check_observations!r}")
    if not trust_pickle:
        refuse_untrusted(source, opt_in="--trust-pickle")
    model_file = sb3_model_file(source, best)
    config_file = next(
        (d / "config.yml" for d in (model_file.parent, model_file.parent.parent) if (d / "config.yml").is_file()), None
    )
    prepare_output_dir(destination, argument="DST")
    copy_config = config_file is not None and config_file.resolve() != (destination / "config.yml").resolve()
    outputs = [*POLICY_FILES, REFERENCE_FILE] + (["config.yml"] if copy_config else [])
    check_output_files(destination, outputs, force=force, argument="DST", what="an earlier conversion")

    model, normalizer, config, files = load_pickled_model(source, trust_pickle=True, best=best, algo=algo)
    recorded = config.get("env_id")
    if env_id is not None and recorded is not None and env_id != recorded:
        raise ValueError(
            f"--env {env_id} differs from the id SRC's config.yml records ({recorded}): the converted policy would "
            "carry the wrong id; leave out --env"
        )
    env_id = env_id or recorded
    if env_id is not None:
        import tether_gym

        if env_id not in tether_gym.ENV_IDS:
            raise ValueError(f"--env {env_id!r} is not a tether-gym id; ids are {list(tether_gym.ENV_IDS)}")
    provenance = {
        "converted_from": [{"file": f.name, "sha256": _sha256(f)} for f in files],
        "seed": config.get("seed"),
        "command": config.get("command"),
    }
    rng = np.random.default_rng(0)
    env_kwargs = (config.get("hyperparams") or {}).get("env_kwargs")
    rollout = (
        trajectory_observations(lambda obs: _original_actions(model, normalizer, obs), env_id, env_kwargs)
        if env_id is not None
        else None
    )
    mean, var = (normalizer.obs_rms.mean, normalizer.obs_rms.var) if normalizer is not None else (0.0, 1.0)
    observations = reference_observations(check_observations, model.observation_space, mean, var, rng, rollout)
    expected = _original_actions(model, normalizer, observations)

    # Write into a scratch directory next to DST, check the result there, then move it in.
    scratch = Path(tempfile.mkdtemp(dir=destination, prefix=".convert-"))
    try:
        save_policy(scratch, model, normalizer, env_id, provenance, training_state=training_state)
        actual = _safe_actions(scratch, observations)
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
    if config_file is not None:
        if copy_config:
            atomic_write_bytes(destination / "config.yml", config_file.read_bytes())
        names.append("config.yml")
    if reference:
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
        names.append(REFERENCE_FILE)
    for stale in set(outputs) - set(names) - {MANIFEST_FILE, "config.yml"}:
        (destination / stale).unlink(missing_ok=True)  # from an earlier conversion (only reached with --force)
    write_manifest(destination, names)
    print(
        f"converted {', '.join(str(f) for f in files)} -> {destination} "
        f"({len(observations)} observations checked: identical actions)"
    )
    return destination


def _sha256(path: Path) -> str:
    import hashlib

    return hashlib.sha256(path.read_bytes()).hexdigest()


def build_parser() -> argparse.ArgumentParser:
    """The command line of ``convert`` (defined in :mod:`agents.common.cli`, which the console script parses
    with before this module's slow imports)."""
    return cli.build_parser("convert")


def main(argv: list[str] | None = None) -> Path:
    args = build_parser().parse_args(argv)
    return convert(
        args.source,
        args.destination,
        trust_pickle=args.trust_pickle,
        best=args.best,
        algo=args.algo,
        env_id=args.env,
        training_state=args.training_state,
        check_observations=args.check_observations,
        reference=args.reference,
        force=args.force,
    )


if __name__ == "__main__":
    try:
        main()
    except (PickleNotTrustedError, OutputError, PolicyFormatError, ValueError, OSError) as error:
        sys.exit(f"{program('convert')}: error: {error}")
