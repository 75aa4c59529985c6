"""The hyperparameter files of the SB3 trainers (``agents/hyperparams/<algo>.yml``, rl-zoo style,
plain YAML, nothing evaluated) and their schema: every key of an entry checked against the
algorithm's constructor (its annotations), the run keys that the trainer reads itself
(:data:`RUN_KEYS`), and the ranges SB3 would otherwise reject deep inside. Errors are
:class:`HyperparameterError` and name the file, the entry and the key.

The other trainers (:mod:`agents.training.rllib`) check their own files with the same value checks
(:func:`check_value`, :func:`check_multiagent`, :func:`schedule`, :func:`unknown_key_error`)."""

from __future__ import annotations

import difflib
import inspect
import types
import typing
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from tether_gym._optional import needs_extra

from ..common.checks import MAX_NUM_ENVS, is_count
from ..common.commands import program
from ..common.data import HYPERPARAMS_DIR
from ..common.reading import read_yaml
from ..controllers.residual import check_residual_on
from ..policies.codecs import CLASS_KWARGS
from ..policies.format import ALGORITHMS

with needs_extra("train", "training"):
    from stable_baselines3.common.vec_env import VecNormalize

__all__ = [
    "CONTROLLED_KEYS",
    "MULTIAGENT_KEYS",
    "RUN_CONFIG_KEYS",
    "RUN_KEYS",
    "SCHEDULE_KEYS",
    "HyperparameterError",
    "check_multiagent",
    "check_value",
    "load_hyperparameters",
    "read_hyperparameter_entry",
    "schedule",
    "unknown_key_error",
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


class HyperparameterError(ValueError):
    """A hyperparameter file or entry that cannot be trained with; the message names the key."""


#: The keys by which a run's ``config.yml`` is told from a hyperparameter file.
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
    table = read_yaml(file, HyperparameterError)
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


def check_value(key: str, value: Any, annotation: Any, where: str) -> Any:
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


def unknown_key_error(key: str, known: list[str], where: str, what: str) -> HyperparameterError:
    """The error for an unknown ``key`` (to be raised): it names ``where`` and what ``what`` accepts
    (``known``), and suggests the closest known key, if one is close."""
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
            raise unknown_key_error(key, accepted, where, f"{algo} (with {program('train')})")
        _check_range(key, checked[key], where)
    return checked


def _check_run_key(algo: str, key: str, value: Any, where: str) -> Any:
    """One of :data:`RUN_KEYS` (what agents.train itself reads, not the algorithm) checked and converted."""
    if key in ("n_timesteps", "n_envs"):
        checked = check_value(key, value, int, where)
        # The envs are one vector env: tether_gym refuses more than MAX_NUM_ENVS, after the run began.
        high = MAX_NUM_ENVS if key == "n_envs" else None
        if checked < 1 or (high is not None and checked > high):
            bound = f"in 1..{high}" if high is not None else ">= 1"
            raise HyperparameterError(f"{where}: '{key}' must be {bound}; got {checked}")
        return checked
    if key == "policy":
        return value  # validate_hyperparameters checked it against the algorithm's policies
    if key == "normalize":
        return _check_normalize(value, where)
    if key == "env_kwargs":
        return check_value(key, value, dict | None, where)
    if key == "curriculum":
        return _check_curriculum(value, where)
    if key == "action_noise_std":
        if algo == "ppo":
            raise HyperparameterError(
                f"{where}: 'action_noise_std' is for sac and td3; PPO explores with "
                "its own policy noise (policy_kwargs.log_std_init)"
            )
        return check_value(key, value, float, where)
    if key == "residual_on":
        try:
            return check_residual_on(value, f"{where}: 'residual_on'")
        except ValueError as error:
            raise HyperparameterError(str(error)) from None
    if key == "multiagent":
        return check_multiagent(value, where)
    if key == "critic_warmup":
        return check_value(key, value, int, where)
    raise AssertionError(f"RUN_KEYS has {key!r}, which _check_run_key does not handle")


def check_multiagent(value: Any, where: str) -> dict[str, Any]:
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
            raise unknown_key_error(str(key), list(MULTIAGENT_KEYS), f"{where}, 'multiagent'", "multi-agent option")
    return dict(value)


def _check_algorithm_key(
    algo: str, key: str, value: Any, parameters: Mapping[str, inspect.Parameter], where: str
) -> Any:
    """A constructor argument of ``algo`` (``parameters``: its keyword parameters) checked against
    its annotation, or a learning-rate style schedule (see :func:`schedule`)."""
    if key in SCHEDULE_KEYS:
        if value is None and key == "clip_range_vf":
            return None
        schedule(value, key, where)
        return value
    if key in ("ent_coef", "target_entropy") and isinstance(value, str) and algo == "sac":
        if not (value == "auto" or key == "ent_coef" and value.startswith("auto_") and _is_number(value[5:])):
            raise HyperparameterError(
                f"{where}: {key!r} must be a number or 'auto'"
                f"{' or auto_<number>' if key == 'ent_coef' else ''}; got {value!r}"
            )
        return value
    return check_value(key, value, parameters[key].annotation, where)


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
            raise unknown_key_error(str(key), list(parameters), f"{where}: normalize", "VecNormalize")
        checked[key] = check_value(f"normalize.{key}", option, parameters[key].annotation, where)
        if key in ("clip_obs", "clip_reward", "epsilon") and not checked[key] > 0:
            raise HyperparameterError(f"{where}: 'normalize.{key}' must be positive; got {option!r}")
        _check_range(key, checked[key], f"{where}: normalize")
    # The policy format stores the observation statistics (normalization.json); VecNormalize keeps
    # none without norm_obs, so such a run was refused only when its first checkpoint was saved.
    if checked.get("norm_obs", True) is not True:
        raise HyperparameterError(
            f"{where}: 'normalize.norm_obs' must be true (a normalised run keeps observation statistics): "
            "to train on raw observations, set normalize: false"
        )
    return checked


def _check_curriculum(value: Any, where: str) -> dict[str, float] | None:
    if value is None or value is False:
        return None
    if not isinstance(value, dict) or set(value) != {"start", "fraction"}:
        raise HyperparameterError(
            f"{where}: 'curriculum' must be a mapping with exactly 'start' and 'fraction'; got {value!r}"
        )
    checked = {key: check_value(f"curriculum.{key}", value[key], float, where) for key in ("start", "fraction")}
    if not (0.0 <= checked["start"] <= 1.0 and 0.0 < checked["fraction"] <= 1.0):
        raise HyperparameterError(f"{where}: 'curriculum' needs start in [0, 1] and fraction in (0, 1]; got {value}")
    return checked


def _check_net_arch(value: Any, where: str) -> Any:
    def layers(sizes: Any, label: str) -> list[int]:
        if not isinstance(sizes, list) or not all(is_count(n) for n in sizes):
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
            raise unknown_key_error(str(key), list(parameters), f"{where}: policy_kwargs", policy_class.__name__)
        if key in CLASS_KWARGS:
            if option not in CLASS_KWARGS[key]:
                raise HyperparameterError(
                    f"{where}: {label!r} must be one of {sorted(CLASS_KWARGS[key])}; got {option!r}"
                )
            checked[key] = option
        elif key == "net_arch":
            checked[key] = _check_net_arch(option, where)
        else:
            checked[key] = check_value(label, option, parameters[key].annotation, where)
    return checked


def schedule(value: Any, name: str, where: str = "hyperparameters") -> float | Callable[[float], float]:
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
