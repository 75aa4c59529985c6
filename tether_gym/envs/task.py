"""The vibration-damping task, batched over clusters: actions, observations, rewards, episode ends.

:class:`DampingTask` sits on one :class:`~tether_gym.BatchSimulator` and turns it into the task
every environment shares: the single :class:`~tether_gym.envs.TetherClusterEnv` is a batch of
one, and a vector env is a batch of many.  Nothing here integrates dynamics; it only maps
actions to forces, and states to observations, rewards and end flags.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike

from tether_gym.cluster import Cluster
from tether_gym.envs import _task_kernels
from tether_gym.simulator import DEFAULT_SAFETY_FACTOR, AdvanceStats, BatchSimulator

__all__ = ["END_REASONS", "OBSERVATION_LIMIT", "DampingTask", "Measurements", "TaskConfig"]

ThrustLimit = Literal["per_axis", "magnitude"]

#: ``end_reason`` codes reported in ``info`` (index into this tuple).
END_REASONS = ("running", "formation_lost", "cable_broken", "numerics_diverged")

RANDOMISABLE = ("masses", "EA", "damping", "N0")

#: Observations are clipped to +-this (it is reached only far beyond a lost formation).
OBSERVATION_LIMIT = 1e4


@dataclasses.dataclass
class Measurements:
    """What the task reads off a batch after each reset or step; arrays over the B clusters.

    Attributes:
        observation: (B, observation_size) float64, before noise.
        vibration_energy: (B,) J.
        max_deviation: (B,) largest distance of a satellite from its nominal place in the cluster
            frame, m.
        slack_fraction: (B,) fraction of cables slack.
    """

    observation: np.ndarray
    vibration_energy: np.ndarray
    max_deviation: np.ndarray
    slack_fraction: np.ndarray

    @classmethod
    def empty(cls, batch: int, observation_size: int) -> Measurements:
        return cls(np.zeros((batch, observation_size)), np.zeros(batch), np.zeros(batch), np.zeros(batch))


def measure(
    sim: BatchSimulator, bias: np.ndarray, nominal: np.ndarray, nominal_strain_energy: np.ndarray,
    observed: np.ndarray, length_scale: float, speed_scale: float, observe_tensions: bool,
    out: Measurements,
) -> Measurements:
    """Fill ``out`` from the simulator's current state (one compiled pass over the batch)."""
    _task_kernels.measure(
        sim.positions_, sim.velocities_, sim.masses, sim.tension, sim.stiffness, sim.L0, sim.breaking_load,
        bias, nominal, nominal_strain_energy, sim.cables, observed, length_scale, speed_scale, observe_tensions,
        out.observation, out.vibration_energy, out.max_deviation, out.slack_fraction,
    )
    return out


