"""Train an SB3 agent on a tether-gym id: ``python -m agents.train --algo ppo --env TetherTetrahedron-v0``.

Console script: ``tether-gym-train`` (``python -m tether_gym_agents.train`` when installed).
Hyperparameters come from the package's ``hyperparams/<algo>.yml`` (``agents/hyperparams`` in a
checkout, ``tether_gym_agents/hyperparams`` installed), keyed by env id (rl-zoo style, plain
YAML, nothing evaluated). Every entry is checked before training starts: an unknown key, a missing
``n_timesteps`` or a string where a number belongs is an error that names the key. Training runs
on the native vector env through the SB3 adapter, with ``VecNormalize`` when configured and
``VecMonitor`` for episode statistics. A run directory ``<out>/<env>/<algo>_seed<seed>/`` receives,
all of it in the safe policy format (:mod:`agents.safe_format`: JSON and safetensors, no pickle):

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
  (:mod:`agents.selection`);
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
import difflib
import inspect
import shutil
import sys
import time
import types
import typing
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import numpy as np

import tether_gym
from tether_gym._optional import needs_extra, require
from tether_gym.registration import DEFAULT_ENV_ID, ENV_IDS
from tether_gym.sb3 import make_sb3_vec_env

from .common import cli
from .common.commands import command_line, program
from .common.data import HYPERPARAMS_DIR
from .common.files import (
    OutputError,
    OutputExistsError,
    atomic_write_text,
    check_no_symlinks_inside,
    prepare_output_dir,
)
from .pickled import (
    PickleNotTrustedError,
    is_pickle_model,
    load_pickled_model,
    normalization_file_of,
    refuse_untrusted,
    sb3_model_file,
)
from .residual import ResidualVecEnv, check_residual_on
from .safe_format import (
    ACTIVATIONS,
    ALGORITHMS,
    CLASS_KWARGS,
    METADATA_FILE,
    POLICY_FILES,
    PolicyFormatError,
    is_policy_dir,
    load_training_state,
    read_metadata,
    save_policy,
)
from .selection import EVALUATIONS_FILE, SeededEvaluation

with needs_extra("train", "training"):
    import yaml
    from stable_baselines3.common.base_class import BaseAlgorithm
    from stable_baselines3.common.callbacks import BaseCallback, CallbackList
    from stable_baselines3.common.vec_env import VecEnv, VecMonitor, VecNormalize

__all__ = [
    "ACTIVATIONS",
    "ALGORITHMS",
    "HyperparameterError",
    "load_hyperparameters",
    "make_training_env",
    "train",
    "validate_hyperparameters",
]


#: Keys of a hyperparameter entry that are not passed to the algorithm's constructor.
RUN_KEYS = (
    "n_timesteps",
    "n_envs",
    "normalize",
    "policy",
    "env_kwargs",
    "curriculum",
    "residual_on",
    "action_noise_std",
    "multiagent",
    "critic_warmup",
)
#: The keys of a ``multiagent`` entry (the options of tether_gym.multiagent, checked there).
MULTIAGENT_KEYS = ("communication", "reward", "local_observation_noise")
#: Constructor arguments that agents.train sets itself, and where the user sets them instead.
CONTROLLED_KEYS = {
    "env": "the env comes from --env",
    "seed": "use --seed",
    "device": "training runs on the CPU",
    "verbose": "use --verbose",
    "tensorboard_log": "logs go to <run>/tensorboard",
    "_init_setup_model": "internal to SB3",
}
#: Keys that take a number or "lin_<number>" (linear decay to 0 over training).
SCHEDULE_KEYS = ("learning_rate", "clip_range", "clip_range_vf")
#: Files an earlier run of agents.train may have left (this format and the pickle-based one).
LEGACY_RUN_FILES = ("model.zip", "vecnormalize.pkl")
LEGACY_BEST_FILES = ("best_model.zip", "vecnormalize.pkl", "evaluations.npz")


class HyperparameterError(ValueError):
    """A hyperparameter file or entry that cannot be trained with; the message names the key."""


# ---------------------------------------------------------------------------------------------
# Hyperparameters
# ---------------------------------------------------------------------------------------------

RUN_CONFIG_KEYS = frozenset({"algo", "env_id", "hyperparams"})


def load_hyperparameters(algo: str, env_id: str, path: str | Path | None = None) -> dict[str, Any]:
    """The checked hyperparameters of ``algo`` for ``env_id``: the id's entry of the YAML file, or
    its ``default`` entry. ``path`` overrides the package's ``hyperparams/<algo>.yml``; it may also be a
    run's ``config.yml`` (as every run directory and shipped model holds), whose recorded
    hyperparameters are then used as they are.

    Raises :class:`HyperparameterError` (naming the file, the entry and the key) for unreadable
    YAML, a missing entry, a missing ``n_timesteps``, an unknown key, or a value of the wrong
    type; FileNotFoundError if the file does not exist."""
    if algo not in ALGORITHMS:
        raise ValueError(f"unknown algorithm {algo!r}; choose one of {sorted(ALGORITHMS)}")
    file = Path(path) if path is not None else HYPERPARAMS_DIR / f"{algo}.yml"
    entry, where = read_hyperparameter_entry(file, env_id, algo)
    return validate_hyperparameters(algo, entry, where=where)


def read_hyperparameter_entry(file: Path, env_id: str, algo: str) -> tuple[dict[str, Any], str]:
    """The unchecked entry of ``env_id`` (or ``default``) in the hyperparameter file ``file``, or
    the hyperparameters a run's ``config.yml`` recorded (which must be an ``algo`` run on
    ``env_id``), and where it was found, for messages. Raises as :func:`load_hyperparameters`."""
    if not file.is_file():
        raise FileNotFoundError(f"hyperparameter file {file} does not exist")
    try:
        table = yaml.safe_load(file.read_bytes().decode("utf-8"))
    except UnicodeDecodeError as error:
        raise HyperparameterError(f"{file} is not UTF-8 text ({error})") from error
    except yaml.YAMLError as error:
        raise HyperparameterError(f"{file} is not valid YAML: {error}") from error
    if table is None:
        table = {}
    if not isinstance(table, dict):
        raise HyperparameterError(
            f"{file} must map env ids (or 'default') to hyperparameter entries; got a {type(table).__name__}"
        )
    if RUN_CONFIG_KEYS <= table.keys():
        return _run_config_hyperparameters(algo, env_id, file, table)
    name = env_id if env_id in table else "default"
    if name not in table:
        raise HyperparameterError(
            f"{file} has no entry for {env_id!r} and no 'default' entry; entries: {sorted(map(str, table))}"
        )
    entry = table[name]
    if not isinstance(entry, dict):
        raise HyperparameterError(f"{file}, entry {name!r}: must be a mapping of hyperparameters; got {entry!r}")
    return entry, f"{file}, entry {name!r}"


def _run_config_hyperparameters(
    algo: str, env_id: str, file: Path, config: dict[str, Any]
) -> tuple[dict[str, Any], str]:
    """The hyperparameters recorded in a run's (or a shipped model's) ``config.yml``: training with
    them reproduces that run whatever the package's ``hyperparams`` files say today."""
    for key, wanted in (("algo", algo), ("env_id", env_id)):
        if config[key] != wanted:
            option = "--algo" if key == "algo" else "--env"
            raise HyperparameterError(
                f"{file} records a {config['algo']} run on {config['env_id']}: pass "
                f"{option} {config[key]} to reproduce it (got {wanted})"
            )
    if not isinstance(config["hyperparams"], dict):
        raise HyperparameterError(f"{file}: 'hyperparams' must be a mapping; got {config['hyperparams']!r}")
    return config["hyperparams"], f"{file}, 'hyperparams'"


