"""The safe policy format: trained policies stored as data that cannot run code when loaded.

A *policy directory* holds:

* ``policy.json``: metadata (JSON) -- the algorithm, env id, SB3 policy alias (``MlpPolicy``),
  the policy's constructor keyword arguments (``net_arch``, activation *name*, ``log_std_init``,
  ...), the observation and action spaces (shapes, dtypes and bounds), the number of timesteps
  trained, the library versions and the provenance (seed, training command, source files);
* ``policy.safetensors``: the policy network's ``state_dict`` (safetensors: a JSON header and
  raw tensor bytes, nothing executable);
* ``normalization.json``: the ``VecNormalize`` statistics (observation mean/var/count, return
  statistics, ``clip_obs``, ``epsilon``, flags), when the policy was trained with them;
* ``training.safetensors`` + ``training.json`` (optional): the optimizer states and counters
  needed to resume training (``python -m agents.train --resume DIR``);
* ``MANIFEST.sha256``: the SHA-256 of every other file, ``sha256sum`` format.

Loading (:func:`load_policy`) reads only JSON, ``sha256`` text and safetensors. It builds the SB3
policy object from the metadata: the class comes from the algorithm's own alias table, every
class-valued keyword argument (activation, feature extractor, optimizer) from a fixed table of
names, so the files cannot name arbitrary code. It then loads the weights with
``load_state_dict(strict=True)``. Nothing here imports :mod:`pickle`: the pickle-based SB3 files
are handled, behind an explicit opt-in, by :mod:`agents.pickled`.

Each file is read once into memory; its checksum is verified on those bytes and the same bytes
are parsed, so a file cannot change between the check and the load.
"""

from __future__ import annotations

import dataclasses
import hashlib
import inspect
import json
import math
import operator
import platform
import re
from collections.abc import Callable, Iterable, Mapping
from pathlib import Path
from typing import Any

import gymnasium
import numpy as np

from tether_gym._optional import needs_extra, require

from .common.commands import program
from .common.files import atomic_write_bytes, atomic_write_text

with needs_extra("train", "the policy files"):
    import torch
    from stable_baselines3 import PPO, SAC, TD3
    from stable_baselines3.common.base_class import BaseAlgorithm
    from stable_baselines3.common.on_policy_algorithm import OnPolicyAlgorithm
    from stable_baselines3.common.policies import BasePolicy
    from stable_baselines3.common.torch_layers import FlattenExtractor
    from stable_baselines3.common.vec_env import VecNormalize

__all__ = [
    "ACTIVATIONS",
    "ALGORITHMS",
    "POLICY_HOSTS",
    "ChecksumError",
    "LoadedPolicy",
    "METADATA_FILE",
    "MANIFEST_FILE",
    "NormalizationStatistics",
    "PolicyFormatError",
    "POLICY_FILES",
    "encode_policy_kwargs",
    "load_tensors",
    "tensor_bytes",
    "is_policy_dir",
    "load_policy",
    "load_training_state",
    "read_metadata",
    "save_policy",
    "verify_manifest",
    "write_manifest",
]

FORMAT = "tether-gym-policy"
FORMAT_VERSION = 1
METADATA_FILE = "policy.json"
WEIGHTS_FILE = "policy.safetensors"
NORMALIZATION_FILE = "normalization.json"
TRAINING_STATE_FILE = "training.safetensors"
TRAINING_META_FILE = "training.json"
MANIFEST_FILE = "MANIFEST.sha256"
#: Every file a save may write (the manifest last).
POLICY_FILES = (METADATA_FILE, WEIGHTS_FILE, NORMALIZATION_FILE, TRAINING_STATE_FILE, TRAINING_META_FILE, MANIFEST_FILE)

ALGORITHMS: dict[str, type[BaseAlgorithm]] = {"ppo": PPO, "sac": SAC, "td3": TD3}
#: Training algorithms that are not SB3's, and the SB3 algorithm whose policy classes store their
#: policies: ARS (:mod:`agents.ars`) trains the linear actor of PPO's ``ActorCriticPolicy``.
POLICY_HOSTS: dict[str, type[BaseAlgorithm]] = {"ars": PPO}
#: Activation functions by the names that hyperparameter files and policy.json use.
ACTIVATIONS: dict[str, type[torch.nn.Module]] = {
    "tanh": torch.nn.Tanh,
    "relu": torch.nn.ReLU,
    "elu": torch.nn.ELU,
    "leaky_relu": torch.nn.LeakyReLU,
    "gelu": torch.nn.GELU,
    "silu": torch.nn.SiLU,
}
FEATURE_EXTRACTORS: dict[str, type[torch.nn.Module]] = {"FlattenExtractor": FlattenExtractor}
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
_SHA256_LINE = re.compile(r"^([0-9a-f]{64})  ([^/\\\x00]+)$")


class PolicyFormatError(ValueError):
    """A policy directory whose files are missing, malformed or inconsistent with each other."""


class ChecksumError(PolicyFormatError):
    """A file of a policy directory whose SHA-256 does not match its ``MANIFEST.sha256``."""


