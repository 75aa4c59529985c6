"""Every scripted baseline by name, and :func:`make_baseline`.

The registry lists each controller explicitly; no module adds itself to it on import. A new
baseline is a class in its room's module (centralised or decentralised) and one entry here.
The order is the order of the comparison's and the benchmark's tables.
"""

from __future__ import annotations

from typing import Any

from .base import Controller
from .centralised import LQRController, PassiveController, TensionAwareController, VelocityFeedbackController
from .decentralised import LocalTensionAwareController, LocalVelocityFeedbackController

__all__ = ["BASELINES", "make_baseline"]

#: The scripted baselines by name: the centralised laws (:mod:`agents.controllers.centralised`),
#: then the decentralised ones (:mod:`agents.controllers.decentralised`), which use only what each
#: satellite measures itself.
BASELINES: dict[str, type[Controller]] = {
    cls.name: cls
    for cls in (
        PassiveController,
        VelocityFeedbackController,
        LQRController,
        TensionAwareController,
        LocalVelocityFeedbackController,
        LocalTensionAwareController,
    )
}


def make_baseline(name: str, env: Any, **kwargs: Any) -> Controller:
    """The baseline ``name`` (one of :data:`BASELINES`) for ``env``, with its keyword arguments."""
    if name not in BASELINES:
        raise ValueError(f"unknown baseline {name!r}; choose one of {sorted(BASELINES)}")
    return BASELINES[name](env, **kwargs)