def _components(annotation: Any) -> tuple[Any, ...]:
    """The alternatives of a type annotation (``int | None`` -> ``(int, NoneType)``)."""
    if typing.get_origin(annotation) in (typing.Union, types.UnionType):
        return typing.get_args(annotation)
    return (annotation,)


def _plain(components: tuple[Any, ...]) -> set[Any]:
    """The annotation's alternatives reduced to what YAML can give: int, float, bool, str, None,
    dict, tuple (for ``tuple[int, str]``)."""
    kinds = set()
    for component in components:
        origin = typing.get_origin(component) or component
        if origin in (int, float, bool, str, dict, tuple, type(None)):
            kinds.add(origin)
        elif origin is Mapping:
            kinds.add(dict)
    return kinds


def _number_text_hint(value: str) -> str:
    try:
        float(value)
    except ValueError:
        return ""
    return f" (YAML reads {value} as text: write it with a decimal point and a signed exponent, e.g. 1.0e+6)"


def _check_value(key: str, value: Any, annotation: Any, where: str) -> Any:
    """``value`` checked against ``annotation`` (and converted: integral floats to int where an int
    is expected, lists to tuples where a tuple is). Raises HyperparameterError naming ``key``."""
    kinds = _plain(_components(annotation))
    label = f"{where}: {key!r}"
    if value is None:
        if type(None) in kinds:
            return None
        raise HyperparameterError(f"{label} is empty; give it a value or remove the key")
    if not kinds - {type(None)}:
        raise HyperparameterError(f"{label} cannot be set from a YAML file (it takes a Python object)")
    if isinstance(value, (bool, int, float, str)):
        return _check_scalar(label, value, kinds)
    if isinstance(value, list) and tuple in kinds:
        return _check_frequency(label, value)
    if isinstance(value, dict) and dict in kinds:
        return _check_mapping(key, value, where)
    raise _mismatch(label, value, kinds)


def _mismatch(label: str, value: Any, kinds: set[Any]) -> HyperparameterError:
    return HyperparameterError(f"{label} must be {_describe(kinds)}; got {value!r} ({type(value).__name__})")


def _check_scalar(label: str, value: bool | int | float | str, kinds: set[Any]) -> Any:
    """A YAML scalar checked against the annotation's alternatives ``kinds`` (see :func:`_plain`):
    ints become floats where only a float is expected, integral floats ints where only an int is."""
    if isinstance(value, bool):
        if bool in kinds:
            return value
        raise HyperparameterError(f"{label} must be {_describe(kinds)}, not {str(value).lower()}")
    if isinstance(value, str):
        if str in kinds:
            return value
        raise HyperparameterError(
            f"{label} must be {_describe(kinds)}; got the text {value!r}{_number_text_hint(value)}"
        )
    if isinstance(value, int):
        if int in kinds:
            return value
        if float in kinds:
            return float(value)
    else:
        if float in kinds:
            return value
        if int in kinds:
            if value.is_integer():
                return int(value)
            raise HyperparameterError(f"{label} must be an integer; got {value!r}")
    raise _mismatch(label, value, kinds)


def _check_frequency(label: str, value: list[Any]) -> tuple[int, str]:
    """A YAML list given for a ``tuple[int, str]`` (SB3's ``train_freq``): [integer, 'step' or 'episode']."""
    if (
        len(value) == 2
        and isinstance(value[0], int)
        and not isinstance(value[0], bool)
        and value[1] in ("step", "episode")
    ):
        return (value[0], value[1])
    raise HyperparameterError(f"{label} must be an integer or [integer, 'step' or 'episode']; got {value!r}")


def _check_mapping(key: str, value: dict[Any, Any], where: str) -> dict[Any, Any]:
    """A YAML mapping given for a dict: text keys, and no number written as text among its values."""
    if not all(isinstance(name, str) for name in value):
        raise HyperparameterError(f"{where}: {key!r} must have string keys; got {list(value)}")
    for name, entry in value.items():
        if isinstance(entry, str) and _number_text_hint(entry):
            raise HyperparameterError(
                f"{where}: '{key}.{name}' is the text {entry!r}, not a number{_number_text_hint(entry)}"
            )
    return value


def _describe(kinds: set[Any]) -> str:
    names = {
        int: "an integer",
        float: "a number",
        bool: "true or false",
        str: "text",
        dict: "a mapping",
        tuple: "[integer, 'step' or 'episode']",
        type(None): "empty",
    }
    if float in kinds:
        kinds = kinds - {int}
    return " or ".join(names[kind] for kind in sorted(kinds, key=lambda kind: list(names).index(kind)))


def _unknown_key(key: str, known: list[str], where: str, what: str) -> HyperparameterError:
    close = difflib.get_close_matches(key, known, n=1)
    hint = f" (did you mean {close[0]!r}?)" if close else ""
    return HyperparameterError(f"{where}: unknown key {key!r}{hint}; {what} accepts {sorted(known)}")


