"""An SB3 model's training state as data: what resuming needs besides the policy's weights.

The optimizer states, the extra torch variables (SAC's entropy coefficient) and the counters
(timesteps, updates, episodes) of a Stable-Baselines3 model, as flat tensors (the policy
directory's ``training.safetensors``) and JSON data (``training.json``), both ways:
:func:`capture_training_state` reads them from a model, :func:`restore_training_state` puts them back.

SB3 has no public API for these: its own ``save`` pickles them. This is the only module of the
project that touches SB3's private attributes (``_get_torch_save_params``, ``_n_updates``,
``_episode_num``), so that an SB3 release that renames them breaks one module, and its tests.
The reading and checking of the files around it is :func:`agents.policies.format.load_training_state`'s.
"""

from __future__ import annotations

import operator
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from tether_gym._optional import needs_extra

from .codecs import json_value, require_entry
from .layout import FORMAT_VERSION, PolicyFormatError

with needs_extra("train", "the policy files"):
    import torch
    from stable_baselines3.common.base_class import BaseAlgorithm

__all__ = ["TRAINING_STATE_FORMAT", "capture_training_state", "restore_training_state"]

#: The ``format`` entry of ``training.json``.
TRAINING_STATE_FORMAT = "tether-gym-training-state"


def capture_training_state(model: BaseAlgorithm) -> tuple[dict[str, torch.Tensor], dict[str, Any]]:
    """The optimizer states, extra torch variables (SAC's entropy coefficient) and counters of
    ``model``: tensors by flat names, and the rest as JSON data."""
    state_dict_names, variable_names = model._get_torch_save_params()
    tensors: dict[str, torch.Tensor] = {}
    optimizers: dict[str, Any] = {}
    for name in state_dict_names:
        if name == "policy":
            continue  # the weights are policy.safetensors
        state = operator.attrgetter(name)(model).state_dict()
        scalars: dict[str, dict[str, Any]] = {}
        for index, entries in state["state"].items():
            for key, value in entries.items():
                if isinstance(value, torch.Tensor):
                    tensors[f"{name}/state/{index}/{key}"] = value
                else:
                    scalars.setdefault(str(index), {})[key] = json_value(value, f"{name}.state.{index}.{key}")
        optimizers[name] = {
            "indices": [int(index) for index in state["state"]],
            "scalars": scalars,
            "param_groups": json_value(state["param_groups"], f"{name}.param_groups"),
        }
    for name in variable_names:
        tensors[f"variables/{name}"] = operator.attrgetter(name)(model)
    meta = {
        "format": TRAINING_STATE_FORMAT,
        "format_version": FORMAT_VERSION,
        "optimizers": optimizers,
        "variables": list(variable_names),
        "counters": {
            "num_timesteps": int(model.num_timesteps),
            "n_updates": int(getattr(model, "_n_updates", 0)),
            "episode_num": int(getattr(model, "_episode_num", 0)),
        },
    }
    return tensors, meta


def restore_training_state(
    model: BaseAlgorithm,
    meta: Any,
    tensors: Mapping[str, torch.Tensor],
    algo: str,
    meta_where: Path,
    tensors_where: Path,
) -> None:
    """Put the training state that :func:`capture_training_state` read back into ``model`` (freshly built
    with the run's hyperparameters, its policy's weights already loaded): the optimizer states, the
    extra variables and the counters.

    Args:
        model: the model to resume.
        meta: the parsed ``training.json`` (its ``format`` already checked).
        tensors: the tensors of ``training.safetensors``, by their flat names.
        algo: ``model``'s algorithm (``ppo``, ...), for the errors.
        meta_where, tensors_where: the two files, for the errors.

    Raises :class:`PolicyFormatError` when the state does not fit ``model`` (other optimizers or
    variables, misshapen tensors, missing counters)."""
    state_dict_names, variable_names = model._get_torch_save_params()
    optimizers = require_entry(meta, "optimizers", dict, meta_where)
    expected = sorted(name for name in state_dict_names if name != "policy")
    if sorted(optimizers) != expected or require_entry(meta, "variables", list, meta_where) != list(variable_names):
        raise PolicyFormatError(
            f"{meta_where}: the checkpoint has optimizers {sorted(optimizers)} and variables {meta['variables']}; "
            f"this {algo} model has {expected} and {list(variable_names)} (were the hyperparameters changed?)"
        )
    for name in expected:
        _restore_optimizer(operator.attrgetter(name)(model), optimizers[name], tensors, name, meta_where)
    for name in variable_names:
        key = f"variables/{name}"
        target = operator.attrgetter(name)(model)
        if key not in tensors or tensors[key].shape != target.shape:
            raise PolicyFormatError(f"{tensors_where}: variable {name!r} is missing or misshapen")
        with torch.no_grad():
            target.copy_(tensors[key])
    counters = require_entry(meta, "counters", dict, meta_where)
    model.num_timesteps = int(require_entry(counters, "num_timesteps", int, meta_where))
    model._n_updates = int(require_entry(counters, "n_updates", int, meta_where))
    model._episode_num = int(require_entry(counters, "episode_num", int, meta_where))


def _restore_optimizer(
    optimizer: torch.optim.Optimizer, saved: Any, tensors: Mapping[str, torch.Tensor], name: str, where: Path
) -> None:
    """Rebuild an optimizer's state dict from the flat tensors and the JSON entries, and load it."""
    if not isinstance(saved, dict) or not isinstance(saved.get("param_groups"), list):
        raise PolicyFormatError(f"{where}: optimizer {name!r} must have param_groups")
    current_groups = optimizer.state_dict()["param_groups"]
    if len(saved["param_groups"]) != len(current_groups):
        raise PolicyFormatError(
            f"{where}: optimizer {name!r} has {len(saved['param_groups'])} param groups; "
            f"this model's optimizer has {len(current_groups)}"
        )
    groups = []
    for group, current in zip(saved["param_groups"], current_groups, strict=True):
        if not isinstance(group, dict):
            raise PolicyFormatError(f"{where}: optimizer {name!r} has a malformed param group")
        # JSON has no tuples; give back tuples where the optimizer uses them (Adam's betas).
        groups.append(
            {
                key: tuple(value) if isinstance(current.get(key), tuple) and isinstance(value, list) else value
                for key, value in group.items()
            }
        )
    state: dict[int, dict[str, Any]] = {}
    prefix = f"{name}/state/"
    for key, tensor in tensors.items():
        if key.startswith(prefix):
            index, _, entry = key[len(prefix) :].partition("/")
            state.setdefault(int(index), {})[entry] = tensor
    for index, entries in (saved.get("scalars") or {}).items():
        state.setdefault(int(index), {}).update(entries)
    # In parameter order, as the optimizer built it: load_state_dict keeps the order it is given,
    # and the next save writes it.
    state = dict(sorted(state.items()))
    try:
        optimizer.load_state_dict({"state": state, "param_groups": groups})
    except (ValueError, KeyError, TypeError) as error:
        raise PolicyFormatError(f"{where}: optimizer {name!r} does not fit this model: {error}") from error
