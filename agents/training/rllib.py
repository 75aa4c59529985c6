"""Training PPO on Ray RLlib: the library part of ``python -m agents.train_rllib``
(:func:`train_rllib`, configured by :class:`RLlibConfig`; the command's docstring describes the run
directory it writes and the multi-agent run).

The module holds, in the order a run needs them: the hyperparameter files' schema
(:func:`load_rllib_hyperparameters`, checked with the SB3 trainer's value checks of
:mod:`.hyperparams`), joining or starting Ray (:func:`connect`), the algorithm's configuration
(:func:`build_config`), the export of RLlib's module to the project's policy format
(:func:`export_policy`), and the training loop with its evaluations and checkpoints.

Ray is imported only inside the functions that need it, so that this module (and the command's
``--help``) imports without the ``rllib`` extra; :class:`RayUnavailableError` says how to install it.

The policy format is SB3's ``MlpPolicy``: RLlib's default PPO module with separate policy and value
networks, no head layers and a free log std has the same structure, and its weights are mapped
onto it (:func:`export_policy`); RLlib's ``MeanStdFilter`` statistics become the normalisation
statistics, so the exported policy's deterministic actions are the RLlib module's.
"""

from __future__ import annotations

import dataclasses
import socket
import time
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

import tether_gym
from tether_gym._optional import needs_extra
from tether_gym.envs.arguments import MAX_NUM_ENVS
from tether_gym.registration import DEFAULT_ENV_ID, ENV_IDS

from ..common.checks import MAX_TRAINING_SEED, check_int, is_count
from ..common.cli import RLLIB_ALGO as ALGO  # the run directory's prefix and config.yml's algo
from ..common.commands import program
from ..common.data import HYPERPARAMS_DIR
from ..common.files import atomic_write_text, holds_output_claims
from ..policies.layout import PolicyFormatError
from ..policies.pickled import PickleNotTrustedError
from ..policies.spec import PolicySpec
from .hyperparams import (
    HyperparameterError,
    check_multiagent,
    check_value,
    read_hyperparameter_entry,
    schedule,
    unknown_key_error,
)
from .runs import clear_earlier_run, prepare_run_dir
from .selection import print_evaluation_summary

with needs_extra("rllib", "training on RLlib"):
    import yaml

__all__ = [
    "ACTIVATIONS",
    "ALGO",
    "CHECKPOINT_MARKER",
    "CONNECT_TIMEOUT_S",
    "KEYS",
    "MULTIAGENT_ENV_NAME",
    "SHARED_MODULE_ID",
    "RLlibConfig",
    "RayUnavailableError",
    "build_config",
    "connect",
    "export_policy",
    "lifetime_steps",
    "load_rllib_hyperparameters",
    "make_multiagent_env",
    "make_vessel",
    "module_weights",
    "observation_filter",
    "resolve_hyperparameters",
    "rllib_actions",
    "train_rllib",
    "validate_rllib_hyperparameters",
]

#: RLlib's checkpoints mark themselves with this file.
CHECKPOINT_MARKER = "rllib_checkpoint.json"
#: Seconds to wait for a cluster's head node to answer on ``--address`` before giving up.
CONNECT_TIMEOUT_S = 5.0

#: Hyperparameter keys and their types (the values are checked as the SB3 trainer checks its own, :mod:`.hyperparams`).
KEYS: dict[str, Any] = {
    "n_timesteps": int,
    "num_envs_per_env_runner": int,
    "train_batch_size_per_learner": int,
    "minibatch_size": int,
    "num_epochs": int,
    "gamma": float,
    "lambda": float,
    "lr": float | str,
    "clip_param": float,
    "vf_clip_param": float,
    "vf_loss_coeff": float,
    "entropy_coeff": float,
    "use_kl_loss": bool,
    "grad_clip": float | None,
    "fcnet_hiddens": list,
    "fcnet_activation": str,
    "normalize_obs": bool,
    "env_kwargs": dict | None,
    "multiagent": dict | None,
}
#: The id of the one module every agent of a multi-agent run maps to.
SHARED_MODULE_ID = "shared"
#: The name under which the multi-agent env is registered with Ray (:func:`make_multiagent_env`).
MULTIAGENT_ENV_NAME = "tether_gym_multiagent"
#: RLlib's activation names that SB3's ``MlpPolicy`` (the export format) has too.
ACTIVATIONS = ("tanh", "relu")
#: Keys in (0, 1].
FRACTIONS = ("gamma", "lambda")


class RayUnavailableError(RuntimeError):
    """Ray is not installed, or the cluster on ``--address`` cannot be reached or cannot run the job."""


def _ray() -> Any:
    """The ``ray`` module, or a :class:`RayUnavailableError` saying how to install it."""
    try:
        import ray
    except ModuleNotFoundError as error:
        raise RayUnavailableError(
            f'{program("train_rllib")} needs Ray RLlib, which is not installed: pip install "tether-gym[rllib]" '
            "(in a checkout: bash scripts/test_rllib.sh, which builds .venv-rllib with it)"
        ) from error
    return ray


