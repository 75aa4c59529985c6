"""The base of the scripted controllers, and the contracts that the evaluation expects of any controller.

Every scripted controller is built from an env (a single env from ``gym.make``, or a vector env
from ``gym.make_vec``, possibly wrapped), reads only the env's observation, and answers
Stable-Baselines3's ``predict(observation, deterministic=True) -> (actions, None)``.
``observation`` may be one observation ``(obs_size,)`` or a batch ``(N, obs_size)``, and the
actions have the matching shape ``(3k,)`` or ``(N, 3k)``, float32 in [-1, 1].

The controllers are designed on the env's **nominal** cluster (domain randomisation is not
seen) and need every satellite to be observed. :class:`Controller` reconstructs the state from
the observation:
- satellite positions relative to the centre of mass, ``r_i = X_i - X_com + d_i`` (m), from the
  displacements ``d_i``;
- velocities relative to the centre of mass ``u_i`` (m/s);
- cable elongations (m); with tethers that have mass, each tether's elongation (the length
  along its beads minus its ``L0``) from its observation block, as one cable of
  :func:`equivalent_cluster`, the model every law is then designed on.

**A delay between command and thrust.** On an env whose commands act ``thrust_delay`` control
steps after they are given and whose observation holds the commands still in flight
(``observe_commands``), a law acts on the state its command will meet, not on the observed one
(:class:`DelayPredictor`, a Smith predictor): the observed state advanced over the delay with the
commands in flight, on the law's own model of the cluster. The observation then determines that
state, so the prediction is exact but for the observation's float32 rounding. Without it a law
tuned for no delay brakes motions that have already changed: on ``TetherDelayedTetrahedron-v0``
(64 held-out seeds) the predicting ``tension_aware`` returns -30.6 against -33.0 without the
prediction (the gains of ``hyperparams/laws.yml``, tuned without it).

Thrust commands beyond the limit are clipped, as the env would do anyway. Each controller counts
how often that happens (:attr:`Controller.saturation_fraction`): a linear design that saturates
most of the time is no longer the design that was analysed.

**The contracts.** The evaluation (:func:`agents.evaluation.rollout.rollout`) runs scripted controllers,
the model-predictive reference (:class:`agents.controllers.mpc.MPCController`), trained
policies (:class:`agents.policies.TrainedPolicy`) and ARS's linear residual policies alike. What
it needs of them is named here by Protocols, checked structurally (no controller inherits them):

- :class:`Policy`: ``predict(observation, state=None, episode_start=None, deterministic=True)
  -> (actions, state)``, Stable-Baselines3's signature; every controller has it.
- :class:`ReadsEnv`: ``attach(env)``, for controllers that read the env they control (``mpc``
  reads its true state, a trained residual or decentralised policy builds its baseline or local
  observer from it). The evaluation attaches them to the env it steps.
- :class:`CountsSaturation`: ``saturation_fraction`` and ``reset_statistics()``, for controllers
  that count their clipped commands. The evaluation restarts the count before a rollout and
  reports it after.
"""

from __future__ import annotations

import dataclasses
from typing import Any, Protocol, runtime_checkable

import numpy as np

from tether_gym.cluster import Cluster
from tether_gym.envs.contract import TETHER_FEATURES
from tether_gym.envs.task import DampingTask

__all__ = ["Controller", "CountsSaturation", "DelayPredictor", "Policy", "ReadsEnv", "equivalent_cluster", "task_of"]


@runtime_checkable
class Policy(Protocol):
    """Anything the evaluation can run: Stable-Baselines3's ``predict``.

    ``observation`` is (obs_size,) or (N, obs_size) in the env's units; the answer is
    ``(actions, state)`` with actions of shape (act_size,) or (N, act_size), float32 in [-1, 1],
    and ``state`` the recurrent state (None for every controller of this package). Callers pass
    ``deterministic=True``."""

    def predict(
        self,
        observation: np.ndarray,
        state: Any = None,
        episode_start: np.ndarray | None = None,
        deterministic: bool = True,
    ) -> tuple[np.ndarray, Any]:
        """Actions for ``observation``, and the recurrent state."""
        ...