def _safetensors() -> Any:
    """The ``safetensors.torch`` module, with an install hint when it is missing."""
    return require("safetensors.torch", "train", "the policy files (stored as safetensors)")


# ---------------------------------------------------------------------------------------------
# JSON values
# ---------------------------------------------------------------------------------------------


def _reject_constant(name: str) -> None:
    raise ValueError(f"non-finite number {name} is not allowed here")


def _finite_float(text: str) -> float:
    value = float(text)
    if not math.isfinite(value):
        raise ValueError(f"number {text} overflows a float")
    return value


def _parse_json(data: bytes, where: Path) -> Any:
    """Strict JSON (UTF-8, no NaN/Infinity literals, no numbers that overflow to inf) with errors
    that name the file."""
    try:
        return json.loads(data.decode("utf-8"), parse_constant=_reject_constant, parse_float=_finite_float)
    except (UnicodeDecodeError, ValueError) as error:
        raise PolicyFormatError(f"{where} is not valid JSON ({error}): restore or re-create the file") from error


def _dump_json(value: Any) -> str:
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


def _encode_float(value: float) -> float | str:
    """A float for JSON: finite numbers as they are (repr round-trips exactly), others as text."""
    value = float(value)
    if math.isfinite(value):
        return value
    return "nan" if math.isnan(value) else ("inf" if value > 0 else "-inf")


def _decode_float(value: Any, where: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, str)):
        raise PolicyFormatError(f"{where} must be a number; got {value!r}")
    if isinstance(value, str):
        if value not in ("inf", "-inf", "nan"):
            raise PolicyFormatError(f"{where} must be a number, 'inf', '-inf' or 'nan'; got {value!r}")
    return float(value)


def _json_value(value: Any, where: str) -> Any:
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
        return [_json_value(item, f"{where}[{i}]") for i, item in enumerate(value)]
    if isinstance(value, Mapping):
        if not all(isinstance(key, str) for key in value):
            raise PolicyFormatError(f"{where} must have string keys; got {list(value)}")
        return {key: _json_value(item, f"{where}.{key}") for key, item in value.items()}
    raise PolicyFormatError(
        f"{where} = {value!r} ({type(value).__name__}) cannot be stored safely: only numbers, strings, "
        f"booleans, lists and dicts (and the named classes {sorted(CLASS_KWARGS)}) can"
    )


def _require(mapping: Any, key: str, kinds: type | tuple[type, ...], where: Path) -> Any:
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
        "low": [_encode_float(v) for v in np.ravel(space.low)],
        "high": [_encode_float(v) for v in np.ravel(space.high)],
    }


def decode_space(data: Any, where: str) -> gymnasium.spaces.Box:
    """The ``Box`` that :func:`encode_space` stored, bounds bit-exact."""
    if not isinstance(data, dict) or data.get("type") != "Box":
        raise PolicyFormatError(f"{where} must be an object with type 'Box'; got {data!r}")
    shape = data.get("shape")
    if not (
        isinstance(shape, list)
        and shape
        and all(isinstance(n, int) and not isinstance(n, bool) and n > 0 for n in shape)
    ):
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
        bounds.append(np.array([_decode_float(v, f"{where}.{key}") for v in values], dtype=dtype).reshape(shape))
    if np.isnan(bounds[0]).any() or np.isnan(bounds[1]).any() or np.any(bounds[0] > bounds[1]):
        raise PolicyFormatError(f"{where}: every low bound must be <= its high bound, without NaN")
    return gymnasium.spaces.Box(low=bounds[0], high=bounds[1], shape=tuple(shape), dtype=np.dtype(dtype))


def _constructor_parameters(policy_class: type) -> dict[str, inspect.Parameter]:
    parameters = dict(inspect.signature(policy_class.__init__).parameters)
    keyword = (inspect.Parameter.POSITIONAL_OR_KEYWORD, inspect.Parameter.KEYWORD_ONLY)
    return {name: p for name, p in parameters.items() if name not in _POSITIONAL and p.kind in keyword}


def policy_constructor_kwargs(model: BaseAlgorithm) -> dict[str, Any]:
    """The keyword arguments ``model`` built its policy with (besides the spaces and the learning
    rate schedule): its ``policy_kwargs``, plus ``use_sde``, which on-policy algorithms pass
    separately."""
    kwargs = dict(model.policy_kwargs)
    if isinstance(model, OnPolicyAlgorithm):
        kwargs["use_sde"] = model.use_sde
    return kwargs


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
            encoded[key] = _json_value(value, f"policy_kwargs.{key}")
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


def _policy_class(algo: str, alias: str, where: str) -> type[BasePolicy]:
    hosts = {**ALGORITHMS, **POLICY_HOSTS}
    if algo not in hosts:
        raise PolicyFormatError(f"{where}: algorithm {algo!r} is not one of {sorted(hosts)}")
    aliases = hosts[algo].policy_aliases
    if alias not in aliases:
        raise PolicyFormatError(f"{where}: policy {alias!r} is not one of {algo}'s {sorted(aliases)}")
    return aliases[alias]


