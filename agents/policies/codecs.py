"""How the safe policy format writes values as data: strict JSON, spaces, and classes by name.

* JSON values (:func:`parse_json`, :func:`dump_json`, :func:`json_value`, :func:`require_entry`):
  strict UTF-8 JSON without NaN or Infinity literals, numbers that round-trip exactly, and errors
  that name the file and the entry;
* spaces (:func:`encode_space`, :func:`decode_space`): a ``Box`` with its shape, dtype and every
  bound, bit-exact;
* classes by name (:data:`CLASS_KWARGS`, :func:`encode_policy_kwargs`,
  :func:`decode_policy_kwargs`): a policy constructor's class-valued keyword arguments
  (activation, feature extractor, optimizer) as names from fixed tables, so that a file cannot
  name arbitrary code.

Every error is a :class:`~.layout.PolicyFormatError`.
"""

from __future__ import annotations

import inspect
import json
import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import gymnasium
import numpy as np

from tether_gym._optional import needs_extra

from ..common.checks import is_count
from ..common.reading import MAX_JSON_INTEGER, decode_json, json_depth
from .layout import PolicyFormatError

with needs_extra("train", "the policy files"):
    import torch
    from stable_baselines3.common.torch_layers import FlattenExtractor

__all__ = [
    "ACTIVATIONS",
    "CLASS_KWARGS",
    "FEATURE_EXTRACTORS",
    "MAX_JSON_BYTES",
    "MAX_JSON_DEPTH",
    "MAX_JSON_INTEGER",
    "OPTIMIZERS",
    "check_action_bounds",
    "decode_float",
    "decode_policy_kwargs",
    "decode_space",
    "dump_json",
    "encode_float",
    "encode_policy_kwargs",
    "encode_space",
    "json_depth",
    "json_value",
    "parse_json",
    "require_entry",
]

#: Activation functions by the names that hyperparameter files and policy.json use.
ACTIVATIONS: dict[str, type[torch.nn.Module]] = {
    "tanh": torch.nn.Tanh,
    "relu": torch.nn.ReLU,
    "elu": torch.nn.ELU,
    "leaky_relu": torch.nn.LeakyReLU,
    "gelu": torch.nn.GELU,
    "silu": torch.nn.SiLU,
}
#: Feature extractors by name (SB3's default, the only one the policies use).
FEATURE_EXTRACTORS: dict[str, type[torch.nn.Module]] = {"FlattenExtractor": FlattenExtractor}
#: Optimizers by name.
OPTIMIZERS: dict[str, type[torch.optim.Optimizer]] = {
    "Adam": torch.optim.Adam,
    "AdamW": torch.optim.AdamW,
    "RMSprop": torch.optim.RMSprop,
    "SGD": torch.optim.SGD,
}
#: Policy keyword arguments whose values are classes, and the only classes each may name.
CLASS_KWARGS: dict[str, dict[str, type]] = {
    "activation_fn": ACTIVATIONS,
    "features_extractor_class": FEATURE_EXTRACTORS,
    "optimizer_class": OPTIMIZERS,
}
#: Policy constructor arguments that the format stores separately (spaces) or replaces (schedule).
_POSITIONAL = ("self", "observation_space", "action_space", "lr_schedule")


# ---------------------------------------------------------------------------------------------
# JSON values
# ---------------------------------------------------------------------------------------------


#: The largest JSON file of a policy directory read, bytes: a policy.json or normalization.json of
#: the largest network and observation the envs have is a few hundred KB.
MAX_JSON_BYTES = 16 * 2**20
#: The deepest nesting of lists and objects read: the format's own files nest 5 deep.
MAX_JSON_DEPTH = 32


def parse_json(data: bytes, where: Path) -> Any:
    """Strict JSON (UTF-8, no NaN/Infinity literals, no numbers that overflow to inf, no integers
    beyond 64 bits, no key twice in an object, at most
    :data:`MAX_JSON_BYTES` long and :data:`MAX_JSON_DEPTH` deep) with errors that name the file."""
    if len(data) > MAX_JSON_BYTES:
        raise PolicyFormatError(
            f"{where} is {len(data):,} bytes, more than a policy file can be ({MAX_JSON_BYTES:,}): "
            "restore or re-create the file"
        )
    return decode_json(
        data, where, PolicyFormatError, "restore or re-create the file", MAX_JSON_DEPTH, ", which no policy file does"
    )


