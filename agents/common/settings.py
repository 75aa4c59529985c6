"""Per-id settings of the agents that are not SB3's (``mpc``, ``ars``), read from plain YAML.

A settings file maps env ids to entries, with a ``default`` entry for the ids it does not list;
each entry gives fields of a frozen dataclass (:class:`agents.controllers.mpc.MPCSettings`,
:class:`agents.training.ars.ARSSettings`), whose ``__post_init__`` checks the values. Nothing in the file
is evaluated, and a key given twice is refused (:func:`agents.common.reading.read_yaml`).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from pathlib import Path
from typing import Any, TypeVar

from .reading import read_yaml

__all__ = ["load_settings"]

SettingsT = TypeVar("SettingsT")


def load_settings(
    cls: type[SettingsT],
    file: Path,
    env_id: str | None,
    label: str,
    overrides: Mapping[str, Any],
    run_algo: str | None = None,
) -> SettingsT:
    """``cls`` from ``env_id``'s entry of the YAML ``file`` (else its ``default`` entry), with
    ``overrides`` on top. With ``run_algo``, ``file`` may also be the ``config.yml`` of a run of
    that algorithm, whose ``hyperparams`` are the entry (so a run reproduces from its own record).

    Raises:
        ValueError: a file that is not a mapping, or an unknown setting (named, with the known
            ones); ``cls`` raises it for bad values. ``label`` names the settings in messages.
    """
    table = read_yaml(file) or {}
    if not isinstance(table, dict):
        raise ValueError(f"{file} must map env ids to {label} settings")
    if run_algo is not None and table.get("algo") == run_algo and isinstance(table.get("hyperparams"), dict):
        entry = dict(table["hyperparams"])
    else:
        entry = dict(table.get(env_id, table.get("default")) or {})
    entry.update(overrides)
    known = {field.name for field in dataclasses.fields(cls)}  # type: ignore[arg-type]
    unknown = sorted(set(entry) - known)
    if unknown:
        raise ValueError(f"{file}: unknown {label} setting(s) {unknown} for {env_id!r}; settings are {sorted(known)}")
    return cls(**entry)