# ---------------------------------------------------------------------------------------------
# Hyperparameters
# ---------------------------------------------------------------------------------------------


def load_rllib_hyperparameters(env_id: str, path: str | Path | None = None) -> dict[str, Any]:
    """The checked hyperparameters for ``env_id`` from the package's ``hyperparams/rllib_ppo.yml`` (or
    ``path``: another file of that form, or an RLlib run's ``config.yml``). Raises
    :class:`~agents.training.hyperparams.HyperparameterError` naming the file, entry and key."""
    file = Path(path) if path is not None else HYPERPARAMS_DIR / f"{ALGO}.yml"
    entry, where = read_hyperparameter_entry(file, env_id, ALGO)
    return validate_rllib_hyperparameters(entry, where)


def validate_rllib_hyperparameters(entry: Mapping[str, Any], where: str = "hyperparameters") -> dict[str, Any]:
    """``entry`` checked: known keys, values of the right type and range, ``n_timesteps`` given."""
    checked: dict[str, Any] = {}
    for key, value in entry.items():
        if key not in KEYS:
            raise unknown_key_error(str(key), list(KEYS), where, program("train_rllib"))
        checked[key] = _check_entry_value(str(key), value, where)
    if "n_timesteps" not in checked:
        raise HyperparameterError(f"{where}: 'n_timesteps' is missing (the total env steps to train)")
    for key in (
        "n_timesteps",
        "num_envs_per_env_runner",
        "train_batch_size_per_learner",
        "minibatch_size",
        "num_epochs",
    ):
        if key in checked and checked[key] < 1:
            raise HyperparameterError(f"{where}: {key!r} must be >= 1; got {checked[key]}")
    for key in FRACTIONS:
        if key in checked and not 0 < checked[key] <= 1:
            raise HyperparameterError(f"{where}: {key!r} must be in (0, 1]; got {checked[key]}")
    for key in ("clip_param", "vf_clip_param", "grad_clip"):
        if checked.get(key) is not None and not checked[key] > 0:
            raise HyperparameterError(f"{where}: {key!r} must be > 0; got {checked[key]}")
    if "lr" in checked:
        schedule(checked["lr"], "lr", where)  # a positive number or lin_<number>, or an error
    if checked.get("fcnet_activation", "tanh") not in ACTIVATIONS:
        raise HyperparameterError(
            f"{where}: 'fcnet_activation' must be one of {list(ACTIVATIONS)} (the activations the policy format "
            f"has); got {checked['fcnet_activation']!r}"
        )
    if "multiagent" in checked:
        _check_multiagent_run(checked, where)
    if checked.get("minibatch_size", 0) > checked.get("train_batch_size_per_learner", 4000):
        raise HyperparameterError(f"{where}: 'minibatch_size' must not exceed 'train_batch_size_per_learner'")
    return checked


def _check_entry_value(key: str, value: Any, where: str) -> Any:
    """One known key's value, checked (and converted as :func:`~agents.training.hyperparams.check_value` does)."""
    if key == "multiagent":
        return check_multiagent(value, where)
    if key == "fcnet_hiddens":
        if not (isinstance(value, list) and value and all(is_count(size) for size in value)):
            raise HyperparameterError(f"{where}: 'fcnet_hiddens' must be a list of layer sizes >= 1; got {value!r}")
        return [int(size) for size in value]
    return check_value(key, value, KEYS[key], where)


def _check_multiagent_run(checked: Mapping[str, Any], where: str) -> None:
    """The settings a multi-agent run cannot take."""
    if checked.get("normalize_obs", False):
        raise HyperparameterError(
            f"{where}: 'normalize_obs' must be false with 'multiagent': RLlib's MeanStdFilter keeps one set of "
            f"statistics per agent, which one shared policy cannot be exported with; set normalize_obs: false"
        )
    if checked.get("num_envs_per_env_runner", 1) != 1:
        raise HyperparameterError(
            f"{where}: 'num_envs_per_env_runner' must be 1 with 'multiagent' (one env per env runner: the setting "
            f"tested); scale out with --num-env-runners instead"
        )


def _learning_rate(value: float | str, total: int) -> float | list[list[float]]:
    """RLlib's ``lr``: a number, or for ``lin_<x>`` the piecewise schedule from x at step 0 to 0
    at ``total`` env steps (what ``lin_`` means for SB3)."""
    if isinstance(value, str):
        return [[0, float(value[4:])], [total, 0.0]]
    return float(value)


# ---------------------------------------------------------------------------------------------
# Ray and the algorithm
# ---------------------------------------------------------------------------------------------


