"""Roll controllers out on held-out seeds and measure what the comparison reports.

One call of :func:`rollout` runs E episodes of one controller at once, on the native vector
env: sub-env e is seeded with ``seeds[e]``, so every controller meets the same initial
conditions. Each episode is recorded up to its first end. The vector env's same-step autoreset
starts a new episode in that slot, and the recording ignores it.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode

import tether_gym  # noqa: F401 - registers the ids
from tether_gym._optional import needs_extra
from tether_gym.envs.contract import Scalar
from tether_gym.limits import is_whole_number

from ..controllers.base import CountsSaturation, ReadsEnv

with needs_extra("train", "the evaluation's confidence intervals"):
    import scipy.stats

__all__ = ["EpisodeRecord", "METRICS", "rollout", "summarise"]


@dataclasses.dataclass
class EpisodeRecord:
    """What E episodes of one controller did, each recorded up to its end (arrays are NaN after).

    Attributes:
        name: the controller's name.
        time: (T+1,) s, from 0 (the reset) to the last control step.
        energy: (E, T+1) vibration energy, J.
        displacement: (E, T+1, 3) displacement of satellite ``satellite`` from its nominal place in
            the cluster frame, m.
        rewards: (E, T) reward of each step (0 after the end).
        slack: (E, T) 1 where some cable was slack after the step, NaN after the end.
        propellant: (E,) thrust impulse used, N*s.
        peak_tension: (E,) largest cable tension reached at any sub-step, N.
        terminated: (E,) whether the episode ended in a failure; ``end_step`` (E,) the step count
            at the end; ``end_reason`` (E,) its reason.
        saturation: fraction of commands the controller clipped (scripted controllers).
        seeds: (E,) the reset seeds.
    """

    name: str
    time: np.ndarray
    energy: np.ndarray
    displacement: np.ndarray
    rewards: np.ndarray
    slack: np.ndarray
    propellant: np.ndarray
    peak_tension: np.ndarray
    terminated: np.ndarray
    end_step: np.ndarray
    end_reason: np.ndarray
    saturation: float
    seeds: np.ndarray


def rollout(
    controller: Any,
    env_id: str,
    seeds: Sequence[int],
    name: str | None = None,
    satellite: int = 0,
    env_kwargs: dict[str, Any] | None = None,
    progress: Any = None,
) -> EpisodeRecord:
    """Run ``controller`` (a :class:`~agents.controllers.base.Policy`: anything with
    ``predict(obs, deterministic=True)``) for one episode per seed on
    ``gym.make_vec(env_id, num_envs=len(seeds), **env_kwargs)``.

    A controller that reads its env (:class:`~agents.controllers.base.ReadsEnv`) is attached to
    the vector env first; one that counts its clipped commands
    (:class:`~agents.controllers.base.CountsSaturation`) has its count restarted, and the record
    holds its ``saturation_fraction`` after the episodes.

    ``progress`` is an optional callable ``progress(steps_done, steps_total)``."""
    seed_list = list(seeds)
    bad = [s for s in seed_list if not is_whole_number(s) or s < 0]
    if bad:
        raise ValueError(f"seeds must be non-negative integers; got {bad[:5]}")
    if not is_whole_number(satellite):
        raise ValueError(f"satellite must be an integer index; got {satellite!r}")
    seeds = np.asarray(seed_list, dtype=np.int64)
    count = seeds.size
    if count == 0:
        raise ValueError("seeds must name at least one episode")
    # Same-step autoreset, as the rollout was written against: an ended sub-env runs on unobserved.
    envs = gym.make_vec(env_id, num_envs=count, **{"autoreset_mode": AutoresetMode.SAME_STEP, **dict(env_kwargs or {})})
    task = envs.unwrapped.task
    # Beads of tethers with mass are nodes too, but not observed: only a satellite has a displacement.
    if not 0 <= satellite < task.cluster.num_satellites:
        raise ValueError(f"satellite must be in 0..{task.cluster.num_satellites - 1}; got {satellite}")
    steps = envs.unwrapped.max_episode_steps
    if steps is None:
        raise ValueError(f"{env_id} has no max_episode_steps; pass env_kwargs={{'max_episode_steps': ...}}")
    if isinstance(controller, ReadsEnv):  # privileged controllers (mpc) read the state of the env they control
        controller.attach(envs)
    if isinstance(controller, CountsSaturation):
        controller.reset_statistics()
    observation, _ = envs.reset(seed=[int(s) for s in seeds])
    energy = np.full((count, steps + 1), np.nan)
    displacement = np.full((count, steps + 1, 3), np.nan)
    rewards = np.zeros((count, steps))
    slack = np.full((count, steps), np.nan)
    propellant = np.zeros(count)
    peak = np.zeros(count)
    terminated = np.zeros(count, dtype=bool)
    end_step = np.full(count, steps)
    end_reason = np.full(count, "running", dtype=object)
    alive = np.ones(count, dtype=bool)
    dev_index = slice(3 * satellite, 3 * satellite + 3)
    energy[:, 0] = task.scalars[:, Scalar.VIBRATION_ENERGY]
    displacement[:, 0] = task.observation[:, dev_index] * task.length_scale
    for k in range(steps):
        actions, _ = controller.predict(observation, deterministic=True)
        # The task's buffers hold the stepped state before any autoreset overwrites it, except for
        # the observation, which same-step autoreset replaces: read that from final_obs.
        observation, reward, term, trunc, infos = envs.step(actions)
        done = term | trunc
        state_energy = stepped_info(infos, done, "vibration_energy")
        rows = np.flatnonzero(alive)
        energy[rows, k + 1] = state_energy[rows]
        deviation = task_deviation(infos, observation, dev_index, task.length_scale)
        displacement[rows, k + 1] = deviation[rows]
        rewards[rows, k] = reward[rows]
        slack_count = stepped_info(infos, done, "slack_count")
        slack[rows, k] = slack_count[rows] > 0
        tension = stepped_info(infos, done, "peak_tension")
        peak[rows] = np.maximum(peak[rows], tension[rows].max(axis=1))
        used = stepped_info(infos, done, "propellant_used")
        propellant[rows] = used[rows]
        ended = alive & done
        if ended.any():
            reasons = infos["final_info"]["end_reason"]
            for e in np.flatnonzero(ended):
                terminated[e] = bool(term[e])
                end_step[e] = k + 1
                end_reason[e] = str(reasons[e])
            alive &= ~done
        if progress is not None:
            progress(k + 1, steps)
        if not alive.any():
            break
    envs.close()
    return EpisodeRecord(
        name=name or getattr(controller, "name", type(controller).__name__),
        time=np.arange(steps + 1) * task.config.control_interval,
        energy=energy,
        displacement=displacement,
        rewards=rewards,
        slack=slack,
        propellant=propellant,
        peak_tension=peak,
        terminated=terminated,
        end_step=end_step,
        end_reason=end_reason,
        saturation=float(getattr(controller, "saturation_fraction", 0.0)),
        seeds=seeds,
    )


def stepped_info(infos: dict[str, Any], done: np.ndarray, key: str) -> np.ndarray:
    """The info ``key`` of the state each sub-env stepped into: from ``infos["final_info"]`` where
    the sub-env ended (``done``, (E,) bool) and was reset in the same step, else from ``infos``."""
    final_info = infos.get("final_info", {})
    new, old = np.asarray(infos.get(key, 0.0)), np.asarray(final_info.get(key, 0.0))
    return np.where(done.reshape((-1,) + (1,) * (max(new.ndim, old.ndim) - 1)), old, new)


def task_deviation(infos: dict[str, Any], observation: np.ndarray, index: slice, length_scale: float) -> np.ndarray:
    """(E, 3) displacement of the recorded satellite after a step, m: from the observation, or,
    for sub-envs that ended (and were reset in the same step), from their final observation."""
    deviation = np.asarray(observation, dtype=np.float64)[:, index] * length_scale
    if "final_obs" in infos:
        for e in np.flatnonzero(infos["_final_obs"]):
            deviation[e] = np.asarray(infos["final_obs"][e], dtype=np.float64)[index] * length_scale
    return deviation


#: The comparison's columns: key, header, unit.
METRICS = (
    ("return", "return (mean ± 95% CI)", ""),
    ("energy_10s", "E(10 s)/E0", ""),
    ("energy_30s", "E(30 s)/E0", ""),
    ("settling_time", "settling to 5% E0 (median)", "s"),
    ("propellant", "propellant", "N·s"),
    ("peak_tension", "peak tension", "N"),
    ("slack_time", "time with slack cables", "%"),
    ("failures", "failures", ""),
    ("saturation", "commands clipped", "%"),
)


def settling_times(record: EpisodeRecord, fraction: float = 0.05) -> np.ndarray:
    """(E,) time (s) from which the vibration energy stays below ``fraction`` of its start, to
    the episode's end; inf if it never does (or the episode failed)."""
    ratio = record.energy / record.energy[:, :1]
    times = np.full(ratio.shape[0], math.inf)
    for e in range(ratio.shape[0]):
        if record.terminated[e]:
            continue
        above = np.flatnonzero(~(ratio[e, : record.end_step[e] + 1] <= fraction))
        if above.size == 0:
            times[e] = 0.0
        elif above[-1] < record.end_step[e]:
            times[e] = record.time[above[-1] + 1]
    return times


