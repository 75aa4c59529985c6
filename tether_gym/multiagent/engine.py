"""The batched multi-agent engine: B clusters x A agents over one :class:`~tether_gym.envs.DampingTask`.

Every multi-agent form (the PettingZoo :class:`~tether_gym.multiagent.TetherParallelEnv`, a batch
of one; the SB3 :class:`~tether_gym.multiagent.sb3.AgentVecEnv`, agents x clusters as rows) is a
thin layer over :class:`AgentBatch`. It adds to the task only what a satellite of its own would
see and be paid: local measurements, a communication graph with a delay line, observation noise
and reward shares. The dynamics, the reward and the end flags are the task's, read through its
public accessors; nothing here integrates anything or recomputes the reward.

**Agents** are the satellites that carry thrusters, in the order of the task's thrusters, named
``"satellite_<node index>"``. Agent k commands thruster k: its (3,) action is entries ``3 k ..
3 k + 2`` of the single-agent env's action, so the joint action is the agents' actions
concatenated in that order.

**A local observation** (float32, every entry NaN-free and clipped to +-1e4) is, per agent:

* ``D`` cable slots, one per cable of the satellite in cable order, padded to ``D``, the largest
  number of cables any agent of the id has. Slot fields (:data:`CABLE_FIELDS`): ``present`` (1,
  or 0 for a padding slot, whose other fields are 0), the cable's direction (unit vector from the
  satellite to its neighbour, as an attachment-angle sensor measures it), the neighbour's velocity
  relative to the satellite (units of ``initial_velocity``), the cable's elongation ``L - L0``
  (units of ``initial_displacement``, as in the single-agent observation) and its tension over its
  breaking load;
* the satellite's own thrust of the last step (delivered, over its ``max_thrust``; 3 entries);
* with communication, ``C`` message slots, padded to ``C``, the most partners any agent has:
  ``present`` then the partner's own measurements (its cable slots and thrust, as above), sent
  ``delay`` control steps earlier.

Everything is in the cluster's frame axes; no satellite sees absolute positions, the centre of
mass or the cluster's energy.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from gymnasium.utils import seeding

from tether_gym.envs.arguments import (
    MAX_OBSERVATION_NOISE,
    MAX_THRUST_DELAY,
    OBSERVATION_LIMIT,
    EnvArgumentError,
    check_choice,
    check_max_episode_steps,
    check_num_envs,
    check_number,
    check_seed,
    check_whole,
)
from tether_gym.envs.contract import REWARD_TERMS, Scalar
from tether_gym.envs.task import DampingTask, task_from_arguments
from tether_gym.limits import short_repr

__all__ = [
    "CABLE_FIELDS",
    "REWARD_MODES",
    "AgentBatch",
    "AgentGraph",
    "Communication",
    "LocalLayout",
    "LocalSensors",
    "agent_name",
]

#: The fields of one cable slot of a local observation, in order, with their widths.
CABLE_FIELDS: tuple[tuple[str, int], ...] = (
    ("present", 1),
    ("direction", 3),
    ("relative_velocity", 3),
    ("elongation", 1),
    ("tension_ratio", 1),
)


def _field_slices() -> dict[str, slice]:
    slices, start = {}, 0
    for name, width in CABLE_FIELDS:
        slices[name] = slice(start, start + width)
        start += width
    return slices


_FIELD_AT = _field_slices()
#: Entries of one cable slot.
CABLE_SLOT = sum(width for _, width in CABLE_FIELDS)

#: ``reward=`` values: the team reward (every agent gets the single-agent reward) or shares of it.
REWARD_MODES = ("team", "shares")


def agent_name(node: int) -> str:
    """The name of the agent on satellite ``node``."""
    return f"satellite_{node}"


def check_local_observation_noise(value: Any) -> float:
    """``local_observation_noise``, the std of the local observations' noise (observation
    units), as a float in ``[0, MAX_OBSERVATION_NOISE]``, or an :class:`EnvArgumentError` naming it."""
    return check_number("local_observation_noise", value, 0.0, MAX_OBSERVATION_NOISE, "(observation units)")


@dataclasses.dataclass(frozen=True)
class Communication:
    """Who hears whom, and how late.

    Attributes:
        hops: partners are the agents within this many cables (hops over the cable graph), or None.
        range: partners are the agents within this distance in the nominal shape, m, or None.
        delay: messages arrive this many control steps after they were measured (0: the same step).

    With neither ``hops`` nor ``range`` there is no communication (the default).
    """

    hops: int | None = None
    range: float | None = None
    delay: int = 0

    @property
    def enabled(self) -> bool:
        return self.hops is not None or self.range is not None

    @classmethod
    def parse(cls, value: Any) -> Communication:
        """``None`` (off) or a dict ``{"hops": h}`` or ``{"range": r}`` (m), with an optional
        ``"delay": k`` (control steps); anything else raises :class:`EnvArgumentError`."""
        if value is None:
            return cls()
        if isinstance(value, Communication):
            return value
        example = "{'hops': 1} or {'range': 50.0, 'delay': 2}"
        if not isinstance(value, Mapping):
            raise EnvArgumentError(
                f"communication must be None (off) or a dict such as {example}; got {short_repr(value)}"
            )
        unknown = sorted(set(value) - {"hops", "range", "delay"}, key=repr)
        if unknown:
            raise EnvArgumentError(
                f"unknown communication key(s) {unknown}; the keys are 'hops' or 'range', and 'delay'"
            )
        if ("hops" in value) == ("range" in value):
            raise EnvArgumentError(
                f"communication needs exactly one of 'hops' (cables) or 'range' (m), e.g. {example}; "
                f"got {short_repr(value)}"
            )
        hops = check_whole("communication['hops']", value["hops"], 1, 1000, "cables") if "hops" in value else None
        distance = (
            check_number("communication['range']", value["range"], 0.0, 1e12, "m", low_open=True)
            if "range" in value
            else None
        )
        delay = check_whole("communication['delay']", value.get("delay", 0), 0, MAX_THRUST_DELAY, "control steps")
        return cls(hops, distance, delay)


@dataclasses.dataclass(frozen=True)
class AgentGraph:
    """The agents of a cluster and what each one is wired to.

    Attributes:
        nodes: (A,) the satellite of each agent (the task's thrusters, in order).
        names: the agents' names.
        cables: (A, D) the cables of each agent, in cable order, -1 for padding.
        neighbours: (A, D) the satellite at the other end of each of those cables, -1 for padding.
        partners: (A, C) the agents (indices into ``nodes``) each agent hears, -1 for padding
            (C = 0 without communication).
    """

    nodes: np.ndarray
    names: tuple[str, ...]
    cables: np.ndarray
    neighbours: np.ndarray
    partners: np.ndarray

    @classmethod
    def build(cls, task: DampingTask, communication: Communication) -> AgentGraph:
        cluster = task.cluster
        nodes = np.asarray(task.thrusters, dtype=np.int64)
        ends = np.asarray(cluster.cables, dtype=np.int64)
        own = [np.flatnonzero((ends[:, 0] == i) | (ends[:, 1] == i)) for i in nodes.tolist()]
        degree = max(1, max(len(c) for c in own))
        cables = np.full((nodes.size, degree), -1, dtype=np.int64)
        neighbours = np.full((nodes.size, degree), -1, dtype=np.int64)
        for a, (i, mine) in enumerate(zip(nodes.tolist(), own, strict=True)):
            cables[a, : mine.size] = mine
            neighbours[a, : mine.size] = np.where(ends[mine, 0] == i, ends[mine, 1], ends[mine, 0])
        heard: list[list[int]] = [[] for _ in nodes]
        if communication.hops is not None:
            # A tether with beads is one hop between its satellites, not one per segment.
            plain = ends[: cluster.num_cables - sum(spec.segments for spec in cluster.tethers)]
            lines = np.array([spec.ends for spec in cluster.tethers], dtype=np.int64).reshape(-1, 2)
            hops = _hop_counts(cluster.num_nodes, np.concatenate([plain, lines]) if cluster.tethers else ends)
            heard = [
                [b for b, j in enumerate(nodes) if b != a and hops[i, j] <= communication.hops]
                for a, i in enumerate(nodes)
            ]
        elif communication.range is not None:
            distance = np.linalg.norm(cluster.positions[:, None] - cluster.positions[None], axis=-1)
            heard = [
                [b for b, j in enumerate(nodes) if b != a and distance[i, j] <= communication.range]
                for a, i in enumerate(nodes)
            ]
        width = max((len(h) for h in heard), default=0)
        partners = np.full((nodes.size, width), -1, dtype=np.int64)
        for a, h in enumerate(heard):
            partners[a, : len(h)] = h
        return cls(nodes, tuple(agent_name(i) for i in nodes.tolist()), cables, neighbours, partners)


def _hop_counts(num_nodes: int, cables: np.ndarray) -> np.ndarray:
    """(n, n) number of cables on the shortest path between two satellites (a large number where
    there is none), by breadth-first search."""
    adjacency: list[list[int]] = [[] for _ in range(num_nodes)]
    for i, j in cables.tolist():
        adjacency[i].append(j)
        adjacency[j].append(i)
    hops = np.full((num_nodes, num_nodes), np.iinfo(np.int64).max // 2, dtype=np.int64)
    for start in range(num_nodes):
        hops[start, start] = 0
        frontier = [start]
        while frontier:
            following = []
            for i in frontier:
                for j in adjacency[i]:
                    if hops[start, j] > hops[start, i] + 1:
                        hops[start, j] = hops[start, i] + 1
                        following.append(j)
            frontier = following
    return hops


@dataclasses.dataclass(frozen=True)
class LocalLayout:
    """Where each part of a local observation lies (see the module docstring).

    Attributes:
        slots: D, cable slots per agent; ``partners``: C, message slots per agent.
        own: slice of the agent's own measurements (``D * CABLE_SLOT + 3`` entries).
        cables: slice of its cable slots (within ``own``); ``thrust``: slice of its thrust.
        messages: slice of the message slots, each ``1 + own size`` entries.
        size: the observation's length.
    """

    slots: int
    partners: int
    own: slice = dataclasses.field(init=False)
    cables: slice = dataclasses.field(init=False)
    thrust: slice = dataclasses.field(init=False)
    messages: slice = dataclasses.field(init=False)
    size: int = dataclasses.field(init=False)

    def __post_init__(self) -> None:
        cable_end = self.slots * CABLE_SLOT
        own = cable_end + 3
        set_ = object.__setattr__
        set_(self, "cables", slice(0, cable_end))
        set_(self, "thrust", slice(cable_end, own))
        set_(self, "own", slice(0, own))
        set_(self, "messages", slice(own, own + self.partners * (1 + own)))
        set_(self, "size", own + self.partners * (1 + own))

    def cable_field(self, observation: np.ndarray, field: str) -> np.ndarray:
        """Field ``field`` of :data:`CABLE_FIELDS` of every cable slot of (..., size) observations:
        (..., D, width) (width 1 kept)."""
        slots = observation[..., self.cables].reshape(observation.shape[:-1] + (self.slots, CABLE_SLOT))
        return slots[..., _FIELD_AT[field]]

    def message(self, observation: np.ndarray, slot: int) -> tuple[np.ndarray, np.ndarray]:
        """``(present, measurements)`` of message slot ``slot`` of (..., size) observations."""
        width = 1 + self.own.stop
        start = self.messages.start + slot * width
        return observation[..., start], observation[..., start + 1 : start + width]


class LocalSensors:
    """What the agents of a task measure, hear and are paid: local observations and reward shares
    from any :class:`DampingTask`'s public state (an :class:`AgentBatch`'s, or a single-agent
    vector env's, for decentralised controllers evaluated there).

    Args:
        task: the batched task.
        communication: who hears whom: a :class:`Communication`, or what
            :meth:`Communication.parse` takes.
        local_observation_noise: std of the noise on measured entries (observation units), in
            ``[0, MAX_OBSERVATION_NOISE]``.

    Attributes:
        graph: the :class:`AgentGraph`; ``layout``: the :class:`LocalLayout`; ``num_agents``: A.
    """

    def __init__(self, task: DampingTask, communication: Any = None, local_observation_noise: float = 0.0) -> None:
        # The engine's checks (AgentBatch runs them too, before it builds the task): LocalSensors
        # is also made directly, over a single-agent vector env's task.
        communication = Communication.parse(communication)
        local_observation_noise = check_local_observation_noise(local_observation_noise)
        self.task = task
        self.communication = communication
        self.local_observation_noise = local_observation_noise
        self.graph = graph = AgentGraph.build(task, communication)
        self.num_agents = A = graph.nodes.size
        self.layout = LocalLayout(graph.cables.shape[1], graph.partners.shape[1])
        present = graph.cables >= 0
        self._present = present
        self._cable = np.where(present, graph.cables, 0)
        self._neighbour = np.where(present, graph.neighbours, 0)
        # Which entries are measured (get noise): not the present flags, not the padding.
        slots = np.repeat(present[:, :, None].astype(np.float64), CABLE_SLOT, axis=2)
        slots[:, :, _FIELD_AT["present"]] = 0.0
        self._measured = np.concatenate([slots.reshape(A, -1), np.ones((A, 3))], axis=1)
        self._partner = np.where(graph.partners >= 0, graph.partners, 0)
        self._heard = (graph.partners >= 0).astype(np.float64)
        # Reward shares: a cable's share is split equally between its agent ends.
        incidence = np.zeros((A, task.cluster.num_cables))
        for a in range(A):
            incidence[a, graph.cables[a, present[a]]] = 1.0
        ends = incidence.sum(axis=0)
        self._incidence = np.divide(incidence, ends, out=np.zeros_like(incidence), where=ends > 0)

    def measure(self, indices: np.ndarray, noise_rngs: Sequence[np.random.Generator] | None = None) -> np.ndarray:
        """(k, A, own size) float64: the agents' own measurements in clusters ``indices`` now;
        with noise configured, cluster ``indices[j]``'s drawn from ``noise_rngs[j]``."""
        task, sim, layout = self.task, self.task.sim, self.layout
        nodes = self.graph.nodes
        positions = sim.positions[indices]  # (k, n, 3) m
        velocities = sim.velocities[indices]
        offset = positions[:, self._neighbour] - positions[:, nodes][:, :, None]  # (k, A, D, 3) m
        length = np.linalg.norm(offset, axis=-1)
        direction = offset / np.maximum(length, 1e-300)[..., None]
        relative = (velocities[:, self._neighbour] - velocities[:, nodes][:, :, None]) / task.speed_scale
        rest = sim.L0[indices][:, self._cable]
        elongation = (length - rest) / task.length_scale
        tension = sim.tension[indices][:, self._cable] / sim.breaking_load[indices][:, self._cable]
        k, A, D = positions.shape[0], nodes.size, layout.slots
        slots = np.empty((k, A, D, CABLE_SLOT))
        slots[..., _FIELD_AT["present"]] = 1.0
        slots[..., _FIELD_AT["direction"]] = direction
        slots[..., _FIELD_AT["relative_velocity"]] = relative
        slots[..., _FIELD_AT["elongation"]] = elongation[..., None]
        slots[..., _FIELD_AT["tension_ratio"]] = tension[..., None]
        slots *= self._present[None, :, :, None]  # padding slots: exactly 0
        thrust = task.thrust[indices][:, nodes] / task.max_thrust[None, :, None]
        measured = np.concatenate([slots.reshape(k, A, D * CABLE_SLOT), thrust], axis=-1)
        if self.local_observation_noise:
            if noise_rngs is None:
                raise ValueError("local_observation_noise is set: measure() needs one noise generator per cluster")
            noise = np.stack([rng.standard_normal(measured.shape[1:]) for rng in noise_rngs])
            measured += self.local_observation_noise * noise * self._measured
        return np.clip(np.nan_to_num(measured, nan=0.0), -OBSERVATION_LIMIT, OBSERVATION_LIMIT)

    def assemble(self, own: np.ndarray, delayed: np.ndarray) -> np.ndarray:
        """(k, A, size) float32 observations from (k, A, own size) measurements now and the
        (k, A, own size) measurements the partners' messages carry (``delay`` steps old)."""
        if not self.layout.partners:
            return own.astype(np.float32)
        messages = delayed[:, self._partner] * self._heard[None, :, :, None]  # (k, A, C, own)
        present = np.broadcast_to(self._heard[None, :, :, None], messages.shape[:-1] + (1,))
        parts = np.concatenate([present, messages], axis=-1).reshape(own.shape[:2] + (-1,))
        return np.concatenate([own, parts], axis=-1).astype(np.float32)

    def shares(self) -> np.ndarray:
        """(B, A) the task's last rewards split between the agents: each reward term (the
        ``Scalar`` columns ``REWARD_*``) by non-negative weights that sum to 1, so that the shares
        add up to the team reward (to round-off):

        * vibration: in proportion to each agent's local energy, its satellite's kinetic energy
          relative to the centre of mass plus its part of its cables' strain energy
          ``T^2 / (2 EA / L0)`` (a cable's energy is split equally between its agent ends);
        * propellant: in proportion to the thrust each agent delivered;
        * slack: in proportion to each agent's part of the slack cables;
        * failure: equally.

        A term whose weights are all 0 (e.g. no thrust at all) is split equally.
        """
        task = self.task
        sim, nodes = task.sim, self.graph.nodes
        masses = sim.masses[:, nodes]
        velocities = sim.velocities
        centre = (sim.masses[:, :, None] * velocities).sum(axis=1) / sim.masses.sum(axis=1)[:, None]
        kinetic = 0.5 * masses * ((velocities[:, nodes] - centre[:, None]) ** 2).sum(axis=-1)
        strain = 0.5 * sim.tension**2 / sim.stiffness
        slack = (sim.tension <= 0.0).astype(np.float64)
        thrust = np.linalg.norm(task.thrust[:, nodes], axis=-1)
        weights = {
            Scalar.REWARD_VIBRATION: kinetic + strain @ self._incidence.T,
            Scalar.REWARD_PROPELLANT: thrust,
            Scalar.REWARD_SLACK: slack @ self._incidence.T,
            Scalar.REWARD_FAILURE: np.zeros_like(thrust),
        }
        shares = np.zeros((task.num_clusters, self.num_agents))
        for term in REWARD_TERMS:
            shares += task.scalars[:, term, None] * _normalised(weights[term])
        return shares


class AgentBatch:
    """B clusters of one id, each with A agents, over one :class:`DampingTask`.

    Holds everything a multi-agent env needs per cluster: the task's generator (disturbances,
    thrust noise, the global observation's noise: the single-agent env's draws, in its order), a
    second generator for the local observations' noise, the episode's step count, the global
    observation of the last reset or step, and the delay line of the agents' measurements.

    Args:
        num_clusters: B.
        env_kwargs: the env's keyword arguments (``preset``, ``preset_kwargs``, ``cluster``, task
            settings), checked by :func:`~tether_gym.envs.task.task_from_arguments`.
        max_episode_steps: truncation after this many steps (None: never).
        communication: None or a dict (see :meth:`Communication.parse`).
        reward: ``"team"`` or ``"shares"`` (see :meth:`rewards`).
        local_observation_noise: std of Gaussian noise on every measured entry of the local
            observations, in their units (not on ``present`` flags nor padding).
    """

    def __init__(
        self,
        num_clusters: int,
        env_kwargs: Mapping[str, Any],
        max_episode_steps: int | None = None,
        communication: Any = None,
        reward: str = "team",
        local_observation_noise: float = 0.0,
    ) -> None:
        communication = Communication.parse(communication)
        self.reward_mode = check_choice("reward", reward, REWARD_MODES)
        noise = check_local_observation_noise(local_observation_noise)
        self.max_episode_steps = max_episode_steps  # checked by the property
        B = check_num_envs(num_clusters)
        self.task = task = task_from_arguments(B, **dict(env_kwargs))
        self.num_clusters = B
        self.sensors = sensors = LocalSensors(task, communication, noise)
        self.graph, self.layout, self.num_agents = sensors.graph, sensors.layout, sensors.num_agents
        self.rngs: list[np.random.Generator] = [seeding.np_random()[0] for _ in range(B)]
        self.noise_rngs: list[np.random.Generator] = [np.random.default_rng() for _ in range(B)]
        self.episode_steps = np.zeros(B, dtype=np.int64)
        self.states = np.zeros((B, task.observation_size), dtype=np.float32)
        # The delay line: measurements of the last delay + 1 steps, the newest at ``head``.
        self.line = np.zeros((communication.delay + 1, B, self.num_agents, self.layout.own.stop))
        self.head = 0
        self._all = np.arange(B)

    @property
    def communication(self) -> Communication:
        return self.sensors.communication

    @property
    def max_episode_steps(self) -> int | None:
        """Truncation after this many steps of a cluster's episode (None: never)."""
        return self._max_episode_steps

    @max_episode_steps.setter
    def max_episode_steps(self, steps: int | None) -> None:
        # The vector env's check, on every assignment (an SB3 adapter's set_attr too).
        self._max_episode_steps = check_max_episode_steps(steps)

    # ------------------------------------------------------------------ reset / step
    def check_seeds(self, seeds: Sequence[Any]) -> list[int | None]:
        """``seeds`` checked: ints >= 0 or None (keep the cluster's generators)."""
        return [check_seed(f"seed[{k}]" if len(seeds) > 1 else "seed", s) for k, s in enumerate(seeds)]

    def reset(
        self,
        indices: np.ndarray,
        seeds: Sequence[int | None],
        positions: np.ndarray | None = None,
        velocities: np.ndarray | None = None,
    ) -> None:
        """Start new episodes for clusters ``indices`` (seeds checked here by :meth:`check_seeds`,
        before anything changes; exact states by the caller, with the task's
        ``check_reset_state``). A seed s gives the cluster the task generator
        ``seeding.np_random(s)`` (the single-agent env's) and a noise generator of its own,
        derived from s. The delay line of a reset cluster is filled with its first measurement."""
        seeds = self.check_seeds(seeds)
        if len(seeds) != len(indices):
            raise EnvArgumentError(
                f"seeds must hold one seed (or None) per reset cluster: {len(indices)}; got {len(seeds)}"
            )
        for b, seed in zip(indices.tolist(), seeds, strict=True):
            if seed is not None:
                self.rngs[b] = seeding.np_random(seed)[0]
                self.noise_rngs[b] = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(1,)))
        rngs = [self.rngs[b] for b in indices.tolist()]
        self.task.reset(rngs, indices, positions, velocities)
        self.episode_steps[indices] = 0
        self.states[indices] = self.task.observe(rngs, indices)
        self.line[:, indices] = self.sensors.measure(indices, [self.noise_rngs[b] for b in indices.tolist()])[None]

    def step(self, joint_actions: np.ndarray) -> None:
        """Step every cluster with (B, 3 A) float64 joint actions (checked by the caller)."""
        task = self.task
        task.step(joint_actions, rngs=self.rngs)
        self.episode_steps += 1
        self.states[:] = task.observe(self.rngs)
        self.head = (self.head + 1) % self.line.shape[0]
        self.line[self.head] = self.sensors.measure(self._all, self.noise_rngs)

    def observations(self, indices: np.ndarray | None = None) -> np.ndarray:
        """(k, A, size) float32 local observations of clusters ``indices`` (default all): the
        newest measurements, and with communication the partners' from ``delay`` steps ago."""
        rows = self._all if indices is None else indices
        delayed = self.line[(self.head + 1) % self.line.shape[0], rows]  # the oldest entry: delay steps ago
        return self.sensors.assemble(self.line[self.head, rows], delayed)

    # ------------------------------------------------------------------ rewards and ends
    def rewards(self) -> np.ndarray:
        """(B, A) rewards of the last step: ``"team"``, every agent gets the single-agent reward;
        ``"shares"``, :meth:`LocalSensors.shares`."""
        if self.reward_mode == "shares":
            return self.sensors.shares()
        return np.repeat(self.task.rewards()[:, None], self.num_agents, axis=1)

    def terminated(self) -> np.ndarray:
        """(B,) bool: clusters whose last step ended the episode (the task's end flags)."""
        return self.task.terminated()

    def truncated(self) -> np.ndarray:
        """(B,) bool: clusters whose episode reached ``max_episode_steps``."""
        if self.max_episode_steps is None:
            return np.zeros(self.num_clusters, dtype=np.bool_)
        return self.episode_steps >= self.max_episode_steps

    def joint_actions(self, per_agent: np.ndarray) -> np.ndarray:
        """(B, 3 A) joint actions from (B, A, 3) per-agent ones (agent k drives thruster k)."""
        return np.ascontiguousarray(per_agent.reshape(self.num_clusters, 3 * self.num_agents), dtype=np.float64)


def _normalised(weights: np.ndarray) -> np.ndarray:
    """(B, A) rows of non-negative ``weights`` scaled to sum to 1 (equal where a row is all 0)."""
    weights = np.where(np.isfinite(weights), np.maximum(weights, 0.0), 0.0)
    total = weights.sum(axis=1, keepdims=True)
    equal = np.full_like(weights, 1.0 / weights.shape[1])
    return np.where(total > 0, weights / np.where(total > 0, total, 1.0), equal)