def connect(address: str | None, num_cpus: int | None) -> bool:
    """Start a local Ray instance (``address`` None; ``num_cpus`` caps it) or join the cluster at
    ``address`` (``host:port`` of its head node, ``auto`` for the one on this machine); nothing if
    Ray is already initialised in this process (e.g. by a test). Returns whether this call
    started Ray (then :func:`train_rllib` shuts it down at the end).

    A ``host:port`` that does not answer within :data:`CONNECT_TIMEOUT_S` raises
    :class:`RayUnavailableError` at once, rather than letting Ray retry for minutes."""
    ray = _ray()
    if ray.is_initialized():
        return False
    if address is None:
        ray.init(num_cpus=num_cpus, include_dashboard=False, configure_logging=False)
        return True
    if address != "auto":
        _check_reachable(address)
    try:
        ray.init(address=address, configure_logging=False)
    except (ConnectionError, RuntimeError, ValueError) as error:
        raise RayUnavailableError(
            f"--address {address}: could not join the Ray cluster ({error}). Start its head node with "
            f"`ray start --head --port 6379` and pass --address HEAD_IP:6379, or leave --address out to start a "
            f"local instance"
        ) from error
    return True


def _check_reachable(address: str) -> None:
    """Raise :class:`RayUnavailableError` unless ``address`` (``[ray://]host:port``) accepts a TCP
    connection within :data:`CONNECT_TIMEOUT_S`."""
    target = address.removeprefix("ray://")
    host, _, port = target.rpartition(":")
    if not host or not port.isdigit():
        raise RayUnavailableError(
            f"--address must be HOST:PORT of a Ray head node (e.g. 10.0.0.1:6379) or 'auto'; got {address!r}"
        )
    try:
        with socket.create_connection((host, int(port)), timeout=CONNECT_TIMEOUT_S):
            pass
    except OSError as error:
        raise RayUnavailableError(
            f"--address {address}: no Ray head node answers there ({error}; waited at most {CONNECT_TIMEOUT_S:.0f} s). "
            f"Start one with `ray start --head --port {port}` on {host}, check the host, port and firewall, or leave "
            f"--address out to start a local Ray instance"
        ) from error


def _check_resources(num_env_runners: int) -> None:
    """Refuse more env runners than the cluster has CPUs for: Ray would wait for them forever."""
    cpus = int(_ray().cluster_resources().get("CPU", 0))
    if num_env_runners > cpus:
        raise RayUnavailableError(
            f"--num-env-runners {num_env_runners} needs {num_env_runners} CPUs (one per runner), but the Ray "
            f"cluster has {cpus}: pass --num-env-runners {cpus} or fewer (0 samples in the driver), or add nodes"
        )


def build_config(
    env_id: str, hyperparams: Mapping[str, Any], num_env_runners: int, envs_per_runner: int, seed: int
) -> Any:
    """The ``PPOConfig`` of a run: RLlib's new API stack, the native vector env (next-step
    autoreset) in every env runner, and a model the policy format can hold."""
    from ray.rllib.algorithms.ppo import PPOConfig
    from ray.rllib.connectors.env_to_module import MeanStdFilter
    from ray.rllib.core.rl_module.default_model_config import DefaultModelConfig

    env_config = {**dict(hyperparams.get("env_kwargs") or {}), "autoreset_mode": "NextStep"}
    training = {
        key: hyperparams[key]
        for key in (
            "train_batch_size_per_learner",
            "minibatch_size",
            "num_epochs",
            "gamma",
            "clip_param",
            "vf_clip_param",
            "vf_loss_coeff",
            "entropy_coeff",
            "use_kl_loss",
            "grad_clip",
        )
        if key in hyperparams
    }
    if "lambda" in hyperparams:
        training["lambda_"] = hyperparams["lambda"]
    if "lr" in hyperparams:
        training["lr"] = _learning_rate(hyperparams["lr"], int(hyperparams["n_timesteps"]))
    connector = (lambda env, spaces, device: MeanStdFilter()) if hyperparams.get("normalize_obs", False) else None
    model_config = DefaultModelConfig(
        fcnet_hiddens=list(hyperparams.get("fcnet_hiddens", [128, 128])),
        fcnet_activation=hyperparams.get("fcnet_activation", "tanh"),
        head_fcnet_hiddens=[],
        free_log_std=True,
        vf_share_layers=False,
    )
    config = PPOConfig()
    multiagent = hyperparams.get("multiagent")
    if multiagent is None:
        # "tether_gym:<id>": gymnasium imports tether_gym (registering the ids) in every runner process.
        config = config.environment(
            f"tether_gym:{env_id}", env_config=env_config, normalize_actions=False, clip_actions=True
        ).env_runners(gym_env_vectorize_mode="vector_entry_point")
        config = config.rl_module(model_config=model_config)
    else:
        from ray.rllib.core.rl_module.multi_rl_module import MultiRLModuleSpec
        from ray.rllib.core.rl_module.rl_module import RLModuleSpec
        from ray.tune.registry import register_env

        register_env(MULTIAGENT_ENV_NAME, make_multiagent_env)
        config = (
            config.environment(
                MULTIAGENT_ENV_NAME,
                env_config={"env_id": env_id, **dict(hyperparams.get("env_kwargs") or {}), **dict(multiagent)},
                normalize_actions=False,
                clip_actions=True,
            )
            # Parameter sharing: every agent (satellite) maps to the one module.
            .multi_agent(policies={SHARED_MODULE_ID}, policy_mapping_fn=_shared_policy)
            .rl_module(
                rl_module_spec=MultiRLModuleSpec(
                    rl_module_specs={SHARED_MODULE_ID: RLModuleSpec(model_config=model_config)}
                )
            )
        )
    return (
        config.env_runners(
            num_env_runners=num_env_runners, num_envs_per_env_runner=envs_per_runner, env_to_module_connector=connector
        )
        .training(**training)
        .debugging(seed=seed)
    )


