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
- cable elongations (m).

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

from typing import Any, Protocol, runtime_checkable

import numpy as np

from tether_gym.envs.task import DampingTask

__all__ = ["Controller", "CountsSaturation", "Policy", "ReadsEnv", "task_of"]


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


class Controller:
    """Base class: observation decoding, the ``predict`` interface and saturation counting.

    Subclasses implement :meth:`thrust`, which maps decoded states to thruster forces in N.

    Args:
        env: a tether-gym env (single or vector); only its configuration is read.
    """

    #: Short name used in tables and on the command line.
    name = "controller"
    #: Whether the law runs on clusters whose tethers have mass (beads): it then sees the
    #: satellites only, and no per-segment elongations.
    supports_beads = False

    def __init__(self, env: Any) -> None:
        task = task_of(env)
        self.task = task
        self.cluster = task.cluster
        if self.cluster.num_beads and not self.supports_beads:
            raise ValueError(
                f"{type(self).__name__} models every node and cable of the cluster, but this env's tethers have "
                f"mass ({self.cluster.num_beads} beads, observed per tether); it does not run on tethers with mass "
                "yet. Use a massless cluster (tether_mass=0) or a controller that supports beads (passive)"
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
    def decode(self, observation: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(N, n, 3) positions relative to the centre of mass (m), (N, n, 3) velocities relative
        to the centre of mass (m/s) and (N, c) cable elongations (m) from (N, obs_size)
        observations."""
        task = self.task
        layout = task.observation_layout
        displacement = layout.satellite_values(observation, "displacement") * task.length_scale
        velocity = layout.satellite_values(observation, "velocity") * task.speed_scale
        elongation = observation[:, layout.elongation] * task.length_scale
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
