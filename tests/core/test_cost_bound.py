"""The rigorous lower bound on a controller's cost (:func:`tether_gym.analysis.cost_lower_bound`).

It is a bound: a controller that scores better than it on any seed fails these tests, and so
does an envelope that a controller can beat by removing energy faster than the bound allows.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import tether_gym as tg
from tether_gym.analysis import CostBoundScopeError, _thrust_efficiency, cost_lower_bound
from tether_gym.envs import TetherClusterEnv
from tether_gym.registration import DEFAULT_ENV_ID

REFERENCE = Path(__file__).resolve().parents[2] / "agents" / "reference" / "reference_scores.json"


def _reference() -> dict[str, Any]:
    return json.loads(REFERENCE.read_text())


@pytest.mark.parametrize("env_id", list(_reference()["per_id"]))
def test_bound_is_below_every_reference_controller_on_every_seed(env_id: str) -> None:
    """Every controller of the shipped reference scores (passive, the scripted laws, mpc, the
    shipped models) costs at least the bound on each held-out seed; the default id is in scope."""
    data = _reference()
    entry = data["per_id"][env_id]
    if env_id not in gym.registry:
        pytest.skip(f"{env_id} is not registered in this checkout")
    kwargs = {**data.get("env_kwargs", {}), **entry.get("env_kwargs", {})}
    try:
        result = cost_lower_bound(env_id, entry["seeds"], **kwargs)
    except CostBoundScopeError as error:
        assert env_id != DEFAULT_ENV_ID, f"the default id must be in the bound's scope: {error}"
        pytest.skip(f"outside the bound's scope: {error}")
    assert result.bounds.shape == (len(entry["seeds"]),)
    assert (result.bounds > 0).all()
    for name, controller in entry["controllers"].items():
        costs = -np.asarray(controller["returns"], dtype=float)
        assert costs.shape == result.bounds.shape, name
        below = np.flatnonzero(costs < result.bounds)
        assert below.size == 0, (
            f"{env_id}: {name} costs {costs[below].tolist()} on seeds {np.asarray(entry['seeds'])[below].tolist()}, "
            f"below the lower bound {result.bounds[below].tolist()}"
        )


def test_initial_energy_is_the_rewards_vibration_energy_at_reset() -> None:
    """The envelope starts from each seed's own vibration energy: the exact rigid split at the
    reset, never above what the reward measures."""
    seeds = [3, 4]
    result = cost_lower_bound(DEFAULT_ENV_ID, seeds, max_episode_steps=5, return_energy=True)
    env = gym.make(DEFAULT_ENV_ID)
    for s, seed in enumerate(seeds):
        _, info = env.reset(seed=seed)
        assert result.initial_energy[s] <= info["vibration_energy"] * (1 + 1e-12)
        assert result.initial_energy[s] == pytest.approx(info["vibration_energy"], rel=1e-9)
        assert result.energy is not None and result.energy[s, 0] == result.initial_energy[s]
        assert (np.diff(result.energy[s]) <= 0).all()


#: A regular tetrahedron with its corners along the cube diagonals (+-1, +-1, +-1) s: every
#: satellite's radial direction has equal components, so a per-axis thrust against the velocity
#: meets the Cauchy-Schwarz and sqrt(3) factors of the bound with equality.
_SIDE = 10.0
_MASS = 10.0
_THRUST = 0.1
_SPEED = 0.1
_CORNERS = _SIDE * np.array([[1.0, 1.0, 1.0], [1.0, -1.0, -1.0], [-1.0, 1.0, -1.0], [-1.0, -1.0, 1.0]])


def _breathing_env(damping_rate: float, **task: Any) -> tuple[TetherClusterEnv, dict[str, np.ndarray]]:
    """The cube-diagonal tetrahedron without pretension (no bias), its satellites all moving
    inward at ``_SPEED``: the cables go slack, and only thrust and damping act."""
    cluster = tg.Cluster(
        positions=_CORNERS,
        masses=_MASS,
        cables=[(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)],
        EA=5e4,
        N0=0.0,
        damping=damping_rate * _MASS,
    )
    velocities = -_SPEED * _CORNERS / np.linalg.norm(_CORNERS, axis=1, keepdims=True)
    env = TetherClusterEnv(cluster=cluster, max_thrust=_THRUST, **task)
    return env, {"positions": _CORNERS, "velocities": velocities}


@pytest.mark.parametrize("damping_rate", [0.0, 0.2])
def test_bang_bang_thrust_meets_the_closed_form_envelope_and_never_beats_it(damping_rate: float) -> None:
    """Four equal satellites moving radially inward, cables slack: full per-axis thrust against
    the velocity decelerates each at sqrt(3) F / m, which is the largest rate of energy removal
    the bound allows, so the envelope follows the hand-computed solution of its ODE,

        sqrt(E(t)) = sqrt(E0) - b t / 2                       (no damping)
        sqrt(E(t)) = (sqrt(E0) + b / a) exp(-a t / 2) - b / a  (C = alpha M, a = 2 alpha)

    with ``b = sqrt(2) sqrt(sum 3 F^2 / m) = 2 sqrt(6) F / sqrt(m)``, to within the slack of its
    rotation terms, and the simulated bang-bang energy stays on or above it."""
    env, options = _breathing_env(damping_rate)
    steps = 35
    result = cost_lower_bound(env, [0], max_episode_steps=steps, return_energy=True, options=options)
    assert result.energy is not None
    envelope = result.energy[0]
    _, info = env.reset(seed=0, options=options)
    energy = [info["vibration_energy"]]
    for _ in range(steps):
        velocity = env.unwrapped.task.sim.velocities[0]
        _, _, terminated, _, info = env.step(-np.sign(velocity).ravel().astype(np.float32))
        assert not terminated
        energy.append(info["vibration_energy"])
    simulated = np.array(energy)

    e0 = 0.5 * 4 * _MASS * _SPEED**2
    b = 2.0 * math.sqrt(6.0) * _THRUST / math.sqrt(_MASS)
    a = 2.0 * damping_rate
    t = result.times
    root = math.sqrt(e0) - 0.5 * b * t if a == 0 else (math.sqrt(e0) + b / a) * np.exp(-0.5 * a * t) - b / a
    hand = np.maximum(root, 0.0) ** 2
    assert result.initial_energy[0] == pytest.approx(e0, rel=1e-12)
    assert result.constants["thrust_coefficient"][0] == pytest.approx(b, rel=1e-12)
    assert result.constants["dissipation_rate"][0] == pytest.approx(a, abs=1e-15)
    # The envelope is the hand solution less the rotation terms' small slack, never above it.
    assert (envelope <= hand * (1 + 1e-12) + 1e-15).all()
    assert np.abs(envelope - hand).max() <= 0.01 * e0
    # Bang-bang achieves the hand solution (central differences are exact for constant thrust)...
    assert np.abs(simulated - hand).max() <= 1e-3 * e0
    # ... and so never gets below the envelope: a bound a controller could beat fails here.
    assert (simulated >= envelope - 1e-12 * e0).all(), np.c_[t, simulated, envelope]


def test_cable_damping_enters_at_its_largest_rate() -> None:
    """The cables' Kelvin-Voigt damping removes at most ``2 lambda_max(M^-1/2 L_c M^-1/2) T_rel``
    (``L_c`` the Laplacian of the cables' coefficients), with equality for the breathing mode of
    equal satellites (``lambda_max = 4 c / m`` for the tetrahedron's complete graph).  Soft,
    pretensioned cables (taut, so damped, but storing little strain energy) and thrust against the
    velocity then follow the hand solution with ``a = 8 c / m`` at first, and never get below the
    envelope.  A fine control interval keeps the simulator's explicit cable damping (evaluated on
    the half-step velocity, which over-dissipates by O(a h) of the energy removed) small."""
    axial = 0.5
    cluster = tg.Cluster(
        positions=_CORNERS,
        masses=_MASS,
        cables=[(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)],
        EA=1.0,
        N0=1.0,
        axial_damping=axial,
    )
    env = TetherClusterEnv(cluster=cluster, max_thrust=_THRUST, control_interval=0.02)
    options = {"positions": _CORNERS, "velocities": _SPEED * _CORNERS / np.linalg.norm(_CORNERS, axis=1, keepdims=True)}
    steps = 100
    result = cost_lower_bound(env, [0], max_episode_steps=steps, return_energy=True, options=options)
    assert result.energy is not None
    assert result.constants["axial_rate"][0] == pytest.approx(4 * axial / _MASS, rel=1e-6)
    _, info = env.reset(seed=0, options=options)
    energy = [info["vibration_energy"]]
    for _ in range(steps):
        velocity = env.unwrapped.task.sim.velocities[0]
        _, _, _, _, info = env.step(-np.sign(velocity).ravel().astype(np.float32))
        energy.append(info["vibration_energy"])
    simulated = np.array(energy)
    e0 = simulated[0]
    a = 8.0 * axial / _MASS
    b = 2.0 * math.sqrt(6.0) * _THRUST / math.sqrt(_MASS)
    hand = np.maximum((math.sqrt(e0) + b / a) * np.exp(-0.5 * a * result.times) - b / a, 0.0) ** 2
    early = result.times <= 0.5
    assert np.abs(simulated[early] - hand[early]).max() <= 2e-3 * e0
    assert (result.energy[0] <= hand * (1 + 1e-12)).all()
    # The explicit cable damping over-dissipates by O(a h) of the energy removed (measured: a
    # sixth of a h, linear in h from h = 0.005 to 0.1 s); the margin allows half of a h.
    margin = 0.5 * a * env.unwrapped.task.config.control_interval * (e0 - result.energy[0])
    assert (simulated >= result.energy[0] - margin).all(), np.c_[result.times, simulated, result.energy[0]][:30]


def test_thrust_efficiency_is_the_concave_hull_of_the_on_off_subsets() -> None:
    """psi(Phi), the largest thrust coefficient a total thrust Phi can have, by hand: equal
    thrusters give sqrt(j / m) Fmax at j Fmax; a light and a heavy one (1 and 4 kg, 1 N each) give
    the hull of (0, 0), (1, 1) (the light one alone), (1, 0.5) and (2, sqrt(1.25))."""
    xs, ys = _thrust_efficiency(np.full(4, 2.0), np.full(4, 10.0))
    np.testing.assert_allclose(xs, 2.0 * np.arange(5))
    np.testing.assert_allclose(ys, 2.0 * np.sqrt(np.arange(5) / 10.0))
    xs, ys = _thrust_efficiency(np.array([1.0, 1.0]), np.array([4.0, 1.0]))
    np.testing.assert_allclose(xs, [0.0, 1.0, 2.0])
    np.testing.assert_allclose(ys, [0.0, 1.0, math.sqrt(1.25)])


def test_propellant_term_raises_the_bound_and_thrust_schedules_pay_it() -> None:
    """Removing energy takes thrust, and thrust costs propellant: the bound over every thrust
    schedule is above the full-thrust envelope's vibration cost alone, equals it when propellant
    is free, and no schedule of the breathing case (full thrust against the velocity for the first
    s steps, then none) costs less than it."""
    seeds = [10000, 10001]
    free = cost_lower_bound(DEFAULT_ENV_ID, seeds, propellant_weight=0.0, return_energy=True)
    assert free.energy is not None
    np.testing.assert_allclose(free.full_episode, free.vibration_weight * free.energy[:, 1:].sum(axis=1), rtol=1e-12)
    paid = cost_lower_bound(DEFAULT_ENV_ID, seeds, return_energy=True)
    assert paid.energy is not None
    assert (paid.full_episode > paid.vibration_weight * paid.energy[:, 1:].sum(axis=1) * 1.05).all()
    assert (paid.optimisation_gap < 0.1 + 0.02 * paid.full_episode).all()

    env, options = _breathing_env(0.0, vibration_weight=30.0)
    steps = 40
    result = cost_lower_bound(env, [0], max_episode_steps=steps, options=options)
    costs = []
    for switch in range(0, 36, 5):
        env.reset(seed=0, options=options)
        cost = 0.0
        for step in range(steps):
            velocity = env.unwrapped.task.sim.velocities[0]
            action = -np.sign(velocity).ravel() if step < switch else np.zeros(12)
            _, reward, terminated, _, _ = env.step(action.astype(np.float32))
            assert not terminated
            cost -= reward
        costs.append(cost)
    assert min(costs) >= result.bounds[0]
    assert min(costs) <= 1.5 * result.bounds[0], (costs, result.bounds)


def test_thruster_settings_enter_the_constants() -> None:
    """Thrusters on some satellites, per-thruster max_thrust and the magnitude limit change the
    thrust coefficient as the derivation says: b = sqrt(2 sum_thrusters Fmax_j^2 / m_j), Fmax =
    sqrt(3) max_thrust per axis, max_thrust for the magnitude limit; weaker thrust bounds higher."""
    seeds = [10000, 10001, 10002]
    full = cost_lower_bound(DEFAULT_ENV_ID, seeds)
    mass = tg.make_cluster("tetrahedron").masses[0]
    assert full.constants["thrust_coefficient"][0] == pytest.approx(math.sqrt(2 * 4 * 3 / mass))
    some = cost_lower_bound(DEFAULT_ENV_ID, seeds, thrusters=[0, 2], max_thrust=[0.5, 1.0])
    assert some.constants["thrust_coefficient"][0] == pytest.approx(math.sqrt(2 * 3 * (0.25 + 1.0) / mass))
    magnitude = cost_lower_bound(DEFAULT_ENV_ID, seeds, thrust_limit="magnitude")
    assert magnitude.constants["thrust_coefficient"][0] == pytest.approx(math.sqrt(2 * 4 / mass))
    weak = cost_lower_bound(DEFAULT_ENV_ID, seeds, max_thrust=0.25)
    # A delay leaves the thrust's limit, and so the bound, as it is.
    delayed = cost_lower_bound(DEFAULT_ENV_ID, seeds, thrust_delay=2)
    np.testing.assert_array_equal(delayed.bounds, full.bounds)
    for weaker in (some, magnitude, weak):
        assert (weaker.full_episode > full.full_episode).all()


_SCOPE_CASES: list[tuple[str, dict[str, Any], str]] = [
    ("TetherSpinningTriangle-v0", {}, "turning frame"),
    ("TetherRadialChain-v0", {}, "turning frame"),
    ("TetherChain-v0", {}, "collinear"),
    ("TetherBeadedTetrahedron-v0", {}, "not proportional to the masses"),
    (DEFAULT_ENV_ID, {"randomize": {"masses": 0.2}}, "not proportional to the masses"),
    (DEFAULT_ENV_ID, {"impulse_magnitude": 0.1}, "disturbances"),
    (DEFAULT_ENV_ID, {"periodic_amplitude": 0.1}, "disturbances"),
    (DEFAULT_ENV_ID, {"thrust_noise": 0.05}, "thrust_noise"),
    (DEFAULT_ENV_ID, {"cable_failure": "continue"}, "cable_failure"),
]


@pytest.mark.parametrize(("env_id", "kwargs", "reason"), _SCOPE_CASES)
def test_settings_outside_the_derivation_are_refused_with_the_reason(
    env_id: str, kwargs: dict[str, Any], reason: str
) -> None:
    try:
        made = gym.make(env_id, **kwargs)
    except ValueError:
        pytest.skip(f"{env_id} refuses {kwargs} itself")
    with pytest.raises(CostBoundScopeError, match=reason):
        cost_lower_bound(made, [0], max_episode_steps=3)


def test_in_scope_variants_are_accepted() -> None:
    """Beads are in scope when nothing is damped, damping is when it is proportional to mass, and a
    thruster fault only takes thrust away."""
    for env_id, kwargs in (
        ("TetherBeadedTetrahedron-v0", {"preset_kwargs": {"damping_rate": 0.0}}),
        (DEFAULT_ENV_ID, {"randomize": {"damping": 0.0}, "thruster_failure_probability": 1.0}),
    ):
        result = cost_lower_bound(env_id, [1, 2], max_episode_steps=20, **kwargs)
        assert (result.bounds > 0).all()


def test_bad_arguments_are_refused() -> None:
    with pytest.raises(ValueError, match="seeds"):
        cost_lower_bound(DEFAULT_ENV_ID, [-1])
    with pytest.raises(ValueError, match="seeds"):
        cost_lower_bound(DEFAULT_ENV_ID, [])
    with pytest.raises(ValueError, match="substeps"):
        cost_lower_bound(DEFAULT_ENV_ID, [0], substeps=0)
    with pytest.raises(ValueError, match="iterations"):
        cost_lower_bound(DEFAULT_ENV_ID, [0], iterations=-1)
    with pytest.raises(ValueError, match="max_episode_steps"):
        cost_lower_bound(DEFAULT_ENV_ID, [0], max_episode_steps=0)
    with pytest.raises(ValueError, match="env_kwargs"):
        cost_lower_bound(gym.make(DEFAULT_ENV_ID), [0], max_thrust=0.5)
    with pytest.raises(TypeError, match="TetherClusterEnv"):
        cost_lower_bound(gym.make("CartPole-v1"), [0])


@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    seed=st.integers(0, 2**31 - 1),
    thrusters=st.sampled_from([None, [0], [1, 3], [0, 1, 2]]),
    max_thrust=st.floats(0.05, 3.0),
    thrust_limit=st.sampled_from(["per_axis", "magnitude"]),
    thrust_mode=st.sampled_from(["continuous", "on_off"]),
    thrust_delay=st.integers(0, 2),
    damping_rate=st.sampled_from([0.0, 0.1, 0.5]),
    policy=st.sampled_from(["against", "random", "full"]),
)
def test_no_controller_gets_below_the_envelope(
    seed: int,
    thrusters: list[int] | None,
    max_thrust: float,
    thrust_limit: str,
    thrust_mode: str,
    thrust_delay: int,
    damping_rate: float,
    policy: str,
) -> None:
    """Property: on the tetrahedron with any thruster layout, limit, mode, delay and damping, thrust
    against each satellite's velocity, random thrust or full thrust never brings the vibration
    energy below the envelope at any step, nor the cost below the bound."""
    kwargs: dict[str, Any] = {
        "preset_kwargs": {"damping_rate": damping_rate},
        "thrusters": thrusters,
        "max_thrust": max_thrust,
        "thrust_limit": thrust_limit,
        "thrust_mode": thrust_mode,
        "thrust_delay": thrust_delay,
    }
    steps = 30
    env = gym.make(DEFAULT_ENV_ID, max_episode_steps=steps, **kwargs)
    result = cost_lower_bound(env, [seed], return_energy=True)
    assert result.energy is not None and result.max_episode_steps == steps
    _, info = env.reset(seed=seed)
    task = env.unwrapped.task
    rng = np.random.default_rng(seed)
    cost = 0.0
    for k in range(1, steps + 1):
        velocity = task.sim.velocities[0][task.thrusters]
        if policy == "against":
            action = -np.sign(velocity - velocity.mean(axis=0)).ravel()
        elif policy == "random":
            action = rng.uniform(-1, 1, env.action_space.shape)
        else:
            action = np.ones(env.action_space.shape)
        _, reward, terminated, truncated, info = env.step(action.astype(np.float32))
        cost -= reward
        assert info["vibration_energy"] >= result.energy[0, k] - 1e-9 * result.initial_energy[0], k
        if terminated or truncated:
            break
    assert cost >= result.bounds[0] - 1e-9
