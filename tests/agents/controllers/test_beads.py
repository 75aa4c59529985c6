"""The scripted laws on clusters whose tethers have mass (beads): the equivalent cluster they are
designed on, the decoding of the satellite-only observation, and every baseline against passive."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agents.controllers.base import Controller, equivalent_cluster
from agents.controllers.registry import BASELINES, make_baseline
from agents.evaluation.rollout import rollout

BEADED = {"preset_kwargs": {"tether_mass": 2.0, "segments": 8}}


def beaded_env(env_id: str = "TetherTetrahedron-v0", **kwargs: object) -> gym.Env:
    return gym.make(env_id, **BEADED, **kwargs)


def test_equivalent_cluster_keeps_mass_centre_and_tether_lengths() -> None:
    cluster = beaded_env().unwrapped.task.cluster
    equivalent = equivalent_cluster(cluster)
    S = cluster.num_satellites
    assert equivalent.num_nodes == S and not equivalent.num_beads
    assert equivalent.num_cables == cluster.num_cables - sum(t.segments for t in cluster.tethers) + cluster.num_tethers
    np.testing.assert_allclose(equivalent.masses.sum(), cluster.masses.sum(), rtol=1e-14)
    centre = (cluster.masses[:, None] * cluster.positions).sum(axis=0) / cluster.masses.sum()
    equivalent_centre = (equivalent.masses[:, None] * equivalent.positions).sum(axis=0) / equivalent.masses.sum()
    np.testing.assert_allclose(equivalent_centre, centre, atol=1e-12)
    for t, spec in enumerate(cluster.tethers):
        c = equivalent.num_cables - cluster.num_tethers + t
        assert tuple(equivalent.cables[c]) == tuple(spec.ends)
        np.testing.assert_allclose(equivalent.L0[c], cluster.L0[cluster.tether_cables(t)].sum(), rtol=1e-14)
    massless = gym.make("TetherTetrahedron-v0").unwrapped.task.cluster
    assert equivalent_cluster(massless) is massless


@settings(max_examples=12, deadline=None, derandomize=True)
@given(
    env_id=st.sampled_from(["TetherTetrahedron-v0", "TetherChain-v0"]),
    tether_mass=st.floats(0.05, 20.0),
    segments=st.integers(2, 16),
    seed=st.integers(0, 2**31 - 1),
)
def test_decode_reads_satellites_and_tethers_of_the_observation(
    env_id: str, tether_mass: float, segments: int, seed: int
) -> None:
    """Property: whatever the tethers' mass and segment count, the decoded state is the
    simulator's satellites (not its first nodes by another count) and its tethers' lengths."""
    env = gym.make(env_id, preset_kwargs={"tether_mass": tether_mass, "segments": segments})
    controller = Controller(env)
    observation, _ = env.reset(seed=seed)
    for _ in range(20):  # let the beads move off their line
        observation, *_ = env.step(env.action_space.sample())
    task = env.unwrapped.task
    cluster = task.cluster
    S = cluster.num_satellites
    X, V, m = task.sim.positions[0], task.sim.velocities[0], cluster.masses
    positions, velocities, elongations = controller.decode(observation[None].astype(np.float64))
    scale = task.length_scale
    centre = (m[:, None] * X).sum(axis=0) / m.sum()
    np.testing.assert_allclose(positions[0], X[:S] - centre, atol=1e-5 * scale)
    centre_velocity = (m[:, None] * V).sum(axis=0) / m.sum()
    np.testing.assert_allclose(velocities[0], V[:S] - centre_velocity, atol=1e-5 * task.speed_scale)
    # Plain cables: chord minus L0; tethers: the length along the beads minus the tether's L0.
    plain = cluster.num_cables - sum(t.segments for t in cluster.tethers)
    ends = cluster.cables[:plain]
    expected = list(np.linalg.norm(X[ends[:, 1]] - X[ends[:, 0]], axis=1) - cluster.L0[:plain])
    for t in range(cluster.num_tethers):
        path = X[cluster.tether_nodes(t)]
        expected.append(
            np.linalg.norm(np.diff(path, axis=0), axis=1).sum() - cluster.L0[cluster.tether_cables(t)].sum()
        )
    assert elongations.shape == (1, controller.cluster.num_cables)
    np.testing.assert_allclose(elongations[0], expected, atol=1e-5 * scale)


def episode_returns(controller: object, env: gym.Env, seeds: tuple[int, ...]) -> np.ndarray:
    returns = []
    for seed in seeds:
        observation, _ = env.reset(seed=seed)
        total, done = 0.0, False
        while not done:
            action, _ = controller.predict(observation)  # type: ignore[attr-defined]
            observation, reward, terminated, truncated, info = env.step(action)
            assert not terminated, (seed, info)
            total += float(reward)
            done = terminated or truncated
        returns.append(total)
    return np.array(returns)


def test_every_baseline_runs_on_a_beaded_tetrahedron_and_beats_passive() -> None:
    env = beaded_env()
    seeds = (0, 1)
    passive = episode_returns(make_baseline("passive", env), env, seeds)
    for name in BASELINES:
        if name == "passive":
            continue
        controller = make_baseline(name, env)
        returns = episode_returns(controller, env, seeds)
        assert np.all(returns > passive), (name, returns, passive)
        assert controller.saturation_fraction < 0.5, name


def test_local_act_refuses_the_multiagent_slots_of_beaded_clusters() -> None:
    controller = make_baseline("local_tension_aware", beaded_env())
    with pytest.raises(ValueError, match="act_local.*tethers with mass"):
        controller.act_local(np.zeros((1, 4, controller.layout.size)))  # type: ignore[attr-defined]


@settings(max_examples=10, deadline=None, derandomize=True)
@given(segments=st.integers(2, 12), beyond=st.integers(0, 200))
def test_rollout_checks_the_satellite_against_the_satellites_not_the_nodes(segments: int, beyond: int) -> None:
    """Property: any index past the satellites is refused, however many beads there are."""
    kwargs = {"preset_kwargs": {"tether_mass": 2.0, "segments": segments}}
    env = gym.make("TetherTetrahedron-v0", **kwargs)
    S = env.unwrapped.task.cluster.num_satellites
    with pytest.raises(ValueError, match=f"satellite must be in 0..{S - 1}"):
        rollout(make_baseline("passive", env), "TetherTetrahedron-v0", [0], satellite=S + beyond, env_kwargs=kwargs)


def test_mpc_plans_the_beads_as_the_env_steps_them() -> None:
    """The planner's rollout of its nominal plan (the prior alone, noise 0) scores exactly the
    return the env then gives that prior, beads included; and a short mpc beats passive."""
    from agents.controllers.mpc import MPCController, MPCSettings

    envs = gym.make_vec("TetherTetrahedron-v0", num_envs=2, **BEADED)
    observation, _ = envs.reset(seed=[7, 8])
    horizon = 6
    planner = MPCController(envs, MPCSettings(samples=2, horizon=horizon, knots=1, noise=0.0, prior="lqr"))
    costs = planner._rollout(planner.task.snapshot().select(planner.rows), planner._candidates(0.0))
    prior = make_baseline("lqr", envs)
    total = np.zeros(2)
    for _ in range(horizon):
        observation, reward, *_ = envs.step(prior.predict(observation)[0])
        total += reward
    assert np.array_equal(-costs[:, 0], total), (costs, total)

    seeds, short = [3000, 3001], {**BEADED, "max_episode_steps": 40}
    probe = gym.make_vec("TetherTetrahedron-v0", num_envs=1, **BEADED)
    passive = rollout(make_baseline("passive", probe), "TetherTetrahedron-v0", seeds, env_kwargs=short)
    settings = MPCSettings(samples=8, horizon=5, knots=2, noise=0.3, terminal_weight=10.0, prior="velocity_feedback")
    mpc = rollout(MPCController(probe, settings), "TetherTetrahedron-v0", seeds, env_kwargs=short)
    assert mpc.rewards.sum(axis=1).mean() > passive.rewards.sum(axis=1).mean()
    assert not mpc.terminated.any()