def _shared_policy(agent_id: str, *args: Any, **kwargs: Any) -> str:
    """RLlib's ``policy_mapping_fn`` of a multi-agent run: every agent acts with the shared module."""
    return SHARED_MODULE_ID


def make_multiagent_env(config: Mapping[str, Any]) -> Any:
    """The env of a multi-agent run (registered with Ray as :data:`MULTIAGENT_ENV_NAME`): Ray's
    ``ParallelPettingZooEnv`` around :func:`tether_gym.multiagent.parallel_env`, whose dicts it
    passes on as they are (``"__all__"``: all agents end together when the cluster's episode
    ends). ``config``: ``env_id`` and the keyword arguments of ``parallel_env``."""
    from ray.rllib.env.wrappers.pettingzoo_env import ParallelPettingZooEnv

    from tether_gym.multiagent import parallel_env

    kwargs = dict(config)
    env_id = kwargs.pop("env_id")
    return ParallelPettingZooEnv(parallel_env(env_id, **kwargs))


def _module_id(algo: Any) -> str:
    """The id of the run's (shared) module: RLlib's default one, or :data:`SHARED_MODULE_ID`."""
    from ray.rllib.core import DEFAULT_MODULE_ID

    return SHARED_MODULE_ID if algo.config.is_multi_agent else DEFAULT_MODULE_ID


# ---------------------------------------------------------------------------------------------
# Export to the policy format
# ---------------------------------------------------------------------------------------------


def module_weights(algo: Any) -> dict[str, np.ndarray]:
    """The learner's RLModule weights (policy and value networks; the shared module of a
    multi-agent run), as numpy arrays by name."""
    module_id = _module_id(algo)
    state = algo.learner_group.get_state(components=f"learner/rl_module/{module_id}")
    return {name: np.asarray(value) for name, value in state["learner"]["rl_module"][module_id].items()}


def observation_filter(algo: Any) -> tuple[np.ndarray, np.ndarray, float] | None:
    """RLlib's ``MeanStdFilter`` of the run as ``(mean, divisor, clip)``: the filter computes
    ``clip((obs - mean) / divisor)``, divisor = float32(std + 1e-8); None without the filter."""
    from ray.rllib.utils.filter import RunningStat

    state = algo.get_state(components="env_runner")["env_runner"].get("env_to_module_connector", {})
    if "MeanStdFilter" not in state:
        return None
    agent = state["MeanStdFilter"][None]
    stats = RunningStat.from_state(agent["running_stats"][0])
    divisor = stats.std + 1e-8  # float32, as the filter computes it
    return np.asarray(stats.mean, dtype=np.float64), divisor.astype(np.float64), float(agent["clip_by_value"])


def make_vessel(env_id: str, hyperparams: Mapping[str, Any], seed: int) -> Any:
    """An SB3 PPO model whose ``MlpPolicy`` has the structure of the run's RLlib module (and a
    ``VecNormalize`` when the run normalises observations): the container the RLlib weights are
    copied into, for evaluation and export. Its own optimizer and rollout buffer are never used."""
    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import VecNormalize

    from tether_gym.sb3 import make_sb3_vec_env

    hidden = list(hyperparams.get("fcnet_hiddens", [128, 128]))
    activation = {"tanh": torch.nn.Tanh, "relu": torch.nn.ReLU}[hyperparams.get("fcnet_activation", "tanh")]
    env_kwargs = dict(hyperparams.get("env_kwargs") or {})
    multiagent = hyperparams.get("multiagent")
    venv: Any
    if multiagent is None:
        venv = make_sb3_vec_env(env_id, 1, seed=seed, **env_kwargs)
    else:
        from tether_gym.multiagent.sb3 import make_agent_vec_env

        # The shared policy's spaces: one agent's local observation and (3,) thrust command.
        venv = make_agent_vec_env(env_id, 1, seed=seed, **env_kwargs, **dict(multiagent))
    if hyperparams.get("normalize_obs", False):
        # epsilon 0: the divisor is set to RLlib's exactly (see export_policy).
        venv = VecNormalize(venv, training=False, norm_obs=True, norm_reward=False, epsilon=0.0)
    return PPO(
        "MlpPolicy",
        venv,
        n_steps=8,
        batch_size=8,
        seed=seed,
        device="cpu",
        policy_kwargs={"net_arch": {"pi": hidden, "vf": hidden}, "activation_fn": activation},
    )


