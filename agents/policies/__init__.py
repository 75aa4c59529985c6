"""Trained policies: their safe file format, loading them as controllers, and converting SB3 files.

The documented import path is this package: ``from tether_gym_agents.policies import
TrainedPolicy, shipped_models, make_controller`` (``agents.policies`` in a checkout). It imports
torch, as loading a policy needs it; the modules hold the rest, each importing only those listed before it:

* :mod:`.spec`: :class:`PolicySpec`, how a policy's outputs become actions (residual, multi-agent);
* :mod:`.layout`: a policy directory's file names, the format's version, and its errors;
* :mod:`.codecs`: strict JSON, spaces, and classes by name;
* :mod:`.normalization`: the observation normalisation statistics, without SB3's wrapper;
* :mod:`.size`: the size of the network a ``policy.json`` describes, without building it;
* :mod:`.sb3_state`: an SB3 model's optimizer state and counters (the only module touching SB3's
  private attributes);
* :mod:`.format`: the safe format itself (save, load, manifest, metadata), and why it describes an
  SB3 policy;
* :mod:`.pickled`: SB3's pickle-based files, only on opt-in;
* :mod:`.loaded`: :class:`TrainedPolicy`, the shipped models, and controllers by name;
* :mod:`.reference`: the observations and actions that conversions and shipped models are checked on;
* :mod:`.conversion`: converting SB3's files to the safe format (``python -m agents.convert``).
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
