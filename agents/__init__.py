"""Controllers for the tether-gym damping task: scripted baselines, RL training and evaluation.

Installed (the ``train`` extra: ``pip install "tether-gym[train]"``), the package is
``tether_gym_agents`` (``from tether_gym_agents.controllers.registry import make_baseline``) and
its commands are console scripts (``tether-gym-train``, ``tether-gym-compare``,
``tether-gym-benchmark``, ..., or ``python -m tether_gym_agents.train``). In a checkout it is also
importable as ``agents`` (``python -m agents.train``), the name the module references below use;
see :mod:`agents.common.commands`. Its modules import each other relatively.

The package is laid out in rooms, lowest first; a module imports only from its own room and the
rooms below it (``tests/agents/test_architecture.py`` enforces it, with no import cycles and no
use of another module's private names):

* :mod:`agents.common`: command lines and their names, careful output files, per-id settings,
  the data folders, value checks and version records;
* :mod:`agents.controllers`: the scripted baselines, ``mpc``, the Protocols a controller meets,
  and the registry of controllers by name;
* :mod:`agents.policies`: trained policies: the safe file format, :class:`TrainedPolicy`, the
  shipped models, controllers by name or path (:func:`make_controller`), and pickle-based SB3
  files on opt-in only;
* :mod:`agents.evaluation`: rollouts on held-out seeds, the statistics, the comparison, the
  benchmark, their tables and plots, and scoring a new policy against the shipped reference;
* :mod:`agents.training`: the trainers (SB3, RLlib, ARS) with their configs, hyperparameter
  schema, run directories, callbacks and model selection, and shipping a run;
* the commands, one module each, thin: ``train``, ``train_rllib``, ``ars``, ``compare``,
  ``benchmark``, ``ship``, ``convert`` and ``scoring`` parse their arguments, build a config and
  call their room.

A module of the flat layout before the rooms (``agents.baselines``, ``agents.safe_format``,
``agents.evaluate``, ...) is not kept as an alias; importing one raises a
:class:`ModuleNotFoundError` that names where its contents went.
"""

import importlib.abc
import importlib.machinery
import sys
from collections.abc import Sequence
from types import ModuleType

# tether_gym sets the OpenMP spin policy (tether_gym._kernels) when it is imported. Importing it
# before torch gives torch's own OpenMP threads the same policy, so that they do not starve the
# simulator's threads in a training process.
import tether_gym  # noqa: F401

#: The modules of the flat layout that the rooms replaced: where their contents are now, as
#: (module, what it holds; "" for all of it).
MOVED_MODULES: dict[str, tuple[tuple[str, str], ...]] = {
    "baselines": (
        ("controllers.base", "Controller, task_of"),
        ("controllers.linear_model", "LinearModel, elastic_modes"),
        ("controllers.centralised", "the centralised laws"),
        ("controllers.registry", "BASELINES, make_baseline"),
    ),
    "decentralised": (("controllers.decentralised", ""),),
    "mpc": (("controllers.mpc", ""),),
    "residual": (
        ("controllers.residual", "residual_actions, check_residual_on"),
        ("training.residual_env", "ResidualVecEnv"),
    ),
    "safe_format": (
        ("policies.format", "save_policy, load_policy, the manifest"),
        ("policies.layout", "file names, PolicyFormatError"),
        ("policies.codecs", "JSON and space codecs"),
        ("policies.normalization", "NormalizationStatistics"),
        ("policies.sb3_state", "SB3 training state"),
        ("policies.reference", "reference observations"),
    ),
    "pickled": (("policies.pickled", ""),),
    "evaluate": (("evaluation.rollout", ""),),
    "selection": (("training.selection", ""),),
    "cli": (("common.cli", ""),),
    "commands": (("common.commands", ""),),
    "files": (("common.files", ""),),
    "settings": (("common.settings", ""),),
}


class MovedModuleFinder(importlib.abc.MetaPathFinder):
    """Answers an import of a module in :data:`MOVED_MODULES` with an error that names its new
    place. It sits last on ``sys.meta_path``, so it sees only imports that no other finder could
    satisfy: it never shadows a module that exists."""

    def find_spec(
        self, fullname: str, path: Sequence[str] | None, target: ModuleType | None = None
    ) -> importlib.machinery.ModuleSpec | None:
        package, _, name = fullname.rpartition(".")
        if package != __name__ or name not in MOVED_MODULES:
            return None
        places = "; ".join(
            f"{__name__}.{module}" + (f" ({holds})" if holds else "") for module, holds in MOVED_MODULES[name]
        )
        raise ModuleNotFoundError(
            f"{fullname} is gone: the agents package is laid out in rooms now; import from {places} "
            "(the changelog's entry 'agents/ as a library with rooms' lists every move)",
            name=fullname,
        )


if not any(isinstance(finder, MovedModuleFinder) for finder in sys.meta_path):
    sys.meta_path.append(MovedModuleFinder())
