"""Train PPO on Ray RLlib, on one machine or a cluster: ``python -m agents.train_rllib --env TetherTetrahedron-v0``.

RLlib's new API stack runs the env in its env runners, and each runner steps tether-gym's native
vector env (``gym_env_vectorize_mode="vector_entry_point"``, in next-step autoreset mode as RLlib
expects): ``--envs-per-runner`` sub-envs per runner, ``--num-env-runners`` runner processes (0:
the driver samples itself). ``--address`` joins a running Ray cluster (``ray start --head`` on one
node, ``ray start --address HEAD:6379`` on the others; docs/rllib.md); without it a local Ray
instance is started, and stopped at the end. It needs the ``rllib`` extra
(``pip install 'tether-gym[rllib]'``).

Console script: ``tether-gym-train-rllib``. Hyperparameters come from the package's
``hyperparams/rllib_ppo.yml`` (``agents/hyperparams`` in a checkout), keyed by env id as the SB3 files
are, with RLlib's names; every entry is checked before Ray starts. A run directory
``<out>/<env>/rllib_ppo_seed<seed>/`` receives:

* ``config.yml``: the resolved hyperparameters, env id, seed, runners, Ray version and the command line;
* ``tensorboard/``: TensorBoard logs (``tensorboard --logdir <run>/tensorboard``): returns, losses,
  env steps/s and the evaluations;
* ``checkpoints/iter_<iteration>/``: RLlib checkpoints every ``--checkpoint-freq`` env steps and
  at the end. They are RLlib's own format, which holds pickles: ``--resume`` from one needs
  ``--trust-pickle`` (only resume checkpoints you wrote yourself);
* ``best/``: the best policy on the fixed evaluation seeds and ``evaluations.json`` (the paired
  comparison with the best scripted baseline and when training first beat it), as ``agents.train``
  writes them (:mod:`agents.training.selection`);
* ``policy.json``, ``policy.safetensors``, ``normalization.json``, ``MANIFEST.sha256``: the final
  policy in the project's safe format, which ``agents.compare``, ``agents.benchmark`` and
  :class:`agents.policies.TrainedPolicy` load like any SB3-trained policy.

``--multiagent`` trains one shared decentralised policy instead (issue 15): every satellite with a
thruster is an RLlib agent of :func:`tether_gym.multiagent.parallel_env` (through Ray's
``ParallelPettingZooEnv``), and all agents map to one module, ``"shared"`` (parameter sharing).
Its hyperparameters come from the package's ``hyperparams/rllib_ppo_multiagent.yml``, whose
``multiagent`` entry holds the options of :mod:`tether_gym.multiagent` as ``agents.train
--multiagent`` takes them; the run directory is ``rllib_ppo_multiagent_seed<seed>/``, and the
shared module is exported as the SB3 multi-agent runs are (``multiagent`` in ``policy.json``), so
``agents.compare`` runs it on each satellite's local observations. One env per runner, and no
observation filter (RLlib's ``MeanStdFilter`` keeps per-agent statistics, which one exported
policy cannot hold).

The policy format is SB3's ``MlpPolicy``, onto which RLlib's module is mapped weight for weight, so
the exported policy's deterministic actions are the RLlib module's (:mod:`agents.training.rllib`,
which holds the training; this module is its command line).
"""

from __future__ import annotations

if __name__ == "__main__":  # --help and bad options answered before the slow imports below
    from .common.cli import parse_before_imports

    parse_before_imports("train_rllib")

import functools
import sys
from pathlib import Path

from .common import cli
from .common.commands import command_line, exit_on_error
from .common.data import HYPERPARAMS_DIR
from .common.files import OutputError
from .policies.layout import PolicyFormatError
from .policies.pickled import PickleNotTrustedError
from .training.rllib import ALGO, RayUnavailableError, RLlibConfig, train_rllib

__all__ = ["ERRORS", "build_parser", "main"]

#: The refusals that end the command with ``<program>: error: <message>`` (see :func:`exit_on_error`).
ERRORS = (RayUnavailableError, PickleNotTrustedError, OutputError, PolicyFormatError, ValueError, OSError)


#: The command line of ``train_rllib``, from :mod:`agents.common.cli` (where the console script parses it
#: before this module's slow imports).
build_parser = functools.partial(cli.build_parser, "train_rllib")


def main(argv: list[str] | None = None) -> Path:
    """Train as the command line ``argv`` (default: ``sys.argv[1:]``) asks; returns the run directory. A
    multi-agent run without ``--hyperparams`` reads the package's ``hyperparams/rllib_ppo_multiagent.yml``."""
    args = build_parser().parse_args(argv)
    config = cli.config_from_args(
        RLlibConfig,
        args,
        env_id=args.env,
        hyperparams_file=args.hyperparams or (HYPERPARAMS_DIR / f"{ALGO}_multiagent.yml" if args.multiagent else None),
        command=command_line("train_rllib", sys.argv[1:] if argv is None else argv),
    )
    return train_rllib(config)


if __name__ == "__main__":
    exit_on_error("train_rllib", main, ERRORS)