def dump_json(value: Any) -> str:
    """JSON text for people too: objects one entry per line, lists of numbers on one line."""

    def form(item: Any, depth: int) -> str:
        pad, inner = " " * depth, " " * (depth + 1)
        if isinstance(item, dict) and item:
            entries = [f"{inner}{json.dumps(key)}: {form(entry, depth + 1)}" for key, entry in item.items()]
            return "{\n" + ",\n".join(entries) + "\n" + pad + "}"
        if isinstance(item, list) and any(isinstance(entry, (dict, list)) for entry in item):
            return "[\n" + ",\n".join(inner + form(entry, depth + 1) for entry in item) + "\n" + pad + "]"
        return json.dumps(item, allow_nan=False)

    return form(value, 0) + "\n"


def encode_float(value: float) -> float | str:
    """A float for JSON: finite numbers as they are (repr round-trips exactly), others as text."""
    value = float(value)
    if math.isfinite(value):
        return value
    return "nan" if math.isnan(value) else ("inf" if value > 0 else "-inf")


def decode_float(value: Any, where: str) -> float:
    """A number that :func:`encode_float` stored (a number, or ``"inf"``, ``"-inf"``,
    ``"nan"``), or a PolicyFormatError naming ``where``."""
    if isinstance(value, bool) or not isinstance(value, (int, float, str)):
        raise PolicyFormatError(f"{where} must be a number; got {value!r}")
    if isinstance(value, str):
        if value not in ("inf", "-inf", "nan"):
            raise PolicyFormatError(f"{where} must be a number, 'inf', '-inf' or 'nan'; got {value!r}")
    return float(value)


def json_value(value: Any, where: str) -> Any:
    """``value`` as plain JSON data (lists for tuples), or a PolicyFormatError naming ``where``."""
    if value is None or isinstance(value, (bool, str)):
        return value
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        if not math.isfinite(value):
            raise PolicyFormatError(f"{where} is {value}; the policy format stores only finite numbers here")
        return float(value)
    if isinstance(value, (list, tuple)):
        return [json_value(item, f"{where}[{i}]") for i, item in enumerate(value)]
    if isinstance(value, Mapping):
        if not all(isinstance(key, str) for key in value):
            raise PolicyFormatError(f"{where} must have string keys; got {list(value)}")
        return {key: json_value(item, f"{where}.{key}") for key, item in value.items()}
    raise PolicyFormatError(
        f"{where} = {value!r} ({type(value).__name__}) cannot be stored safely: only numbers, strings, "
        f"booleans, lists and dicts (and the named classes {sorted(CLASS_KWARGS)}) can"
    )


def require_entry(mapping: Any, key: str, kinds: type | tuple[type, ...], where: Path) -> Any:
    """``mapping[key]``, checked to be of ``kinds`` (bools are not numbers)."""
    if not isinstance(mapping, dict):
        raise PolicyFormatError(f"{where} must hold a JSON object")
    if key not in mapping:
        raise PolicyFormatError(f"{where} has no {key!r} entry: restore or re-create the file")
    value = mapping[key]
    numeric = kinds in (int, float) or (isinstance(kinds, tuple) and set(kinds) <= {int, float, type(None)})
    if not isinstance(value, kinds) or (numeric and isinstance(value, bool)):
        names = kinds.__name__ if isinstance(kinds, type) else " or ".join(kind.__name__ for kind in kinds)
        raise PolicyFormatError(f"{where}: {key!r} must be {names}; got {value!r}")
    return value


# ---------------------------------------------------------------------------------------------
# Spaces and policy keyword arguments
# ---------------------------------------------------------------------------------------------


def encode_space(space: gymnasium.Space, where: str) -> dict[str, Any]:
    """A ``Box`` as JSON data: shape, dtype and every bound (non-finite bounds as text)."""
    if not isinstance(space, gymnasium.spaces.Box):
        raise PolicyFormatError(f"{where} is a {type(space).__name__}; the policy format stores Box spaces only")
    return {
        "type": "Box",
        "shape": [int(n) for n in space.shape],
        "dtype": str(space.dtype),
        "low": [encode_float(v) for v in np.ravel(space.low)],
        "high": [encode_float(v) for v in np.ravel(space.high)],
    }


