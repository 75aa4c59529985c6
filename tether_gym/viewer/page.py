"""The viewer's page: the HTML template, the bundled script, and the episodes as the page reads them.

One page serves every use. An export (:func:`export_html`) and a served recording carry their
episodes inside the page; the live view carries none and fetches them from the server's
``/api/meta`` and ``/api/frames`` in the same form (:func:`episode_meta`, :func:`frames_chunk`).
Arrays travel as base64 of their little-endian bytes: float64 positions, so that the page holds
the recorded numbers to the bit.
"""

from __future__ import annotations

import base64
import json
import os
from collections.abc import Mapping, Sequence
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from .recording import EpisodeRecording

__all__ = ["episode_meta", "export_html", "frames_chunk", "page_html", "suggested_exaggeration"]

#: The exaggeration of the live view, whose displacements are not known ahead (the envs'
#: ``render_exaggeration`` default).
LIVE_EXAGGERATION = 100.0

#: Each array the page reads per frame, and its wire type (see viewer/src/main.js, FIELDS).
WIRE_TYPES = {
    "time": "<f8",
    "positions": "<f8",
    "tension": "<f8",
    "slack": "u1",
    "broken": "u1",
    "thrust": "<f8",
    "reward": "<f8",
    "energy": "<f8",
}


def static_text(name: str) -> str:
    """A file of the package's ``viewer/static`` folder, as text."""
    return resources.files("tether_gym.viewer").joinpath("static").joinpath(name).read_text(encoding="utf-8")


def _finite(value: Any) -> Any:
    """JSON has no NaN: the page reads null where a number is not finite (frame 0's reward)."""
    return value if not (isinstance(value, float) and not np.isfinite(value)) else None


def episode_meta(meta: Mapping[str, Any]) -> dict[str, Any]:
    """What the page needs of a recording's metadata (the flat forms it indexes)."""
    nominal = np.asarray(meta["nominal"], dtype=float)
    return {
        "env_id": meta["env_id"],
        "controller": meta["controller"],
        "seed": meta["seed"],
        "frame": meta["frame"],
        "control_interval": meta["control_interval"],
        "max_steps": meta["max_steps"] or 0,
        "num_nodes": int(nominal.shape[0]),
        "nominal": nominal.reshape(-1).tolist(),
        "cables": meta["cables"],
        "roles": meta["roles"],
        "thrusters": meta["thrusters"],
        "max_thrust": float(max(meta["max_thrust"], default=1.0)),
        "end_reason": meta["end_reason"],
        "return": _finite(meta["return"]),
    }


def frames_chunk(
    arrays: Mapping[str, Any], start: int, stop: int, done: bool, meta: Mapping[str, Any]
) -> dict[str, Any]:
    """Frames ``start``..``stop - 1`` of ``arrays`` (per-frame arrays by name, as in
    :class:`~tether_gym.viewer.recording.EpisodeRecording`, or lists of per-frame arrays) in the
    page's wire form."""
    count = max(stop - start, 0)
    frames = {}
    for name, wire in WIRE_TYPES.items():
        values = np.ascontiguousarray(np.asarray(arrays[name][start:stop]).astype(wire, copy=False))
        frames[name] = base64.b64encode(values.tobytes()).decode("ascii")
    return {
        "count": count,
        "done": done,
        "end_reason": meta["end_reason"],
        "return": _finite(meta["return"]),
        "frames": frames,
    }


def recording_payload(recording: EpisodeRecording) -> dict[str, Any]:
    """A whole recording as the page reads an embedded episode."""
    chunk = frames_chunk(recording.arrays(), 0, recording.steps + 1, True, recording.meta)
    return {"meta": episode_meta(recording.meta), **chunk}


def page_html(config: Mapping[str, Any], title: str) -> str:
    """The viewer page with ``config`` (``{"mode": "static", "episodes": [...]}`` or
    ``{"mode": "live"}``, plus ``exaggeration``) and the bundled script inlined."""
    data = json.dumps(config, separators=(",", ":"), allow_nan=False)
    # Inside a <script> element only "</" can end it early; JSON allows "<\/" for it.
    data = data.replace("</", "<\\/")
    script = static_text("viewer.js").replace("</script", "<\\/script")
    html = static_text("page.html")
    safe_title = title.replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;")
    return (
        html.replace("__TETHER_VIEW_TITLE__", safe_title)
        .replace("__TETHER_VIEW_DATA__", data)
        .replace("__TETHER_VIEW_SCRIPT__", script)
    )


def recordings_config(recordings: Sequence[EpisodeRecording], exaggeration: float) -> dict[str, Any]:
    """The page's configuration for ``recordings`` shown side by side."""
    episodes = [recording_payload(recording) for recording in recordings]
    return {"mode": "static", "exaggeration": exaggeration, "episodes": episodes}


def suggested_exaggeration(recordings: Sequence[EpisodeRecording], reach: float = 0.4, most: float = 100.0) -> float:
    """The displacement exaggeration that draws the largest deviation from the nominal shape in
    ``recordings`` (centre-of-mass frame, as the page draws) within ``reach`` of the cluster's
    half-size: 1, 2 or 5 times a power of ten, at most ``most``."""
    ceiling = most
    for recording in recordings:
        nominal = np.asarray(recording.meta["nominal"], dtype=float)
        nominal = nominal - nominal.mean(axis=0)
        positions = recording.positions - recording.positions.mean(axis=1, keepdims=True)
        largest = float(np.linalg.norm(positions - nominal, axis=2).max(initial=0.0))
        half_size = 0.5 * float(np.ptp(nominal, axis=0).max())
        ceiling = min(ceiling, reach * half_size / max(largest, 1e-12))
    nice = [m * 10.0**k for k in range(-3, 4) for m in (1, 2, 5) if m * 10.0**k <= ceiling]
    return max(nice, default=0.001)


def title_of(recordings: Sequence[EpisodeRecording]) -> str:
    """The page title: the id and the controllers on their seeds."""
    first = recordings[0].meta
    shown = " vs ".join(f"{r.meta['controller']} (seed {r.meta['seed']})" for r in recordings)
    return f"tether-gym: {first['env_id']}, {shown}"


def export_html(
    recordings: Sequence[EpisodeRecording], path: str | os.PathLike[str], exaggeration: float | None = None
) -> Path:
    """Write ``recordings`` (one, or several side by side on one time slider) to a self-contained
    HTML file that opens offline in any browser, with no server; ``exaggeration`` is the initial
    displacement exaggeration (None: :func:`suggested_exaggeration`). Returns the path written."""
    if not recordings:
        raise ValueError("export_html needs at least one recording")
    if exaggeration is None:
        exaggeration = suggested_exaggeration(recordings)
    target = Path(path)
    target.parent.mkdir(parents=True, exist_ok=True)
    html = page_html(recordings_config(recordings, exaggeration), title_of(recordings))
    temporary = target.with_name(f".{target.name}.tmp")
    temporary.write_text(html, encoding="utf-8")
    os.replace(temporary, target)
    return target