def _sb3_name(rllib_name: str) -> str | None:
    """The SB3 ``MlpPolicy`` parameter that RLlib's default PPO module parameter maps onto (None
    for RLlib's constants)."""
    prefixes = {
        "encoder.actor_encoder.net.mlp.": "mlp_extractor.policy_net.",
        "encoder.critic_encoder.net.mlp.": "mlp_extractor.value_net.",
        "pi.net.mlp.0.": "action_net.",
        "vf.net.mlp.0.": "value_net.",
    }
    if rllib_name == "pi.log_std":
        return "log_std"
    for prefix, target in prefixes.items():
        if rllib_name.startswith(prefix):
            return target + rllib_name[len(prefix) :]
    return None


def export_policy(algo: Any, vessel: Any, timesteps: int) -> None:
    """Copy ``algo``'s module weights and observation filter into ``vessel`` (from
    :func:`make_vessel`), so that its policy acts as RLlib's module does deterministically.

    Raises PolicyFormatError if the module's parameters do not map one to one onto the vessel's
    (another RLlib model than :func:`build_config` builds)."""
    import torch

    weights = module_weights(algo)
    target = vessel.policy.state_dict()
    mapped = {}
    for name, value in weights.items():
        sb3_name = _sb3_name(name)
        if sb3_name is None:
            continue
        if sb3_name not in target or tuple(target[sb3_name].shape) != value.shape:
            raise PolicyFormatError(f"RLlib parameter {name} {value.shape} has no counterpart in the policy format")
        mapped[sb3_name] = torch.as_tensor(value, dtype=target[sb3_name].dtype)
    if set(mapped) != set(target):
        raise PolicyFormatError(f"the policy format's parameters {sorted(set(target) - set(mapped))} got no weights")
    vessel.policy.load_state_dict(mapped)
    vessel.num_timesteps = int(timesteps)
    normalizer = vessel.get_vec_normalize_env()
    statistics = observation_filter(algo)
    if (normalizer is None) != (statistics is None):
        raise PolicyFormatError("the run's observation filter and the vessel's normaliser do not match")
    if normalizer is not None and statistics is not None:
        mean, divisor, clip = statistics
        # sqrt(divisor**2 + 0) == divisor exactly, so VecNormalize divides by what the filter does.
        normalizer.obs_rms.mean, normalizer.obs_rms.var = mean, divisor * divisor
        normalizer.clip_obs = clip


def rllib_actions(algo: Any, observations: np.ndarray) -> np.ndarray:
    """(B, act_dim) the deterministic actions of ``algo``'s module for (B, obs_dim) raw
    ``observations``: through the run's observation filter (without updating it), the module's
    mean action, clipped to [-1, 1] as the env runners clip them. For tests of the export."""
    import torch

    obs = np.asarray(observations, dtype=np.float32)
    statistics = observation_filter(algo)
    if statistics is not None:
        mean, divisor, clip = statistics
        obs = np.clip((obs - mean) / divisor.astype(np.float32), -clip, clip).astype(np.float32)
    module = algo.get_module(_module_id(algo))
    with torch.no_grad():
        out = module.forward_inference({"obs": torch.as_tensor(obs)})
    distribution = module.get_inference_action_dist_cls().from_logits(out["action_dist_inputs"])
    return np.clip(distribution.to_deterministic().sample().numpy(), -1.0, 1.0)


# ---------------------------------------------------------------------------------------------
# Training
# ---------------------------------------------------------------------------------------------


def _resume_checkpoint(resume: str | Path, trust_pickle: bool) -> Path:
    """The RLlib checkpoint ``resume`` names (a checkpoint or a run directory: its latest), checked."""
    path = Path(resume)
    if not path.exists():
        raise FileNotFoundError(f"--resume {path} does not exist: pass <run>/checkpoints/iter_<n> or a run directory")
    if not (path / CHECKPOINT_MARKER).is_file():
        found = sorted((path / "checkpoints").glob(f"iter_*/{CHECKPOINT_MARKER}"))
        if not found:
            raise FileNotFoundError(f"--resume {path} holds no RLlib checkpoint (no {CHECKPOINT_MARKER})")
        path = found[-1].parent
    if not trust_pickle:
        raise PickleNotTrustedError(
            f"--resume {path}: RLlib checkpoints hold pickles, and a crafted one runs arbitrary code when it is "
            f"loaded. Pass --trust-pickle to resume from a checkpoint you wrote yourself"
        )
    return path