def _keyword_parameters(cls: type) -> dict[str, inspect.Parameter]:
    keyword = (inspect.Parameter.POSITIONAL_OR_KEYWORD, inspect.Parameter.KEYWORD_ONLY)
    return {
        name: p
        for name, p in inspect.signature(cls.__init__).parameters.items()
        if name != "self" and p.kind in keyword
    }


def _check_range(key: str, value: Any, where: str) -> None:
    """The ranges SB3 would otherwise reject deep inside, or silently misuse."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return
    positive = (
        "n_timesteps",
        "n_envs",
        "n_steps",
        "batch_size",
        "n_epochs",
        "buffer_size",
        "learning_rate",
        "clip_range",
        "train_freq",
        "policy_delay",
        "target_update_interval",
    )
    non_negative = (
        "learning_starts",
        "vf_coef",
        "max_grad_norm",
        "target_policy_noise",
        "target_noise_clip",
        "action_noise_std",
        "critic_warmup",
    )
    unit = ("gamma", "gae_lambda", "tau")
    if key in positive and not value > 0:
        raise HyperparameterError(f"{where}: {key!r} must be positive; got {value!r}")
    if key in non_negative and not value >= 0:
        raise HyperparameterError(f"{where}: {key!r} must be >= 0; got {value!r}")
    if key in unit and not 0 < value <= 1:
        raise HyperparameterError(f"{where}: {key!r} must be in (0, 1]; got {value!r}")


def validate_hyperparameters(algo: str, entry: Mapping[str, Any], where: str = "hyperparameters") -> dict[str, Any]:
    """A copy of ``entry`` with every key checked for ``algo`` (see :func:`load_hyperparameters`);
    ``where`` (file and entry) starts every message."""
    if algo not in ALGORITHMS:
        raise ValueError(f"unknown algorithm {algo!r}; choose one of {sorted(ALGORITHMS)}")
    cls = ALGORITHMS[algo]
    parameters = _keyword_parameters(cls)
    accepted = sorted(set(parameters) - {"policy", *CONTROLLED_KEYS} | set(RUN_KEYS))
    checked: dict[str, Any] = {}
    policy = entry.get("policy", "MlpPolicy")
    if not isinstance(policy, str) or policy not in cls.policy_aliases:
        raise HyperparameterError(f"{where}: 'policy' must be one of {sorted(cls.policy_aliases)}; got {policy!r}")
    if "n_timesteps" not in entry:
        raise HyperparameterError(
            f"{where}: 'n_timesteps' is missing: add the number of env steps to train for "
            f"(e.g. n_timesteps: 2000000), or pass --timesteps"
        )
    for key, value in entry.items():
        if not isinstance(key, str):
            raise HyperparameterError(f"{where}: key {key!r} is not text")
        if key in CONTROLLED_KEYS:
            raise HyperparameterError(
                f"{where}: {key!r} cannot be set in a hyperparameter file: {CONTROLLED_KEYS[key]}"
            )
        if key in RUN_KEYS:
            checked[key] = _check_run_key(algo, key, value, where)
        elif key == "policy_kwargs":
            checked[key] = _check_policy_kwargs(value, cls.policy_aliases[policy], where)
        elif key in parameters:
            checked[key] = _check_algorithm_key(algo, key, value, parameters, where)
        else:
            raise _unknown_key(key, accepted, where, f"{algo} (with {program('train')})")
        _check_range(key, checked[key], where)
    return checked


def _check_run_key(algo: str, key: str, value: Any, where: str) -> Any:
    """One of :data:`RUN_KEYS` (what agents.train itself reads, not the algorithm) checked and converted."""
    if key in ("n_timesteps", "n_envs"):
        return _check_value(key, value, int, where)
    if key == "policy":
        return value  # validate_hyperparameters checked it against the algorithm's policies
    if key == "normalize":
        return _check_normalize(value, where)
    if key == "env_kwargs":
        return _check_value(key, value, dict | None, where)
    if key == "curriculum":
        return _check_curriculum(value, where)
    if key == "action_noise_std":
        if algo == "ppo":
            raise HyperparameterError(
                f"{where}: 'action_noise_std' is for sac and td3; PPO explores with "
                "its own policy noise (policy_kwargs.log_std_init)"
            )
        return _check_value(key, value, float, where)
    if key == "residual_on":
        try:
            return check_residual_on(value, f"{where}: 'residual_on'")
        except ValueError as error:
            raise HyperparameterError(str(error)) from None
    if key == "multiagent":
        return _check_multiagent(value, where)
    if key == "critic_warmup":
        return _check_value(key, value, int, where)
    raise AssertionError(f"RUN_KEYS has {key!r}, which _check_run_key does not handle")


def _check_multiagent(value: Any, where: str) -> dict[str, Any]:
    """A ``multiagent`` entry: a mapping of multi-agent options (:data:`MULTIAGENT_KEYS`; their
    values are checked when the env is built), possibly empty (the defaults)."""
    if value is None:
        value = {}
    if not isinstance(value, dict):
        raise HyperparameterError(
            f"{where}: 'multiagent' must be a mapping of multi-agent options ({', '.join(MULTIAGENT_KEYS)}), "
            f"e.g. {{}} for the defaults; got {value!r}"
        )
    for key in value:
        if key not in MULTIAGENT_KEYS:
            raise _unknown_key(str(key), list(MULTIAGENT_KEYS), f"{where}, 'multiagent'", "multi-agent option")
    return dict(value)


def _check_algorithm_key(
    algo: str, key: str, value: Any, parameters: Mapping[str, inspect.Parameter], where: str
) -> Any:
    """A constructor argument of ``algo`` (``parameters``: its keyword parameters) checked against
    its annotation, or a learning-rate style schedule (see :func:`_schedule`)."""
    if key in SCHEDULE_KEYS:
        if value is None and key == "clip_range_vf":
            return None
        _schedule(value, key, where)
        return value
    if key in ("ent_coef", "target_entropy") and isinstance(value, str) and algo == "sac":
        if not (value == "auto" or key == "ent_coef" and value.startswith("auto_") and _is_number(value[5:])):
            raise HyperparameterError(
                f"{where}: {key!r} must be a number or 'auto'"
                f"{' or auto_<number>' if key == 'ent_coef' else ''}; got {value!r}"
            )
        return value
    return _check_value(key, value, parameters[key].annotation, where)


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def _check_normalize(value: Any, where: str) -> bool | dict[str, Any]:
    if isinstance(value, bool):
        return value
    if not isinstance(value, dict):
        raise HyperparameterError(
            f"{where}: 'normalize' must be true, false or a mapping of VecNormalize options; got {value!r}"
        )
    parameters = {name: p for name, p in _keyword_parameters(VecNormalize).items() if name not in ("venv", "training")}
    checked = {}
    for key, option in value.items():
        if key not in parameters:
            raise _unknown_key(str(key), list(parameters), f"{where}: normalize", "VecNormalize")
        checked[key] = _check_value(f"normalize.{key}", option, parameters[key].annotation, where)
        if key in ("clip_obs", "clip_reward", "epsilon") and not checked[key] > 0:
            raise HyperparameterError(f"{where}: 'normalize.{key}' must be positive; got {option!r}")
        _check_range(key, checked[key], f"{where}: normalize")
    return checked


def _check_curriculum(value: Any, where: str) -> dict[str, float] | None:
    if value is None or value is False:
        return None
    if not isinstance(value, dict) or set(value) != {"start", "fraction"}:
        raise HyperparameterError(
            f"{where}: 'curriculum' must be a mapping with exactly 'start' and 'fraction'; got {value!r}"
        )
    checked = {key: _check_value(f"curriculum.{key}", value[key], float, where) for key in ("start", "fraction")}
    if not (0.0 <= checked["start"] <= 1.0 and 0.0 < checked["fraction"] <= 1.0):
        raise HyperparameterError(f"{where}: 'curriculum' needs start in [0, 1] and fraction in (0, 1]; got {value}")
    return checked


def _check_net_arch(value: Any, where: str) -> Any:
    def layers(sizes: Any, label: str) -> list[int]:
        if not isinstance(sizes, list) or not all(
            isinstance(n, int) and not isinstance(n, bool) and n > 0 for n in sizes
        ):
            raise HyperparameterError(f"{where}: {label!r} must be a list of positive layer sizes; got {sizes!r}")
        return sizes

    if isinstance(value, dict):
        return {key: layers(sizes, f"policy_kwargs.net_arch.{key}") for key, sizes in value.items()}
    return layers(value, "policy_kwargs.net_arch")


def _check_policy_kwargs(value: Any, policy_class: type, where: str) -> dict[str, Any]:
    if value is None:
        return {}
    if not isinstance(value, dict):
        raise HyperparameterError(f"{where}: 'policy_kwargs' must be a mapping; got {value!r}")
    parameters = {
        name: p
        for name, p in _keyword_parameters(policy_class).items()
        if name not in ("observation_space", "action_space", "lr_schedule")
    }
    checked = {}
    for key, option in value.items():
        label = f"policy_kwargs.{key}"
        if key not in parameters:
            raise _unknown_key(str(key), list(parameters), f"{where}: policy_kwargs", policy_class.__name__)
        if key in CLASS_KWARGS:
            if option not in CLASS_KWARGS[key]:
                raise HyperparameterError(
                    f"{where}: {label!r} must be one of {sorted(CLASS_KWARGS[key])}; got {option!r}"
                )
            checked[key] = option
        elif key == "net_arch":
            checked[key] = _check_net_arch(option, where)
        else:
            checked[key] = _check_value(label, option, parameters[key].annotation, where)
    return checked


def _schedule(value: Any, name: str, where: str = "hyperparameters") -> float | Callable[[float], float]:
    """A positive number, or "lin_<number>": linear decay from that number to 0 over training."""
    if isinstance(value, str):
        if not (value.startswith("lin_") and _is_number(value[4:]) and float(value[4:]) > 0):
            raise HyperparameterError(
                f"{where}: {name!r} must be a positive number or 'lin_<number>' "
                f"(linear decay to 0); got {value!r}{_number_text_hint(value)}"
            )
        start = float(value[4:])
        return lambda progress_remaining: progress_remaining * start
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not value > 0:
        raise HyperparameterError(f"{where}: {name!r} must be a positive number or 'lin_<number>'; got {value!r}")
    return float(value)


def _algorithm_kwargs(hyperparams: Mapping[str, Any]) -> dict[str, Any]:
    """Constructor keyword arguments from a checked hyperparameter entry: schedules and
    policy_kwargs' class names turned into Python objects."""
    kwargs = {key: value for key, value in hyperparams.items() if key not in RUN_KEYS}
    for key in SCHEDULE_KEYS:
        if kwargs.get(key) is not None:
            kwargs[key] = _schedule(kwargs[key], key)
    policy_kwargs = dict(kwargs.get("policy_kwargs") or {})
    for key, table in CLASS_KWARGS.items():
        if key in policy_kwargs:
            policy_kwargs[key] = table[policy_kwargs[key]]
    if policy_kwargs:
        kwargs["policy_kwargs"] = policy_kwargs
    return kwargs


