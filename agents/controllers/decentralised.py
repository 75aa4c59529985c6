"""Decentralised controllers: each thruster acts on what its own satellite measures.

Two scripted laws (listed in :data:`agents.controllers.registry.BASELINES`, so the comparison and
the benchmark run them like the other baselines) and the adapter that runs a shared decentralised
policy (trained with ``python -m agents.train --multiagent``) on the single-agent envs.

**Local laws.** Satellite i with thruster k sees, for each of its cables c to a neighbour j, the
unit direction ``e_c`` from i to j, the neighbour's velocity relative to its own ``w_c = v_j - v_i``
(m/s) and the cable's elongation ``dL_c`` (m): the cable slots of the multi-agent env's local
observation (:mod:`tether_gym.multiagent.engine`). A law maps them to a force ``F_i`` (N) and
knows its own cables' specifications (``L0``, ``EA``, ``N0``) and its neighbours' masses, as a
satellite's designer would:

* :class:`LocalVelocityFeedbackController`: a virtual dashpot to every cable neighbour,
  ``F_i = g sum_c mu_c w_c`` with ``mu_c = m_i m_j / (m_i + m_j)`` the pair's reduced mass: it
  brakes the relative motion of the satellite and its neighbours in every direction, and, since
  the two forces of a pair are equal and opposite, it never pushes the cluster as a whole.
* :class:`LocalTensionAwareController`: the same dashpot along each cable only,
  ``g_c mu_c (w_c . e_c) e_c``, its rate scheduled on the cable's state (``g_taut`` while the
  cable is taut, ``g_slack`` while it is slack: a slack cable no longer couples the pair, so the
  thrusters are the only damper left), plus the virtual strut of
  :class:`agents.controllers.centralised.TensionAwareController` across a slack cable,
  ``-kappa_c (dL_slack - dL_c) e_c`` with ``dL_slack = -N0 L0 / EA``, again equal and opposite.

Their gains were tuned on the tuning seeds 2000-2063 (apart from the benchmark's held-out seeds
10 000 and up and the training evaluation seeds 1 000 000 and up); see each class for the values
and the measurements.

Both read the single-agent observation too (``predict`` as every baseline): the decoded state
(:meth:`agents.controllers.base.Controller.decode`) gives each satellite exactly its local quantities,
so the same law runs on the multi-agent env (:meth:`LocalController.act_local`) and on the
single-agent envs, and a batch of observations gives each row what that row alone gives.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from types import SimpleNamespace
from typing import Any, cast

import numpy as np

from tether_gym.envs.task import DampingTask
from tether_gym.multiagent.engine import AgentGraph, Communication, LocalLayout, LocalSensors

from .base import Controller, task_of

__all__ = [
    "LocalController",
    "LocalObserver",
    "LocalTensionAwareController",
    "LocalVelocityFeedbackController",
    "local_trajectory_observations",
]


class LocalController(Controller):
    """Base class of the decentralised laws: :meth:`local_force` maps each satellite's cable
    measurements to its thruster's force.

    With tethers that have mass, a tether is one cable slot to the satellite at its far end
    (:func:`~agents.controllers.base.equivalent_cluster`), slack while its observed elongation
    (along its beads) is below its slack point; :meth:`act_local` then refuses, since the
    multi-agent env's slots are the tethers' first segments.

    **Passive satellites** (ids with thrusters on some satellites only). The agents are the
    thrusting satellites; a passive satellite has no law. A thrusting satellite keeps every cable
    slot, including those to a passive neighbour, and applies its own half of the pair's force
    there (the dashpot with the pair's reduced mass, the strut); the passive end's half is not
    applied, so the pair's forces are no longer equal and opposite. Two alternatives were
    measured on the tuning seeds 2000-2031 with the default gains (32 episodes, mean return,
    underactuated tetrahedron / end-actuated chain): the thrusting end doing the whole pair's
    work (its own mass in place of the reduced mass) gave -81.2 / -66.6 for
    ``local_velocity_feedback`` against -77.1 / -70.8, and -69.0 / -57.7 for
    ``local_tension_aware`` against -69.8 / -56.3, mixed and within a few percent; dropping the
    slots to passive neighbours gave -90.8 / -104.1 and -97.0 / -104.1 (on the chain, passive's
    return: no slot is left). So the laws are unchanged; their gains for those ids are in
    ``hyperparams/laws.yml``.

    Attributes:
        graph: the agents and their cables (:class:`tether_gym.multiagent.engine.AgentGraph`).
        slack_point: (A, D) elongation below which each cable slot is slack, m (0 for padding).
        present: (A, D) bool, the real cable slots.
    """

    name = "local"

    def __init__(self, env: Any, predict_delay: bool | None = None) -> None:
        super().__init__(env, predict_delay)
        # With tethers that have mass the law is wired on the equivalent cluster (the base class's
        # ``cluster``): a tether is one cable to the satellite at its far end, whose elongation is
        # the tether's (length along its beads minus L0, from the observation's tether block).
        # AgentGraph reads only the cluster and the thrusters of the task it is given.
        wiring = (
            cast(DampingTask, SimpleNamespace(cluster=self.cluster, thrusters=self.task.thrusters))
            if self.task.cluster.num_beads
            else self.task
        )
        self.graph = graph = AgentGraph.build(wiring, Communication())
        self.present = graph.cables >= 0
        cables = np.where(self.present, graph.cables, 0)
        self._cable = cables
        self._neighbour = np.where(self.present, graph.neighbours, 0)
        cluster = self.cluster
        self.slack_point = np.where(self.present, -cluster.N0[cables] / cluster.stiffness[cables], 0.0)
        self.layout = LocalLayout(graph.cables.shape[1], 0)
        # (A, D) kg: the reduced mass m_i m_j / (m_i + m_j) of the pair each cable slot joins (0
        # for padding). A pair's two thrusters then push with equal and opposite forces.
        m_i = self.masses[graph.nodes][:, None]
        m_j = self.masses[self._neighbour]
        self.pair_mass = np.where(self.present, m_i * m_j / (m_i + m_j), 0.0)

    def local_force(self, direction: np.ndarray, relative: np.ndarray, elongation: np.ndarray) -> np.ndarray:
        """(N, A, 3) forces, N, from (N, A, D, 3) cable directions, (N, A, D, 3) relative
        velocities (m/s) and (N, A, D) elongations (m); padding slots hold zeros."""
        raise NotImplementedError

    def thrust(self, positions: np.ndarray, velocities: np.ndarray, elongations: np.ndarray) -> np.ndarray:
        nodes = self.graph.nodes
        offset = positions[:, self._neighbour] - positions[:, nodes][:, :, None]
        direction = offset / np.maximum(np.linalg.norm(offset, axis=-1, keepdims=True), 1e-300)
        relative = velocities[:, self._neighbour] - velocities[:, nodes][:, :, None]
        mask = self.present[None, :, :, None]
        return self.local_force(direction * mask, relative * mask, elongations[:, self._cable] * self.present)

    def act_local(self, observations: np.ndarray) -> np.ndarray:
        """(N, A, 3) float32 commands in [-1, 1] from (N, A, size) local observations of the
        multi-agent env (its own cable slots only; messages are not used)."""
        if self.task.cluster.num_beads:
            # The multi-agent env's cable slots of a beaded cluster are the first segments, to a
            # bead; this law is wired to the satellite at the tether's far end.
            raise ValueError(
                f"{type(self).__name__}.act_local reads the multi-agent env's cable slots, which on tethers with "
                "mass are the first segments of each tether, not the tether this law is designed on; run it on the "
                "single-agent env (predict) there"
            )
        obs = np.asarray(observations, dtype=np.float64)
        layout = self.layout
        direction = layout.cable_field(obs, "direction")
        relative = layout.cable_field(obs, "relative_velocity") * self.task.speed_scale
        elongation = layout.cable_field(obs, "elongation")[..., 0] * self.task.length_scale
        force = self.local_force(direction, relative, elongation)
        return np.clip(force / self.max_thrust[None, :, None], -1.0, 1.0).astype(np.float32)


class LocalVelocityFeedbackController(LocalController):
    """Virtual dashpots to the cable neighbours: ``F_i = g sum_c mu_c (v_j - v_i)``.

    The rate ``g`` (1/s) is one number for every id, 0.5 /s: of 0.25, 0.5, 1 and 2 /s it has the
    largest mean gain over passive on the tuning seeds, averaged over the 8 ids in units of the
    centralised velocity feedback's gain (1.14; 0.25 /s: 1.13, 1 /s: 1.11, 2 /s: 1.05). The
    measurements are in ``docs/multiagent.md``.

    Args:
        env: a tether-gym env.
        gain: the rate ``g``, 1/s.
        predict_delay: act on the state predicted over a thrust delay (see
            :class:`~agents.controllers.base.Controller`).
    """

    name = "local_velocity_feedback"

    def __init__(self, env: Any, gain: float = 0.5, predict_delay: bool | None = None) -> None:
        super().__init__(env, predict_delay)
        if not (np.isfinite(gain) and gain >= 0):
            raise ValueError(f"gain must be a finite rate >= 0 in 1/s; got {gain!r}")
        self.gain = float(gain)

    def local_force(self, direction: np.ndarray, relative: np.ndarray, elongation: np.ndarray) -> np.ndarray:
        return self.gain * (self.pair_mass[None, :, :, None] * relative).sum(axis=2)


class LocalTensionAwareController(LocalController):
    """Dashpots along each cable with the rate scheduled on its state, and struts across slack
    cables (see the module docstring).

    Defaults ``g_taut = 2 /s``, ``g_slack = 1 /s``, with the strut: on the tuning seeds, averaged
    over the 8 ids in units of the centralised velocity feedback's gain over passive, 1.23
    (slack rate 2 /s: 1.20, 4 /s: 1.04; without the strut 1.04 at 1 /s). The taut rate hardly
    matters (0.5, 2 and 8 /s: 1.197, 1.201, 1.184 at a slack rate of 2 /s: a taut cable damps the
    pair itself); the strut across slack cables is what the schedule is for. On the orbital
    chain, whose cables are barely taut, the law is poor (see ``docs/multiagent.md``).

    Args:
        env: a tether-gym env.
        taut_gain: ``g_taut``, 1/s, the axial dashpot's rate while the cable is taut.
        slack_gain: ``g_slack``, 1/s, its rate while the cable is slack.
        strut_stiffness: ``kappa``, N/m; None: ``mu_c g_slack^2 / 4`` per cable (critical
            damping of the strut against the slack dashpot, as in the centralised law).
        predict_delay: act on the state predicted over a thrust delay (see
            :class:`~agents.controllers.base.Controller`).
    """

    name = "local_tension_aware"

    def __init__(
        self,
        env: Any,
        taut_gain: float = 2.0,
        slack_gain: float = 1.0,
        strut_stiffness: float | None = None,
        predict_delay: bool | None = None,
    ) -> None:
        super().__init__(env, predict_delay)
        for label, value in (("taut_gain", taut_gain), ("slack_gain", slack_gain)):
            if not (np.isfinite(value) and value >= 0):
                raise ValueError(f"{label} must be a finite rate >= 0 in 1/s; got {value!r}")
        self.taut_gain, self.slack_gain = float(taut_gain), float(slack_gain)
        if strut_stiffness is not None and not (np.isfinite(strut_stiffness) and strut_stiffness >= 0):
            raise ValueError(f"strut_stiffness must be a finite stiffness >= 0 N/m; got {strut_stiffness!r}")
        self.strut = (  # (A, D) N/m
            self.pair_mass * self.slack_gain**2 / 4.0
            if strut_stiffness is None
            else np.where(self.present, float(strut_stiffness), 0.0)
        )

    def local_force(self, direction: np.ndarray, relative: np.ndarray, elongation: np.ndarray) -> np.ndarray:
        slack = elongation < self.slack_point[None]
        rate = np.where(slack, self.slack_gain, self.taut_gain) * self.present[None]
        axial = (relative * direction).sum(axis=-1)  # (N, A, D) m/s, positive: the pair moves apart
        damping = (rate * self.pair_mass[None] * axial)[..., None] * direction
        shortfall = np.where(slack, self.slack_point[None] - elongation, 0.0)  # m, >= 0
        strut = -(self.strut[None] * shortfall)[..., None] * direction
        return (damping + strut).sum(axis=2)


class LocalObserver:
    """The multi-agent env's local observations of a single-agent env's clusters, for running a
    shared decentralised policy there (``agents.compare``, the benchmark, the training
    evaluation): it reads the attached env's task, whose state is the one the observation
    handed to ``predict`` describes.

    Only the stateless options can be reproduced that way: communication without delay, and no
    local observation noise (a policy trained with them is evaluated in the multi-agent env).

    Args:
        env: a tether-gym env (single or vector).
        options: the policy's multi-agent options (``communication``, ``reward``,
            ``local_observation_noise``), as recorded in its ``policy.json``.
    """

    def __init__(self, env: Any, options: Mapping[str, Any]) -> None:
        unknown = sorted(set(options) - {"communication", "reward", "local_observation_noise"})
        if unknown:
            raise ValueError(
                f"unknown multi-agent option(s) {unknown}; the options are communication, reward and "
                "local_observation_noise"
            )
        communication = Communication.parse(options.get("communication"))
        if communication.delay or options.get("local_observation_noise"):
            raise ValueError(
                "this decentralised policy was trained with a communication delay or local observation noise, which "
                "the single-agent envs cannot reproduce: evaluate it in tether_gym.multiagent.parallel_env"
            )
        self.task = task_of(env)
        self.sensors = LocalSensors(self.task, communication)
        self.num_agents = self.sensors.num_agents
        self.observation_size = self.sensors.layout.size

    def observe(self, observation: np.ndarray) -> tuple[np.ndarray, bool]:
        """``(local, single)``: (N, A, size) local observations of the attached env's clusters
        now, checked against the (obs_size,) or (N, obs_size) ``observation`` handed to
        ``predict`` (one row per cluster), and whether that was a single observation."""
        obs = np.asarray(observation)
        single = obs.ndim == 1
        rows = 1 if single else obs.shape[0]
        if obs.ndim not in (1, 2) or rows != self.task.num_clusters or obs.shape[-1] != self.task.observation_size:
            raise ValueError(
                f"a decentralised policy reads the local observations of the env it is attached to "
                f"({self.task.num_clusters} cluster(s), observations of size {self.task.observation_size}); got an "
                f"observation batch of shape {obs.shape}: attach(env) it to the env that produced the observations"
            )
        clusters = np.arange(self.task.num_clusters)
        own = self.sensors.measure(clusters)
        return self.sensors.assemble(own, own), single


def local_trajectory_observations(
    act: Callable[[np.ndarray], np.ndarray], env_id: str, options: Mapping[str, Any]
) -> Callable[[int], np.ndarray]:
    """A function ``n -> (n, size)`` of agents' local observations along the trajectories of
    ``act`` (a batch of local observations -> a batch of (3,) commands), 8 clusters in parallel,
    seeds 0-7: what :func:`agents.policies.reference.trajectory_observations` is to a centralised policy,
    for the reference actions of a shipped decentralised one."""
    from tether_gym.multiagent.sb3 import make_agent_vec_env

    def observations(count: int) -> np.ndarray:
        venv = make_agent_vec_env(env_id, num_envs=8, seed=0, **dict(options))
        rows = [venv.reset()]
        while sum(len(r) for r in rows) < count:
            obs, *_ = venv.step(act(rows[-1]))
            rows.append(obs)
        venv.close()
        return np.concatenate(rows)[:count]

    return observations