def _tensorboard_logger(run: Path) -> Any:
    """An SB3 logger writing TensorBoard events to ``<run>/tensorboard/rllib_ppo_<n>`` (a new n per
    run, as SB3 numbers its runs)."""
    from stable_baselines3.common.logger import configure

    number = 1
    while (run / "tensorboard" / f"{ALGO}_{number}").exists():
        number += 1
    return configure(str(run / "tensorboard" / f"{ALGO}_{number}"), ["tensorboard"])


def _record_iteration(logger: Any, result: Mapping[str, Any], steps_per_s: float, module_id: str) -> None:
    """The iteration's returns, losses and speed into the TensorBoard logger."""
    runners = result.get("env_runners", {})
    for key, name in (("episode_return_mean", "rollout/ep_rew_mean"), ("episode_len_mean", "rollout/ep_len_mean")):
        if key in runners:
            logger.record(name, float(runners[key]))
    learner = result.get("learners", {}).get(module_id, {})
    for key in ("policy_loss", "vf_loss", "entropy", "mean_kl_loss", "vf_explained_var"):
        if key in learner:
            logger.record(f"train/{key}", float(learner[key]))
    logger.record("time/env_steps_per_s", steps_per_s)
    logger.record("time/iterations", int(result.get("training_iteration", 0)))


@dataclasses.dataclass(frozen=True)
class RLlibConfig:
    """What :func:`train_rllib` trains and how: the options of ``python -m agents.train_rllib``.
    The values are checked here, before any file is read or Ray starts; errors name the argument."""

    env_id: str = DEFAULT_ENV_ID
    """The tether-gym id to train on."""
    seed: int = 0
    """The run's seed (RLlib's and the export vessel's), >= 0; it names the run directory."""
    out: str | Path = "runs"
    """Parent of the run directory ``<out>/<env_id>/rllib_ppo_seed<seed>`` (``rllib_ppo_multiagent_seed<seed>``
    for a multi-agent run)."""
    timesteps: int | None = None
    """Env steps to train, instead of the file's ``n_timesteps`` (RLlib trains whole iterations, so a
    few more may run); None: the file's."""
    num_env_runners: int = 0
    """Env runner processes, each needing a CPU of the Ray cluster; 0: the driver samples itself."""
    envs_per_runner: int | None = None
    """Sub-envs of each runner's native vector env, instead of the file's ``num_envs_per_env_runner``."""
    address: str | None = None
    """``host:port`` of a running Ray cluster's head node to join (``auto``: the one on this machine);
    None starts a local Ray instance, and stops it at the end."""
    num_cpus: int | None = None
    """CPUs of the local Ray instance (None: all of the machine's); not with ``address``."""
    hyperparams_file: str | Path | None = None
    """A hyperparameter file of the form of the package's ``hyperparams/rllib_ppo.yml``, or an RLlib
    run's ``config.yml``; None: that file."""
    multiagent: bool = False
    """Train one shared decentralised policy, with the file's ``multiagent`` options or the defaults
    (an entry with ``multiagent`` trains one without it)."""
    resume: str | Path | None = None
    """An RLlib checkpoint to continue from, or a run directory (its latest checkpoint); needs
    ``trust_pickle``."""
    trust_pickle: bool = False
    """Load the pickles of ``resume``'s checkpoint (only for checkpoints you wrote yourself)."""
    eval_freq: int = 50_000
    """Env steps over all runners between evaluations on the fixed evaluation seeds, acted on at the
    first iteration that reaches it (a multi-agent run counts env steps, each of which moves every
    agent)."""
    eval_episodes: int = 32
    """Episodes of each evaluation."""
    checkpoint_freq: int = 250_000
    """Env steps over all runners between RLlib checkpoints (one is also written at the end)."""
    force: bool = False
    """Replace an earlier run in the same run directory."""
    command: str | None = None
    """The command line recorded in ``config.yml`` and in the policy's provenance."""

    def __post_init__(self) -> None:
        if self.env_id not in ENV_IDS:
            raise ValueError(f"unknown env id {self.env_id!r}; tether-gym ids are {list(ENV_IDS)}")
        optional = ("num_cpus", "timesteps", "envs_per_runner")  # None: Ray's or the file's value
        for name, minimum in (
            ("seed", 0),
            ("num_env_runners", 0),
            ("eval_freq", 1),
            ("eval_episodes", 2),  # each evaluation's paired difference has a t interval
            ("checkpoint_freq", 1),
            ("num_cpus", 1),
            ("timesteps", 1),
            ("envs_per_runner", 1),
        ):
            if name not in optional or getattr(self, name) is not None:
                # Stored as a plain int (a numpy integer passes the check), so that config.yml can hold it.
                maximum = {"seed": MAX_TRAINING_SEED, "eval_episodes": MAX_NUM_ENVS}.get(name)
                object.__setattr__(self, name, check_int(name, getattr(self, name), minimum, maximum))
        if self.num_cpus is not None and self.address is not None:
            raise ValueError(
                "num_cpus sets the size of a local Ray instance; with --address the cluster's nodes set it"
            )


