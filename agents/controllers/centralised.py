"""The centralised scripted baselines: what a control engineer would try before reinforcement
learning, with the whole cluster's state at hand.

* :class:`PassiveController`: zero thrust, the cluster's own damping.
* :class:`VelocityFeedbackController`: direct velocity feedback, its gain set by a rule on the
  linear model.
* :class:`LQRController`: a discrete-time LQR designed on the cluster with every cable slack.
* :class:`TensionAwareController`: velocity feedback plus virtual struts across slack cables.

Each reconstructs the state from the observation, as :class:`~agents.controllers.base.Controller`
does for every scripted controller (see :mod:`agents.controllers.base` for the interface, the
decoding and the saturation count). The gains come from the linear model of
:mod:`agents.controllers.linear_model`. The decentralised laws are in
:mod:`agents.controllers.decentralised`, and every baseline is listed by name in
:data:`agents.controllers.registry.BASELINES`.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from tether_gym._optional import needs_extra

from .base import Controller
from .linear_model import LinearModel

with needs_extra("train", "the LQR baseline's Riccati solver"):
    import scipy.linalg

__all__ = ["LQRController", "PassiveController", "TensionAwareController", "VelocityFeedbackController"]


def controllable_subspace(ad: np.ndarray, bd: np.ndarray, tolerance: float = 1e-9) -> np.ndarray:
    """(2r, s) orthonormal basis of the controllable subspace of ``z+ = Ad z + Bd F``: the span of
    ``Bd, Ad Bd, Ad^2 Bd, ...``, grown one power at a time (no power of ``Ad`` is formed). Each
    step maps the basis through ``Ad``, removes what the basis already spans (twice, for
    orthogonality in floating point) and keeps the directions of what is left whose singular
    values exceed ``tolerance`` times ``|Ad|`` (for the first block, times ``|Bd|``). ``s = 2r``
    when every state is reachable.

    Args:
        ad: (2r, 2r) sampled state matrix.
        bd: (2r, m) sampled input matrix.
        tolerance: relative rank threshold.
    """
    size = ad.shape[0]

    def directions(columns: np.ndarray, scale: float) -> np.ndarray:
        left, singular, _ = np.linalg.svd(columns, full_matrices=False)
        return left[:, singular > tolerance * scale]

    basis = directions(bd, float(np.linalg.norm(bd, 2)))
    scale = float(np.linalg.norm(ad, 2))
    while 0 < basis.shape[1] < size:
        new = ad @ basis
        for _ in range(2):
            new = new - basis @ (basis.T @ new)
        found = directions(new, scale)
        if found.shape[1] == 0:
            break
        basis = np.hstack([basis, found])
    return basis


class PassiveController(Controller):
    """Zero thrust: the cluster rings down under its own damping (the bias thrust still holds the
    nominal shape). With tethers that have mass, the beads ring down under the tethers' damping.
    Passive satellites (ids with thrusters on some satellites only) change nothing."""

    name = "passive"

    def thrust(self, positions: np.ndarray, velocities: np.ndarray, elongations: np.ndarray) -> np.ndarray:
        return np.zeros((positions.shape[0], self.thrusters.size, 3))


class VelocityFeedbackController(Controller):
    """Direct velocity feedback: each thruster pushes against its satellite's velocity relative to
    the cluster's rigid motion, ``F_i = -g m_i (v_i - v_com - omega x r_i)``.

    The gain rate ``g`` (1/s) is chosen by a rule, not by hand: it is the value that minimises
    the expected time integral of the vibration energy of the linearised, sampled closed loop
    (:class:`LinearModel`, zero-order hold at the env's control interval), from the env's own
    distribution of initial states (:meth:`LinearModel.expected_vibration_energy`), found by a
    golden-section search over ``log g`` after a coarse scan. Too low a gain damps slowly, and
    too high a gain overshoots because the thrust is held for a whole interval. (Maximising the
    slowest decay rate instead would tune the gain to the slowest mode: for the orbital chain,
    whose lateral modes are 300 times slower than its axial ones, it gives a 240 times smaller
    gain and 40 times more vibration energy.) The rule ignores the thrust limit. With large
    initial conditions the commands saturate, and the law becomes bang-bang in the saturated axes.

    With tethers that have mass, the satellites' masses, the velocities and the rule's model
    are those of :func:`~agents.controllers.base.equivalent_cluster` (each tether one cable, its
    beads' mass on its ends); the beads are damped only through the satellites.

    **Passive satellites** (ids with thrusters on some satellites only): each thruster brakes
    its own satellite; the rigid motion is still estimated from every satellite (all are
    observed), and a passive satellite is damped only through its taut cables. Nothing else is
    adapted. The rule's model is the taut cluster, where braking the thrusting satellites damps
    the others through the cables; in the env those cables are mostly slack, and the rule's
    gain is far too high there (14.7 /s on the underactuated tetrahedron, 15.5 /s on the
    end-actuated chain). The gains of the hard ids are re-tuned in ``hyperparams/laws.yml``.

    Args:
        env: a tether-gym env.
        gain: the gain rate ``g`` in 1/s; None applies the rule.
        predict_delay: act on the state predicted over a thrust delay (see
            :class:`~agents.controllers.base.Controller`).
    """

    name = "velocity_feedback"

    def __init__(self, env: Any, gain: float | None = None, predict_delay: bool | None = None) -> None:
        super().__init__(env, predict_delay)
        self.model = LinearModel(self.task, cluster=self.cluster)
        if gain is None:
            gain = self.best_gain()
        if not (math.isfinite(gain) and gain >= 0):
            raise ValueError(f"gain must be a finite rate >= 0 in 1/s; got {gain!r}")
        self.gain = float(gain)

    def feedback_matrix(self, gain: float) -> np.ndarray:
        """(3k, 2r) modal state feedback equivalent to gain rate ``gain``: ``F = -g M_k q'``
        mapped through the modes (velocities of the thruster satellites, elastic part)."""
        model = self.model
        masses = np.repeat(self.masses[self.thrusters], 3)
        modal_velocity = model.modes.reshape(self.num_nodes, 3, -1)[self.thrusters].reshape(-1, model.num_modes)
        return np.hstack([np.zeros_like(modal_velocity), gain * masses[:, None] * modal_velocity])

    def best_gain(self) -> float:
        """The gain rate (1/s) minimising :meth:`LinearModel.expected_vibration_energy`."""

        def cost(log_gain: float) -> float:
            return float(self.model.expected_vibration_energy(self.feedback_matrix(math.exp(log_gain))))

        grid = np.linspace(math.log(1e-3), math.log(10.0 / self.control_interval), 60)
        values = [cost(x) for x in grid]
        best = int(np.argmin(values))
        low, high = grid[max(best - 1, 0)], grid[min(best + 1, grid.size - 1)]
        ratio = (math.sqrt(5.0) - 1.0) / 2.0
        a, b = high - ratio * (high - low), low + ratio * (high - low)
        cost_a, cost_b = cost(a), cost(b)
        for _ in range(40):  # golden section: one new evaluation per iteration
            if cost_a < cost_b:
                high, b, cost_b = b, a, cost_a
                a = high - ratio * (high - low)
                cost_a = cost(a)
            else:
                low, a, cost_a = a, b, cost_b
                b = low + ratio * (high - low)
                cost_b = cost(b)
        return math.exp(0.5 * (low + high))

    def thrust(self, positions: np.ndarray, velocities: np.ndarray, elongations: np.ndarray) -> np.ndarray:
        relative = self.deformation_velocity(positions, velocities)[:, self.thrusters]
        return -self.gain * self.masses[self.thrusters][None, :, None] * relative


class LQRController(Controller):
    """Discrete-time LQR designed on the cluster with every cable slack, with the thrust clipped
    to the limit.

    **The design.** The model is :class:`LinearModel` with ``cables="slack"``: the env's
    masses, satellite damping, frame terms, thrusters and zero-order hold, and no cable at all.
    The cost is the one the earlier design used, Bryson's rule in the task's own units:

        J = sum_k  E_vib(z_k) / E_scale + thrust_weight * sum_j (F_j,k / F_max,j)^2

    with ``E_vib`` the modal vibration energy of the *taut* cluster (:meth:`LinearModel.energy_weight`),
    ``E_scale`` the env's reward normaliser, ``F_max`` each thruster's limit and
    ``thrust_weight = 1``. The gain comes from scipy's discrete algebraic Riccati solver. The law
    is ``F = -G [q, q']``, where ``q = Phi^T M d`` projects the observed displacements and
    velocities on the elastic modes.

    **Why the slack model.** Cables are tension-only. Over the task's initial conditions most of
    them are slack most of the time (100 % of the time for the passive tetrahedron), and while
    one is slack its stiffness is gone, not just smaller. The LQR of the *taut* model
    (``design="taut"``, the earlier baseline) softens the structure: on every id the modal
    stiffness its position gain adds has negative eigenvalues (down to -0.8 (rad/s)^2 on the
    tetrahedron, whose modes are at 50-200 (rad/s)^2). Against a taut cable that costs nothing.
    Against a slack one nothing resists it, and it pulls the crumpled cluster inward against the
    small bias thrust that re-tensions it. On the tuning seeds 2000-2063 (64 episodes per id,
    apart from the comparison's held-out seeds) it lost to passive on 7 of 8 ids, by a factor of
    15 on the default id (-2128 against -139, 34 formations lost). A larger thrust weight does
    not cure that, it only shrinks the harm: with ``thrust_weight = 100`` the default id's return
    is -199, and it tends to passive's from below as the weight grows. The taut gain without its
    position part beats passive, but is a weak damper (-93 on the default id).

    Designed with every cable slack, the same cost makes the Riccati gain a stiffness *and* a
    damper on every elastic mode: the law pulls the cluster back to its shape with the cables'
    help or without it. The slack model is the softest of the 2^c linear models of a
    tension-only cluster (each cable taut or slack), and taut cables only add stiffness and
    damping to it. The closed loop of every one of those models is stable on every id (checked
    for all 2^c patterns in ``tests/agents/controllers/test_lqr.py``; the slowest continuous-time pole has real part
    at most -0.003 /s, on the orbital chain). Scheduling the gain on the cables' state (the taut
    gain while every observed cable is taut, the slack gain otherwise) measured the same within
    2 % on 7 ids and worse on the orbital chain (-25.6 against -23.6): the cables are almost never
    all taut, so the single gain is kept. The thrust weight was not tuned. On the tuning seeds,
    every weight of 0.1, 1 and 10 beats passive on every id by a factor of 2.8 or more. Against
    1, a weight of 10 gains 1-11 % on six ids but loses 5 % on the spinning hub and 46 % on the
    orbital chain, and 0.1 loses 7-21 % on seven ids.

    **Measured** on the comparison's held-out seeds (10 000-10 063, 64 episodes, default
    amplitudes), mean return, passive / taut-model LQR (before) / this LQR:

    ==========================  =======  =====================  ===============  ====================
    id                          passive  taut-model LQR         this LQR         paired gain (95 % CI)
    ==========================  =======  =====================  ===============  ====================
    TetherTetrahedron-v0         -127.2  -2091.0 (33 lost)      -34.6            +92.6 +- 23.3
    TetherChain-v0                -92.9   -536.2 (64 lost)      -17.0            +75.9 +- 10.9
    TetherTriangle-v0            -111.2  -2557.0 (6 lost)       -28.2            +83.0 +- 27.4
    TetherOctahedron-v0          -125.8  -1629.0 (51 lost)      -34.2            +91.6 +- 15.1
    TetherHub-v0                 -129.3  -1332.6 (15 lost)      -41.0            +88.3 +- 12.9
    TetherRadialChain-v0         -206.5  -1586.9                -21.0           +185.5 +- 31.1
    TetherSpinningTriangle-v0    -124.3   -582.2 (4 lost)       -28.3            +95.9 +- 43.7
    TetherSpinningHub-v0         -152.9   -150.2                -42.1           +110.8 +- 24.2
    ==========================  =======  =====================  ===============  ====================

    This LQR loses no formation and beats passive in each of the 64 episodes of every id, by a
    factor of 3 to 10 in mean return; the old design lost to passive on 7 of 8 ids.

    On small perturbations, where every cable stays taut, both designs remove over 99 % of the
    energy in 3 s, as velocity feedback does. The thrust is clipped to the limit, and
    :attr:`saturation_fraction` reports how often (1-9 % of commands over the task).

    With tethers that have mass, the design model is that of
    :func:`~agents.controllers.base.equivalent_cluster` (each tether one cable, its beads' mass
    on its ends): the tethers' own modes are neither in the state nor in the cost.

    **Passive satellites** (ids with thrusters on some satellites only). With every cable slack,
    no thruster reaches a passive satellite: in the design model its motion is a free mass's (in
    an orbital frame, Hill's), so ``(Ad, Bd)`` is not stabilisable and the Riccati equation has no
    solution. Then, and only then, the gain is designed on the controllable part (a Kalman
    decomposition: an orthonormal basis ``T`` of the controllable subspace,
    :func:`controllable_subspace`; the Riccati equation of ``T^T Ad T, T^T Bd`` with the state
    weight ``T^T Q T``; ``G = G_r T^T``). In an inertial frame the controllable part is the elastic
    motion the thrusting satellites can make with the passive ones at rest (a test checks that
    it spans exactly that; in a turning frame the frame terms may let the thrusters reach more).
    The law reads the state through its projection on that subspace, ``T^T z``, and
    stiffens and damps it; the rest, the passive satellites' own motion, gets no gain and keeps
    its open-loop poles in the design model (a drift at ``z = 1`` and the satellite damping). In
    the env a passive satellite is then damped only through its taut cables, by the thrusting
    satellites' motion. On a fully actuated id the system is
    controllable and the gain is the full design's, bit for bit. The thrust weight is set per
    id in ``hyperparams/laws.yml``.

    Args:
        env: a tether-gym env.
        thrust_weight: weight of the normalised thrust in the cost (Bryson's rule: 1).
        design: the model the gain is designed on: ``"slack"`` (every cable slack, the
            baseline) or ``"taut"`` (every cable taut, the earlier design, kept for comparison).
        predict_delay: act on the state predicted over a thrust delay (see
            :class:`~agents.controllers.base.Controller`).
    """

    name = "lqr"

    def __init__(
        self, env: Any, thrust_weight: float = 1.0, design: str = "slack", predict_delay: bool | None = None
    ) -> None:
        super().__init__(env, predict_delay)
        weight_is_number = isinstance(thrust_weight, (int, float, np.integer, np.floating)) and not isinstance(
            thrust_weight, bool
        )
        if not (weight_is_number and math.isfinite(thrust_weight) and thrust_weight > 0):
            raise ValueError(f"thrust_weight must be a finite number > 0; got {thrust_weight!r}")
        if design not in ("slack", "taut"):
            raise ValueError(f"design must be 'slack' (every cable slack) or 'taut' (every cable taut); got {design!r}")
        self.thrust_weight = float(thrust_weight)
        self.design = design
        #: The linear models with every cable taut and with every cable slack (same coordinates).
        self.models = {
            cables: LinearModel(self.task, cables=cables, cluster=self.cluster) for cables in ("taut", "slack")
        }
        self.model = model = self.models[design]
        state_weight = model.energy_weight() / self.task.energy_scale
        force_scale = np.repeat(self.max_thrust, 3)
        input_weight = np.diag(self.thrust_weight / force_scale**2)
        #: (2r, s) orthonormal basis of the design model's controllable subspace (s = 2r: all of it).
        self.controllable_basis = basis = controllable_subspace(model.Ad, model.Bd)
        if basis.shape[1] == model.Ad.shape[0]:
            riccati = scipy.linalg.solve_discrete_are(model.Ad, model.Bd, state_weight, input_weight)
            self.gain = np.linalg.solve(
                input_weight + model.Bd.T @ riccati @ model.Bd, model.Bd.T @ riccati @ model.Ad
            )  # (3k, 2r)
        else:
            # Kalman decomposition: no thruster reaches the rest (the passive satellites' free
            # motion while their cables are slack), which makes (Ad, Bd) unstabilisable. Design on
            # the controllable part, whose subspace Ad leaves invariant and Bd lies in.
            reduced_ad, reduced_bd = basis.T @ model.Ad @ basis, basis.T @ model.Bd
            reduced = scipy.linalg.solve_discrete_are(
                reduced_ad, reduced_bd, basis.T @ state_weight @ basis, input_weight
            )
            reduced_gain = np.linalg.solve(
                input_weight + reduced_bd.T @ reduced @ reduced_bd, reduced_bd.T @ reduced @ reduced_ad
            )  # (3k, s)
            self.gain = reduced_gain @ basis.T  # (3k, 2r)
            riccati = basis @ reduced @ basis.T
        self.riccati = riccati

    def closed_loop_eigenvalues(self, continuous: bool = True, cables: str | None = None) -> np.ndarray:
        """Eigenvalues of the unclipped closed loop of a linear model under this gain: of
        ``A - B G`` (1/s) with ``continuous=True``, else of the sampled ``Ad - Bd G``. ``cables``
        picks the model, ``"taut"`` or ``"slack"`` (None: the design model)."""
        model = self.model if cables is None else self.models.get(cables)
        if model is None:
            raise ValueError(f"cables must be 'taut', 'slack' or None; got {cables!r}")
        matrix = model.A - model.B @ self.gain if continuous else model.Ad - model.Bd @ self.gain
        return np.linalg.eigvals(matrix)

    def thrust(self, positions: np.ndarray, velocities: np.ndarray, elongations: np.ndarray) -> np.ndarray:
        displacement = positions - self.nominal_relative[None]
        state = self.model.modal_state(displacement, velocities)
        return -(state @ self.gain.T).reshape(positions.shape[0], self.thrusters.size, 3)


class TensionAwareController(Controller):
    """Tension-aware damping: velocity feedback, plus virtual struts across slack cables.

    **The idea.** A tension-only cable resists stretching but not shortening. With large initial
    conditions the cables of this task are slack much of the time. The cluster is then a
    mechanism, and only the small bias thrust (about 0.5 N for the default tetrahedron) pulls it
    back out to its nominal shape. Velocity feedback treats that slow re-tensioning like any
    other motion and brakes it. So the satellites creep outward at the speed where the brake
    equals the bias, and a slow tail of energy stored against the bias is left.

    This law gives each slack cable what it lacks, a compression strut. Each cable whose observed
    elongation ``dL`` is below the slack point ``-N0 L0 / EA`` pushes its two satellites apart
    with ``kappa |dL|`` along the cable. Together with velocity feedback ``-g m w`` on the
    deformation velocity, the strut is a proportional-derivative law in the slack directions.
    The stiffness is set for critical damping against the velocity-feedback gain,
    ``kappa = m g^2 / 4``, with ``g`` from the rule of :class:`VelocityFeedbackController`. Taut
    cables get no strut, because the cable itself is the spring there. The thrust limit clips
    the sum.

    **Passive satellites** (ids with thrusters on some satellites only): a strut across a cable
    with one passive end is pushed by the thrusting end alone, with its half of the pair of
    forces (a strut between two passive satellites pushes nothing). It then holds the thrusting
    satellite off the passive one rather than the pair apart. Dropping those struts instead (a
    strut only between two thrusting satellites) was measured on the tuning seeds 2000-2031 (32
    episodes, mean return): with the default gains it is better (underactuated tetrahedron
    -110.1 against -161.1, end-actuated chain -37.6 against -43.8), but with each variant's
    gain and strut re-tuned the one-sided strut wins (-62.6 against -70.0, and -29.6 against
    -35.4: the chain has no cable between two thrusting satellites, so without the one-sided
    struts the law is velocity feedback). So the law is unchanged, and its gains for those ids
    are in ``hyperparams/laws.yml``.

    Args:
        env: a tether-gym env.
        gain: velocity-feedback rate ``g`` in 1/s; None applies the velocity-feedback rule.
        strut_stiffness: ``kappa`` in N/m; None uses ``m g^2 / 4`` with the mean thruster mass.
        tether_strut_stiffness: the strut across a tether with mass, N/m (default 0: none).
        predict_delay: act on the state predicted over a thrust delay (see
            :class:`~agents.controllers.base.Controller`).

    **Tethers with mass.** The law runs on :func:`~agents.controllers.base.equivalent_cluster`:
    a tether is one cable between its satellites, slack while the length along its beads (its
    observed elongation) is below the slack point, and its strut pushes the satellites apart
    along their chord. That strut is off by default. A slack line with mass is re-tensioned
    by a snap that whips its beads, and a stronger strut snaps it sooner and harder. On the
    beaded tetrahedron (2 kg tethers, 8 segments, tuning seeds 2000-2005), the mean return was
    -68.2 with no strut, -61.7 at 4 N/m, -99.0 at 40 N/m and -136.7 at the massless rule's
    413 N/m (94 % of commands saturated), against -61.2 for ``local_tension_aware``. Plain
    cables keep their struts.
    """

    name = "tension_aware"

    def __init__(
        self,
        env: Any,
        gain: float | None = None,
        strut_stiffness: float | None = None,
        tether_strut_stiffness: float = 0.0,
        predict_delay: bool | None = None,
    ) -> None:
        super().__init__(env, predict_delay)
        # The inner law only supplies the gain and the feedback on the state this law decoded.
        self.velocity_feedback = VelocityFeedbackController(env, gain=gain, predict_delay=False)
        self.gain = self.velocity_feedback.gain
        if strut_stiffness is None:
            strut_stiffness = float(self.masses[self.thrusters].mean()) * self.gain**2 / 4.0
        if not (math.isfinite(strut_stiffness) and strut_stiffness >= 0):
            raise ValueError(f"strut_stiffness must be a finite stiffness >= 0 N/m; got {strut_stiffness!r}")
        self.strut_stiffness = float(strut_stiffness)
        if not (isinstance(tether_strut_stiffness, (int, float)) and math.isfinite(tether_strut_stiffness)) or (
            tether_strut_stiffness < 0
        ):
            raise ValueError(
                f"tether_strut_stiffness must be a finite stiffness >= 0 N/m; got {tether_strut_stiffness!r}"
            )
        cluster = self.cluster
        #: (c,) N/m, each cable's strut; the last cables of a beaded env's equivalent cluster are its tethers.
        self.cable_strut_stiffness = np.full(cluster.num_cables, self.strut_stiffness)
        self.cable_strut_stiffness[cluster.num_cables - self.task.cluster.num_tethers :] = float(tether_strut_stiffness)
        self.cables = cluster.cables
        self.slack_point = -cluster.N0 / cluster.stiffness  # (c,) m, elongation below which a cable is slack

    def strut_forces(self, positions: np.ndarray, elongations: np.ndarray) -> np.ndarray:
        """(N, n, 3) forces (N) of the virtual struts across the slack cables."""
        i, j = self.cables[:, 0], self.cables[:, 1]
        delta = positions[:, j] - positions[:, i]
        direction = delta / np.maximum(np.linalg.norm(delta, axis=2, keepdims=True), 1e-12)
        shortfall = np.where(elongations < self.slack_point[None], -elongations, 0.0)  # (N, c) m, >= 0
        push = (self.cable_strut_stiffness * shortfall)[:, :, None] * direction
        force = np.zeros(positions.shape)
        np.add.at(force, (slice(None), i), -push)
        np.add.at(force, (slice(None), j), push)
        return force

    def thrust(self, positions: np.ndarray, velocities: np.ndarray, elongations: np.ndarray) -> np.ndarray:
        damping = self.velocity_feedback.thrust(positions, velocities, elongations)
        return damping + self.strut_forces(positions, elongations)[:, self.thrusters]
