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

import inspect
import operator
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from tether_gym._optional import needs_extra

from .codecs import json_value, require_entry
from .layout import FORMAT_VERSION, PolicyFormatError

with needs_extra("train", "the policy files"):
    import torch
    from stable_baselines3.common.base_class import BaseAlgorithm

__all__ = ["TRAINING_STATE_FORMAT", "capture_training_state", "check_training_state", "restore_training_state"]

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


#: The per-parameter state every step of each optimizer reads (more is allowed: Adam's
#: ``max_exp_avg_sq`` with amsgrad, momentum buffers); a state without them would fail inside the
#: optimizer's first step, far from the file.
_REQUIRED_STATE: dict[str, frozenset[str]] = {
    "Adam": frozenset({"step", "exp_avg", "exp_avg_sq"}),
    "AdamW": frozenset({"step", "exp_avg", "exp_avg_sq"}),
    "RMSprop": frozenset({"step", "square_avg"}),
    "SGD": frozenset(),
}
#: Entries an optimizer's per-parameter state may hold besides those: scalars (``step``) or
#: tensors of the parameter's shape.
_OPTIONAL_STATE = frozenset({"max_exp_avg_sq", "momentum_buffer", "grad_avg"})


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
    extra variables and the counters. Everything is checked before anything is written, so a
    refused state leaves ``model`` as it was.

    Args:
        model: the model to resume.
        meta: the parsed ``training.json`` (its ``format`` already checked).
        tensors: the tensors of ``training.safetensors``, by their flat names.
        algo: ``model``'s algorithm (``ppo``, ...), for the errors.
        meta_where, tensors_where: the two files, for the errors.

    Raises :class:`PolicyFormatError` when the state does not fit ``model`` (other optimizers or
    variables, misshapen or mistyped tensors, text where numbers belong, missing counters)."""
    apply = check_training_state(model, meta, tensors, algo, meta_where, tensors_where)
    apply()


def check_training_state(
    model: BaseAlgorithm,
    meta: Any,
    tensors: Mapping[str, torch.Tensor],
    algo: str,
    meta_where: Path,
    tensors_where: Path,
) -> Callable[[], None]:
    """Check the training state that :func:`capture_training_state` read against ``model``
    (arguments as :func:`restore_training_state`'s) and return the function that writes it into
    ``model``: every optimizer tensor has its parameter's shape and dtype (or is a scalar step),
    every optimizer setting has the type the optimizer's own has, every counter is a count, and
    ``training.safetensors`` holds no tensor that nothing reads."""
    state_dict_names, variable_names = model._get_torch_save_params()
    optimizers = require_entry(meta, "optimizers", dict, meta_where)
    expected = sorted(name for name in state_dict_names if name != "policy")
    if sorted(optimizers) != expected or require_entry(meta, "variables", list, meta_where) != list(variable_names):
        raise PolicyFormatError(
            f"{meta_where}: the checkpoint has optimizers {sorted(optimizers)} and variables {meta['variables']}; "
            f"this {algo} model has {expected} and {list(variable_names)} (were the hyperparameters changed?)"
        )
    known = {f"variables/{name}" for name in variable_names}
    unknown = sorted(
        key for key in tensors if key not in known and not any(key.startswith(f"{name}/state/") for name in expected)
    )
    if unknown:
        raise PolicyFormatError(
            f"{tensors_where}: tensors {unknown[:5]} belong to no optimizer or variable of this {algo} model: restore "
            "or re-create the checkpoint"
        )
    states = {
        name: _optimizer_state(
            operator.attrgetter(name)(model), optimizers[name], tensors, name, meta_where, tensors_where
        )
        for name in expected
    }
    variables = {}
    for name in variable_names:
        key = f"variables/{name}"
        target = operator.attrgetter(name)(model)
        if key not in tensors or tensors[key].shape != target.shape or tensors[key].dtype != target.dtype:
            found = f"{tuple(tensors[key].shape)} {tensors[key].dtype}" if key in tensors else "nothing"
            raise PolicyFormatError(
                f"{tensors_where}: variable {name!r} must be {tuple(target.shape)} {target.dtype}; found {found}"
            )
        variables[name] = (target, tensors[key])
    counters = require_entry(meta, "counters", dict, meta_where)
    counts = {}
    for key in ("num_timesteps", "n_updates", "episode_num"):
        value = require_entry(counters, key, int, meta_where)
        if value < 0:
            raise PolicyFormatError(f"{meta_where}: counters.{key} must be a count >= 0; got {value}")
        counts[key] = value

    def apply() -> None:
        for name, state in states.items():
            optimizer = operator.attrgetter(name)(model)
            try:
                optimizer.load_state_dict(state)
            except (ValueError, KeyError, TypeError) as error:
                raise PolicyFormatError(f"{meta_where}: optimizer {name!r} does not fit this model: {error}") from error
        for target, value in variables.values():
            with torch.no_grad():
                target.copy_(value)
        model.num_timesteps = counts["num_timesteps"]
        model._n_updates = counts["n_updates"]
        model._episode_num = counts["episode_num"]

    return apply


def _same_kind(value: Any, current: Any) -> bool:
    """Whether a JSON ``value`` can stand where an optimizer setting is ``current``: numbers for
    numbers (bools are not), bools (or None) for flags, sequences of numbers of the same length."""
    if isinstance(current, bool) or current is None:
        return value is None or isinstance(value, bool)
    if isinstance(current, (int, float)):
        return isinstance(value, (int, float)) and not isinstance(value, bool)
    if isinstance(current, (tuple, list)):
        return (
            isinstance(value, list)
            and len(value) == len(current)
            and all(_same_kind(item, entry) for item, entry in zip(value, current, strict=True))
        )
    return type(value) is type(current)


def _negative(value: Any) -> bool:
    """Whether ``value`` (a number or a list of them) has a number below 0."""
    if isinstance(value, list):
        return any(_negative(item) for item in value)
    return isinstance(value, (int, float)) and not isinstance(value, bool) and value < 0


#: Per-parameter entries that are running averages of squares, which no optimizer step makes
#: negative: a negative one makes Adam's or RMSprop's square root NaN at the first step.
_SQUARES = frozenset({"exp_avg_sq", "max_exp_avg_sq", "square_avg"})


def _check_entry_content(entry: str, value: torch.Tensor, label: str) -> None:
    """Refuse an optimizer state entry whose values no optimizer writes: a ``step`` that is not a
    whole number >= 0 (a negative one makes Adam's bias correction negative, and its step NaN) or
    a negative average of squares (:data:`_SQUARES`). Finiteness is checked where tensors are read."""
    if entry == "step":
        if not bool(torch.isfinite(value).all()) or bool((value < 0).any()) or bool((value != value.round()).any()):
            raise PolicyFormatError(
                f"{label} must be a whole number of steps >= 0; got {value.tolist()}: restore or re-create it"
            )
    elif entry in _SQUARES and bool((value < 0).any()):
        raise PolicyFormatError(
            f"{label} is an average of squares and has negative entries (min {float(value.min())}), which no "
            "optimizer step writes: restore or re-create the checkpoint"
        )


def _optimizer_state(
    optimizer: torch.optim.Optimizer,
    saved: Any,
    tensors: Mapping[str, torch.Tensor],
    name: str,
    where: Path,
    tensors_where: Path,
) -> dict[str, Any]:
    """The checked state dict of ``optimizer``, rebuilt from the flat tensors and the JSON entries."""
    if not isinstance(saved, dict) or not isinstance(saved.get("param_groups"), list):
        raise PolicyFormatError(f"{where}: optimizer {name!r} must have param_groups")
    groups = _param_groups(optimizer, saved["param_groups"], name, where)
    state = _parameter_state(optimizer, saved, tensors, name, where, tensors_where)
    # In parameter order, as the optimizer built it: load_state_dict keeps the order it is given,
    # and the next save writes it.
    return {"state": dict(sorted(state.items())), "param_groups": groups}


def _param_groups(optimizer: torch.optim.Optimizer, saved: list[Any], name: str, where: Path) -> list[dict[str, Any]]:
    """The saved param groups of ``optimizer``, each entry checked to be of the kind the
    optimizer's own is (numbers, flags, tuples), with its parameters' indices."""
    current_groups = optimizer.state_dict()["param_groups"]
    if len(saved) != len(current_groups):
        raise PolicyFormatError(
            f"{where}: optimizer {name!r} has {len(saved)} param groups; "
            f"this model's optimizer has {len(current_groups)}"
        )
    groups = []
    for number, (group, current) in enumerate(zip(saved, current_groups, strict=True)):
        label = f"{where}: optimizers.{name}.param_groups[{number}]"
        if not isinstance(group, dict) or "params" not in group or set(group) - set(current):
            keys = sorted(group) if isinstance(group, dict) else group
            raise PolicyFormatError(f"{label} must have params and entries of {sorted(current)}; got {keys!r}")
        # A setting the writer's torch did not have yet takes this torch's value, as torch does.
        group = {**current, **group}
        if group["params"] != current["params"]:
            raise PolicyFormatError(f"{label}.params must be {current['params']}; got {group['params']!r}")
        for key, value in group.items():
            if not _same_kind(value, current[key]):
                raise PolicyFormatError(
                    f"{label}.{key} must be {type(current[key]).__name__} like {current[key]!r}; got {value!r}"
                )
            if key != "params" and _negative(value):
                # Rates, decays, epsilons and betas are >= 0 in every optimizer the format names:
                # a negative one steps the wrong way or divides by zero.
                raise PolicyFormatError(f"{label}.{key} must be >= 0; got {value!r}")
        # JSON has no tuples; give back tuples where the optimizer uses them (Adam's betas).
        group = {key: tuple(value) if isinstance(current[key], tuple) else value for key, value in group.items()}
        _check_settings(optimizer, group, current, label)
        groups.append(group)
    return groups


#: Param-group entries that choose how an optimizer runs, not what it computes, or that its class
#: fixes (AdamW's ``decoupled_weight_decay``): they must be what this run's optimizer has, since
#: ``load_state_dict`` would switch them (``capturable`` on a CPU model fails at the first step).
_FIXED_SETTINGS = frozenset({"foreach", "fused", "capturable", "differentiable", "decoupled_weight_decay"})


def _check_settings(
    optimizer: torch.optim.Optimizer, group: dict[str, Any], current: dict[str, Any], label: str
) -> None:
    """Refuse a param group whose settings this optimizer's own constructor refuses (Adam's
    ``betas`` must lie in [0, 1): a beta of 1 divides by zero at the first step), or whose
    :data:`_FIXED_SETTINGS` differ from this run's, naming ``label`` and the entry."""
    for key in sorted(_FIXED_SETTINGS & set(group)):
        if group[key] != current[key]:
            raise PolicyFormatError(
                f"{label}.{key} is {group[key]!r}; this run's {type(optimizer).__name__} has {current[key]!r}, "
                "and it must stay so: restore or re-create the checkpoint"
            )
    accepted = inspect.signature(type(optimizer).__init__).parameters
    settings = {key: value for key, value in group.items() if key in accepted and key not in ("params", "self")}
    try:
        type(optimizer)([torch.nn.Parameter(torch.zeros(1))], **settings)
    except (ValueError, TypeError, RuntimeError) as error:
        raise PolicyFormatError(
            f"{label}: {type(optimizer).__name__} refuses these settings ({error}): restore or re-create the checkpoint"
        ) from error


def _parameter_state(
    optimizer: torch.optim.Optimizer,
    saved: dict[str, Any],
    tensors: Mapping[str, torch.Tensor],
    name: str,
    where: Path,
    tensors_where: Path,
) -> dict[int, dict[str, Any]]:
    """The per-parameter state of ``optimizer`` by parameter index: every tensor of its
    parameter's shape and dtype (a scalar ``step``), every scalar a number, the entries its class
    needs, for every parameter or none."""
    parameters = [parameter for group in optimizer.param_groups for parameter in group["params"]]

    def index_of(text: str, label: str) -> int:
        # Only the canonical decimal form: "00", "0 " or a non-ASCII digit would name parameter 0 a
        # second time, and whichever came last would be kept silently.
        if not (text.isascii() and text.isdigit() and str(int(text)) == text and int(text) < len(parameters)):
            raise PolicyFormatError(
                f"{label}: parameter index {text!r} is not one of this optimizer's 0..{len(parameters) - 1}"
            )
        return int(text)

    state: dict[int, dict[str, Any]] = {}
    prefix = f"{name}/state/"
    for key, tensor in tensors.items():
        if key.startswith(prefix):
            text, _, entry = key[len(prefix) :].partition("/")
            index = index_of(text, f"{tensors_where}: tensor {key!r}")
            parameter = parameters[index]
            shape = () if entry == "step" else tuple(parameter.shape)
            if tuple(tensor.shape) != shape or tensor.dtype != parameter.dtype:
                raise PolicyFormatError(
                    f"{tensors_where}: tensor {key!r} is {tuple(tensor.shape)} {tensor.dtype}; the parameter it "
                    f"belongs to needs {shape} {parameter.dtype}: restore or re-create the checkpoint"
                )
            _check_entry_content(entry, tensor, f"{tensors_where}: tensor {key!r}")
            state.setdefault(index, {})[entry] = tensor
    _add_scalars(state, saved.get("scalars") or {}, index_of, name, where, tensors_where)
    required = _REQUIRED_STATE.get(type(optimizer).__name__, frozenset())
    for index, entries in state.items():
        missing, extra = sorted(required - set(entries)), sorted(set(entries) - required - _OPTIONAL_STATE)
        if missing or extra:
            raise PolicyFormatError(
                f"{tensors_where}: optimizer {name!r}, parameter {index}: "
                + (f"missing {missing} " if missing else "")
                + (f"unknown {extra} " if extra else "")
                + f"(a {type(optimizer).__name__} state has {sorted(required)}): restore or re-create the checkpoint"
            )
    if state and sorted(state) != list(range(len(parameters))):
        raise PolicyFormatError(
            f"{tensors_where}: optimizer {name!r} has state for parameters {sorted(state)[:8]}, not for each of its "
            f"{len(parameters)}: restore or re-create the checkpoint"
        )
    return state


def _add_scalars(
    state: dict[int, dict[str, Any]],
    scalars: Any,
    index_of: Callable[[str, str], int],
    name: str,
    where: Path,
    tensors_where: Path,
) -> None:
    """Add the per-parameter scalars of ``training.json`` (``optimizers.<name>.scalars``) to
    ``state``, each a number or null, checked, and not an entry a tensor gives already."""
    if not isinstance(scalars, dict):
        raise PolicyFormatError(f"{where}: optimizers.{name}.scalars must be an object; got {scalars!r}")
    for text, entries in scalars.items():
        label = f"{where}: optimizers.{name}.scalars.{text}"
        index = index_of(text, label)
        if not isinstance(entries, dict):
            raise PolicyFormatError(f"{label} must be an object; got {entries!r}")
        for key, value in entries.items():
            if value is not None and (isinstance(value, bool) or not isinstance(value, (int, float))):
                raise PolicyFormatError(f"{label}.{key} must be a number or null; got {value!r}")
            if key in state.get(index, {}):
                raise PolicyFormatError(
                    f"{label}.{key} is also a tensor of {tensors_where}: each entry once; restore or re-create the "
                    "checkpoint"
                )
            if value is not None:
                _check_entry_content(key, torch.tensor(float(value), dtype=torch.float64), f"{label}.{key}")
            state.setdefault(index, {})[key] = value
