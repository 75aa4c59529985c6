"""The single-cluster Gymnasium environment."""

from __future__ import annotations

import copy
from collections.abc import Mapping
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from tether_gym.cluster import Cluster
from tether_gym.envs.arguments import (
    MAX_RENDER_EXAGGERATION,
    OBSERVATION_LIMIT,
    EnvArgumentError,
    check_actions,
    check_number,
    check_seed,
)
from tether_gym.envs.contract import ObservationLayout
from tether_gym.envs.task import RESET_OPTION_KEYS, task_from_arguments

__all__ = ["RESET_OPTION_KEYS", "TetherClusterEnv"]


class TetherClusterEnv(gym.Env[np.ndarray, np.ndarray]):
    """Damp the vibrations of a cluster of tethered satellites with thrusters.

    ## Description

    Satellites (point masses) are joined by tension-only elastic cables with pretension. Their
    motion is integrated by the explicit central-difference method of the source paper, with
    automatic sub-stepping at the estimated critical time step (several sub-steps per control
    interval). In free space each satellite is held in its nominal shape by a constant **bias
    thrust** ``p_bias = f_int(nominal)``. Without it, pretension would pull the cluster together.
    The presets in turning frames (``radial_chain`` in the Hill frame of a circular orbit,
    ``spinning_triangle`` and ``spinning_hub`` in their spinning frame) are held taut by the
    gravity gradient or the spin instead, and their bias is zero to round-off. The agent's
    thrust is added on top of the bias. Each episode starts from large random initial
    conditions: a cluster whose cables keep going slack and snapping taut. The task is to damp
    that vibration quickly, with little propellant, and without losing the formation.

    ## Action Space

    ``Box(-1, 1, (3 k,), float32)``, where k is the number of thrusters. Entry ``3 j + d`` is
    the thrust command of thruster j along axis d (x, y, z). It is multiplied by that
    thruster's ``max_thrust`` (N) and held constant over the control interval. With
    ``thrust_limit="per_axis"`` (the default), each component lies within ``+-max_thrust``.
    With ``"magnitude"``, a command longer than 1 is scaled back to length 1, which bounds the
    force's norm. Commands outside [-1, 1] are clipped. With ``thrust_mode="on_off"`` each axis
    of a thruster fires at full thrust or not at all over the interval: a component of 0.5 or
    more in magnitude fires it along its sign (minimum impulse bit ``max_thrust *
    control_interval``). A NaN or infinite command, one of the
    wrong shape, or one that is not made of real numbers (strings, booleans, complex numbers)
    raises :class:`~tether_gym.envs.EnvArgumentError` (a ``ValueError``).

    ## Observation Space

    ``Box(-1e4, 1e4, (6 s + c [+ c] [+ f t] [+ d a],), float32)``, where s is the number of
    observed satellites, c the number of cables, t of tethers with mass (f entries each, below),
    d the ``thrust_delay`` and a the action size (with ``observe_commands`` only).
    Everything is in the **cluster frame**: the origin is at the centre of mass, and the axes are
    those of the simulation frame (inertial, Hill or spinning), in which the nominal shape is at
    rest. ``D`` is
    ``initial_displacement`` and ``V`` is ``initial_velocity``.

    OBSERVATION_TABLE

    A cluster whose tethers have mass (beads, see ``tether_mass`` and ``segments`` of the
    presets) observes its satellites only, its plain cables only (c counts those), and then one
    block per tether: with t such tethers and P the entries above, ``len(TETHER_FEATURES) t``
    more entries (``tether_gym.envs.contract``; ``ObservationLayout.tether``), tether k's
    feature f at ``P + len(TETHER_FEATURES) k + f``. Modal amplitudes are signed, along
    ``lateral = r x e / |r x e|`` and ``normal = e x lateral`` (``e`` the unit chord from
    ``ends[0]`` to ``ends[1]``, ``r`` the z axis, or x for a tether within 45 degrees of z):

    TETHER_TABLE

    With ``thrust_delay`` d and ``observe_commands``, the last d a entries are the commands
    given but not acting yet, oldest (the next to act) first, each the action as given, clipped
    to [-1, 1] (``ObservationLayout.command``). They are the controller's own numbers, so
    ``observation_noise`` leaves them exact.

    At reset every entry is of order 1; values are clipped to +-1e4. ``observation_noise`` adds Gaussian noise with that
    standard deviation, in these units.

    ## Rewards

    ``reward = reward_vibration + reward_propellant + reward_slack + reward_failure``, and every
    term is reported in ``info``.

    - ``reward_vibration = -vibration_weight * E_vib / E_scale``.
      - ``E_vib`` is the vibration energy: kinetic energy relative to the rigid translation and
        rotation, plus strain energy, plus the bias-thrust potential ``-p_bias . (x - X)``, plus
        in a turning frame the centrifugal/tidal potential of the shape about its centre of
        mass, measured from the nominal state.
      - ``E_scale`` is the mean ``E_vib`` of the reset distribution (64 fixed-seed draws).
    - ``reward_propellant = -propellant_weight * sum_j |F_j| dt / (F_full dt)``: the thrust
      impulse of the interval, as a fraction of full thrust on every thruster.
    - ``reward_slack = -slack_weight * (fraction of cables slack)``.
    - ``reward_failure = -failure_penalty`` on the step that ends in a failure, else 0.

    ## Starting State

    The cluster starts from its nominal shape, plus Gaussian displacements of standard
    deviation ``initial_displacement`` (m) and velocities of standard deviation
    ``initial_velocity`` (m/s) per component. The rigid part is removed: the centre of mass
    stays in place, and the linear and angular momentum are zero. All draws come from
    ``self.np_random``. ``randomize={"masses": 0.2, ...}`` also draws the masses, EA, damping or
    N0 within ``+-spread`` of nominal at each reset, and the bias is recomputed to match.
    ``reset(options={"positions": X0, "velocities": V0})`` sets exact (n, 3) initial conditions
    instead. ``difficulty`` (in [0, 1], or ``set_difficulty(d)`` between episodes) scales the
    initial conditions, the randomisation spreads and the disturbances together, for curricula.

    ## Disturbances and Faults

    All off by default; each cluster draws its own from ``self.np_random``.
    - ``impulse_magnitude`` (N*s) kicks at Poisson rate ``impulse_rate`` (1/s), each on one random
      satellite in a random direction, applied over one control interval.
    - ``periodic_amplitude`` (N): ``A d_i sin(2 pi t / periodic_period + phi_i)`` on every
      satellite, random unit direction and phase per satellite and episode.
    - ``thrust_noise``: Gaussian error on each delivered thrust component, as a fraction of
      ``max_thrust``; ``thrust_delay``: actions act that many control intervals late.
    - ``thruster_failure_probability``: one random thruster fails (delivers nothing) at a time
      drawn in ``thruster_failure_window`` (s).
    - Cables always break past their breaking load and stay broken until reset;
      ``cable_failure="terminate"`` (default) ends the episode there, ``"continue"`` lets the
      cluster go on without them.

    ## Episode End

    - ``terminated``: the formation is lost (a satellite farther than ``max_deviation`` from its
      nominal place), a cable's tension passes its breaking load at any sub-step of the interval
      (unless ``cable_failure="continue"``), or the numerics diverge (the state became
      non-finite, the sub-step budget ran out, or the reward would be NaN, infinite or beyond
      ``1e30``: the step then gets the finite reward ``-failure_penalty`` plus its propellant and
      slack terms). ``info["end_reason"]`` says which. The reward and the observation are
      always finite.
    - ``truncated``: the registered time limit (``max_episode_steps``) is reached. A failure always
      sets ``terminated``, never ``truncated`` alone; one on the very last step sets both, as
      Gymnasium's ``TimeLimit`` does.

    ## Info

    After a step, ``info`` holds everything below; after a reset it holds the state quantities
    only (no reward terms, sub-step figures, ``peak_tension`` or ``end_reason``). It holds:
    - the reward terms;
    - ``substeps``, ``step_min`` and ``step_max`` (s) of the interval, and ``peak_tension``
      ((c,) N, each cable's largest tension within it);
    - ``simulator_status``: the simulator's status code, which says why an episode ended as
      ``numerics_diverged`` (0 ok, 1 non-finite state, 2 interval refused for its sub-step
      budget, 3 energy runaway; ``tether_gym.simulator.STATUS_NAMES``);
    - ``vibration_energy``, ``kinetic_energy``, ``strain_energy``, ``frame_potential``,
      ``dissipated_energy``, ``external_work`` and ``energy_residual`` (J);
    - ``tensions`` (N), ``slack_count``, ``broken_cables`` ((c,) bool), and ``propellant_used``
      (N*s, cumulative);
    - ``thrust`` ((n, 3) N, the agent's part as delivered, noise included), ``disturbance``
      ((n, 3) N, the external disturbance of the interval) and ``thruster_ok`` ((k,) bool);
    - ``time`` (s) and ``end_reason``.

    ## Arguments

    | argument | default | meaning |
    |---|---|---|
    | ``preset`` | ``"tetrahedron"`` | a preset name (see ``tether_gym.preset_names()``) |
    | ``preset_kwargs`` | ``None`` | overrides of the preset's parameters, e.g. ``{"N0": 1.0}`` |
    | ``cluster`` | ``None`` | a :class:`~tether_gym.Cluster` to use instead of a preset |
    | ``render_mode`` | ``None`` | ``"rgb_array"`` or ``"human"`` |
    | ``render_exaggeration`` | 100 | displacements from nominal are drawn this many times larger |
    | ``**task`` | | any :class:`~tether_gym.envs.TaskConfig` field (listed below) |

    The task fields and their defaults: ``control_interval`` (0.1 s), ``thrusters`` (all),
    ``max_thrust`` (1 N), ``thrust_limit`` (``"per_axis"``), ``thrust_mode`` (``"continuous"``),
    ``initial_displacement`` (0.05 m),
    ``initial_velocity`` (0.1 m/s), ``vibration_weight`` (1), ``propellant_weight`` (0.1),
    ``slack_weight`` (0), ``failure_penalty`` (100), ``max_deviation`` (30 % of the shortest
    cable), ``observe_tensions``, ``observe_commands``, ``observation_noise``,
    ``observed_satellites``, ``randomize``, ``safety_factor``, and the disturbance, fault and
    ``difficulty`` options above.

    Every argument is checked before anything is built, and a bad one raises
    :class:`~tether_gym.envs.EnvArgumentError` (a ``ValueError``; ``TypeError`` for an unknown
    argument) naming it, the allowed range and the fix. The ranges are named constants in
    :mod:`tether_gym.envs.arguments`, generous but physical: e.g. ``control_interval`` in
    [1e-4, 3600] s and within the simulator's sub-step budget at the cluster's critical step,
    ``max_thrust`` in [1e-9, 1e6] N, weights and ``failure_penalty`` up to 1e6,
    ``initial_displacement`` up to 10 % of the shortest cable, ``initial_velocity`` up to that
    displacement times the fastest cable frequency, ``randomize`` spreads up to 0.9. Seeds are
    ints >= 0 or None. Reset options are (n, 3) arrays of finite numbers, each satellite within
    10 longest-cable lengths of its nominal place, no two ends of a cable on top of each other,
    speeds up to 10 times the ``initial_velocity`` limit. A refused ``reset`` or
    ``set_difficulty`` leaves the env as it was.

    ## Version History

    - v0: initial release.
    """

    metadata = {"render_modes": ["rgb_array", "human"], "render_fps": 10}

    def __init__(
        self,
        preset: str = "tetrahedron",
        preset_kwargs: Mapping[str, Any] | None = None,
        cluster: Cluster | None = None,
        render_mode: str | None = None,
        render_exaggeration: float = 100.0,
        **task: Any,
    ) -> None:
        super().__init__()
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise EnvArgumentError(
                f"render_mode must be one of {self.metadata['render_modes']} or None; got {render_mode!r}"
            )
        exaggeration = check_number(
            "render_exaggeration",
            render_exaggeration,
            0.0,
            MAX_RENDER_EXAGGERATION,
            low_open=True,
            fix="displacements are drawn this many times larger",
        )
        self.task = task_from_arguments(1, preset, preset_kwargs, cluster, **task)
        self.config = self.task.config
        cluster = self.task.cluster
        self.cluster = cluster
        self.render_mode = render_mode
        self.action_space = spaces.Box(-1.0, 1.0, (self.task.action_size,), np.float32)
        self.observation_space = spaces.Box(
            -OBSERVATION_LIMIT, OBSERVATION_LIMIT, (self.task.observation_size,), np.float32
        )
        self._index = np.zeros(1, dtype=np.int64)
        self._action_shape = (self.task.action_size,)
        self._viewer: Any = None
        self.render_exaggeration = exaggeration

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict]:
        """Start an episode (see Starting State).  ``seed``: None or an int >= 0; ``options``:
        ``{"positions": X0, "velocities": V0}``, (n, 3) arrays in m and m/s, for exact initial
        conditions.  Both are checked before anything changes: a bad one raises
        :class:`~tether_gym.envs.EnvArgumentError` and leaves the env as it was."""
        seed = check_seed("seed", seed)
        positions, velocities = self.task.check_reset_state(options, (self.cluster.num_nodes, 3))
        super().reset(seed=seed)
        self.task.reset([self.np_random], self._index, positions, velocities)
        if self.render_mode == "human":
            self.render()
        return self.task.observe([self.np_random])[0], self.task.info(0, stepped=False)

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict]:
        a = check_actions("action", action, self._action_shape, "3 per thruster")
        task = self.task
        rngs = [self.np_random]
        task.step(a.reshape(1, -1), rngs=rngs)
        observation = task.observe(rngs)[0]
        reward, terminated, info = task.outcome(0)
        if self.render_mode == "human":
            self.render()
        return observation, reward, terminated, False, info

    def set_difficulty(self, difficulty: float) -> None:
        """Scale initial conditions, randomisation and disturbances by ``difficulty`` in [0, 1]
        from the next reset on (curriculum training; see the ``difficulty`` argument)."""
        self.task.set_difficulty(difficulty)

    def render(self) -> np.ndarray | None:
        if self.render_mode is None:
            gym.logger.warn("render() was called without a render_mode; pass render_mode='rgb_array' or 'human'")
            return None
        from tether_gym.envs.rendering import ClusterRenderer

        if self._viewer is None:
            self._viewer = ClusterRenderer(
                self.cluster,
                self.task.max_thrust.max(),
                human=self.render_mode == "human",
                exaggeration=self.render_exaggeration,
            )
        sim = self.task.sim
        return self._viewer.draw(
            sim.positions_[0], sim.slack[0], self.task.thrust[0], float(sim.time[0]), broken=sim.broken[0]
        )

    def close(self) -> None:
        if self._viewer is not None:
            self._viewer.close()
            self._viewer = None

    def __getstate__(self) -> dict[str, Any]:
        state = self.__dict__.copy()
        state["_viewer"] = None  # figures do not pickle; a copy draws its own
        return state

    def __deepcopy__(self, memo: dict[int, Any]) -> TetherClusterEnv:
        clone = self.__class__.__new__(self.__class__)
        memo[id(self)] = clone
        for key, value in self.__getstate__().items():
            setattr(clone, key, copy.deepcopy(value, memo))
        return clone


# The observation table is written once, in tether_gym.envs.contract (docstrings are absent under -OO).
if TetherClusterEnv.__doc__:
    TetherClusterEnv.__doc__ = TetherClusterEnv.__doc__.replace(
        "OBSERVATION_TABLE", ObservationLayout.symbolic_table().replace("\n", "\n    ")
    ).replace("TETHER_TABLE", ObservationLayout.symbolic_tether_table().replace("\n", "\n    "))