@runtime_checkable
class ReadsEnv(Protocol):
    """A controller that reads the env it controls (its true state, or its cluster): the
    evaluation calls :meth:`attach` with the env it steps, before the first ``predict``."""

    def attach(self, env: Any) -> None:
        """Control ``env`` (a tether-gym single or vector env, possibly wrapped) from now on."""
        ...


@runtime_checkable
class CountsSaturation(Protocol):
    """A controller that counts how often its commands were beyond the thrust limit."""

    @property
    def saturation_fraction(self) -> float:
        """Fraction of commands that were clipped since the last :meth:`reset_statistics`, in [0, 1]."""
        ...

    def reset_statistics(self) -> None:
        """Restart the counts."""
        ...


def task_of(env: Any) -> DampingTask:
    """The :class:`~tether_gym.envs.task.DampingTask` behind a tether-gym env (single, vector, or
    wrapped in Gymnasium or SB3 wrappers)."""
    candidate = env
    for _ in range(16):
        task = getattr(getattr(candidate, "unwrapped", candidate), "task", None)
        if isinstance(task, DampingTask):
            return task
        inner = getattr(candidate, "venv", None) or getattr(candidate, "env", None)
        if inner is None:
            break
        candidate = inner
    raise TypeError(
        f"{type(env).__name__} is not a tether-gym environment: pass an env made by gym.make or "
        "gym.make_vec with a tether-gym id (or tether_gym.sb3.make_sb3_vec_env)"
    )


def equivalent_cluster(cluster: Cluster) -> Cluster:
    """The massless cluster the scripted laws are designed on when ``cluster``'s tethers have mass.

    Its nodes are ``cluster``'s S satellites and its cables are ``cluster``'s plain cables, then
    one cable per tether (in tether order) between the tether's satellites, with the tether's
    ``EA``, its whole reference length (the sum of its segments' ``L0``, m), the mean pretension
    of its segments (N), their Kelvin-Voigt coefficients in series (N*s/m) and the lowest
    breaking load of its segments (N). Each bead's mass goes half to each end satellite of its
    tether, so the total mass, the centre of mass of the nominal straight line and the
    momentum of a rigid motion are those of ``cluster``.

    What it leaves out: the tethers' own transverse and higher axial modes, the lowest at
    ``sqrt(N0 / mu) / (2 L)`` Hz. The laws damp them only through the satellites they end on.
    A cluster without beads is returned as it is.
    """
    if not cluster.num_beads:
        return cluster
    satellites = cluster.num_satellites
    masses = cluster.masses[:satellites].copy()
    plain = cluster.num_cables - sum(spec.segments for spec in cluster.tethers)
    cables = [tuple(pair) for pair in cluster.cables[:plain].tolist()]
    columns = {name: list(getattr(cluster, name)[:plain]) for name in ("EA", "N0", "L0", "axial_damping")}
    breaking = list(cluster.breaking_load[:plain])
    for t, spec in enumerate(cluster.tethers):
        a, b = spec.ends
        bead_mass = float(cluster.masses[cluster.tether_beads(t)].sum())
        masses[a] += 0.5 * bead_mass
        masses[b] += 0.5 * bead_mass
        segments = cluster.tether_cables(t)
        cables.append((a, b))
        columns["EA"].append(float(cluster.EA[segments].mean()))
        columns["N0"].append(float(cluster.N0[segments].mean()))
        columns["L0"].append(float(cluster.L0[segments].sum()))
        coefficients = cluster.axial_damping[segments]
        columns["axial_damping"].append(0.0 if np.any(coefficients == 0.0) else float(1.0 / (1.0 / coefficients).sum()))
        breaking.append(float(cluster.breaking_load[segments].min()))
    return Cluster(
        positions=cluster.positions[:satellites],
        masses=masses,
        cables=np.array(cables, dtype=np.int64),
        damping=cluster.damping[:satellites],
        breaking_load=np.array(breaking),
        frame=cluster.frame,
        name=f"{cluster.name} (tethers as cables)",
        EA=np.array(columns["EA"]),
        N0=np.array(columns["N0"]),
        L0=np.array(columns["L0"]),
        axial_damping=np.array(columns["axial_damping"]),
    )


