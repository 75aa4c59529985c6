"""Episodes saved for the viewer: ``--save-episodes SEED ...`` of ``agents.compare`` and
``agents.benchmark``.

Each chosen seed is run again, one episode per controller, and written as a recording
(:mod:`tether_gym.viewer.recording`, plain ``.npz`` data) to
``<out>/episodes/<env id>/<controller>_seed<S>.npz``; ``tether-gym-view --recording A B`` plays
two controllers of one seed side by side, which is the picture behind a row of the table. The
episode is rerun rather than taken from the batched rollout, whose same-step autoreset has
already replaced the last state; a controller whose actions do not depend on the batch (every
scripted law, every trained policy) returns the same episode, to the bit, as in the table.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

from tether_gym.viewer import record_episode, recording_file_name, save_recording

from ..common.checks import check_int
from ..policies import make_controller

__all__ = ["checked_seeds", "save_episodes"]


def checked_seeds(field: str, seeds: Any) -> tuple[int, ...]:
    """``seeds`` as a tuple of ints >= 0, or ValueError naming ``field``."""
    if isinstance(seeds, (str, bytes)) or not hasattr(seeds, "__iter__"):
        raise ValueError(f"{field} must be a list of seeds (integers >= 0); got {seeds!r}")
    return tuple(check_int(field, seed, 0) for seed in seeds)


def episode_path(out: str | Path, env_id: str, name: str, seed: int) -> Path:
    """Where the episode of controller ``name`` on ``seed`` goes (a path-safe file name)."""
    return Path(out) / "episodes" / env_id / recording_file_name(name, seed)


def save_episodes(
    out: str | Path,
    env_id: str,
    names: Sequence[str],
    seeds: Sequence[int],
    env_kwargs: dict[str, Any] | None = None,
    trust_pickle: bool = False,
    allow_other_id: bool = False,
) -> list[Path]:
    """Record and save every controller of ``names`` on every seed of ``seeds`` on ``env_id``;
    returns the paths written (see the module docstring)."""
    paths = []
    for name in names:

        def make(env: Any, name: str = name) -> Any:
            return make_controller(name, env, trust_pickle=trust_pickle, allow_other_id=allow_other_id)

        for seed in seeds:
            recording = record_episode(env_id, int(seed), make, name, env_kwargs)
            paths.append(save_recording(recording, episode_path(out, env_id, name, int(seed))))
    if paths:
        folder = Path(out) / "episodes" / env_id
        print(f"saved {len(paths)} episode(s) in {folder}; watch them with tether-gym-view --recording FILE [FILE]")
    return paths
