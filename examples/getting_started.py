"""Getting started: a cluster, its simulator, the Gymnasium env, and three controllers compared.

The tutorial (``docs/tutorial.md``) walks through this script step by step, and shows its
output, which ``bash scripts/figures.sh`` writes there from a real run. Every number it prints
comes from the simulation; nothing in it depends on the machine's speed, so a rerun prints the
same lines. Run it from the repository root (about 20 s, most of it loading the compiled kernels
and torch), or from any directory with a Python that has the wheel installed::

    .venv/bin/python examples/getting_started.py

It needs the ``train`` extra (``bash scripts/install.sh train``) for the scripted baselines and
the shipped policies of ``agents/``. It imports them as ``tether_gym_agents``, the name they are
installed under (from a wheel, or editable from a checkout), so it runs from any directory; in
a checkout, ``agents`` is the same code.
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np
from tether_gym_agents.evaluation.rollout import rollout, summarise
from tether_gym_agents.policies import make_controller, shipped_models

import tether_gym as tg


def simulator_step() -> None:
    """Step 1: a preset cluster, released from a disturbed shape, in the bare simulator."""
    cluster = tg.make_cluster("tetrahedron")
    print(f"1. cluster 'tetrahedron': {cluster.num_nodes} satellites, {cluster.num_cables} cables")
    sim = tg.Simulator(cluster)
    rng = np.random.default_rng(0)
    # A 5 cm disturbance of every satellite, at rest: small next to the 100 m cables.
    positions = cluster.positions + rng.normal(0.0, 0.05, cluster.positions.shape)
    sim.reset(positions=positions, velocities=np.zeros_like(positions))
    print(f"   critical time step at the start: {sim.critical_time_step():.4f} s")
    # The bias thrust holds the nominal shape against the cables' pretension (the envs add it too).
    bias = sim.internal_forces(cluster.positions)
    stats = sim.advance(10.0, force=bias)
    energy = sim.energy()
    # A Simulator is a batch of one: its per-cluster statistics have shape (1,).
    print(f"   advanced 10 s in {int(stats.substeps[0])} sub-steps of {float(stats.step_min[0]):.4f} s or more")
    print(
        f"   energy account (J): mechanical {energy.initial:.4f} -> {energy.total:.4f}, "
        f"dissipated by damping {energy.dissipated:.4f}, work of the thrust {energy.work:.4f}, "
        f"residual {energy.residual:.1e}"
    )


def one_episode(env: gym.Env, controller: str, seed: int) -> tuple[float, float]:
    """One episode of ``controller`` on ``env`` from the reset seeded ``seed``:
    (return, vibration energy at the end as a fraction of the initial one)."""
    policy = make_controller(controller, env)
    obs, info = env.reset(seed=seed)
    energy0 = info["vibration_energy"]
    total, done = 0.0, False
    while not done:
        action, _ = policy.predict(obs, deterministic=True)
        obs, reward, terminated, truncated, info = env.step(action)
        total += float(reward)
        done = terminated or truncated
    return total, info["vibration_energy"] / energy0


def env_step() -> None:
    """Step 2: the default Gymnasium id, one episode of three controllers on the same seed."""
    env = gym.make(tg.DEFAULT_ENV_ID)
    print(f"2. {tg.DEFAULT_ENV_ID}")
    print(f"   action space:      {env.action_space}")
    print(f"   observation space: {env.observation_space}")
    print(f"   shipped models for this id: {sorted(shipped_models(tg.DEFAULT_ENV_ID))}")
    print("   one episode from seed 0:")
    for controller in ("passive", "lqr", "ars"):
        total, left = one_episode(env, controller, seed=0)
        print(f"   {controller:>8}: return {total:8.2f}, energy left at 30 s {100 * left:6.2f} %")
    env.close()


def comparison_step() -> None:
    """Step 3: the same controllers on 16 held-out episodes at once, as tether-gym-compare does."""
    seeds = range(10_000, 10_016)
    print(f"3. {len(seeds)} held-out episodes (seeds {seeds[0]}..{seeds[-1]}), on the native vector env")
    probe = gym.make_vec(tg.DEFAULT_ENV_ID, num_envs=1)
    for controller in ("passive", "lqr", "ars"):
        record = rollout(make_controller(controller, probe), tg.DEFAULT_ENV_ID, seeds, name=controller)
        cells = summarise(record)["cells"]
        print(
            f"   {controller:>8}: return {cells['return']:>14}, E(10 s)/E0 {cells['energy_10s']}, "
            f"propellant {cells['propellant']} N*s, failures {cells['failures']}"
        )
    probe.close()


def main() -> None:
    simulator_step()
    env_step()
    comparison_step()


if __name__ == "__main__":
    main()
