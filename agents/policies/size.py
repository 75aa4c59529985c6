"""The size of the network a ``policy.json`` describes, computed from the file alone.

Building an SB3 policy allocates and initialises every weight (an orthogonal initialisation of a
4096 x 4096 layer alone takes seconds), so a few-KB ``policy.json`` that asks for a huge network
would cost seconds and hundreds of MB before any check could refuse it. :func:`parameter_count`
counts the parameters that SB3 would build -- from the algorithm, ``net_arch``, the spaces and
the few keyword arguments that add parameters (``use_sde``, ``full_std``, ``n_critics``) -- without
building anything, so that the loader can refuse a network above :data:`MAX_POLICY_PARAMETERS`,
or one whose weights file holds another number of values, before any torch module exists.

The count is exact for the policy classes the format can name (``MlpPolicy`` of PPO, SAC, TD3
and ARS's PPO host); a test checks it against SB3's own ``state_dict`` over a grid of settings.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

from ..common.checks import is_count
from .layout import PolicyFormatError

__all__ = ["MAX_LAYERS", "MAX_POLICY_PARAMETERS", "MAX_TENSOR_FILE_BYTES", "parameter_count"]

#: The most parameters a loaded policy may have: 4 million (16 MB of float32), about 80 times the
#: shipped PPO models (128 x 128 actor and critic, under 50 000 on the largest id) and 9 times the
#: SAC settings of ``agents/hyperparams/sac.yml`` (256 x 256 with two critics and their targets,
#: about 430 000 on the largest id). Built from scratch, a network of this size costs well under a
#: second; it bounds what a crafted ``policy.json`` can make the loader allocate.
MAX_POLICY_PARAMETERS = 4_000_000
#: The largest safetensors file of a policy directory read, bytes: the weights of the largest
#: policy allowed take 16 MB as float32, and its training state (Adam's two moments of every
#: trained tensor) twice that; 128 MiB leaves room for float64 and the header.
MAX_TENSOR_FILE_BYTES = 128 * 2**20
#: The most hidden layers a network of ``net_arch`` may have (the shipped ones have 2).
MAX_LAYERS = 16

#: SB3's default ``net_arch`` of each algorithm's ``MlpPolicy`` (None in the file): PPO's actor and
#: critic ``[64, 64]``, SAC's ``[256, 256]``, TD3's ``[400, 300]``.
_DEFAULT_NET_ARCH: dict[str, Any] = {
    "ppo": {"pi": [64, 64], "vf": [64, 64]},
    "ars": {"pi": [64, 64], "vf": [64, 64]},
    "dagger": {"pi": [64, 64], "vf": [64, 64]},
    "sac": [256, 256],
    "td3": [400, 300],
}
#: The keys a dict ``net_arch`` may have, by the algorithm's policy family.
_NET_ARCH_KEYS = {
    "ppo": ("pi", "vf"),
    "ars": ("pi", "vf"),
    "dagger": ("pi", "vf"),
    "sac": ("pi", "qf"),
    "td3": ("pi", "qf"),
}
#: The algorithms whose policy is SB3's ``ActorCriticPolicy`` (PPO's, and the trainers that store
#: theirs in it: ARS and DAgger).
_ACTOR_CRITIC = ("ppo", "ars", "dagger")


def _mlp(inputs: int, hidden: list[int], outputs: int | None) -> int:
    """Parameters of linear layers ``inputs -> hidden... (-> outputs)``, each with a bias."""
    count, width = 0, inputs
    for size in [*hidden, *([] if outputs is None else [outputs])]:
        count += width * size + size
        width = size
    return count


def _layers(value: Any, where: str) -> list[int]:
    if not isinstance(value, list) or not all(is_count(n) for n in value):
        raise PolicyFormatError(f"{where} must be a list of positive layer sizes; got {value!r}")
    if len(value) > MAX_LAYERS:
        raise PolicyFormatError(
            f"{where} has {len(value)} layers; a policy may have at most {MAX_LAYERS}: restore or re-create the file"
        )
    return [int(n) for n in value]


def _net_arch(algo: str, value: Any, where: str) -> tuple[list[int], list[int]]:
    """The actor's and the critic's hidden layers of ``net_arch`` as SB3 reads it."""
    if value is None:
        value = _DEFAULT_NET_ARCH[algo]
    if isinstance(value, list) and len(value) == 1 and isinstance(value[0], dict) and algo in _ACTOR_CRITIC:
        value = value[0]  # SB3 < 1.8's form, which SB3 still accepts for actor-critic policies
    keys = _NET_ARCH_KEYS[algo]
    if isinstance(value, dict):
        unknown = sorted(set(value) - set(keys))
        if unknown:
            raise PolicyFormatError(f"{where}: net_arch has keys {unknown}; a {algo} policy knows only {list(keys)}")
        if algo in ("sac", "td3") and set(value) != set(keys):
            raise PolicyFormatError(f"{where}: net_arch must have both {list(keys)} for a {algo} policy")
        return (
            _layers(value.get(keys[0], []), f"{where}: net_arch.{keys[0]}"),
            _layers(value.get(keys[1], []), f"{where}: net_arch.{keys[1]}"),
        )
    layers = _layers(value, f"{where}: net_arch")
    return layers, layers


def _flag(kwargs: Mapping[str, Any], key: str, default: bool, where: str) -> bool:
    value = kwargs.get(key, default)
    if not isinstance(value, bool):
        raise PolicyFormatError(f"{where}: {key} must be true or false; got {value!r}")
    return value


def parameter_count(
    algo: str, policy_kwargs: Mapping[str, Any], observation_size: int, action_size: int, where: str
) -> int:
    """The number of parameters (values of every tensor of its ``state_dict``) of the ``MlpPolicy``
    of ``algo`` (``ppo``, ``ars``, ``dagger``, ``sac``, ``td3``) that ``policy_kwargs`` (as ``policy.json``
    stores them) describe, for flat observations of ``observation_size`` and actions of
    ``action_size`` values; a PolicyFormatError naming ``where`` for a malformed ``net_arch``,
    one deeper than :data:`MAX_LAYERS`, or a count above :data:`MAX_POLICY_PARAMETERS`."""
    if algo not in _NET_ARCH_KEYS:
        raise PolicyFormatError(f"{where}: algorithm {algo!r} is not one of {sorted(_NET_ARCH_KEYS)}")
    actor, critic = _net_arch(algo, policy_kwargs.get("net_arch"), where)
    use_sde = _flag(policy_kwargs, "use_sde", False, where)
    full_std = _flag(policy_kwargs, "full_std", True, where)
    if algo in _ACTOR_CRITIC:
        latent_pi = actor[-1] if actor else observation_size
        latent_vf = critic[-1] if critic else observation_size
        std = latent_pi * (action_size if full_std else 1) if use_sde else action_size
        count = (
            _mlp(observation_size, actor, None)
            + _mlp(observation_size, critic, None)
            + _mlp(latent_pi, [], action_size)  # action_net
            + _mlp(latent_vf, [], 1)  # value_net
            + std  # log_std
        )
    else:
        n_critics = policy_kwargs.get("n_critics", 2)
        if not is_count(n_critics) or n_critics > 16:
            raise PolicyFormatError(f"{where}: n_critics must be an integer in 1..16; got {n_critics!r}")
        latent = actor[-1] if actor else observation_size
        critics = n_critics * _mlp(observation_size + action_size, critic, 1)
        if algo == "sac":
            std = latent * (action_size if full_std else 1) if use_sde else _mlp(latent, [], action_size)
            # The actor (latent_pi, mu, log_std), the critics and their target copies.
            count = _mlp(observation_size, actor, action_size) + std + 2 * critics
        else:
            # The actor and the critics, each with its target copy.
            count = 2 * _mlp(observation_size, actor, action_size) + 2 * critics
    if count > MAX_POLICY_PARAMETERS:
        raise PolicyFormatError(
            f"{where}: the network it describes has {count:,} parameters, more than a policy may have "
            f"({MAX_POLICY_PARAMETERS:,}; about {math.ceil(count * 4 / 2**20):,} MB to build): restore or re-create "
            "the file"
        )
    return count