def decode_space(data: Any, where: str) -> gymnasium.spaces.Box:
    """The ``Box`` that :func:`encode_space` stored, bounds bit-exact."""
    if not isinstance(data, dict) or data.get("type") != "Box":
        raise PolicyFormatError(f"{where} must be an object with type 'Box'; got {data!r}")
    shape = data.get("shape")
    if not (isinstance(shape, list) and shape and all(is_count(n) for n in shape)):
        raise PolicyFormatError(f"{where}.shape must be a list of positive integers; got {shape!r}")
    dtype = data.get("dtype")
    if dtype not in ("float32", "float64"):
        raise PolicyFormatError(f"{where}.dtype must be 'float32' or 'float64'; got {dtype!r}")
    size = math.prod(shape)
    bounds = []
    for key in ("low", "high"):
        values = data.get(key)
        if not isinstance(values, list) or len(values) != size:
            raise PolicyFormatError(f"{where}.{key} must be a list of {size} numbers (shape {shape})")
        bounds.append(np.array([decode_float(v, f"{where}.{key}") for v in values], dtype=dtype).reshape(shape))
    if np.isnan(bounds[0]).any() or np.isnan(bounds[1]).any() or np.any(bounds[0] > bounds[1]):
        raise PolicyFormatError(f"{where}: every low bound must be <= its high bound, without NaN")
    return gymnasium.spaces.Box(low=bounds[0], high=bounds[1], shape=tuple(shape), dtype=np.dtype(dtype))


def check_action_bounds(space: gymnasium.spaces.Box, where: str) -> None:
    """Refuse an action space with an infinite bound, naming ``where``: a policy's actions are
    clipped or rescaled into its bounds, so unbounded ones would reach the env as they are."""
    if not (np.all(np.isfinite(space.low)) and np.all(np.isfinite(space.high))):
        raise PolicyFormatError(
            f"{where} is unbounded (low {np.ravel(space.low)[:3].tolist()}..., high "
            f"{np.ravel(space.high)[:3].tolist()}...): a policy's actions need finite bounds, those of the env it was "
            "trained on (the tether-gym envs' are [-1, 1]); restore or re-create the file"
        )


def _constructor_parameters(policy_class: type) -> dict[str, inspect.Parameter]:
    parameters = dict(inspect.signature(policy_class.__init__).parameters)
    keyword = (inspect.Parameter.POSITIONAL_OR_KEYWORD, inspect.Parameter.KEYWORD_ONLY)
    return {name: p for name, p in parameters.items() if name not in _POSITIONAL and p.kind in keyword}


def encode_policy_kwargs(kwargs: Mapping[str, Any], policy_class: type) -> dict[str, Any]:
    """Policy keyword arguments as JSON data: classes by their names in :data:`CLASS_KWARGS`."""
    known = _constructor_parameters(policy_class)
    encoded = {}
    for key, value in kwargs.items():
        if key not in known:
            raise PolicyFormatError(f"policy_kwargs.{key} is not a parameter of {policy_class.__name__}")
        if key in CLASS_KWARGS:
            names = [name for name, cls in CLASS_KWARGS[key].items() if cls is value]
            if not names:
                raise PolicyFormatError(
                    f"policy_kwargs.{key} = {value!r} cannot be stored safely: it must be one of the classes "
                    f"{sorted(CLASS_KWARGS[key])}"
                )
            encoded[key] = names[0]
        else:
            encoded[key] = json_value(value, f"policy_kwargs.{key}")
    return encoded


def decode_policy_kwargs(data: Any, policy_class: type, where: str) -> dict[str, Any]:
    """The keyword arguments that :func:`encode_policy_kwargs` stored, classes looked up by name."""
    if not isinstance(data, dict):
        raise PolicyFormatError(f"{where} must be a JSON object; got {data!r}")
    known = _constructor_parameters(policy_class)
    kwargs = {}
    for key, value in data.items():
        if key not in known:
            raise PolicyFormatError(
                f"{where}.{key} is not a parameter of {policy_class.__name__}; its parameters are {sorted(known)}"
            )
        if key in CLASS_KWARGS:
            if value not in CLASS_KWARGS[key]:
                raise PolicyFormatError(f"{where}.{key} must be one of {sorted(CLASS_KWARGS[key])}; got {value!r}")
            kwargs[key] = CLASS_KWARGS[key][value]
        else:
            kwargs[key] = value
    return kwargs