@holds_output_claims
def train_rllib(config: RLlibConfig) -> Path:
    """Train PPO with RLlib as ``config`` says and return the run directory (see the command's
    docstring, :mod:`agents.train_rllib`, for what the directory holds).

    Everything is checked before Ray starts (the arguments by ``config``, the hyperparameters by
    :func:`resolve_hyperparameters`, the checkpoint to resume), the cluster's CPUs against the
    runners after: errors name the argument and the fix."""
    started = time.perf_counter()
    hyperparams = resolve_hyperparameters(config)
    checkpoint = _resume_checkpoint(config.resume, config.trust_pickle) if config.resume is not None else None
    ray = _ray()
    from .shipping import model_name

    name = model_name({"algo": ALGO, "multiagent": hyperparams.get("multiagent")})
    run = prepare_run_dir(config.out, config.env_id, name, config.seed, config.force)
    owns_ray = connect(config.address, config.num_cpus)
    try:
        _check_resources(config.num_env_runners)
        envs = _envs_per_runner(hyperparams)
        algo = build_config(config.env_id, hyperparams, config.num_env_runners, envs, config.seed).build_algo()
        if checkpoint is not None:
            algo.restore_from_path(str(checkpoint.resolve()))
        if config.force:
            clear_earlier_run(run, ALGO, {checkpoint} if checkpoint else set())
        record = _run_record(config, hyperparams, checkpoint, ray.__version__)
        atomic_write_text(run / "config.yml", yaml.safe_dump(record, sort_keys=False))
        _train_loop(algo, run, config, hyperparams, started, record)
        algo.stop()
    finally:
        if owns_ray:
            ray.shutdown()
    return run


def resolve_hyperparameters(config: RLlibConfig) -> dict[str, Any]:
    """The run's checked hyperparameters: the file's entry for the id (:func:`load_rllib_hyperparameters`)
    with ``config``'s overrides (``multiagent``, ``timesteps``, ``envs_per_runner``) on top, checked
    again, and a multi-agent run's options tried on the env (:func:`_check_multiagent_env`)."""
    hyperparams = load_rllib_hyperparameters(config.env_id, config.hyperparams_file)
    if config.multiagent:
        hyperparams["multiagent"] = hyperparams.get("multiagent") or {}
    if config.timesteps is not None:
        hyperparams["n_timesteps"] = config.timesteps
    if config.envs_per_runner is not None:
        hyperparams["num_envs_per_env_runner"] = config.envs_per_runner
    hyperparams = validate_rllib_hyperparameters(hyperparams, where="hyperparameters (with overrides)")
    envs = _envs_per_runner(hyperparams)
    if envs > MAX_NUM_ENVS:
        raise ValueError(f"envs_per_runner must be at most {MAX_NUM_ENVS} (use more runners); got {envs}")
    if hyperparams.get("multiagent") is not None:
        _check_multiagent_env(config.env_id, hyperparams)
    return hyperparams


def _envs_per_runner(hyperparams: Mapping[str, Any]) -> int:
    """The sub-envs of each env runner (RLlib's default: 1)."""
    return int(hyperparams.get("num_envs_per_env_runner", 1))


def _run_record(
    config: RLlibConfig, hyperparams: Mapping[str, Any], checkpoint: Path | None, ray_version: str
) -> dict[str, Any]:
    """The run's ``config.yml`` as first written (the env steps that ran are added at the end)."""
    return {
        "algo": ALGO,
        "env_id": config.env_id,
        "seed": config.seed,
        "hyperparams": hyperparams,
        "num_env_runners": config.num_env_runners,
        "envs_per_runner": _envs_per_runner(hyperparams),
        "address": config.address,
        "command": config.command,
        "resumed_from": str(checkpoint) if checkpoint else None,
        "tether_gym_version": tether_gym.__version__,
        "ray_version": ray_version,
    }


def _train_loop(
    algo: Any, run: Path, config: RLlibConfig, hyperparams: Mapping[str, Any], started: float, record: dict[str, Any]
) -> None:
    """Train until ``n_timesteps`` env steps, evaluating, checkpointing and logging on the way
    (:func:`_train_iterations`); export the final policy into ``run``, with ``record`` (the run's
    ``config.yml``) completed by the env steps that actually ran. ``started``: ``time.perf_counter()``
    at the start of the command (the evaluations' wall times count from it)."""
    from ..policies.format import save_policy

    env_id = config.env_id
    spec = PolicySpec(multiagent=hyperparams.get("multiagent"))
    vessel = make_vessel(env_id, hyperparams, config.seed)
    vessel.set_logger(_tensorboard_logger(run))
    provenance = {
        "seed": config.seed,
        "command": config.command,
        "config": "config.yml of the run directory",
        "trainer": "rllib",
    }
    evaluation = _seeded_evaluation(config, run, vessel, hyperparams, provenance, spec, started)
    total = int(hyperparams["n_timesteps"])
    first = lifetime_steps(algo)
    start = time.perf_counter()
    steps = _train_iterations(algo, run, config, vessel, evaluation, total, first)
    export_policy(algo, vessel, steps)
    if steps > total:
        # RLlib trains whole iterations (train_batch_size_per_learner steps each): say so, and record it.
        print(
            f"trained {steps - first:,} env steps for the {total - first:,} asked: RLlib trains whole iterations "
            f"of about {hyperparams.get('train_batch_size_per_learner', 'train_batch_size_per_learner')} steps",
            flush=True,
        )
    record["num_timesteps"] = int(steps)
    atomic_write_text(run / "config.yml", yaml.safe_dump(record, sort_keys=False))
    save_policy(
        run,
        vessel,
        vessel.get_vec_normalize_env(),
        env_id,
        provenance,
        extra_files=["config.yml"],
        spec=spec,
    )
    evaluation.finish(steps)
    elapsed = time.perf_counter() - start
    print(
        f"trained rllib ppo on {env_id} for {steps - first:,} steps in {elapsed / 60:.1f} min "
        f"({(steps - first) / max(elapsed, 1e-9):,.0f} steps/s); run directory {run}"
    )
    print_evaluation_summary(evaluation)


