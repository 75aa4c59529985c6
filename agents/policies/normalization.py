"""Observation normalisation statistics as data: ``VecNormalize``'s state without the wrapper.

:class:`NormalizationStatistics` holds the running mean, variance and count of the observations
(and of the discounted return) with the normaliser's settings, reads and writes them as the
policy directory's ``normalization.json``, and normalises observations exactly as SB3's
``VecNormalize.normalize_obs`` does. Nothing here depends on SB3 beyond the two conversions
(:meth:`NormalizationStatistics.from_vec_normalize`, :meth:`NormalizationStatistics.apply_to`),
which only read and set its public attributes.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np

from tether_gym.limits import is_whole_number

from .codecs import decode_float, dump_json, encode_float, parse_json, require_entry
from .layout import FORMAT_VERSION, NORMALIZATION_FILE, PolicyFormatError

if TYPE_CHECKING:
    from stable_baselines3.common.vec_env import VecNormalize

__all__ = ["NormalizationStatistics"]


@dataclasses.dataclass
class NormalizationStatistics:
    """``VecNormalize``'s statistics and settings, without the wrapper and without pickle.

    :meth:`normalize_obs` computes exactly what ``VecNormalize.normalize_obs`` computes, with the
    same operations in the same dtypes, so actions match the SB3 pipeline bit for bit.

    Attributes:
        obs_mean, obs_var: (obs_dim,) running mean and variance of the raw observations.
        obs_count: number of observations behind them (SB3 starts it at 1e-4).
        ret_mean, ret_var, ret_count: the same for the discounted return (reward scaling).
        clip_obs, clip_reward: normalised observations and rewards are clipped to +-these.
        epsilon: added to the variance before the square root.
        gamma: discount of the return statistics.
        norm_obs, norm_reward: whether observations and rewards are normalised.
    """

    obs_mean: np.ndarray
    obs_var: np.ndarray
    obs_count: float
    ret_mean: np.ndarray
    ret_var: np.ndarray
    ret_count: float
    clip_obs: float
    clip_reward: float
    epsilon: float
    gamma: float
    norm_obs: bool
    norm_reward: bool

    @classmethod
    def fixed(cls, observations: np.ndarray) -> NormalizationStatistics:
        """Statistics fixed from (N, obs_dim) ``observations``, as ``VecNormalize`` would hold them
        had it seen exactly these: their mean and variance, no reward scaling, SB3's defaults for
        the rest (clip 10, epsilon 1e-8). The trainers that do not adapt their statistics while
        training (ARS, DAgger) normalise with these."""
        states = np.asarray(observations, dtype=np.float64)
        return cls(
            obs_mean=states.mean(axis=0),
            obs_var=states.var(axis=0),
            obs_count=float(len(states)),
            ret_mean=np.zeros(()),
            ret_var=np.ones(()),
            ret_count=1e-4,
            clip_obs=10.0,
            clip_reward=10.0,
            epsilon=1e-8,
            gamma=0.99,
            norm_obs=True,
            norm_reward=False,
        )

    @classmethod
    def from_vec_normalize(cls, normalizer: VecNormalize) -> NormalizationStatistics:
        """The statistics of a ``VecNormalize`` (Box observations only)."""
        if isinstance(normalizer.obs_rms, dict):
            raise PolicyFormatError("VecNormalize of dict observations is not supported by the policy format")
        return cls(
            obs_mean=np.array(normalizer.obs_rms.mean),
            obs_var=np.array(normalizer.obs_rms.var),
            obs_count=float(normalizer.obs_rms.count),
            ret_mean=np.array(normalizer.ret_rms.mean),
            ret_var=np.array(normalizer.ret_rms.var),
            ret_count=float(normalizer.ret_rms.count),
            clip_obs=float(normalizer.clip_obs),
            clip_reward=float(normalizer.clip_reward),
            epsilon=float(normalizer.epsilon),
            gamma=float(normalizer.gamma),
            norm_obs=bool(normalizer.norm_obs),
            norm_reward=bool(normalizer.norm_reward),
        )

    def apply_to(self, normalizer: VecNormalize) -> None:
        """Load these statistics and settings into a ``VecNormalize`` (to resume training)."""
        if normalizer.obs_rms.mean.shape != self.obs_mean.shape:
            raise PolicyFormatError(
                f"normalisation statistics have {self.obs_mean.shape} observations; the env has "
                f"{normalizer.obs_rms.mean.shape}"
            )
        normalizer.obs_rms.mean, normalizer.obs_rms.var = self.obs_mean.copy(), self.obs_var.copy()
        normalizer.obs_rms.count = self.obs_count
        normalizer.ret_rms.mean, normalizer.ret_rms.var = self.ret_mean.copy(), self.ret_var.copy()
        normalizer.ret_rms.count = self.ret_count
        normalizer.clip_obs, normalizer.clip_reward = self.clip_obs, self.clip_reward
        normalizer.epsilon, normalizer.gamma = self.epsilon, self.gamma
        normalizer.norm_obs, normalizer.norm_reward = self.norm_obs, self.norm_reward

    #: The normaliser's settings (not its running statistics): what a resumed run must share with
    #: the checkpoint, since the weights were trained on observations normalised so.
    SETTINGS: ClassVar[tuple[str, ...]] = ("norm_obs", "norm_reward", "clip_obs", "clip_reward", "epsilon", "gamma")

    def settings(self) -> dict[str, Any]:
        """The :data:`SETTINGS` of these statistics, by name."""
        return {name: getattr(self, name) for name in self.SETTINGS}

    @classmethod
    def settings_of(cls, normalizer: VecNormalize) -> dict[str, Any]:
        """The :data:`SETTINGS` of a ``VecNormalize`` (read from its public attributes)."""
        return {name: getattr(normalizer, name) for name in cls.SETTINGS}

    def normalize_obs(self, obs: np.ndarray) -> np.ndarray:
        """``clip((obs - mean) / sqrt(var + epsilon), -clip_obs, clip_obs)`` as float32 (obs
        unchanged if ``norm_obs`` is off), as ``VecNormalize.normalize_obs`` does."""
        if not self.norm_obs:
            return np.array(obs, copy=True)
        return np.clip(
            (obs - self.obs_mean) / np.sqrt(self.obs_var + self.epsilon), -self.clip_obs, self.clip_obs
        ).astype(np.float32)

    def to_json(self) -> str:
        def array(values: np.ndarray) -> dict[str, Any]:
            return {
                "shape": list(values.shape),
                "dtype": str(values.dtype),
                "values": [encode_float(v) for v in np.ravel(values)],
            }

        data = {
            "format": "tether-gym-normalization",
            "format_version": FORMAT_VERSION,
            "norm_obs": self.norm_obs,
            "norm_reward": self.norm_reward,
            "clip_obs": self.clip_obs,
            "clip_reward": self.clip_reward,
            "epsilon": self.epsilon,
            "gamma": self.gamma,
            "obs_rms": {"mean": array(self.obs_mean), "var": array(self.obs_var), "count": self.obs_count},
            "ret_rms": {"mean": array(self.ret_mean), "var": array(self.ret_var), "count": self.ret_count},
        }
        self.check(Path(NORMALIZATION_FILE))
        return dump_json(data)

    @classmethod
    def from_json(cls, data: bytes, where: Path) -> NormalizationStatistics:
        """Parse and check :meth:`to_json`'s output; errors name the file and the entry."""
        table = parse_json(data, where)
        if require_entry(table, "format", str, where) != "tether-gym-normalization":
            raise PolicyFormatError(f"{where} is not a tether-gym normalisation file (format {table['format']!r})")
        if require_entry(table, "format_version", int, where) != FORMAT_VERSION:
            raise PolicyFormatError(
                f"{where}: format_version {table['format_version']} is not {FORMAT_VERSION}: "
                f"use the tether-gym version that wrote it"
            )

        def array(entry: Any, key: str) -> np.ndarray:
            label = f"{where}: {key}"
            if not isinstance(entry, dict):
                raise PolicyFormatError(f"{label} must be an object with shape, dtype and values")
            shape, dtype, values = entry.get("shape"), entry.get("dtype"), entry.get("values")
            if not (isinstance(shape, list) and all(is_whole_number(n) and n >= 0 for n in shape)):
                raise PolicyFormatError(f"{label}.shape must be a list of non-negative integers; got {shape!r}")
            if dtype not in ("float32", "float64"):
                raise PolicyFormatError(f"{label}.dtype must be 'float32' or 'float64'; got {dtype!r}")
            if not isinstance(values, list) or len(values) != math.prod(shape):
                raise PolicyFormatError(f"{label}.values must be a list of {math.prod(shape)} numbers")
            return np.array([decode_float(v, f"{label}.values") for v in values], dtype=dtype).reshape(shape)

        obs_rms, ret_rms = require_entry(table, "obs_rms", dict, where), require_entry(table, "ret_rms", dict, where)
        statistics = cls(
            obs_mean=array(obs_rms.get("mean"), "obs_rms.mean"),
            obs_var=array(obs_rms.get("var"), "obs_rms.var"),
            obs_count=float(require_entry(obs_rms, "count", (int, float), where)),
            ret_mean=array(ret_rms.get("mean"), "ret_rms.mean"),
            ret_var=array(ret_rms.get("var"), "ret_rms.var"),
            ret_count=float(require_entry(ret_rms, "count", (int, float), where)),
            clip_obs=float(require_entry(table, "clip_obs", (int, float), where)),
            clip_reward=float(require_entry(table, "clip_reward", (int, float), where)),
            epsilon=float(require_entry(table, "epsilon", (int, float), where)),
            gamma=float(require_entry(table, "gamma", (int, float), where)),
            norm_obs=require_entry(table, "norm_obs", bool, where),
            norm_reward=require_entry(table, "norm_reward", bool, where),
        )
        statistics.check(where)
        return statistics

    def check(self, where: Path) -> None:
        """Finite statistics, non-negative variances and positive clips, or an error naming them."""
        for name in ("obs_mean", "obs_var", "ret_mean", "ret_var"):
            values = getattr(self, name)
            if not np.all(np.isfinite(values)):
                raise PolicyFormatError(f"{where}: {name} has non-finite entries")
            if name.endswith("var") and np.any(values < 0):
                raise PolicyFormatError(f"{where}: {name} has negative entries")
        if self.obs_mean.shape != self.obs_var.shape or self.ret_mean.shape != self.ret_var.shape:
            raise PolicyFormatError(f"{where}: mean and var shapes differ")
        if self.ret_mean.shape != ():
            # The return statistics are one number (VecNormalize's ret_rms has shape ()): any other
            # shape broadcast against the batch of rewards and failed, or scaled them wrongly.
            raise PolicyFormatError(
                f"{where}: ret_rms.mean and ret_rms.var must have shape [] (one number each); got "
                f"{list(self.ret_mean.shape)}: restore or re-create the file"
            )
        if not self.gamma <= 1:
            raise PolicyFormatError(f"{where}: gamma is a discount and must be in (0, 1]; got {self.gamma}")
        for name in ("obs_count", "ret_count", "clip_obs", "clip_reward", "epsilon", "gamma"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0) and not (name == "epsilon" and value == 0):
                raise PolicyFormatError(f"{where}: {name} must be a positive finite number; got {value}")
        if self.epsilon == 0 and (np.any(self.obs_var == 0) or np.any(self.ret_var == 0)):
            # (x - mean) / sqrt(var + epsilon) divides by zero: every such observation would be NaN.
            raise PolicyFormatError(
                f"{where}: epsilon is 0 and a variance is 0, which normalises to NaN: epsilon must be > 0 "
                "(SB3's default is 1e-8)"
            )