def energy_fraction_at(record: EpisodeRecord, seconds: float) -> np.ndarray:
    """(E,) vibration energy at ``seconds`` over its start (NaN for episodes that ended before)."""
    k = int(round(seconds / (record.time[1] - record.time[0])))
    if k >= record.time.size:
        return np.full(record.energy.shape[0], np.nan)
    return record.energy[:, k] / record.energy[:, 0]


def _mean_of_finite(values: np.ndarray) -> float:
    """Mean over the entries that are not NaN; NaN if there are none (no warning)."""
    finite = values[~np.isnan(values)]
    return float(finite.mean()) if finite.size else math.nan


def summarise(record: EpisodeRecord) -> dict[str, Any]:
    """The comparison's metrics of one controller: numbers (mean over episodes unless stated)
    and their formatted table cells."""
    returns = record.rewards.sum(axis=1)
    count = returns.size
    half_width = (
        float(scipy.stats.t.ppf(0.975, count - 1) * returns.std(ddof=1) / math.sqrt(count)) if count > 1 else math.nan
    )
    settle = settling_times(record)
    settled = np.isfinite(settle)
    median_settle = float(np.median(settle))
    values = {
        "return": float(returns.mean()),
        "return_ci95": half_width,
        "energy_10s": _mean_of_finite(energy_fraction_at(record, 10.0)),
        "energy_30s": _mean_of_finite(energy_fraction_at(record, 30.0)),
        "settling_time": median_settle,
        "settled": int(settled.sum()),
        "propellant": float(record.propellant.mean()),
        "peak_tension": float(record.peak_tension.mean()),
        "slack_time": float(100 * np.nanmean(record.slack)),
        "failures": int(record.terminated.sum()),
        "episodes": count,
        "saturation": 100 * record.saturation,
    }
    horizon = record.time[-1]
    cells = {
        "return": f"{values['return']:.1f} ± {half_width:.1f}",
        "energy_10s": f"{values['energy_10s']:.3f}",
        "energy_30s": f"{values['energy_30s']:.4f}",
        "settling_time": (f"{median_settle:.1f} s" if math.isfinite(median_settle) else f"> {horizon:.0f} s")
        + f" ({values['settled']}/{count} settle)",
        "propellant": f"{values['propellant']:.2f}",
        "peak_tension": f"{values['peak_tension']:.1f}",
        "slack_time": f"{values['slack_time']:.0f}",
        "failures": f"{values['failures']}/{count}",
        "saturation": f"{values['saturation']:.0f}",
    }
    return {"values": values, "cells": cells}
