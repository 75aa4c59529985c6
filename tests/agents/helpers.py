"""Helpers of the agents' tests: the id and episode length they run on, the SB3 action pipeline,
and pickle payloads."""

from __future__ import annotations

import base64
import json
import pickle
import zipfile
from pathlib import Path

import numpy as np

ENV = "TetherTetrahedron-v0"

SHORT = {"max_episode_steps": 20}


def sb3_actions(model: object, normalizer: object, observations: np.ndarray) -> np.ndarray:
    """The SB3 pipeline: VecNormalize.normalize_obs, then model.predict(deterministic=True)."""
    return model.predict(normalizer.normalize_obs(observations).astype(np.float32), deterministic=True)[0]


def payload(marker: Path, genuine: bytes) -> bytes:
    """Pickle bytes that write ``marker`` when unpickled, then return ``pickle.loads(genuine)``."""
    code = (
        f"(__import__('pathlib').Path({str(marker)!r}).write_text('pwned'), __import__('pickle').loads({genuine!r}))[1]"
    )

    class Payload:
        def __reduce__(self) -> tuple:
            return (eval, (code,))

    return pickle.dumps(Payload())


def crafted_zip(source: Path, target: Path, marker: Path) -> None:
    """A copy of an SB3 model zip whose cloudpickled ``policy_class`` field carries a payload."""
    with zipfile.ZipFile(source) as archive:
        members = {name: archive.read(name) for name in archive.namelist()}
    data = json.loads(members["data"])
    genuine = base64.b64decode(data["policy_class"][":serialized:"])
    data["policy_class"][":serialized:"] = base64.b64encode(payload(marker, genuine)).decode()
    members["data"] = json.dumps(data).encode()
    with zipfile.ZipFile(target, "w") as archive:
        for name, content in members.items():
            archive.writestr(name, content)
