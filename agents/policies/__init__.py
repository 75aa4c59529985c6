"""Trained policies: their safe file format, loading them as controllers, and converting SB3 files.

The documented import path is this package: ``from tether_gym_agents.policies import
TrainedPolicy, shipped_models, make_controller`` (``agents.policies`` in a checkout). It imports
torch, as loading a policy needs it; the modules below hold the rest:

* :mod:`.spec`: :class:`PolicySpec`, how a policy's outputs become actions (residual, multi-agent);
* :mod:`.loaded`: :class:`TrainedPolicy`, the shipped models, and controllers by name.
"""

from .loaded import (
    MODELS_DIR,
    OtherIdError,
    OtherIdWarning,
    TrainedPolicy,
    env_id_of,
    is_shipped,
    make_controller,
    shipped_models,
)
from .spec import PolicySpec

__all__ = [
    "MODELS_DIR",
    "OtherIdError",
    "OtherIdWarning",
    "PolicySpec",
    "TrainedPolicy",
    "env_id_of",
    "is_shipped",
    "make_controller",
    "shipped_models",
]