def _action_noise(hyperparams: Mapping[str, Any], venv: VecEnv) -> dict[str, Any]:
    """``action_noise`` for SAC/TD3 from ``action_noise_std`` (Gaussian, that std in the [-1, 1]
    action units, the same on every action component), or nothing."""
    std = hyperparams.get("action_noise_std")
    if not std:
        return {}
    from stable_baselines3.common.noise import NormalActionNoise

    size = int(np.prod(venv.action_space.shape))
    return {"action_noise": NormalActionNoise(np.zeros(size), np.full(size, float(std)))}


def start_at_the_baseline(model: BaseAlgorithm) -> None:
    """Zero the last layer of ``model``'s actor, so that a residual policy's deterministic action
    is exactly 0 at the start of training: the closed loop starts as the baseline's. (SB3 already
    scales PPO's last layer by 0.01, but SAC and TD3 start with full-size random outputs, a
    random residual thrust of about a third of full thrust.)"""
    import torch

    if hasattr(model.policy, "action_net"):  # PPO
        layers = [model.policy.action_net]
    else:  # SAC (a Linear mu) or TD3 (mu ending in Linear, Tanh)
        mu = model.actor.mu
        layers = [mu if isinstance(mu, torch.nn.Linear) else [m for m in mu if isinstance(m, torch.nn.Linear)][-1]]
    with torch.no_grad():
        for layer in layers:
            layer.weight.zero_()
            layer.bias.zero_()
    if getattr(model, "actor_target", None) is not None:
        model.actor_target.load_state_dict(model.actor.state_dict())