@dataclasses.dataclass(frozen=True)
class TaskConfig:
    """Settings of the damping task (SI units).  Frozen: build a new one to change anything.

    Attributes:
        control_interval: time between actions, s; the simulator sub-steps inside it.
        thrusters: indices of the satellites that carry a thruster (None: all).
        max_thrust: largest thruster force, N; a scalar or one value per thruster.
        thrust_limit: ``"per_axis"`` (each component within +-max_thrust) or ``"magnitude"`` (the
            force vector's norm within max_thrust; a longer command is scaled back).
        initial_displacement: std of the random initial displacement per component, m.
        initial_velocity: std of the random initial velocity per component, m/s.
        vibration_weight: weight of the normalised vibration energy in the cost.
        propellant_weight: weight of the normalised thrust impulse in the cost.
        slack_weight: weight of the fraction of slack cables in the cost.
        failure_penalty: one-off cost when the episode terminates on a failure.
        max_deviation: a satellite farther than this from its nominal place in the cluster
            frame ends the episode (formation lost), m; None: 30 % of the shortest cable.
        observe_tensions: append cable tensions / breaking load to the observation.
        observation_noise: std of Gaussian noise added to the observation (its own units).
        observed_satellites: satellites whose displacements and velocities are observed (None:
            all).
        randomize: relative spread of domain randomisation per reset, e.g. ``{"masses": 0.2}``
            draws every mass uniformly within +-20 % of nominal; keys among masses, EA, damping, N0.
        safety_factor: the simulator's sub-step as a fraction of the critical step.
    """

    control_interval: float = 0.1
    thrusters: tuple[int, ...] | None = None
    max_thrust: float | tuple[float, ...] = 1.0
    thrust_limit: ThrustLimit = "per_axis"
    initial_displacement: float = 0.05
    initial_velocity: float = 0.1
    vibration_weight: float = 1.0
    propellant_weight: float = 0.1
    slack_weight: float = 0.0
    failure_penalty: float = 100.0
    max_deviation: float | None = None
    observe_tensions: bool = False
    observation_noise: float = 0.0
    observed_satellites: tuple[int, ...] | None = None
    randomize: Mapping[str, float] = dataclasses.field(default_factory=dict)
    safety_factor: float = DEFAULT_SAFETY_FACTOR

    def validate(self, cluster: Cluster) -> None:
        """Raise ``ValueError`` naming any setting that does not fit ``cluster``."""
        n = cluster.num_nodes
        if not (math.isfinite(self.control_interval) and self.control_interval > 0):
            raise ValueError(f"control_interval must be a finite number of seconds > 0; got {self.control_interval!r}")
        for name, indices in (("thrusters", self.thrusters), ("observed_satellites", self.observed_satellites)):
            if indices is None:
                continue
            if len(indices) == 0:
                raise ValueError(f"{name} must name at least one satellite (or be None for all)")
            bad = [i for i in indices if not (isinstance(i, (int, np.integer)) and 0 <= i < n)]
            if bad:
                raise ValueError(f"{name} {bad} are not satellites of this {n}-satellite cluster (valid: 0..{n - 1})")
            if len(set(indices)) != len(indices):
                raise ValueError(f"{name} lists a satellite twice: {list(indices)}")
        count = n if self.thrusters is None else len(self.thrusters)
        thrust = np.asarray(self.max_thrust, dtype=float)
        if thrust.ndim > 1 or (thrust.ndim == 1 and thrust.shape[0] != count):
            raise ValueError(f"max_thrust must be a scalar or one value per thruster ({count}); got {self.max_thrust!r}")
        if not np.all(np.isfinite(thrust)) or np.any(thrust <= 0):
            raise ValueError(f"max_thrust must be finite and > 0 N; got {self.max_thrust!r}")
        if self.thrust_limit not in ("per_axis", "magnitude"):
            raise ValueError(f"thrust_limit must be 'per_axis' or 'magnitude'; got {self.thrust_limit!r}")
        for name in ("initial_displacement", "initial_velocity", "vibration_weight", "propellant_weight",
                     "slack_weight", "failure_penalty", "observation_noise"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0):
                raise ValueError(f"{name} must be a finite number >= 0; got {value!r}")
        if self.max_deviation is not None and not (self.max_deviation > 0):
            raise ValueError(f"max_deviation must be > 0 m (or None); got {self.max_deviation!r}")
        unknown = set(self.randomize) - set(RANDOMISABLE)
        if unknown:
            raise ValueError(f"randomize keys {sorted(unknown)} are unknown; use some of {list(RANDOMISABLE)}")
        for key, spread in self.randomize.items():
            if not (0 <= spread < 1):
                raise ValueError(f"randomize[{key!r}] must be a relative spread in [0, 1); got {spread!r}")


