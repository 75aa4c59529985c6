"""Where the package's data folders are: the hyperparameter files, the shipped models and the
benchmark's reference scores. They sit beside the modules, in a checkout (``agents/...``) and in
an installed wheel (``tether_gym_agents/...``) alike."""

from __future__ import annotations

from pathlib import Path

__all__ = ["HYPERPARAMS_DIR", "MODELS_DIR", "PACKAGE_DIR", "REFERENCE_DIR"]

#: The agents package's folder.
PACKAGE_DIR = Path(__file__).resolve().parent.parent
#: The YAML hyperparameter files, one per algorithm (``ppo.yml``, ``ars.yml``, ``mpc.yml``, ...).
HYPERPARAMS_DIR = PACKAGE_DIR / "hyperparams"
#: The shipped policies, ``<env id>/<model name>/``, and the record of the runs they came from.
MODELS_DIR = PACKAGE_DIR / "models"
#: The benchmark's per-seed returns, which :mod:`agents.scoring` scores a policy against.
REFERENCE_DIR = PACKAGE_DIR / "reference"