class DelayPredictor:
    """The state a command given now will meet, on an env with a thrust delay: a Smith predictor.

    The observed state (satellite positions and velocities relative to the centre of mass) is put
    into a model task of the env's nominal cluster, with the env's settings but no delay, noise,
    disturbance or fault, and advanced ``thrust_delay`` control intervals with the commands in
    flight, read from the observation's ``command`` block, oldest first. The model integrates as
    the env does (the same cluster, control interval, thrusters, thrust limit and bias), so with
    a noise-free observation the prediction differs from the env's own future only by the
    observation's float32 rounding. The centre of mass is put at its nominal place: exact in
    free space, where the relative motion does not depend on it; in the Hill and rotating frames
    the observation does not give it, and the prediction neglects its drift over the delay.

    Args:
        task: the env's task; it must have ``thrust_delay`` > 0, ``observe_commands``, every
            satellite observed and massless tethers (beads are not observed whole).
    """

    @staticmethod
    def applies(task: DampingTask) -> bool:
        """Whether a predictor can serve ``task``: a thrust delay, its commands in flight
        observed, and no tether with mass (whose beads are observed only as a summary)."""
        config = task.config
        return bool(config.thrust_delay and config.observe_commands and not task.cluster.num_beads)

    def __init__(self, task: DampingTask) -> None:
        config = task.config
        if not (config.thrust_delay and config.observe_commands):
            raise ValueError(
                "predicting over the thrust delay needs an env with thrust_delay > 0 that observes its commands "
                f"in flight (observe_commands=True); this env has thrust_delay={config.thrust_delay}, "
                f"observe_commands={config.observe_commands}. Make the env with both, or pass predict_delay=False"
            )
        if task.cluster.num_beads:
            raise ValueError(
                "predicting over the thrust delay needs the whole state observed, but this env's tethers have mass and "
                "their beads are observed only as a summary per tether; pass predict_delay=False"
            )
        self.delay = config.thrust_delay
        self.action_size = task.action_size
        self.command = task.observation_layout.command
        self.cluster = task.cluster
        masses = task.cluster.masses
        self.centre_of_mass = (masses[:, None] * task.cluster.positions).sum(axis=0) / masses.sum()
        self.config = dataclasses.replace(
            config,
            thrust_delay=0,
            observe_commands=False,
            observation_noise=0.0,
            impulse_magnitude=0.0,
            periodic_amplitude=0.0,
            thrust_noise=0.0,
            thruster_failure_probability=0.0,
            randomize={},
        )
        self._models: dict[int, tuple[DampingTask, list[np.random.Generator]]] = {}

    def model(self, batch: int) -> tuple[DampingTask, list[np.random.Generator]]:
        """The model task of ``batch`` clusters and its generators (built once per batch size)."""
        if batch not in self._models:
            # The model draws nothing (no randomisation, disturbance or noise); reset wants a generator per cluster.
            self._models[batch] = (
                DampingTask(self.cluster, batch, self.config),
                [np.random.default_rng(0) for _ in range(batch)],
            )
        return self._models[batch]

    def predict(self, positions: np.ndarray, velocities: np.ndarray, observation: np.ndarray) -> DampingTask:
        """Advance (N, n, 3) positions relative to the centre of mass (m) and (N, n, 3) velocities
        (m/s) over the delay with the commands in flight of (N, obs_size) ``observation``; returns
        the model task, whose ``observation`` ((N, model obs_size) float64) is the predicted one."""
        batch = positions.shape[0]
        model, rngs = self.model(batch)
        model.reset(rngs, np.arange(batch), positions + self.centre_of_mass, velocities)
        in_flight = observation[:, self.command].reshape(batch, self.delay, self.action_size)
        for step in range(self.delay):
            # The env's actions are float32: the commands in flight are those numbers, exactly.
            model.step(np.ascontiguousarray(in_flight[:, step], dtype=np.float64))
        return model