class DampingTask:
    """The damping task over a batch of B clusters of one topology.

    Args:
        cluster: the nominal cluster (its positions are the nominal shape).
        num_clusters: B.
        config: the :class:`TaskConfig`.
    """

    def __init__(self, cluster: Cluster, num_clusters: int, config: TaskConfig) -> None:
        config.validate(cluster)
        self.cluster = cluster
        self.config = config
        self.num_clusters = B = num_clusters
        n, m = cluster.num_nodes, cluster.num_cables
        self.sim = BatchSimulator(cluster, B, safety_factor=config.safety_factor)
        self.thrusters = np.arange(n) if config.thrusters is None else np.array(config.thrusters, dtype=np.int64)
        self.observed = np.arange(n) if config.observed_satellites is None else np.array(config.observed_satellites)
        self.max_thrust = np.broadcast_to(np.asarray(config.max_thrust, dtype=float), self.thrusters.shape).copy()
        self.action_size = 3 * self.thrusters.size
        self.max_deviation = (
            0.3 * float(cluster.L0.min()) if config.max_deviation is None else float(config.max_deviation)
        )
        # Observation scales: displacements and elongations in units of the initial displacement,
        # velocities in units of the initial velocity (each at least a small floor, so exact
        # resets with zero scales still give finite observations).
        self.length_scale = max(config.initial_displacement, 1e-3 * float(cluster.L0.min()))
        self.speed_scale = max(config.initial_velocity, 1e-3)
        self.observation_size = 6 * self.observed.size + m + (m if config.observe_tensions else 0)
        self.nominal = np.broadcast_to(cluster.positions, (B, n, 3)).copy()
        self.bias = np.zeros((B, n, 3))
        self.nominal_strain_energy = np.zeros(B)
        for b in range(B):
            self._set_nominal(b, cluster)
        self.full_impulse = float(self.max_thrust.sum()) * config.control_interval * (
            math.sqrt(3.0) if config.thrust_limit == "per_axis" else 1.0
        )
        self.energy_scale = self._energy_scale()
        self.propellant = np.zeros(B)
        self.impulse = np.zeros(B)
        self.last_thrust = np.zeros((B, n, 3))
        self.measurements = Measurements.empty(B, self.observation_size)
        self._measure()

    # ------------------------------------------------------------------ nominal state
    def _set_nominal(self, index: int, cluster: Cluster) -> None:
        """Cluster ``index`` gets ``cluster``'s parameters, and the bias thrust holding its shape."""
        self.sim.set_cluster(index, cluster, reset=False)
        self.bias[index] = self.sim.internal_forces(
            np.broadcast_to(cluster.positions, self.sim.positions.shape)
        )[index]
        tension = np.maximum(cluster.N0, 0.0)
        self.nominal_strain_energy[index] = float((0.5 * tension**2 / cluster.stiffness).sum())

    def _energy_scale(self) -> float:
        """Vibration-energy normaliser, J: the mean vibration energy of 64 reset states of the
        nominal cluster drawn with a fixed seed (so it is the same for every env instance)."""
        count = 64
        x0, v0 = self.sample_initial_state(np.random.default_rng(0), count)
        probe = BatchSimulator(self.cluster, count, safety_factor=self.config.safety_factor)
        probe.reset(x0, v0)
        shape = (count,) + self.cluster.positions.shape
        result = self._measure_batch(
            probe, np.ascontiguousarray(np.broadcast_to(self.bias[0], shape)),
            np.ascontiguousarray(np.broadcast_to(self.cluster.positions, shape)),
            np.full(count, self.nominal_strain_energy[0]), Measurements.empty(count, self.observation_size),
        )
        scale = float(np.mean(result.vibration_energy))
        return scale if scale > 0 else 1.0

    def _measure_batch(
        self, sim: BatchSimulator, bias: np.ndarray, nominal: np.ndarray, nominal_strain_energy: np.ndarray,
        out: Measurements,
    ) -> Measurements:
        return measure(sim, bias, nominal, nominal_strain_energy, self.observed, self.length_scale,
                       self.speed_scale, self.config.observe_tensions, out)

    def _measure(self) -> None:
        self._measure_batch(self.sim, self.bias, self.nominal, self.nominal_strain_energy, self.measurements)

    # ------------------------------------------------------------------ reset
    def sample_initial_state(self, rng: np.random.Generator, count: int) -> tuple[np.ndarray, np.ndarray]:
        """(count, n, 3) positions and velocities: the nominal shape plus Gaussian displacements and
        velocities of the configured scales, with the rigid part removed (centroid kept in place,
        zero linear and angular momentum), so that the motion is pure deformation."""
        n = self.cluster.num_nodes
        shape = (count, n, 3)
        displacement = self.config.initial_displacement * rng.standard_normal(shape)
        velocity = self.config.initial_velocity * rng.standard_normal(shape)
        masses = self.cluster.masses[None, :, None]
        displacement -= (masses * displacement).sum(axis=1, keepdims=True) / masses.sum(axis=1, keepdims=True)
        x0 = self.cluster.positions[None] + displacement
        _task_kernels.remove_rigid_velocity(x0, velocity, np.ascontiguousarray(np.broadcast_to(self.cluster.masses, (count, n))))
        return x0, velocity

    def reset(
        self,
        rng: np.random.Generator,
        indices: np.ndarray,
        positions: ArrayLike | None = None,
        velocities: ArrayLike | None = None,
    ) -> None:
        """Start new episodes for clusters ``indices``: randomise parameters (if configured) and
        draw initial conditions from ``rng``, or use the given (k, n, 3) positions/velocities."""
        for b in indices:
            if self.config.randomize:
                self._set_nominal(int(b), self._randomised_cluster(rng))
            elif self.sim.clusters[b] is not self.cluster:
                self._set_nominal(int(b), self.cluster)
        if positions is None and velocities is None:
            x0, v0 = self.sample_initial_state(rng, len(indices))
        else:
            x0 = self.nominal[indices] if positions is None else positions
            v0 = velocities
        self.sim.reset(x0, v0, indices=indices)
        self.propellant[indices] = 0.0
        self.last_thrust[indices] = 0.0
        self.impulse[indices] = 0.0
        self._measure()

    def _randomised_cluster(self, rng: np.random.Generator) -> Cluster:
        changes: dict[str, Any] = {}
        for key in RANDOMISABLE:  # fixed order: the draws do not depend on dict order
            spread = self.config.randomize.get(key, 0.0)
            if spread:
                nominal = getattr(self.cluster, key)
                changes[key] = nominal * rng.uniform(1 - spread, 1 + spread, nominal.shape)
        if "EA" in changes:  # keep the nominal reference lengths
            changes["L0"] = self.cluster.L0
        return self.cluster.replace(**changes)

    # ------------------------------------------------------------------ step
    def thrust(self, actions: np.ndarray) -> np.ndarray:
        """(B, n, 3) thruster forces, N, from (B, action_size) normalised actions (clipped to
        [-1, 1]; with the magnitude limit a command longer than 1 is scaled back to length 1)."""
        a = np.clip(actions, -1.0, 1.0).reshape(self.num_clusters, self.thrusters.size, 3)
        if self.config.thrust_limit == "magnitude":
            norm = np.sqrt((a * a).sum(axis=2, keepdims=True))
            a = a / np.maximum(norm, 1.0)
        forces = np.zeros((self.num_clusters, self.cluster.num_nodes, 3))
        forces[:, self.thrusters] = a * self.max_thrust[None, :, None]
        return forces

    def step(self, actions: np.ndarray, active: np.ndarray | None = None) -> AdvanceStats:
        """Apply (B, action_size) actions for one control interval (bias thrust added), then
        measure the new state."""
        thrust = self.thrust(actions)
        stats = self.sim.advance(self.config.control_interval, self.bias + thrust, active=active)
        impulse = np.sqrt((thrust * thrust).sum(axis=2)).sum(axis=1) * self.config.control_interval
        mask = slice(None) if active is None else active
        self.propellant[mask] += impulse[mask]
        self.impulse[mask] = impulse[mask]
        self.last_thrust[mask] = thrust[mask]
        self._measure()
        return stats

    # ------------------------------------------------------------------ results
    def observe(self, rng: np.random.Generator) -> np.ndarray:
        """(B, observation_size) float32 observation (see the env's documentation)."""
        observation = self.measurements.observation
        if self.config.observation_noise > 0:
            observation = observation + self.config.observation_noise * rng.standard_normal(observation.shape)
        clipped = np.clip(np.nan_to_num(observation, nan=0.0), -OBSERVATION_LIMIT, OBSERVATION_LIMIT)
        return clipped.astype(np.float32)

    def outcome(self, stats: AdvanceStats) -> dict[str, np.ndarray]:
        """Reward terms, reward and end flags of the interval just stepped, as (B,) arrays."""
        cfg = self.config
        measured = self.measurements
        diverged = stats.diverged
        broken = np.any(stats.peak_tension > self.sim.breaking_load, axis=1)
        lost = ~(measured.max_deviation <= self.max_deviation)  # NaN counts as lost
        end_reason = np.where(diverged, 3, np.where(broken, 2, np.where(lost, 1, 0)))
        terminated = end_reason > 0
        vibration = np.where(diverged, 0.0, measured.vibration_energy)
        terms = {
            "reward_vibration": -cfg.vibration_weight * vibration / self.energy_scale,
            "reward_propellant": -cfg.propellant_weight * self.impulse / self.full_impulse,
            "reward_slack": -cfg.slack_weight * measured.slack_fraction,
            "reward_failure": -cfg.failure_penalty * terminated,
        }
        reward = terms["reward_vibration"] + terms["reward_propellant"] + terms["reward_slack"] + terms["reward_failure"]
        return dict(terms, reward=reward, terminated=terminated, end_reason=end_reason)

    def info(self, index: int, stats: AdvanceStats | None, outcome: Mapping[str, np.ndarray] | None) -> dict[str, Any]:
        """The ``info`` dict of cluster ``index``."""
        sim = self.sim
        energy = sim.energy()
        info: dict[str, Any] = {
            "time": float(sim.time[index]),
            "vibration_energy": float(self.measurements.vibration_energy[index]),
            "kinetic_energy": float(energy.kinetic[index]),
            "strain_energy": float(energy.strain[index]),
            "dissipated_energy": float(energy.dissipated[index]),
            "external_work": float(energy.work[index]),
            "energy_residual": float(energy.residual[index]),
            "tensions": sim.tension[index].copy(),
            "slack_count": int(round(self.measurements.slack_fraction[index] * self.cluster.num_cables)),
            "max_deviation": float(self.measurements.max_deviation[index]),
            "propellant_used": float(self.propellant[index]),
            "thrust": self.last_thrust[index].copy(),
        }
        if stats is not None:
            info.update(
                substeps=int(stats.substeps[index]),
                step_min=float(stats.step_min[index]),
                step_max=float(stats.step_max[index]),
                peak_tension=stats.peak_tension[index].copy(),
            )
        if outcome is not None:
            for key in ("reward_vibration", "reward_propellant", "reward_slack", "reward_failure"):
                info[key] = float(outcome[key][index])
            info["end_reason"] = END_REASONS[int(outcome["end_reason"][index])]
        return info