def make_training_env(
    env_id: str,
    num_envs: int,
    seed: int,
    normalize: Any,
    env_kwargs: Mapping[str, Any] | None = None,
    training: bool = True,
    residual_on: str | None = None,
    multiagent: Mapping[str, Any] | None = None,
) -> VecEnv:
    """The native vector env of ``env_id`` through the SB3 adapter, with ``VecMonitor`` and, if
    ``normalize`` is truthy (a bool or ``VecNormalize`` keyword arguments), ``VecNormalize``;
    with ``residual_on`` (a baseline's name) the actions are corrections to that baseline's
    (:class:`agents.residual.ResidualVecEnv`); with ``multiagent`` (the multi-agent options) it
    is ``num_envs`` clusters x their agents, one row per agent, for a shared decentralised policy
    (:class:`tether_gym.multiagent.sb3.AgentVecEnv`)."""
    base: VecEnv
    if multiagent is not None:
        from tether_gym.multiagent.sb3 import make_agent_vec_env

        base = make_agent_vec_env(env_id, num_envs, seed=seed, **dict(env_kwargs or {}), **dict(multiagent))
    else:
        base = make_sb3_vec_env(env_id, num_envs, seed=seed, **dict(env_kwargs or {}))
    if residual_on is not None:
        base = ResidualVecEnv(base, residual_on)
    venv: VecEnv = VecMonitor(base)
    if normalize:
        options = dict(normalize) if isinstance(normalize, Mapping) else {}
        if not training:
            options.update(training=False, norm_reward=False)
        venv = VecNormalize(venv, **options)
    return venv


# ---------------------------------------------------------------------------------------------
# Callbacks
# ---------------------------------------------------------------------------------------------


def actor_parameters(model: BaseAlgorithm) -> list[Any]:
    """The parameters of ``model``'s actor alone (torch tensors): PPO's policy branch, action
    head and log-std; SAC's and TD3's actor network. Shared layers (a shared feature extractor
    with parameters, shared hidden layers) are left out: they serve the critic too."""
    import torch

    policy = model.policy
    if hasattr(policy, "action_net"):  # PPO's ActorCriticPolicy
        log_std = getattr(policy, "log_std", None)
        extra = [log_std] if isinstance(log_std, torch.nn.Parameter) else []
        modules = [policy.mlp_extractor.policy_net, policy.action_net]
        return [p for module in modules for p in module.parameters()] + extra
    return list(model.actor.parameters())


class CriticWarmup(BaseCallback):
    """Freezes the actor for the first ``steps`` env steps, so that only the critic (PPO's value
    function, SAC's and TD3's Q networks) learns, then releases it.

    Why: a residual policy starts exactly at its baseline (:func:`start_at_the_baseline`), and a
    critic that has learned nothing yet gives it random gradients. Updating the actor from the
    first batch moves it away from a strong baseline before the critic can say which way is up
    (a TD3 residual on LQR fell 46 below LQR in 20 000 steps, ``docs/benchmark.md``). Residual
    policy learning (Silver et al., 2018, arXiv:1812.06298) trains the critic alone for a
    burn-in period for this reason.

    The freeze is ``requires_grad = False`` on :func:`actor_parameters`: their gradients stay
    ``None``, which the optimisers skip, so the actor's weights, its Adam state and (for TD3) its
    target network stay exactly as they were. It is applied before every update (at the end of
    each rollout) and logged as ``train/actor_frozen``.
    """

    def __init__(self, steps: int) -> None:
        super().__init__()
        if steps < 0:
            raise ValueError(f"critic_warmup must be >= 0 env steps; got {steps!r}")
        self.steps = int(steps)
        self.frozen: bool | None = None

    def _on_training_start(self) -> None:
        self._update()

    def _on_rollout_end(self) -> None:
        self._update()

    def _on_step(self) -> bool:
        return True

    def _update(self) -> None:
        frozen = self.num_timesteps < self.steps
        if frozen != self.frozen:
            for parameter in actor_parameters(self.model):
                parameter.requires_grad_(not frozen)
            self.frozen = frozen
        self.logger.record("train/actor_frozen", float(frozen))


class SafePolicySaver(BaseCallback):
    """Saves the model, the training env's ``VecNormalize`` statistics and the optimizer state in
    the safe format: into ``directory`` on every call (as EvalCallback's ``callback_on_new_best``),
    or, with ``every`` steps, into ``directory/<prefix>_<timesteps>_steps/`` every ``every``
    calls (checkpoints)."""

    def __init__(
        self,
        directory: Path,
        env_id: str,
        provenance: Mapping[str, Any],
        every: int | None = None,
        prefix: str = "",
        residual_on: str | None = None,
        training_state: bool = True,
        multiagent: Mapping[str, Any] | None = None,
    ) -> None:
        super().__init__()
        self.directory, self.env_id, self.provenance = directory, env_id, dict(provenance)
        self.every, self.prefix, self.residual_on = every, prefix, residual_on
        #: Whether to save the optimizer state (False where the model only carries the weights).
        self.training_state = training_state
        self.multiagent = multiagent

    def _on_step(self) -> bool:
        if self.every is None:
            self._save(self.directory)
        elif self.n_calls % self.every == 0:
            self._save(self.directory / f"{self.prefix}_{self.num_timesteps}_steps")
        return True

    def _save(self, directory: Path) -> None:
        save_policy(
            directory,
            self.model,
            self.model.get_vec_normalize_env(),
            self.env_id,
            self.provenance,
            training_state=self.training_state,
            residual_on=self.residual_on,
            multiagent=self.multiagent,
        )