def policy_alias(model: BaseAlgorithm) -> str:
    """The name (``MlpPolicy``, ...) under which ``model``'s algorithm knows its policy class."""
    for alias, cls in model.policy_aliases.items():
        if cls is model.policy_class:
            return alias
    raise PolicyFormatError(
        f"policy class {model.policy_class.__name__} is not one of {type(model).__name__}'s named policies "
        f"{sorted(model.policy_aliases)}: the policy format can store only those"
    )


def _algo_name(model: BaseAlgorithm) -> str:
    for name, cls in ALGORITHMS.items():
        if type(model) is cls:
            return name
    raise PolicyFormatError(f"{type(model).__name__} is not one of the algorithms {sorted(ALGORITHMS)}")


def _constant_schedule(_: float) -> float:
    """The learning rate of a policy loaded for inference: never used."""
    return 0.0


# ---------------------------------------------------------------------------------------------
# VecNormalize statistics
# ---------------------------------------------------------------------------------------------


@dataclasses.dataclass
class NormalizationStatistics:
    """``VecNormalize``'s statistics and settings, without the wrapper and without pickle.

    :meth:`normalize_obs` computes exactly what ``VecNormalize.normalize_obs`` computes, with the
    same operations in the same dtypes, so actions match the SB3 pipeline bit for bit.

    Attributes:
        obs_mean, obs_var: (obs_dim,) running mean and variance of the raw observations.
        obs_count: number of observations behind them (SB3 starts it at 1e-4).
        ret_mean, ret_var, ret_count: the same for the discounted return (reward scaling).
        clip_obs, clip_reward: normalised observations and rewards are clipped to +-these.
        epsilon: added to the variance before the square root.
        gamma: discount of the return statistics.
        norm_obs, norm_reward: whether observations and rewards are normalised.
    """

    obs_mean: np.ndarray
    obs_var: np.ndarray
    obs_count: float
    ret_mean: np.ndarray
    ret_var: np.ndarray
    ret_count: float
    clip_obs: float
    clip_reward: float
    epsilon: float
    gamma: float
    norm_obs: bool
    norm_reward: bool

    @classmethod
    def from_vec_normalize(cls, normalizer: VecNormalize) -> NormalizationStatistics:
        """The statistics of a ``VecNormalize`` (Box observations only)."""
        if isinstance(normalizer.obs_rms, dict):
            raise PolicyFormatError("VecNormalize of dict observations is not supported by the policy format")
        return cls(
            obs_mean=np.array(normalizer.obs_rms.mean),
            obs_var=np.array(normalizer.obs_rms.var),
            obs_count=float(normalizer.obs_rms.count),
            ret_mean=np.array(normalizer.ret_rms.mean),
            ret_var=np.array(normalizer.ret_rms.var),
            ret_count=float(normalizer.ret_rms.count),
            clip_obs=float(normalizer.clip_obs),
            clip_reward=float(normalizer.clip_reward),
            epsilon=float(normalizer.epsilon),
            gamma=float(normalizer.gamma),
            norm_obs=bool(normalizer.norm_obs),
            norm_reward=bool(normalizer.norm_reward),
        )

    def apply_to(self, normalizer: VecNormalize) -> None:
        """Load these statistics and settings into a ``VecNormalize`` (to resume training)."""
        if normalizer.obs_rms.mean.shape != self.obs_mean.shape:
            raise PolicyFormatError(
                f"normalisation statistics have {self.obs_mean.shape} observations; the env has "
                f"{normalizer.obs_rms.mean.shape}"
            )
        normalizer.obs_rms.mean, normalizer.obs_rms.var = self.obs_mean.copy(), self.obs_var.copy()
        normalizer.obs_rms.count = self.obs_count
        normalizer.ret_rms.mean, normalizer.ret_rms.var = self.ret_mean.copy(), self.ret_var.copy()
        normalizer.ret_rms.count = self.ret_count
        normalizer.clip_obs, normalizer.clip_reward = self.clip_obs, self.clip_reward
        normalizer.epsilon, normalizer.gamma = self.epsilon, self.gamma
        normalizer.norm_obs, normalizer.norm_reward = self.norm_obs, self.norm_reward

    def normalize_obs(self, obs: np.ndarray) -> np.ndarray:
        """``clip((obs - mean) / sqrt(var + epsilon), -clip_obs, clip_obs)`` as float32 (obs
        unchanged if ``norm_obs`` is off), as ``VecNormalize.normalize_obs`` does."""
        if not self.norm_obs:
            return np.array(obs, copy=True)
        return np.clip(
            (obs - self.obs_mean) / np.sqrt(self.obs_var + self.epsilon), -self.clip_obs, self.clip_obs
        ).astype(np.float32)

    def to_json(self) -> str:
        def array(values: np.ndarray) -> dict[str, Any]:
            return {
                "shape": list(values.shape),
                "dtype": str(values.dtype),
                "values": [_encode_float(v) for v in np.ravel(values)],
            }

        data = {
            "format": "tether-gym-normalization",
            "format_version": FORMAT_VERSION,
            "norm_obs": self.norm_obs,
            "norm_reward": self.norm_reward,
            "clip_obs": self.clip_obs,
            "clip_reward": self.clip_reward,
            "epsilon": self.epsilon,
            "gamma": self.gamma,
            "obs_rms": {"mean": array(self.obs_mean), "var": array(self.obs_var), "count": self.obs_count},
            "ret_rms": {"mean": array(self.ret_mean), "var": array(self.ret_var), "count": self.ret_count},
        }
        self._check(Path(NORMALIZATION_FILE))
        return _dump_json(data)

    @classmethod
    def from_json(cls, data: bytes, where: Path) -> NormalizationStatistics:
        """Parse and check :meth:`to_json`'s output; errors name the file and the entry."""
        table = _parse_json(data, where)
        if _require(table, "format", str, where) != "tether-gym-normalization":
            raise PolicyFormatError(f"{where} is not a tether-gym normalisation file (format {table['format']!r})")
        if _require(table, "format_version", int, where) != FORMAT_VERSION:
            raise PolicyFormatError(
                f"{where}: format_version {table['format_version']} is not {FORMAT_VERSION}: "
                f"use the tether-gym version that wrote it"
            )

        def array(entry: Any, key: str) -> np.ndarray:
            label = f"{where}: {key}"
            if not isinstance(entry, dict):
                raise PolicyFormatError(f"{label} must be an object with shape, dtype and values")
            shape, dtype, values = entry.get("shape"), entry.get("dtype"), entry.get("values")
            if not (
                isinstance(shape, list)
                and all(isinstance(n, int) and not isinstance(n, bool) and n >= 0 for n in shape)
            ):
                raise PolicyFormatError(f"{label}.shape must be a list of non-negative integers; got {shape!r}")
            if dtype not in ("float32", "float64"):
                raise PolicyFormatError(f"{label}.dtype must be 'float32' or 'float64'; got {dtype!r}")
            if not isinstance(values, list) or len(values) != math.prod(shape):
                raise PolicyFormatError(f"{label}.values must be a list of {math.prod(shape)} numbers")
            return np.array([_decode_float(v, f"{label}.values") for v in values], dtype=dtype).reshape(shape)

        obs_rms, ret_rms = _require(table, "obs_rms", dict, where), _require(table, "ret_rms", dict, where)
        statistics = cls(
            obs_mean=array(obs_rms.get("mean"), "obs_rms.mean"),
            obs_var=array(obs_rms.get("var"), "obs_rms.var"),
            obs_count=float(_require(obs_rms, "count", (int, float), where)),
            ret_mean=array(ret_rms.get("mean"), "ret_rms.mean"),
            ret_var=array(ret_rms.get("var"), "ret_rms.var"),
            ret_count=float(_require(ret_rms, "count", (int, float), where)),
            clip_obs=float(_require(table, "clip_obs", (int, float), where)),
            clip_reward=float(_require(table, "clip_reward", (int, float), where)),
            epsilon=float(_require(table, "epsilon", (int, float), where)),
            gamma=float(_require(table, "gamma", (int, float), where)),
            norm_obs=_require(table, "norm_obs", bool, where),
            norm_reward=_require(table, "norm_reward", bool, where),
        )
        statistics._check(where)
        return statistics

    def _check(self, where: Path) -> None:
        """Finite statistics, non-negative variances and positive clips, or an error naming them."""
        for name in ("obs_mean", "obs_var", "ret_mean", "ret_var"):
            values = getattr(self, name)
            if not np.all(np.isfinite(values)):
                raise PolicyFormatError(f"{where}: {name} has non-finite entries")
            if name.endswith("var") and np.any(values < 0):
                raise PolicyFormatError(f"{where}: {name} has negative entries")
        if self.obs_mean.shape != self.obs_var.shape or self.ret_mean.shape != self.ret_var.shape:
            raise PolicyFormatError(f"{where}: mean and var shapes differ")
        for name in ("obs_count", "ret_count", "clip_obs", "clip_reward", "epsilon", "gamma"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0) and not (name == "epsilon" and value == 0):
                raise PolicyFormatError(f"{where}: {name} must be a positive finite number; got {value}")