class Controller:
    """Base class: observation decoding, the ``predict`` interface and saturation counting.

    Subclasses implement :meth:`thrust`, which maps decoded states to thruster forces in N.

    Args:
        env: a tether-gym env (single or vector); only its configuration is read.
        predict_delay: act on the state the command will meet (:class:`DelayPredictor`): None
            (the default) on an env with a thrust delay that observes its commands in flight,
            else not; True requires such an env; False acts on the observed state.
    """

    #: Short name used in tables and on the command line.
    name = "controller"
    #: Whether the law runs on clusters whose tethers have mass (beads). Every scripted law of
    #: this package does: it is designed on :func:`equivalent_cluster` (each tether one cable,
    #: its mass on its ends) and decodes the tethers' observation block as those cables.
    supports_beads = True

    def __init__(self, env: Any, predict_delay: bool | None = None) -> None:
        task = task_of(env)
        self.task = task
        #: The cluster the law is designed on: the env's own, or with tethers that have mass,
        #: :func:`equivalent_cluster` of it (satellites only).
        self.cluster = equivalent_cluster(task.cluster) if task.cluster.num_beads else task.cluster
        if task.cluster.num_beads and not self.supports_beads:
            raise ValueError(
                f"{type(self).__name__} models every node and cable of the cluster, but this env's tethers have "
                f"mass ({task.cluster.num_beads} beads, observed per tether); it does not run on tethers with mass. "
                "Use a massless cluster (tether_mass=0) or a controller that supports beads"
            )
        # The observation holds the satellites only (the leading nodes); beads are not decoded.
        n = self.cluster.num_satellites
        if task.observed.size != n:
            raise ValueError(
                f"{type(self).__name__} needs every satellite observed; this env observes "
                f"{task.observed.tolist()} of {n}. Make the env with observed_satellites=None."
            )
        self.num_nodes = n
        self.thrusters = task.thrusters
        self.max_thrust = task.max_thrust
        self.masses = self.cluster.masses[:n]
        satellites = self.cluster.positions[:n]
        self.nominal_relative = satellites - (self.masses[:, None] * satellites).sum(axis=0) / self.masses.sum()
        self.control_interval = task.config.control_interval
        self.action_size = task.action_size
        self.observation_size = task.observation_size
        self.magnitude_limit = task.config.thrust_limit == "magnitude"
        self.commands = 0
        self.saturated = 0
        if predict_delay is not None and not isinstance(predict_delay, bool):
            raise ValueError(f"predict_delay must be True, False or None; got {predict_delay!r}")
        if predict_delay is None:
            predict_delay = DelayPredictor.applies(task)
        #: The Smith predictor the law acts through, or None: it acts on the observed state.
        self.delay_predictor = DelayPredictor(task) if predict_delay else None

    # ------------------------------------------------------------------ interface
    def predict(
        self,
        observation: np.ndarray,
        state: Any = None,
        episode_start: np.ndarray | None = None,
        deterministic: bool = True,
    ) -> tuple[np.ndarray, None]:
        """Actions for ``observation`` ((obs_size,) or (N, obs_size)), as SB3's ``predict``.

        Returns ``(actions, None)``: (3k,) or (N, 3k) float32 commands in [-1, 1]. The scripted
        controllers are deterministic and stateless, so ``state``, ``episode_start`` and
        ``deterministic`` are accepted and ignored."""
        obs = np.asarray(observation, dtype=np.float64)
        single = obs.ndim == 1
        batch = obs[None] if single else obs
        if batch.ndim != 2 or batch.shape[1] != self.observation_size:
            raise ValueError(
                f"observation must have shape ({self.observation_size},) or (N, {self.observation_size}) "
                f"for this env; got {obs.shape}"
            )
        if not np.isfinite(batch).all():
            raise ValueError("observation contains NaN or inf")
        positions, velocities, elongations = self.decode(batch)
        if self.delay_predictor is not None:
            model = self.delay_predictor.predict(positions, velocities, batch)
            positions, velocities, elongations = self.decode(model.observation, model)
        force = self.thrust(positions, velocities, elongations)  # (N, k, 3) N
        commands = force / self.max_thrust[None, :, None]
        if self.magnitude_limit:
            norms = np.linalg.norm(commands, axis=2, keepdims=True)
            over = norms > 1.0
            self.saturated += int(over.sum())
            self.commands += over.size
            commands = np.where(over, commands / np.maximum(norms, 1e-300), commands)
        else:
            over = np.abs(commands) > 1.0
            self.saturated += int(over.sum())
            self.commands += over.size
            commands = np.clip(commands, -1.0, 1.0)
        actions = commands.reshape(batch.shape[0], self.action_size).astype(np.float32)
        return (actions[0] if single else actions), None

    @property
    def saturation_fraction(self) -> float:
        """Fraction of thrust commands (per axis, or per thruster with the magnitude limit) that
        were beyond the limit and clipped, since construction or :meth:`reset_statistics`."""
        return self.saturated / self.commands if self.commands else 0.0

    def reset_statistics(self) -> None:
        """Restart the saturation count."""
        self.commands = 0
        self.saturated = 0

    # ------------------------------------------------------------------ decoding
    def decode(
        self, observation: np.ndarray, task: DampingTask | None = None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(N, n, 3) positions relative to the centre of mass (m), (N, n, 3) velocities relative
        to the centre of mass (m/s) and (N, c) cable elongations (m) from (N, obs_size)
        observations of ``task`` (default: the env's; the predictor's model is another)."""
        task = self.task if task is None else task
        layout = task.observation_layout
        displacement = layout.satellite_values(observation, "displacement") * task.length_scale
        velocity = layout.satellite_values(observation, "velocity") * task.speed_scale
        elongation = observation[:, layout.elongation] * task.length_scale
        if layout.tethers:
            # Each tether is the last cables of :func:`equivalent_cluster`, in tether order: its
            # elongation is the length along its beads minus its L0 (feature 0 of its block).
            block = observation[:, layout.tether].reshape(observation.shape[0], layout.tethers, len(TETHER_FEATURES))
            tether_elongation = block[:, :, TETHER_FEATURES.index("elongation")] * task.length_scale
            elongation = np.concatenate([elongation, tether_elongation], axis=1)
        return self.nominal_relative[None] + displacement, velocity, elongation

    def deformation_velocity(self, positions: np.ndarray, velocities: np.ndarray) -> np.ndarray:
        """(N, n, 3) velocities with the rigid rotation removed as well: ``u - omega x r``, where
        ``I omega`` is the angular momentum about the centre of mass."""
        m = self.masses[None, :, None]
        momentum = (m * np.cross(positions, velocities)).sum(axis=1)  # (N, 3)
        r2 = (positions**2).sum(axis=2)  # (N, n)
        inertia = (
            self.masses[None, :, None, None]
            * (r2[:, :, None, None] * np.eye(3) - positions[:, :, :, None] * positions[:, :, None, :])
        ).sum(axis=1)  # (N, 3, 3)
        # A collinear cluster has no inertia about its axis: regularise as the task does.
        inertia += 1e-9 * (self.masses[None, :] * r2).sum(axis=1)[:, None, None] * np.eye(3)
        omega = np.linalg.solve(inertia, momentum[:, :, None])[:, :, 0]
        return velocities - np.cross(omega[:, None, :], positions)

    def thrust(self, positions: np.ndarray, velocities: np.ndarray, elongations: np.ndarray) -> np.ndarray:
        """(N, k, 3) thruster forces in N (before the thrust limit)."""
        raise NotImplementedError