class DifficultyCurriculum(BaseCallback):
    """Raises the training env's difficulty linearly from ``start`` to 1 over the first
    ``fraction`` of ``total`` timesteps (``env_method("set_difficulty", d)``, which takes effect at
    each sub-env's next reset), and logs it as ``curriculum/difficulty``.

    Args:
        start: difficulty at timestep 0, in [0, 1].
        fraction: fraction of the run over which it reaches 1, in (0, 1].
        total: the run's total timesteps.
    """

    def __init__(self, start: float, fraction: float, total: int) -> None:
        super().__init__()
        if not (0.0 <= start <= 1.0 and 0.0 < fraction <= 1.0 and total > 0):
            raise ValueError(
                f"curriculum needs start in [0, 1] and fraction in (0, 1]; got start={start!r}, fraction={fraction!r}"
            )
        self.start, self.fraction, self.total = float(start), float(fraction), int(total)
        self.difficulty = -1.0

    def difficulty_at(self, timesteps: int) -> float:
        """The scheduled difficulty after ``timesteps`` env steps."""
        progress = min(1.0, timesteps / (self.fraction * self.total))
        return self.start + (1.0 - self.start) * progress

    def _on_training_start(self) -> None:
        self._update()

    def _on_step(self) -> bool:
        self._update()
        return True

    def _update(self) -> None:
        target = self.difficulty_at(self.num_timesteps)
        if abs(target - self.difficulty) >= 0.01 or (target == 1.0 and self.difficulty != 1.0):
            self.training_env.env_method("set_difficulty", target)
            self.difficulty = target
            self.logger.record("curriculum/difficulty", target)


# ---------------------------------------------------------------------------------------------
# The run directory
# ---------------------------------------------------------------------------------------------


def _earlier_run_files(run: Path) -> list[str]:
    """What an earlier run left in ``run`` (relative names), empty for a new run directory."""
    found = [name for name in ("config.yml", METADATA_FILE, *LEGACY_RUN_FILES) if (run / name).exists()]
    for sub in ("best", "checkpoints"):
        if (run / sub).is_dir() and any((run / sub).iterdir()):
            found.append(f"{sub}/")
    return found


def _prepare_run_dir(out: str | Path, env_id: str, algo: str, seed: int, force: bool) -> Path:
    """The run directory ``out/env_id/algo_seed<seed>`` (``algo`` may carry a suffix, e.g.
    ``ppo_multiagent``), checked before any work: usable, no symlinks in it, and no earlier run
    unless ``force``."""
    out = Path(out)
    if out.is_symlink():
        raise OutputError(f"--out {out} is a symlink; refusing to write through it: pass the real directory")
    run = prepare_output_dir(out / env_id / f"{algo}_seed{seed}", argument="--out")
    check_no_symlinks_inside(run)
    earlier = _earlier_run_files(run)
    if earlier and not force:
        raise OutputExistsError(
            f"{run} already holds a run ({', '.join(earlier)}) with the same --out, env, algorithm and seed: pass "
            f"--force to replace it (its models, best/ and checkpoints/ are deleted; TensorBoard logs are kept), "
            f"or choose another --seed or --out"
        )
    return run


def _clear_earlier_run(run: Path, algo: str, keep: set[Path]) -> None:
    """Delete what an earlier run wrote (models, best/, checkpoints/), except the paths in
    ``keep`` (the checkpoint being resumed). TensorBoard logs stay: SB3 numbers each run's
    subdirectory, so they do not mix."""
    keep = {path.resolve() for path in keep}

    def remove(path: Path) -> None:
        if path.resolve() in keep or not (path.exists() or path.is_symlink()):
            return
        if path.is_dir() and not path.is_symlink():
            shutil.rmtree(path)
        else:
            path.unlink()

    if run.resolve() not in keep:
        for name in (*POLICY_FILES, *LEGACY_RUN_FILES):
            remove(run / name)
    best = run / "best"
    if best.is_dir() and best.resolve() not in keep:
        for name in (*POLICY_FILES, EVALUATIONS_FILE, *LEGACY_BEST_FILES):
            remove(best / name)
    checkpoints = run / "checkpoints"
    if checkpoints.is_dir():
        for entry in checkpoints.iterdir():
            ours = (entry.is_dir() and (entry / METADATA_FILE).is_file()) or (
                entry.suffix in (".zip", ".pkl") and entry.name.startswith(f"{algo}_")
            )
            if ours:
                remove(entry)


def _resume_source(resume: str | Path, trust_pickle: bool, algo: str, env_id: str) -> tuple[str, Path, set[Path]]:
    """What ``--resume`` names: ``("safe", policy directory, paths)`` or ``("pickle", model .zip,
    paths)``, checked before any work: PickleNotTrustedError for a pickle without the opt-in,
    PolicyFormatError for a safe checkpoint of another algorithm or env, or without training state."""
    path = Path(resume)
    if not path.exists():
        raise FileNotFoundError(
            f"--resume {path} does not exist: pass a checkpoint directory "
            f"(<run>/checkpoints/<algo>_<steps>_steps), <run>/best or a run directory"
        )
    if is_policy_dir(path):
        metadata = read_metadata(path)
        if metadata["algo"] != algo:
            raise PolicyFormatError(
                f"--resume {path} is a {metadata['algo']} checkpoint; resume it with --algo "
                f"{metadata['algo']} (not {algo})"
            )
        if metadata["env_id"] != env_id:
            raise PolicyFormatError(
                f"--resume {path} was trained on {metadata['env_id']}; resume it with --env "
                f"{metadata['env_id']} (not {env_id})"
            )
        if not metadata["training_state"]:
            raise PolicyFormatError(
                f"--resume {path} holds a policy for inference only (no optimizer state): resume from a checkpoint "
                f"that {program('train')} wrote (<run>/checkpoints/<algo>_<steps>_steps, <run>/best or the run "
                "directory)"
            )
        return "safe", path, {path}
    if is_pickle_model(path):
        if not trust_pickle:
            refuse_untrusted(path, opt_in="--trust-pickle")
        model_file = sb3_model_file(path)
        statistics = normalization_file_of(model_file)
        return "pickle", model_file, {model_file} | ({statistics} if statistics else set())
    raise FileNotFoundError(
        f"--resume {path} holds no checkpoint: pass a directory with {METADATA_FILE} "
        f"(or, with --trust-pickle, an SB3 .zip)"
    )


def _positive_int(name: str, value: Any, minimum: int = 1) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or value < minimum:
        raise ValueError(f"{name} must be an integer >= {minimum}; got {value!r}")
    return value


# ---------------------------------------------------------------------------------------------
# Training
# ---------------------------------------------------------------------------------------------


