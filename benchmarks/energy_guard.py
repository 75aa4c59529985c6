"""Choose the stable safety-factor range and the runaway guard's tolerance from measurements.

What it measures
----------------
(a) **Snapping pairs.**  Undamped pairs (1 kg satellites, a 10 m cable of EA = 1e4 N) with a
    pretension of 1, 100 and 1000 N, 64 random perturbations each (0.05 m, 0.1 m/s), so that the
    cable goes slack and snaps taut, advanced in 0.1 s intervals for 10 s.  For each safety
    factor: the largest growth of the mechanical energy ``E / E0``, the worst relative residual
    of the energy balance, and how many pairs the runaway guard flags.

(b) **The eight default ids at the default safety factor and at the largest accepted without
    opt-in** (0.1 and 0.2), 64 envs each for 300 steps, with
    uniform random and saturated (+-1) thrust, and then again with every disturbance on (kicks,
    a periodic force, thrust noise, failing thrusters) and cables that break (a 3 N breaking
    load, ``cable_failure="continue"``).  It reports the worst relative residual seen: the guard's
    tolerance must leave a wide margin above it, and nothing may be flagged.

(c) **The same ids at a safety factor of 1.0** (with the opt-in), random thrust: the runs the
    guard must stop.

The relative residual is ``|kinetic + strain + frame potential - initial + dissipated - work|``
over the largest of ``|initial|``, ``kinetic + strain + |frame potential|``, ``|work|`` and
``dissipated`` (the kernel's check also keeps the largest of these since the reset).

Usage::

    python benchmarks/energy_guard.py            # about a minute on two cores
    python benchmarks/energy_guard.py --quick    # fewer envs and steps
"""

from __future__ import annotations

import argparse
import warnings

import numpy as np

import tether_gym as tg
from tether_gym.envs.vector_env import TetherClusterVectorEnv
from tether_gym.registration import ENV_IDS
from tether_gym.simulator import (
    ENERGY_RUNAWAY_TOLERANCE,
    MAX_STABLE_SAFETY_FACTOR,
    BatchSimulator,
    UnstableSafetyFactorWarning,
)

RUNAWAY = 3
FACTORS = (0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.8, 1.0)
DISTURBED = dict(
    impulse_magnitude=0.5,
    impulse_rate=0.5,
    periodic_amplitude=0.2,
    periodic_period=5.0,
    thrust_noise=0.1,
    thruster_failure_probability=0.5,
    cable_failure="continue",
)


def relative_residual(sim: BatchSimulator) -> np.ndarray:
    """(B,) |energy-balance residual| over the energy scale of the books, now."""
    return sim.energy().relative_residual


def quiet_batch(cluster: tg.Cluster, count: int, safety_factor: float) -> BatchSimulator:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UnstableSafetyFactorWarning)
        return BatchSimulator(cluster, count, safety_factor=safety_factor, allow_unstable_safety_factor=True)


def snapping_pairs(count: int, seconds: float) -> None:
    print(f"(a) snapping pairs, {count} perturbations each, {seconds:g} s in 0.1 s intervals")
    print("    N0 (N)  factor  max E/E0  median E/E0  worst residual  flagged")
    rng = np.random.default_rng(0)
    for pretension in (1.0, 100.0, 1000.0):
        pair = tg.Cluster(positions=[[0, 0, 0], [10, 0, 0]], masses=1.0, cables=[(0, 1)], EA=1e4, N0=pretension)
        x0 = pair.positions + rng.normal(0, 0.05, (count, 2, 3))
        v0 = rng.normal(0, 0.1, (count, 2, 3))
        for factor in FACTORS:
            batch = quiet_batch(pair, count, factor)
            batch.reset(x0, v0)
            energy0 = batch.energy().total.copy()
            worst = 0.0
            growth = np.ones(count)
            for _ in range(round(seconds / 0.1)):
                batch.advance(0.1)
                healthy = batch.status == 0
                worst = max(worst, float(relative_residual(batch)[healthy].max(initial=0.0)))
                growth = np.where(healthy, np.maximum(growth, batch.energy().total / energy0), growth)
            flagged = int((batch.status == RUNAWAY).sum())
            print(
                f"    {pretension:6g}  {factor:6.2f}  {growth.max():8.3g}  {np.median(growth):11.3g}  "
                f"{worst:14.3g}  {flagged:3d}/{count}"
            )


def env_ids(count: int, steps: int, safety_factor: float, modes: tuple[str, ...]) -> float:
    overall = 0.0
    width = max(map(len, ENV_IDS))  # the id column fits the longest id
    for env_id, (preset, _, task) in ENV_IDS.items():
        for mode in modes:
            kwargs = dict(task, safety_factor=safety_factor, allow_unstable_safety_factor=True)
            # An id's own preset settings (such as its segment count) stay; the disturbed mode adds to them.
            preset_kwargs = dict(kwargs.pop("preset_kwargs", None) or {}) or None
            if mode.endswith("disturbed"):
                kwargs.update(DISTURBED)
                preset_kwargs = {**(preset_kwargs or {}), "breaking_load": 3.0}
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", UnstableSafetyFactorWarning)
                env = TetherClusterVectorEnv(
                    count, preset, preset_kwargs=preset_kwargs, max_episode_steps=steps, **kwargs
                )
            env.reset(seed=1)
            rng = np.random.default_rng(2)
            worst, flagged, broken = 0.0, 0, 0
            for _ in range(steps):
                action = rng.uniform(-1, 1, env.action_space.shape)
                if mode.startswith("saturated"):
                    action = np.sign(action)
                env.step(action.astype(np.float32))
                sim = env.task.sim
                healthy = sim.status == 0
                worst = max(worst, float(relative_residual(sim)[healthy].max(initial=0.0)))
                flagged += int((sim.status == RUNAWAY).sum())
                broken += int(sim.broken.any(axis=1).sum())
            overall = max(overall, worst)
            print(
                f"    {env_id:{width}s} {mode:19s} worst residual {worst:7.4f}  flagged env-steps {flagged:5d}  "
                f"env-steps with a broken cable {broken}"
            )
            env.close()
    return overall


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="16 envs, 100 steps, 3 s of pairs")
    args = parser.parse_args()
    count, steps, seconds = (16, 100, 3.0) if args.quick else (64, 300, 10.0)
    print(f"runaway guard tolerance: {ENERGY_RUNAWAY_TOLERANCE:g}")
    snapping_pairs(count, seconds)
    modes = ("random", "saturated", "random disturbed", "saturated disturbed")
    for factor in (tg.simulator.DEFAULT_SAFETY_FACTOR, MAX_STABLE_SAFETY_FACTOR):
        print(f"(b) the {len(ENV_IDS)} ids at safety factor {factor:g}, {count} envs x {steps} steps")
        worst = env_ids(count, steps, factor, modes)
        print(f"    largest relative residual at {factor:g}: {worst:.4f}")
    print(f"(c) the {len(ENV_IDS)} ids at safety factor 1.0 (opt-in), {count} envs x {steps} steps")
    env_ids(count, steps, 1.0, ("random",))


if __name__ == "__main__":
    main()