# ---------------------------------------------------------------------------------------------
# Checksums
# ---------------------------------------------------------------------------------------------


def sha256_hex(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def write_manifest(directory: Path, names: Iterable[str]) -> None:
    """Write ``MANIFEST.sha256`` (``sha256sum`` format, sorted) for ``names`` in ``directory``
    (the manifest itself is never listed: its own hash cannot be in it)."""
    lines = [f"{sha256_hex((directory / name).read_bytes())}  {name}" for name in sorted(set(names) - {MANIFEST_FILE})]
    atomic_write_text(directory / MANIFEST_FILE, "\n".join(lines) + "\n")


def read_manifest(directory: Path) -> dict[str, str] | None:
    """``MANIFEST.sha256`` as name -> sha256, or None if the directory has none."""
    path = directory / MANIFEST_FILE
    if not path.is_file():
        return None
    entries = {}
    try:
        text = path.read_bytes().decode("utf-8")
    except UnicodeDecodeError as error:
        raise ChecksumError(f"{path} is not UTF-8 text: restore it") from error
    for number, line in enumerate(text.splitlines(), start=1):
        match = _SHA256_LINE.match(line)
        if match is None or match.group(2) in (".", ".."):
            raise ChecksumError(f"{path}, line {number}: expected '<64 hex digits>  <file name>'; got {line[:100]!r}")
        entries[match.group(2)] = match.group(1)
    return entries


class _VerifiedReader:
    """Reads the files of one policy directory, each checked against the manifest (if any)."""

    def __init__(self, directory: Path, require_manifest: bool) -> None:
        self.directory = directory
        self.manifest = read_manifest(directory)
        if self.manifest is None and require_manifest:
            raise ChecksumError(
                f"{directory} has no {MANIFEST_FILE}: a shipped model must have one; restore the directory "
                f"from the repository"
            )
        if self.manifest is not None and require_manifest:
            listed = set(self.manifest) | {MANIFEST_FILE}
            present = {path.name for path in directory.iterdir()}
            unlisted, missing = sorted(present - listed), sorted(listed - present)
            if unlisted or missing:
                raise ChecksumError(
                    f"{directory} does not match its {MANIFEST_FILE}: "
                    + (f"files not listed: {unlisted}; " if unlisted else "")
                    + (f"listed files missing: {missing}; " if missing else "")
                    + "restore the directory from the repository"
                )

    def read(self, name: str) -> bytes:
        path = self.directory / name
        if not path.is_file():
            raise PolicyFormatError(f"{path} is missing: restore it, or re-create the policy directory")
        data = path.read_bytes()
        if self.manifest is not None:
            if name not in self.manifest:
                raise ChecksumError(f"{path} is not listed in {self.directory / MANIFEST_FILE}: the manifest is stale")
            actual = sha256_hex(data)
            if actual != self.manifest[name]:
                raise ChecksumError(
                    f"{path}: SHA-256 {actual} does not match {MANIFEST_FILE} ({self.manifest[name]}); the file "
                    f"is corrupted or was changed: restore it (for a shipped model, git checkout the directory)"
                )
        return data


def verify_manifest(directory: str | Path, strict: bool = True) -> None:
    """Check every file listed in ``directory``'s manifest (and, if ``strict``, that the manifest
    lists exactly the directory's files). Raises :class:`ChecksumError` naming the file."""
    directory = Path(directory)
    reader = _VerifiedReader(directory, require_manifest=strict)
    for name in reader.manifest or {}:
        reader.read(name)


# ---------------------------------------------------------------------------------------------
# Saving
# ---------------------------------------------------------------------------------------------


def _versions() -> dict[str, str]:
    import stable_baselines3

    import tether_gym

    return {
        "stable_baselines3": stable_baselines3.__version__,
        "torch": torch.__version__,
        "numpy": np.__version__,
        "gymnasium": gymnasium.__version__,
        "tether_gym": tether_gym.__version__,
        "python": platform.python_version(),
    }


def tensor_bytes(tensors: Mapping[str, torch.Tensor], metadata: Mapping[str, str] | None = None) -> bytes:
    """``tensors`` (and text ``metadata``) as the bytes of a safetensors file."""
    # Cloned so that no two entries share storage, which safetensors refuses.
    return _safetensors().save(
        {key: value.detach().cpu().contiguous().clone() for key, value in tensors.items()},
        metadata=dict(metadata) if metadata else None,
    )


def load_tensors(data: bytes, where: Path) -> dict[str, torch.Tensor]:
    """The tensors of a safetensors file's bytes; a PolicyFormatError naming ``where`` if malformed."""
    try:
        return _safetensors().load(data)
    except Exception as error:  # noqa: BLE001 - safetensors raises its own error types for bad headers
        raise PolicyFormatError(
            f"{where} is not a valid safetensors file ({error}): restore or re-create it"
        ) from error


def policy_metadata(
    model: BaseAlgorithm,
    env_id: str | None,
    provenance: Mapping[str, Any] | None,
    normalization: bool,
    training_state: bool,
    residual_on: str | None = None,
    multiagent: Mapping[str, Any] | None = None,
    algo: str | None = None,
) -> dict[str, Any]:
    """The ``policy.json`` of ``model`` (see the module docstring); ``algo`` names a training
    algorithm of :data:`POLICY_HOSTS` whose policy ``model`` holds (default: ``model``'s own)."""
    if algo is not None and POLICY_HOSTS.get(algo) is not type(model):
        host = type(model).__name__
        raise PolicyFormatError(f"algo {algo!r} is not one of {sorted(POLICY_HOSTS)} with a {host} policy")
    policy_class = model.policy_class
    return {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "algo": algo or _algo_name(model),
        "env_id": env_id,
        "policy": policy_alias(model),
        "policy_kwargs": encode_policy_kwargs(policy_constructor_kwargs(model), policy_class),
        "observation_space": encode_space(model.observation_space, "observation_space"),
        "action_space": encode_space(model.action_space, "action_space"),
        "num_timesteps": int(model.num_timesteps),
        "normalization": normalization,
        "training_state": training_state,
        "residual_on": residual_on,
        "multiagent": None if multiagent is None else _json_value(dict(multiagent), "multiagent"),
        "versions": _versions(),
        "provenance": _json_value(dict(provenance or {}), "provenance"),
    }


def save_policy(
    directory: str | Path,
    model: BaseAlgorithm,
    normalizer: VecNormalize | NormalizationStatistics | None,
    env_id: str | None,
    provenance: Mapping[str, Any] | None = None,
    training_state: bool = False,
    extra_files: Iterable[str] = (),
    residual_on: str | None = None,
    multiagent: Mapping[str, Any] | None = None,
    algo: str | None = None,
) -> Path:
    """Write ``model``'s policy (and ``normalizer``'s statistics) to ``directory`` in the safe
    format; with ``training_state``, also the optimizer states and counters that resuming needs;
    ``algo`` as in :func:`policy_metadata`.
    Every file is written atomically, the manifest last; it also covers ``extra_files`` (names
    of files already in ``directory``, such as ``config.yml``). Returns the directory."""
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    statistics = (
        NormalizationStatistics.from_vec_normalize(normalizer) if isinstance(normalizer, VecNormalize) else normalizer
    )
    metadata = policy_metadata(
        model, env_id, provenance, statistics is not None, training_state, residual_on, multiagent, algo
    )
    written = [METADATA_FILE, WEIGHTS_FILE]
    atomic_write_bytes(directory / WEIGHTS_FILE, tensor_bytes(model.policy.state_dict()))
    if statistics is not None:
        atomic_write_text(directory / NORMALIZATION_FILE, statistics.to_json())
        written.append(NORMALIZATION_FILE)
    else:
        (directory / NORMALIZATION_FILE).unlink(missing_ok=True)
    if training_state:
        tensors, meta = _training_state(model)
        atomic_write_bytes(directory / TRAINING_STATE_FILE, tensor_bytes(tensors))
        atomic_write_text(directory / TRAINING_META_FILE, _dump_json(meta))
        written += [TRAINING_STATE_FILE, TRAINING_META_FILE]
    else:
        for name in (TRAINING_STATE_FILE, TRAINING_META_FILE):
            (directory / name).unlink(missing_ok=True)
    atomic_write_text(directory / METADATA_FILE, _dump_json(metadata))
    write_manifest(directory, written + [name for name in extra_files if (directory / name).is_file()])
    return directory


def _training_state(model: BaseAlgorithm) -> tuple[dict[str, torch.Tensor], dict[str, Any]]:
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
                    scalars.setdefault(str(index), {})[key] = _json_value(value, f"{name}.state.{index}.{key}")
        optimizers[name] = {
            "indices": [int(index) for index in state["state"]],
            "scalars": scalars,
            "param_groups": _json_value(state["param_groups"], f"{name}.param_groups"),
        }
    for name in variable_names:
        tensors[f"variables/{name}"] = operator.attrgetter(name)(model)
    meta = {
        "format": "tether-gym-training-state",
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


# ---------------------------------------------------------------------------------------------
# Loading
# ---------------------------------------------------------------------------------------------


@dataclasses.dataclass
class LoadedPolicy:
    """A policy rebuilt from a policy directory.

    Attributes:
        policy: the SB3 policy (``predict(obs, deterministic=True)``), on the CPU, in eval mode.
        metadata: the parsed ``policy.json``.
        normalizer: the observation statistics, or None if the policy was trained without.
        directory: where it was loaded from.
    """

    policy: BasePolicy
    metadata: dict[str, Any]
    normalizer: NormalizationStatistics | None
    directory: Path


def is_policy_dir(path: str | Path) -> bool:
    """Whether ``path`` is a directory in the safe policy format (it holds ``policy.json``)."""
    return Path(path).is_dir() and (Path(path) / METADATA_FILE).is_file()


def read_metadata(directory: Path, reader: _VerifiedReader | None = None) -> dict[str, Any]:
    """The parsed and checked ``policy.json`` of ``directory``."""
    reader = reader or _VerifiedReader(directory, require_manifest=False)
    where = directory / METADATA_FILE
    metadata = _parse_json(reader.read(METADATA_FILE), where)
    if _require(metadata, "format", str, where) != FORMAT:
        raise PolicyFormatError(f"{where} is not a tether-gym policy file (format {metadata['format']!r})")
    if _require(metadata, "format_version", int, where) != FORMAT_VERSION:
        raise PolicyFormatError(
            f"{where}: format_version {metadata['format_version']} is not {FORMAT_VERSION}: use the tether-gym "
            f"version that wrote it"
        )
    _require(metadata, "algo", str, where)
    _require(metadata, "policy", str, where)
    _require(metadata, "env_id", (str, type(None)), where)
    _require(metadata, "policy_kwargs", dict, where)
    _require(metadata, "num_timesteps", int, where)
    _require(metadata, "normalization", bool, where)
    _require(metadata, "training_state", bool, where)
    # Optional (policies written before residual training have none): the baseline the
    # policy's actions are corrections to.
    from .controllers.residual import check_residual_on

    try:
        metadata["residual_on"] = check_residual_on(metadata.get("residual_on"), f"{where}: residual_on")
    except ValueError as error:
        raise PolicyFormatError(str(error)) from None
    # Optional (centralised policies have none): the multi-agent options of a shared
    # decentralised policy, which acts on local observations (agents.controllers.decentralised).
    multiagent = metadata.get("multiagent")
    if multiagent is not None and not isinstance(multiagent, dict):
        raise PolicyFormatError(
            f"{where}: multiagent must be a dict of multi-agent options or null; got {multiagent!r}"
        )
    metadata["multiagent"] = multiagent
    return metadata


def load_policy(directory: str | Path, require_manifest: bool = False, device: str = "cpu") -> LoadedPolicy:
    """Rebuild the policy stored in ``directory`` (see the module docstring).

    With ``require_manifest`` (shipped models), the directory must have a ``MANIFEST.sha256``
    that lists exactly its files; otherwise a manifest is verified when present. Raises
    :class:`PolicyFormatError` (or :class:`ChecksumError`) naming the file and the problem."""
    directory = Path(directory)
    if not is_policy_dir(directory):
        raise PolicyFormatError(f"{directory} is not a policy directory (it has no {METADATA_FILE})")
    reader = _VerifiedReader(directory, require_manifest)
    metadata = read_metadata(directory, reader)
    where = directory / METADATA_FILE
    policy_class = _policy_class(metadata["algo"], metadata["policy"], str(where))
    observation_space = decode_space(metadata.get("observation_space"), f"{where}: observation_space")
    action_space = decode_space(metadata.get("action_space"), f"{where}: action_space")
    kwargs = decode_policy_kwargs(metadata["policy_kwargs"], policy_class, f"{where}: policy_kwargs")
    try:
        # Building the policy draws its random initial weights: keep the caller's torch RNG as it was.
        with torch.random.fork_rng(devices=[]):
            policy = policy_class(observation_space, action_space, _constant_schedule, **kwargs)
    except Exception as error:  # noqa: BLE001 - only allow-listed classes run here; any failure is bad kwargs
        raise PolicyFormatError(f"{where}: policy_kwargs do not build a {policy_class.__name__}: {error}") from error
    weights = load_tensors(reader.read(WEIGHTS_FILE), directory / WEIGHTS_FILE)
    _load_state_dict(policy, weights, directory / WEIGHTS_FILE)
    policy.to(device)
    policy.set_training_mode(False)
    normalizer = None
    if metadata["normalization"]:
        normalizer = NormalizationStatistics.from_json(reader.read(NORMALIZATION_FILE), directory / NORMALIZATION_FILE)
        if normalizer.obs_mean.shape != observation_space.shape:
            raise PolicyFormatError(
                f"{directory / NORMALIZATION_FILE}: statistics of shape {normalizer.obs_mean.shape} do not fit the "
                f"observation space {observation_space.shape} of {where}"
            )
    return LoadedPolicy(policy=policy, metadata=metadata, normalizer=normalizer, directory=directory)


def _load_state_dict(module: torch.nn.Module, weights: Mapping[str, torch.Tensor], where: Path) -> None:
    """``module.load_state_dict(weights, strict=True)`` after checking names, shapes and dtypes,
    with errors that name the file and the tensors."""
    expected = module.state_dict()
    missing, unexpected = sorted(set(expected) - set(weights)), sorted(set(weights) - set(expected))
    if missing or unexpected:
        raise PolicyFormatError(
            f"{where} does not fit the policy that policy.json describes: "
            + (f"missing tensors {missing[:5]}{' ...' if len(missing) > 5 else ''}; " if missing else "")
            + (f"unexpected tensors {unexpected[:5]}{' ...' if len(unexpected) > 5 else ''}" if unexpected else "")
        )
    for key, tensor in expected.items():
        if weights[key].shape != tensor.shape or weights[key].dtype != tensor.dtype:
            raise PolicyFormatError(
                f"{where}: tensor {key!r} has shape {tuple(weights[key].shape)} ({weights[key].dtype}); the policy "
                f"needs {tuple(tensor.shape)} ({tensor.dtype})"
            )
    module.load_state_dict(weights, strict=True)


def load_training_state(model: BaseAlgorithm, directory: str | Path, normalizer: VecNormalize | None) -> dict[str, Any]:
    """Resume ``model`` (freshly built with the run's hyperparameters) from the policy directory
    ``directory``: its weights, optimizer states, extra variables and counters, and the
    normalisation statistics into ``normalizer``. Returns the checkpoint's metadata.

    Raises :class:`PolicyFormatError` when the directory has no training state, or when it does
    not fit ``model`` (another algorithm, architecture or normalisation)."""
    directory = Path(directory)
    if not is_policy_dir(directory):
        raise PolicyFormatError(f"{directory} is not a policy directory (it has no {METADATA_FILE})")
    reader = _VerifiedReader(directory, require_manifest=False)
    metadata = read_metadata(directory, reader)
    where = directory / METADATA_FILE
    algo = _algo_name(model)
    if metadata["algo"] != algo:
        raise PolicyFormatError(
            f"{where}: the checkpoint is a {metadata['algo']} model; resume it with --algo "
            f"{metadata['algo']} (not {algo})"
        )
    if not metadata["training_state"]:
        raise PolicyFormatError(
            f"{directory} holds a policy for inference only (no optimizer state): resume from a checkpoint "
            f"directory that {program('train')} wrote (checkpoints/<algo>_<steps>_steps, best/ or the run directory)"
        )
    ours = encode_policy_kwargs(policy_constructor_kwargs(model), model.policy_class)
    differing = sorted(
        key for key in set(ours) | set(metadata["policy_kwargs"]) if ours.get(key) != metadata["policy_kwargs"].get(key)
    )
    if differing or policy_alias(model) != metadata["policy"]:
        details = "; ".join(
            f"{key}: checkpoint {metadata['policy_kwargs'].get(key)!r}, now {ours.get(key)!r}" for key in differing
        )
        raise PolicyFormatError(
            f"{where}: the checkpoint's policy differs from the one the hyperparameters build ({details or 'policy'}): "
            f"resume with the run's hyperparameters (its config.yml)"
        )
    for key in ("observation_space", "action_space"):
        if decode_space(metadata.get(key), f"{where}: {key}") != getattr(model, key):
            raise PolicyFormatError(f"{where}: the checkpoint's {key} differs from the env's")
    _load_state_dict(
        model.policy, load_tensors(reader.read(WEIGHTS_FILE), directory / WEIGHTS_FILE), directory / WEIGHTS_FILE
    )
    meta_where = directory / TRAINING_META_FILE
    meta = _parse_json(reader.read(TRAINING_META_FILE), meta_where)
    if _require(meta, "format", str, meta_where) != "tether-gym-training-state":
        raise PolicyFormatError(f"{meta_where} is not a tether-gym training state")
    tensors = load_tensors(reader.read(TRAINING_STATE_FILE), directory / TRAINING_STATE_FILE)
    state_dict_names, variable_names = model._get_torch_save_params()
    optimizers = _require(meta, "optimizers", dict, meta_where)
    expected = sorted(name for name in state_dict_names if name != "policy")
    if sorted(optimizers) != expected or _require(meta, "variables", list, meta_where) != list(variable_names):
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
            raise PolicyFormatError(f"{directory / TRAINING_STATE_FILE}: variable {name!r} is missing or misshapen")
        with torch.no_grad():
            target.copy_(tensors[key])
    counters = _require(meta, "counters", dict, meta_where)
    model.num_timesteps = int(_require(counters, "num_timesteps", int, meta_where))
    model._n_updates = int(_require(counters, "n_updates", int, meta_where))
    model._episode_num = int(_require(counters, "episode_num", int, meta_where))
    if metadata["normalization"] != (normalizer is not None):
        raise PolicyFormatError(
            f"{where}: the checkpoint was trained {'with' if metadata['normalization'] else 'without'} VecNormalize, "
            f"but the hyperparameters' 'normalize' is {'off' if normalizer is None else 'on'}: use the run's settings"
        )
    if normalizer is not None:
        NormalizationStatistics.from_json(reader.read(NORMALIZATION_FILE), directory / NORMALIZATION_FILE).apply_to(
            normalizer
        )
    return metadata


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
    try:
        optimizer.load_state_dict({"state": state, "param_groups": groups})
    except (ValueError, KeyError, TypeError) as error:
        raise PolicyFormatError(f"{where}: optimizer {name!r} does not fit this model: {error}") from error


def reference_observations(
    count: int,
    observation_space: gymnasium.spaces.Box,
    mean: np.ndarray | float,
    var: np.ndarray | float,
    rng: np.random.Generator,
    rollout: Callable[[int], np.ndarray] | None = None,
) -> np.ndarray:
    """(count, obs_dim) float32 observations to compare two implementations of a policy on: env
    observations from ``rollout(n)`` when given (half of them), the rest drawn around ``mean``
    with variance ``var`` (the normalisation statistics) at 0.3, 1, 3 and 30 standard deviations,
    so that the normaliser's clipping is exercised too."""
    rows = []
    if rollout is not None:
        rows.append(np.asarray(rollout(count // 2), dtype=np.float32).reshape(-1, *observation_space.shape))
    remaining = count - sum(len(r) for r in rows)
    scales = np.array([0.3, 1.0, 3.0, 30.0])[rng.integers(0, 4, size=(remaining, 1))]
    noise = rng.standard_normal((remaining,) + observation_space.shape)
    drawn = np.asarray(mean) + np.sqrt(np.asarray(var)) * scales * noise
    rows.append(np.clip(drawn, observation_space.low, observation_space.high).astype(np.float32))
    return np.concatenate(rows)[:count]