def train(
    algo: str = "ppo",
    env_id: str = DEFAULT_ENV_ID,
    seed: int = 0,
    out: str | Path = "runs",
    timesteps: int | None = None,
    num_envs: int | None = None,
    hyperparams_file: str | Path | None = None,
    overrides: Mapping[str, Any] | None = None,
    resume: str | Path | None = None,
    eval_freq: int = 50_000,
    eval_episodes: int = 32,
    checkpoint_freq: int = 250_000,
    progress_bar: bool = True,
    verbose: int = 0,
    command: str | None = None,
    force: bool = False,
    trust_pickle: bool = False,
) -> Path:
    """Train ``algo`` on ``env_id`` and return the run directory (see the module docstring).

    ``timesteps`` and ``num_envs`` override the file's ``n_timesteps``/``n_envs`` (the steps are
    rounded up to whole rollouts, see :func:`rollout_steps`); ``overrides``
    replaces any other entries (and is checked like the file). ``eval_freq`` and
    ``checkpoint_freq`` count total env steps (over all envs). ``command`` is recorded in
    ``config.yml`` (the command line, when run as ``python -m agents.train``). ``force``
    replaces an earlier run in the same run directory; ``trust_pickle`` allows ``resume`` to be
    a pickle-based SB3 ``.zip``.

    Every argument, the hyperparameters, the resume source and the run directory are checked
    before any env is built: errors name the argument or key and the fix."""
    started = time.perf_counter()
    if algo not in ALGORITHMS:
        raise ValueError(f"unknown algorithm {algo!r}; choose one of {sorted(ALGORITHMS)}")
    if env_id not in ENV_IDS:
        raise ValueError(f"unknown env id {env_id!r}; tether-gym ids are {list(ENV_IDS)}")
    _positive_int("seed", seed, minimum=0)
    _positive_int("eval_freq", eval_freq)
    _positive_int("eval_episodes", eval_episodes)
    _positive_int("checkpoint_freq", checkpoint_freq)
    _positive_int("verbose", verbose, minimum=0)
    # SB3 finds these missing only when training starts, and then names its own extra, not ours.
    require("tensorboard", "train", "the training's TensorBoard logs")
    if progress_bar:
        for module in ("tqdm", "rich"):
            require(module, "train", "the progress bar (or pass --no-progress)")
    hyperparams = load_hyperparameters(algo, env_id, hyperparams_file)
    hyperparams.update(overrides or {})
    if timesteps is not None:
        hyperparams["n_timesteps"] = _positive_int("timesteps", timesteps)
    if num_envs is not None:
        hyperparams["n_envs"] = _positive_int("num_envs", num_envs)
    hyperparams = validate_hyperparameters(algo, hyperparams, where="hyperparameters (with overrides)")
    n_envs = int(hyperparams.get("n_envs", 1))
    total = int(hyperparams["n_timesteps"])
    resume_kind, resume_path, keep = (
        _resume_source(resume, trust_pickle, algo, env_id) if resume is not None else (None, None, set())
    )
    multiagent = hyperparams.get("multiagent")
    if multiagent is not None and hyperparams.get("residual_on") is not None:
        raise HyperparameterError("'multiagent' and 'residual_on' do not combine: a residual policy is centralised")
    from .ship import model_name

    run = _prepare_run_dir(out, env_id, model_name({"algo": algo, "multiagent": multiagent}), seed, force)

    record = {
        "algo": algo,
        "env_id": env_id,
        "seed": seed,
        "hyperparams": hyperparams,
        "command": command,
        "resumed_from": str(resume_path) if resume_path else None,
        "tether_gym_version": tether_gym.__version__,
    }
    normalize = hyperparams.get("normalize", False)
    env_kwargs = hyperparams.get("env_kwargs")
    residual_on = hyperparams.get("residual_on")
    venv = make_training_env(
        env_id, n_envs, seed, normalize, env_kwargs, residual_on=residual_on, multiagent=multiagent
    )
    # The vector env's rows: n_envs, or n_envs clusters x their agents (timesteps count rows).
    rows = venv.num_envs
    cls = ALGORITHMS[algo]
    model = _build_model(cls, hyperparams, venv, seed, verbose, run, resume_kind, resume_path)
    venv = model.get_env()  # a pickle resume wraps the statistics it loaded around the env
    total = _whole_rollouts(model, total, "--timesteps" if timesteps is not None else "n_timesteps")
    hyperparams["n_timesteps"] = total  # config.yml records what runs, and reproduces it
    if force:
        _clear_earlier_run(run, algo, keep)
    atomic_write_text(run / "config.yml", yaml.safe_dump(record, sort_keys=False))
    provenance = {"seed": seed, "command": command, "config": "config.yml of the run directory"}
    callback_items: list[BaseCallback] = [
        SafePolicySaver(
            run / "checkpoints",
            env_id,
            provenance,
            every=max(checkpoint_freq // rows, 1),
            prefix=algo,
            residual_on=residual_on,
            multiagent=multiagent,
        ),
    ]
    evaluation = SeededEvaluation(
        env_id,
        eval_episodes,
        every=eval_freq // rows,
        log_dir=run / "best",
        on_new_best=SafePolicySaver(run / "best", env_id, provenance, residual_on=residual_on, multiagent=multiagent),
        started=started,
        env_kwargs=env_kwargs,
        residual_on=residual_on,
        multiagent=multiagent,
        verbose=1 if progress_bar or verbose else 0,
    )
    callback_items.append(evaluation)
    if hyperparams.get("critic_warmup"):
        callback_items.append(CriticWarmup(hyperparams["critic_warmup"]))
    curriculum = hyperparams.get("curriculum")
    if curriculum:
        callback_items.append(DifficultyCurriculum(curriculum["start"], curriculum["fraction"], total))
    start = time.perf_counter()
    model.learn(
        total_timesteps=total,
        callback=CallbackList(callback_items),
        progress_bar=progress_bar,
        tb_log_name=algo,
        reset_num_timesteps=resume_kind is None,
    )
    if not evaluation.history:
        # best/ is chosen among evaluations: a run shorter than --eval-freq would leave none.
        print(
            f"no evaluation ran in {total:,} steps (--eval-freq {eval_freq:,}): evaluating the final policy "
            f"for {run / 'best'}",
            flush=True,
        )
        evaluation.num_timesteps = model.num_timesteps
        evaluation.evaluate()
    record["num_timesteps"] = int(model.num_timesteps)  # counted from the start of a resumed run
    atomic_write_text(run / "config.yml", yaml.safe_dump(record, sort_keys=False))
    save_policy(
        run,
        model,
        model.get_vec_normalize_env(),
        env_id,
        provenance,
        training_state=True,
        extra_files=["config.yml"],
        residual_on=residual_on,
        multiagent=multiagent,
    )
    elapsed = time.perf_counter() - start
    evaluation.finish(model.num_timesteps)
    print(
        f"trained {algo} on {env_id} for {model.num_timesteps:,} steps in {elapsed / 60:.1f} min "
        f"({model.num_timesteps / max(elapsed, 1e-9):,.0f} steps/s); run directory {run}"
    )
    print_evaluation_summary(evaluation)
    venv.close()
    return run


def rollout_steps(model: BaseAlgorithm) -> tuple[int, str] | None:
    """The env steps (over all rows of the vector env) that one iteration of ``model.learn``
    collects, and how they come about, for a message; None when it varies (an off-policy
    ``train_freq`` counted in episodes). ``learn`` stops only between iterations, so it trains a
    whole number of them: at least one, whatever ``total_timesteps`` asks."""
    from stable_baselines3.common.on_policy_algorithm import OnPolicyAlgorithm
    from stable_baselines3.common.type_aliases import TrainFrequencyUnit

    if isinstance(model, OnPolicyAlgorithm):
        return model.n_steps * model.n_envs, f"rollouts of n_steps {model.n_steps} x {model.n_envs} envs"
    train_freq = getattr(model, "train_freq", None)
    if train_freq is None or train_freq.unit != TrainFrequencyUnit.STEP:
        return None
    return train_freq.frequency * model.n_envs, f"train_freq {train_freq.frequency} steps x {model.n_envs} envs"


def _whole_rollouts(model: BaseAlgorithm, total: int, source: str) -> int:
    """``total`` env steps rounded up to whole iterations of ``model.learn`` (see
    :func:`rollout_steps`), which is what it would train anyway; says so when it rounds."""
    chunk = rollout_steps(model)
    if chunk is None or total % chunk[0] == 0:
        return total
    rounded = -(-total // chunk[0]) * chunk[0]
    print(
        f"{source} {total:,} rounded up to {rounded:,} env steps: training runs whole {chunk[1]} "
        f"= {chunk[0]:,} steps (give a multiple of {chunk[0]:,} to train exactly that)",
        flush=True,
    )
    return rounded


def print_evaluation_summary(evaluation: SeededEvaluation) -> None:
    """One line: the best evaluation return against the bar, and when training first beat it."""
    if not evaluation.history:
        return
    beat = evaluation.first_beat.get(evaluation.bar)
    print(
        f"best evaluation return {evaluation.best_mean:.2f} against {evaluation.bar} "
        f"{evaluation.baseline_returns[evaluation.bar].mean():.2f} on the evaluation seeds; "
        + (
            f"first beat it at {beat['timesteps']:,} steps, {beat['wall_time_s']:.0f} s after the command started"
            if beat
            else "never beat it"
        )
    )


def _build_model(
    cls: type[BaseAlgorithm],
    hyperparams: Mapping[str, Any],
    venv: VecEnv,
    seed: int,
    verbose: int,
    run: Path,
    resume_kind: str | None,
    resume_path: Path | None,
) -> BaseAlgorithm:
    """A new model, or one resumed from a safe checkpoint directory or (trusted) SB3 ``.zip``."""
    if resume_kind == "pickle":
        assert resume_path is not None
        normalized = isinstance(venv, VecNormalize)
        model, normalizer, _, _ = load_pickled_model(
            resume_path,
            trust_pickle=True,
            algo=_algo_of(cls),
            env=venv.venv if normalized else venv,
            tensorboard_log=str(run / "tensorboard"),
        )
        if normalized != (normalizer is not None):
            raise FileNotFoundError(
                f"--resume {resume_path}: the hyperparameters' 'normalize' is {'on' if normalized else 'off'}, but "
                f"{'no' if normalized else 'a'} VecNormalize statistics file was found next to it"
            )
        if normalizer is not None:
            normalizer.training = True
        return model
    model = cls(
        hyperparams.get("policy", "MlpPolicy"),
        venv,
        seed=seed,
        device="cpu",
        verbose=verbose,
        tensorboard_log=str(run / "tensorboard"),
        **_algorithm_kwargs(hyperparams),
        **_action_noise(hyperparams, venv),
    )
    if hyperparams.get("residual_on") is not None and resume_kind is None:
        start_at_the_baseline(model)
    if resume_kind == "safe":
        assert resume_path is not None
        load_training_state(model, resume_path, venv if isinstance(venv, VecNormalize) else None)
    return model


def _algo_of(cls: type[BaseAlgorithm]) -> str:
    return next(name for name, candidate in ALGORITHMS.items() if candidate is cls)


def build_parser() -> argparse.ArgumentParser:
    """The command line of ``train`` (defined in :mod:`agents.common.cli`, which the console script parses
    with before this module's slow imports)."""
    return cli.build_parser("train")


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


def main(argv: list[str] | None = None) -> Path:
    args = build_parser().parse_args(argv)
    return train(
        algo=args.algo,
        env_id=args.env,
        seed=args.seed,
        out=args.out,
        timesteps=args.timesteps,
        num_envs=args.n_envs,
        hyperparams_file=args.hyperparams
        or (HYPERPARAMS_DIR / f"{args.algo}_multiagent.yml" if args.multiagent else None),
        resume=args.resume,
        eval_freq=args.eval_freq,
        overrides=_overrides(args),
        eval_episodes=args.eval_episodes,
        checkpoint_freq=args.checkpoint_freq,
        progress_bar=not args.no_progress,
        verbose=args.verbose,
        force=args.force,
        trust_pickle=args.trust_pickle,
        command=command_line("train", sys.argv[1:] if argv is None else argv),
    )


if __name__ == "__main__":
    try:
        main()
    except (PickleNotTrustedError, OutputError, PolicyFormatError, HyperparameterError, ValueError, OSError) as error:
        sys.exit(f"{program('train')}: error: {error}")
