"""Every scripted baseline by name, and :func:`make_baseline`.

The registry lists each controller explicitly; no module adds itself to it on import. A new
baseline is a class in its room's module (centralised or decentralised) and one entry here.
The order is the order of the comparison's and the benchmark's tables.

Per-id gains: the package's ``hyperparams/laws.yml`` maps an env id to law names to keyword
arguments of the law's constructor (:func:`load_law_settings`). :func:`make_baseline` uses the
entry of its env's id, with explicit keyword arguments on top; an id the file does not list keeps
the constructors' defaults.
"""

from __future__ import annotations

import inspect
from pathlib import Path
from typing import Any

from tether_gym.registration import ENV_IDS

from ..common.data import HYPERPARAMS_DIR
from ..common.reading import read_yaml
from .base import Controller
from .centralised import LQRController, PassiveController, TensionAwareController, VelocityFeedbackController
from .decentralised import LocalTensionAwareController, LocalVelocityFeedbackController

__all__ = ["BASELINES", "LAW_SETTINGS_FILE", "load_law_settings", "make_baseline"]

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


#: The per-id gains of the scripted laws: env id -> law name -> constructor keyword arguments.
LAW_SETTINGS_FILE = HYPERPARAMS_DIR / "laws.yml"


def law_arguments(name: str) -> list[str]:
    """The keyword arguments of baseline ``name``'s constructor, after ``env``."""
    return [p for p in inspect.signature(BASELINES[name].__init__).parameters if p not in ("self", "env")]


def load_law_settings(env_id: str | None, path: str | Path | None = None) -> dict[str, dict[str, Any]]:
    """The per-id law settings of ``env_id``: law name -> keyword arguments of its constructor, from
    the package's ``hyperparams/laws.yml`` (or ``path``); ``{}`` for an id the file does not list
    (or None).

    The whole file is checked whichever id is asked for, so that a typo cannot hide until its id
    is run. Values are numbers, strings or ``null``; the constructors check them.

    Raises:
        ValueError: a file that is not a mapping of env ids to mappings of law names to mappings,
            an unknown env id, law or argument (named, with the known ones), or a value that is
            not a number, a string or null.
    """
    file = Path(path) if path is not None else LAW_SETTINGS_FILE
    table = read_yaml(file) or {}
    if not isinstance(table, dict):
        raise ValueError(f"{file} must map env ids to law names to the laws' keyword arguments")
    for file_id, laws in table.items():
        if file_id not in ENV_IDS:
            raise ValueError(f"{file}: unknown env id {file_id!r}; the ids are {sorted(ENV_IDS)}")
        if not isinstance(laws, dict):
            raise ValueError(f"{file}: {file_id} must map law names to their keyword arguments; got {laws!r}")
        for law, arguments in laws.items():
            if law not in BASELINES:
                raise ValueError(f"{file}: {file_id}: unknown law {law!r}; the laws are {sorted(BASELINES)}")
            if not isinstance(arguments, dict):
                raise ValueError(f"{file}: {file_id}: {law} must map argument names to values; got {arguments!r}")
            known = law_arguments(law)
            unknown = sorted(str(key) for key in set(arguments) - set(known))
            if unknown:
                raise ValueError(
                    f"{file}: {file_id}: {law}: unknown argument(s) {unknown}; {law}'s arguments are {known}"
                )
            for key, value in arguments.items():
                if value is not None and (isinstance(value, bool) or not isinstance(value, (int, float, str))):
                    raise ValueError(
                        f"{file}: {file_id}: {law}: {key} must be a number, a string or null; got {value!r}"
                    )
    if env_id is None:
        return {}
    return {law: dict(arguments) for law, arguments in (table.get(env_id) or {}).items()}


def make_baseline(name: str, env: Any, **kwargs: Any) -> Controller:
    """The baseline ``name`` (one of :data:`BASELINES`) for ``env``: its gains those of the env's id
    in the package's ``hyperparams/laws.yml`` (:func:`load_law_settings`), with explicit keyword
    arguments ``kwargs`` on top. An env without an id, or an id the file does not list, gets the
    constructor's defaults."""
    if name not in BASELINES:
        raise ValueError(f"unknown baseline {name!r}; choose one of {sorted(BASELINES)}")
    env_id = getattr(getattr(env, "spec", None), "id", None)
    arguments = load_law_settings(env_id).get(name, {})
    return BASELINES[name](env, **{**arguments, **kwargs})