def _seeded_evaluation(
    config: RLlibConfig,
    run: Path,
    vessel: Any,
    hyperparams: Mapping[str, Any],
    provenance: Mapping[str, Any],
    spec: PolicySpec,
    started: float,
) -> Any:
    """The evaluation on the fixed evaluation seeds (:class:`~agents.training.selection.SeededEvaluation`),
    attached to ``vessel`` and started (the baselines rolled out): it saves each new best policy
    into ``run/best``."""
    from .callbacks import SafePolicySaver
    from .selection import SeededEvaluation

    evaluation = SeededEvaluation(
        config.env_id,
        config.eval_episodes,
        every=1,
        log_dir=run / "best",
        on_new_best=SafePolicySaver(run / "best", config.env_id, provenance, spec=spec, training_state=False),
        started=started,
        env_kwargs=hyperparams.get("env_kwargs"),
        spec=spec,
    )
    evaluation.init_callback(vessel)
    evaluation.on_training_start({}, {})
    return evaluation


def _train_iterations(
    algo: Any, run: Path, config: RLlibConfig, vessel: Any, evaluation: Any, total: int, first: int
) -> int:
    """RLlib's iterations from ``first`` env steps until ``total``: each one logged and printed,
    the policy exported and evaluated every ``eval_freq`` env steps, a checkpoint written every
    ``checkpoint_freq`` (and both at the end). Returns the env steps sampled since the run began."""
    steps = first
    next_eval, next_checkpoint = steps + config.eval_freq, steps + config.checkpoint_freq
    while steps < total:
        tick = time.perf_counter()
        result = algo.train()
        before, steps = steps, lifetime_steps(algo)
        speed = (steps - before) / max(time.perf_counter() - tick, 1e-9)
        _record_iteration(vessel.logger, result, speed, _module_id(algo))
        returns = result.get("env_runners", {}).get("episode_return_mean", float("nan"))
        ended = f"episode return {returns:.2f}" if np.isfinite(returns) else "no episode ended"
        print(
            f"iteration {algo.iteration}: {steps:,} / {total:,} env steps, {speed:,.0f} steps/s, {ended}",
            flush=True,
        )
        if steps >= next_eval or steps >= total:
            export_policy(algo, vessel, steps)
            evaluation.on_step()
            next_eval = steps + config.eval_freq
        if steps >= next_checkpoint or steps >= total:
            algo.save_to_path(str((run / "checkpoints" / f"iter_{algo.iteration:06d}").resolve()))
            next_checkpoint = steps + config.checkpoint_freq
        vessel.logger.dump(steps)
    return steps


def _check_multiagent_env(env_id: str, hyperparams: Mapping[str, Any]) -> None:
    """Build the multi-agent env once in the driver, so that a bad multi-agent option fails here
    with the env's own message (naming the option and the fix), not inside an env runner."""
    from tether_gym.envs.arguments import EnvArgumentError
    from tether_gym.multiagent import parallel_env

    try:
        parallel_env(env_id, **dict(hyperparams.get("env_kwargs") or {}), **dict(hyperparams["multiagent"])).close()
    except (EnvArgumentError, TypeError) as error:
        raise HyperparameterError(f"hyperparameters, 'multiagent' {hyperparams['multiagent']!r}: {error}") from error


def lifetime_steps(algo: Any) -> int:
    """Env steps that ``algo`` (an RLlib ``Algorithm``) has sampled, over all its env runners, since
    the run began (kept across a resume): what the run's step counts and frequencies count."""
    from ray.rllib.utils.metrics import ENV_RUNNER_RESULTS, NUM_ENV_STEPS_SAMPLED_LIFETIME

    value = algo.metrics.peek((ENV_RUNNER_RESULTS, NUM_ENV_STEPS_SAMPLED_LIFETIME), default=0)
    return int(value)
