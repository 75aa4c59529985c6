"""Controllers by name: the scripted baselines, and trained SB3 models loaded from disk."""

from __future__ import annotations

import pickle
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from agents.baselines import BASELINES, make_baseline

__all__ = ["MODELS_DIR", "TrainedPolicy", "make_controller", "shipped_models"]

#: Where the repository keeps its trained models: ``<env id>/<name>/model.zip``.
MODELS_DIR = Path(__file__).resolve().parent / "models"


class TrainedPolicy:
    """A trained SB3 model with its ``VecNormalize`` observation statistics, as a policy with
    the baselines' interface (``predict(observation, deterministic=True)``, for one observation
    or a batch).

    Args:
        path: a ``model.zip``, or a run directory holding ``model.zip`` (``best/best_model.zip``
            is used when ``best=True``). ``vecnormalize.pkl`` next to the model is applied to
            observations when present, and ``config.yml`` in the run directory names the
            algorithm.
        best: load ``best/best_model.zip`` of a run directory instead of the final model.
        name: the name shown in tables (default: the algorithm, e.g. ``"ppo"``).
    """

    def __init__(self, path: str | Path, best: bool = False, name: str | None = None) -> None:
        from agents.train import ALGORITHMS

        path = Path(path)
        if path.is_dir():
            path = path / "best" / "best_model.zip" if best else path / "model.zip"
        if not path.is_file():
            raise FileNotFoundError(
                f"no trained model at {path}: pass a model .zip or a run directory written by agents.train"
            )
        run = path.parent.parent if path.parent.name == "best" else path.parent
        config_file = run / "config.yml"
        config = yaml.safe_load(config_file.read_text()) if config_file.is_file() else {}
        algo = config.get("algo")
        if algo is None:  # not written by agents.train: try every algorithm
            for candidate, cls in ALGORITHMS.items():
                try:
                    self.model = cls.load(str(path), device="cpu")
                    algo = candidate
                    break
                except Exception:  # noqa: BLE001 - the wrong class fails in several ways
                    continue
            else:
                raise ValueError(f"{path} is not a model of any of {sorted(ALGORITHMS)}")
        else:
            if algo not in ALGORITHMS:
                raise ValueError(f"{config_file} names algorithm {algo!r}; known: {sorted(ALGORITHMS)}")
            self.model = ALGORITHMS[algo].load(str(path), device="cpu")
        self.algo = algo
        self.env_id = config.get("env_id")
        self.path = path
        self.name = name or algo
        statistics = path.with_name("vecnormalize.pkl")
        self.normalizer = None
        if statistics.is_file():
            with open(statistics, "rb") as stream:
                self.normalizer = pickle.load(stream)  # a VecNormalize without its venv
        self.observation_size = int(np.prod(self.model.observation_space.shape))

    @property
    def saturation_fraction(self) -> float:
        """Always 0: the policy's actions are squashed or clipped into [-1, 1] by SB3 itself."""
        return 0.0

    def reset_statistics(self) -> None:
        """Nothing to reset (for the baselines' interface)."""

    def predict(
        self,
        observation: np.ndarray,
        state: Any = None,
        episode_start: np.ndarray | None = None,
        deterministic: bool = True,
    ) -> tuple[np.ndarray, Any]:
        """SB3's ``predict`` on the normalised observation: ``(actions, state)``."""
        obs = np.asarray(observation, dtype=np.float32)
        if obs.shape[-1] != self.observation_size or obs.ndim not in (1, 2):
            raise ValueError(
                f"observation must have shape ({self.observation_size},) or (N, {self.observation_size}) "
                f"for this model; got {obs.shape}"
            )
        if self.normalizer is not None:
            obs = self.normalizer.normalize_obs(obs).astype(np.float32)
        return self.model.predict(obs, state=state, episode_start=episode_start, deterministic=deterministic)


def shipped_models(env_id: str) -> dict[str, Path]:
    """The repository's trained models for ``env_id``: name -> run directory."""
    root = MODELS_DIR / env_id
    if not root.is_dir():
        return {}
    return {run.name: run for run in sorted(root.iterdir()) if (run / "model.zip").is_file()}


def make_controller(spec: str, env: Any) -> Any:
    """A controller from a name: a baseline (``passive``, ``velocity_feedback``, ``lqr``,
    ``tension_aware``), a shipped model of the env's id (e.g. ``ppo``), or a path to a model
    .zip or run directory."""
    if spec in BASELINES:
        return make_baseline(spec, env)
    env_id = getattr(getattr(env, "spec", None), "id", None)
    if env_id is not None and spec in shipped_models(env_id):
        return TrainedPolicy(shipped_models(env_id)[spec], name=spec)
    path = Path(spec)
    if path.exists():
        return TrainedPolicy(path)
    known = sorted(BASELINES) + (sorted(shipped_models(env_id)) if env_id else [])
    raise ValueError(f"unknown controller {spec!r}: not one of {known}, and no such file or directory")
