"""Train an SB3 agent on a tether-gym id: ``python -m agents.train --algo ppo --env TetherTetrahedron-v0``.

Console script: ``tether-gym-train`` (``python -m tether_gym_agents.train`` when installed).
Hyperparameters come from the package's ``hyperparams/<algo>.yml`` (``agents/hyperparams`` in a
checkout, ``tether_gym_agents/hyperparams`` installed), keyed by env id (rl-zoo style, plain
YAML, nothing evaluated). Every entry is checked before training starts: an unknown key, a missing
``n_timesteps`` or a string where a number belongs is an error that names the key. Training runs
on the native vector env through the SB3 adapter, with ``VecNormalize`` when configured and
``VecMonitor`` for episode statistics. A run directory ``<out>/<env>/<algo>_seed<seed>/`` receives,
all of it in the safe policy format (:mod:`agents.policies.format`: JSON and safetensors, no pickle):

* ``config.yml``: the resolved hyperparameters, env id, seed and command line, and the steps
  trained (``num_timesteps``). SB3 trains whole rollouts (PPO: ``n_steps`` x ``n_envs`` steps),
  so ``n_timesteps`` is rounded up to a whole number of them, with a message, and recorded so;
* ``tensorboard/``: TensorBoard logs (``tensorboard --logdir <run>/tensorboard``);
* ``checkpoints/<algo>_<steps>_steps/``: the policy, its ``VecNormalize`` statistics and the
  optimizer state every ``--checkpoint-freq`` steps;
* ``best/``: the best policy on the evaluation episodes (with its statistics and optimizer
  state; a run shorter than ``--eval-freq`` evaluates its final policy once, so that ``best/``
  always holds one), and ``evaluations.json``: every evaluation's returns and paired difference from the
  best scripted baseline on the same seeds, and when training first beat it
  (:mod:`agents.training.selection`);
* ``policy.json``, ``policy.safetensors``, ``normalization.json``, ``training.*`` and
  ``MANIFEST.sha256``: the final policy.

``--resume DIR`` continues from a checkpoint directory, ``best/`` or a run directory: the weights,
optimizer states, timestep count and normalisation statistics are restored, and the timesteps
keep counting from there. Resuming from a pickle-based SB3 ``.zip`` (with its ``vecnormalize.pkl``)
needs ``--trust-pickle``, because unpickling runs any code a crafted file contains.

The run directory must be new: if it holds an earlier run (same ``--out``, env, algorithm and
seed), the command stops before any work unless ``--force`` is given, which deletes the earlier
run's models, ``best/`` and checkpoints (TensorBoard logs are kept) and then trains.

``--curriculum START FRACTION`` (or a ``curriculum: {start: ..., fraction: ...}`` entry) trains on
easier episodes first: the env's ``difficulty`` (initial-condition size, randomisation and
disturbances together) rises linearly from START to 1 over the first FRACTION of the run. The
evaluation episodes are always at difficulty 1.
"""

from __future__ import annotations

if __name__ == "__main__":  # --help and bad options answered before the slow imports below
    from .common.cli import parse_before_imports

    parse_before_imports("train")

import argparse
import functools
import sys
from pathlib import Path
from typing import Any

from .common import cli
from .common.commands import command_line, exit_on_error
from .common.data import HYPERPARAMS_DIR
from .common.files import OutputError
from .policies.layout import PolicyFormatError
from .policies.pickled import PickleNotTrustedError
from .training.config import TrainConfig
from .training.hyperparams import HyperparameterError, load_hyperparameters
from .training.sb3 import train

__all__ = ["ERRORS", "build_parser", "config_from_args", "main"]

#: The refusals that end the command with ``<program>: error: <message>`` (see :func:`exit_on_error`).
ERRORS = (PickleNotTrustedError, OutputError, PolicyFormatError, HyperparameterError, ValueError, OSError)


#: The command line of ``train``, from :mod:`agents.common.cli` (where the console script parses it
#: before this module's slow imports).
build_parser = functools.partial(cli.build_parser, "train")


def _overrides(args: argparse.Namespace) -> dict[str, Any] | None:
    """The hyperparameters the command line sets: the curriculum, and ``--multiagent`` (the
    file's ``multiagent`` options, or the defaults)."""
    overrides: dict[str, Any] = {}
    if args.curriculum:
        overrides["curriculum"] = {"start": args.curriculum[0], "fraction": args.curriculum[1]}
    if args.multiagent:
        file = args.hyperparams or HYPERPARAMS_DIR / f"{args.algo}_multiagent.yml"
        overrides["multiagent"] = load_hyperparameters(args.algo, args.env, file).get("multiagent") or {}
    return overrides or None


def config_from_args(args: argparse.Namespace, command: str | None = None) -> TrainConfig:
    """The run that the parsed command line ``args`` asks for; ``command`` (the command line) is
    recorded in its ``config.yml``."""
    return cli.config_from_args(
        TrainConfig,
        args,
        env_id=args.env,
        num_envs=args.n_envs,
        hyperparams_file=args.hyperparams
        or (HYPERPARAMS_DIR / f"{args.algo}_multiagent.yml" if args.multiagent else None),
        overrides=_overrides(args),
        progress_bar=not args.no_progress,
        command=command,
    )


def main(argv: list[str] | None = None) -> Path:
    """Train as the command line ``argv`` (default: ``sys.argv[1:]``) asks; returns the run directory."""
    args = build_parser().parse_args(argv)
    return train(config_from_args(args, command_line("train", sys.argv[1:] if argv is None else argv)))


if __name__ == "__main__":
    exit_on_error("train", main, ERRORS)
