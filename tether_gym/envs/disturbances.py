"""Disturbances and faults of the damping task: their settings, and what they do to each episode.

All are off by default.  Each cluster draws its own from its own generator, so a cluster gets
the same disturbances in any batch:

* disturbances: random kicks (``impulse_magnitude`` at Poisson rate ``impulse_rate``), a
  periodic force on every satellite (``periodic_amplitude``, ``periodic_period``), Gaussian
  thrust noise (``thrust_noise``) and an actuation delay (``thrust_delay`` control intervals);
* faults: one thruster failing at a random time (``thruster_failure_probability``,
  ``thruster_failure_window``), and cables breaking past their breaking load, which end the
  episode or not (``cable_failure``).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from typing import Any, Literal

import numpy as np

from tether_gym.envs.arguments import (
    MAX_IMPULSE,
    MAX_IMPULSE_RATE,
    MAX_PERIODIC_AMPLITUDE,
    MAX_THRUST_DELAY,
    MAX_THRUST_NOISE,
    MAX_TIME,
    EnvArgumentError,
    check_choice,
    check_number,
    check_whole,
    items_of,
    real_or_none,
)
from tether_gym.limits import short_repr

__all__ = ["CableFailure", "DisturbanceConfig", "Disturbances", "FaultConfig"]

CableFailure = Literal["terminate", "continue"]


@dataclasses.dataclass(frozen=True)
class DisturbanceConfig:
    """What disturbs every episode (SI units); see :class:`~tether_gym.envs.TaskConfig`.

    Attributes:
        impulse_magnitude: size of random impulsive kicks, N*s (0: none).  Kicks arrive as a
            Poisson process of rate ``impulse_rate``; each hits one random satellite in a random
            direction, as a force held over one control interval.
        impulse_rate: mean number of kicks per second.
        periodic_amplitude: amplitude of a periodic external force on every satellite, N (0:
            none), ``A d_i sin(2 pi t / periodic_period + phi_i)`` with a random unit direction
            ``d_i`` and phase ``phi_i`` per satellite and episode.
        periodic_period: its period, s.
        thrust_noise: std of Gaussian noise added to each delivered thrust component, as a
            fraction of the thruster's ``max_thrust``.
        thrust_delay: actuation delay in control intervals: an action acts this many steps
            after it is given (zero thrust before).
    """

    impulse_magnitude: float = 0.0
    impulse_rate: float = 0.05
    periodic_amplitude: float = 0.0
    periodic_period: float = 20.0
    thrust_noise: float = 0.0
    thrust_delay: int = 0

    def __post_init__(self) -> None:
        number = check_number
        fields = {
            "impulse_magnitude": number("impulse_magnitude", self.impulse_magnitude, 0.0, MAX_IMPULSE, "N*s"),
            "impulse_rate": number("impulse_rate", self.impulse_rate, 0.0, MAX_IMPULSE_RATE, "1/s"),
            "periodic_amplitude": number(
                "periodic_amplitude", self.periodic_amplitude, 0.0, MAX_PERIODIC_AMPLITUDE, "N"
            ),
            "periodic_period": number("periodic_period", self.periodic_period, 0.0, MAX_TIME, "s", low_open=True),
            "thrust_noise": number(
                "thrust_noise", self.thrust_noise, 0.0, MAX_THRUST_NOISE, fix="a multiple of max_thrust"
            ),
            "thrust_delay": check_whole("thrust_delay", self.thrust_delay, 0, MAX_THRUST_DELAY, "control intervals"),
        }
        for name, value in fields.items():
            object.__setattr__(self, name, value)

    def check_sampling(self, control_interval: float) -> None:
        """Raise unless the periodic force is sampled at least twice per period by
        ``control_interval`` (s): the force is held over each interval, so a shorter period
        aliases."""
        if self.periodic_amplitude and self.periodic_period < 2.0 * control_interval:
            raise EnvArgumentError(
                f"periodic_period ({self.periodic_period:g} s) must be at least two control intervals "
                f"(2 x {control_interval:g} s): the periodic force is sampled once per interval, so a "
                "shorter period aliases; raise periodic_period or lower control_interval"
            )


@dataclasses.dataclass(frozen=True)
class FaultConfig:
    """What may fail in an episode; see :class:`~tether_gym.envs.TaskConfig`.

    Attributes:
        thruster_failure_probability: chance that one random thruster fails in an episode; it
            then delivers no thrust from a time drawn uniformly in ``thruster_failure_window``.
        thruster_failure_window: (start, end) of that time, s.
        cable_failure: a cable past its breaking load breaks (and stays broken until reset);
            ``"terminate"`` ends the episode there, ``"continue"`` lets the cluster go on
            without it.
    """

    thruster_failure_probability: float = 0.0
    thruster_failure_window: tuple[float, float] = (0.0, 30.0)
    cable_failure: CableFailure = "terminate"

    def __post_init__(self) -> None:
        fields: dict[str, Any] = {
            "thruster_failure_probability": check_number(
                "thruster_failure_probability", self.thruster_failure_probability, 0.0, 1.0, fix="a probability"
            ),
            "thruster_failure_window": self._checked_window(),
            "cable_failure": check_choice("cable_failure", self.cable_failure, ("terminate", "continue")),
        }
        for name, value in fields.items():
            object.__setattr__(self, name, value)

    def _checked_window(self) -> tuple[float, float]:
        """``thruster_failure_window`` as (start, end) with 0 <= start <= end <= MAX_TIME."""
        usage = f"thruster_failure_window must be (start, end) in s with 0 <= start <= end <= {MAX_TIME:g}"
        items = items_of("thruster_failure_window", self.thruster_failure_window, "(start, end) in s")
        times = [real_or_none(item) for item in items]
        if len(times) != 2 or any(t is None or not math.isfinite(t) for t in times):
            raise EnvArgumentError(f"{usage}; got {short_repr(self.thruster_failure_window)}")
        start, end = times
        if not (0.0 <= start <= end <= MAX_TIME):  # type: ignore[operator]
            raise EnvArgumentError(f"{usage}; got {short_repr(self.thruster_failure_window)}")
        return (start, end)  # type: ignore[return-value]


class Disturbances:
    """The disturbances and faults of B episodes: what each cluster's episode holds, drawn at its
    reset, and what they do to the actions and forces of each step.

    Args:
        disturbances, faults: the settings.
        num_clusters: B.
        num_nodes: n, the nodes per cluster.
        thrusters: (k,) the satellites that carry a thruster.
        max_thrust: (k,) each thruster's largest force, N.
        control_interval: s.
        num_satellites: S, the leading nodes that are satellites (default n): periodic forces and
            impulses act on them only, never on a tether's beads.

    Attributes (the episodes' state, (B, ...) arrays):
        disturbance: (B, n, 3) the external disturbance force of the last interval, N.
        thruster_ok: (B, k) bool, thrusters that have not failed.
        failure_time: (B,) when the episode's failing thruster fails, s (inf: none fails).
        failing_thruster: (B,) which one.
        periodic_direction: (B, n, 3) unit directions of the periodic force.
        periodic_phase: (B, n) its phases, rad.
        action_queue: (B, thrust_delay, 3k) the actions given but not acting yet.
        draws: whether any disturbance or fault draws random numbers (``apply`` then needs one
            generator per cluster).
        alters_actions: whether :meth:`acting_actions` may change the actions (a delay or a
            thruster failure is configured).
    """

    #: The arrays above, in the order the task's snapshots list them.
    STATE = (
        "disturbance",
        "thruster_ok",
        "failure_time",
        "failing_thruster",
        "periodic_direction",
        "periodic_phase",
        "action_queue",
    )

    def __init__(
        self,
        disturbances: DisturbanceConfig,
        faults: FaultConfig,
        num_clusters: int,
        num_nodes: int,
        thrusters: np.ndarray,
        max_thrust: np.ndarray,
        control_interval: float,
        num_satellites: int | None = None,
    ) -> None:
        self.config = disturbances
        self.faults = faults
        self.thrusters = thrusters
        self.max_thrust = max_thrust
        self.control_interval = control_interval
        B, n, k = num_clusters, num_nodes, thrusters.size
        self.disturbance = np.zeros((B, n, 3))
        self.thruster_ok = np.ones((B, k), dtype=np.bool_)
        self.failure_time = np.full(B, np.inf)
        self.failing_thruster = np.zeros(B, dtype=np.int64)
        # External forces act on the satellites (the leading nodes), not on a tether's beads.
        S = n if num_satellites is None else num_satellites
        self.periodic_direction = np.zeros((B, S, 3))
        self.periodic_phase = np.zeros((B, S))
        self.action_queue = np.zeros((B, disturbances.thrust_delay, 3 * k))
        self.draws = bool(
            disturbances.impulse_magnitude
            or disturbances.periodic_amplitude
            or disturbances.thrust_noise
            or faults.thruster_failure_probability
        )
        self.alters_actions = bool(disturbances.thrust_delay or faults.thruster_failure_probability)

    def reset(self, rngs: Sequence[np.random.Generator], indices: np.ndarray) -> None:
        """Start the episodes of clusters ``indices``: nothing in the delay line, every thruster
        working, and (when configured) the episode's periodic force and thruster failure drawn
        from ``rngs[k]`` for cluster ``indices[k]``."""
        self.disturbance[indices] = 0.0
        self.thruster_ok[indices] = True
        self.action_queue[indices] = 0.0
        if self.draws:
            for rng, b in zip(rngs, indices, strict=True):
                self._draw_episode(rng, int(b))

    def _draw_episode(self, rng: np.random.Generator, b: int) -> None:
        """Draw cluster ``b``'s periodic-force directions and phases and its thruster failure."""
        n = self.periodic_phase.shape[1]
        if self.config.periodic_amplitude:
            direction = rng.standard_normal((n, 3))
            self.periodic_direction[b] = direction / np.linalg.norm(direction, axis=1, keepdims=True)
            self.periodic_phase[b] = rng.uniform(0.0, 2.0 * math.pi, n)
        self.failure_time[b] = math.inf
        probability = self.faults.thruster_failure_probability
        if probability and rng.random() < probability:
            self.failure_time[b] = rng.uniform(*self.faults.thruster_failure_window)
            self.failing_thruster[b] = rng.integers(self.thrusters.size)

    def acting_actions(self, actions: np.ndarray, active: np.ndarray, time: np.ndarray) -> np.ndarray:
        """The (B, 3k) actions that act in this step, given the ``actions`` just given to the
        ``active`` clusters at their ``time`` (B,) s: those given ``thrust_delay`` steps earlier,
        with the commands of failed thrusters zeroed."""
        if self.config.thrust_delay:
            given = actions
            actions = np.where(active[:, None], self.action_queue[:, 0], 0.0)
            self.action_queue[active] = np.concatenate([self.action_queue[active, 1:], given[active, None]], axis=1)
        if self.faults.thruster_failure_probability:
            failing = np.flatnonzero(active & (time >= self.failure_time))
            self.thruster_ok[failing, self.failing_thruster[failing]] = False
            if not self.thruster_ok.all():
                count = self.thruster_ok.shape[0]
                actions = (actions.reshape(count, -1, 3) * self.thruster_ok[:, :, None]).reshape(actions.shape)
        return actions

    def apply(
        self,
        active: np.ndarray,
        rngs: Sequence[np.random.Generator],
        time: np.ndarray,
        difficulty: float,
        force: np.ndarray,
        thrust: np.ndarray,
    ) -> None:
        """Add this interval's disturbance force and thrust noise to the ``force`` (B, n, 3) N
        and the ``thrust`` (B, n, 3) N of the ``active`` clusters, at their ``time`` (B,) s, scaled
        by ``difficulty``.

        Each cluster makes at most one draw per kind from its own generator (so it gets the same
        numbers in any batch); the rest is vectorised over the batch."""
        config = self.config
        interval = self.control_interval
        n = self.disturbance.shape[1]
        clusters = np.flatnonzero(active)
        disturbance = np.zeros((clusters.size, n, 3))
        if config.periodic_amplitude:
            midpoint = time[clusters] + 0.5 * interval
            wave = np.sin(2.0 * math.pi * midpoint[:, None] / config.periodic_period + self.periodic_phase[clusters])
            S = self.periodic_phase.shape[1]
            disturbance[:, :S] += (
                difficulty * config.periodic_amplitude * wave[:, :, None] * self.periodic_direction[clusters]
            )
        if config.impulse_magnitude:
            # Per cluster: whether a kick comes, which satellite, and a direction uniform on the sphere.
            draws = np.array([rngs[int(b)].random(4) for b in clusters]).reshape(-1, 4)
            kicked = np.flatnonzero(draws[:, 0] < 1.0 - math.exp(-config.impulse_rate * interval))
            S = self.periodic_phase.shape[1]
            node = np.minimum((draws[kicked, 1] * S).astype(np.int64), S - 1)
            z = 2.0 * draws[kicked, 2] - 1.0
            azimuth = 2.0 * math.pi * draws[kicked, 3]
            radius = np.sqrt(1.0 - z * z)
            direction = np.stack([radius * np.cos(azimuth), radius * np.sin(azimuth), z], axis=1)
            disturbance[kicked, node] += difficulty * config.impulse_magnitude / interval * direction
        if config.thrust_noise:
            k = self.thrusters.size
            noise = np.array([rngs[int(b)].standard_normal((k, 3)) for b in clusters]).reshape(-1, k, 3)
            noise *= (difficulty * config.thrust_noise * self.max_thrust[None, :] * self.thruster_ok[clusters])[
                :, :, None
            ]
            thrust[clusters[:, None], self.thrusters[None, :]] += noise
            force[clusters[:, None], self.thrusters[None, :]] += noise
        self.disturbance[clusters] = disturbance
        force[clusters] += disturbance
