"""What a policy is besides its network: the settings that decide how its outputs become actions.

A trained policy's network maps observations to numbers; two settings say what those numbers are,
and they travel together from the hyperparameters through training, saving (``policy.json``),
loading and evaluation:

* ``residual_on``: the scripted baseline whose actions the network's outputs correct
  (:mod:`agents.controllers.residual`), or None when the outputs are the actions themselves;
* ``multiagent``: the options of a shared decentralised policy (:mod:`tether_gym.multiagent`),
  whose network acts on each agent's local observation (:mod:`agents.controllers.decentralised`), or None for a
  centralised policy, which acts on the env's whole observation.

:class:`PolicySpec` holds the two, in place of two keyword arguments threaded through every
function on that path.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any

__all__ = ["PolicySpec"]


@dataclasses.dataclass(frozen=True)
class PolicySpec:
    """How a policy's network outputs become the env's actions (see the module docstring).

    The default, ``PolicySpec()``, is a centralised policy whose outputs are its actions.
    """

    residual_on: str | None = None
    """The name of the scripted baseline (``agents.controllers.registry.BASELINES``) whose actions the
    policy's outputs are corrections to, ``clip(baseline + output, -1, 1)``; None for a policy
    whose outputs are its actions. The ``residual_on`` hyperparameter and ``policy.json`` entry."""

    multiagent: dict[str, Any] | None = dataclasses.field(default=None, hash=False)
    """A shared decentralised policy's multi-agent options, as the ``multiagent`` hyperparameter
    and ``policy.json`` entry hold them: a mapping of ``communication``, ``reward`` and
    ``local_observation_noise`` (each optional; ``{}`` is every default, and the values are checked
    where the env or the local observer is built). None for a centralised policy. Held as a copy,
    in the order given (``policy.json`` writes it in that order); treat it as read-only."""

    def __post_init__(self) -> None:
        if self.residual_on is not None and not isinstance(self.residual_on, str):
            raise ValueError(f"residual_on must be a baseline's name or None; got {self.residual_on!r}")
        if self.multiagent is not None:
            if not isinstance(self.multiagent, Mapping):
                raise ValueError(
                    f"multiagent must be a mapping of multi-agent options (communication, reward, "
                    f"local_observation_noise), e.g. {{}} for the defaults, or None; got {self.multiagent!r}"
                )
            # A copy: the caller's mapping may change later, the spec may not.
            object.__setattr__(self, "multiagent", dict(self.multiagent))

    @property
    def decentralised(self) -> bool:
        """Whether the policy is a shared decentralised one (it has multi-agent options)."""
        return self.multiagent is not None

    @classmethod
    def from_metadata(cls, metadata: Mapping[str, Any]) -> PolicySpec:
        """The spec a policy's metadata records (its ``residual_on`` and ``multiagent`` entries,
        absent in files older than those settings)."""
        return cls(residual_on=metadata.get("residual_on"), multiagent=metadata.get("multiagent"))
