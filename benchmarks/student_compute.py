"""Compute per control step of each shipped DAgger student against its teacher, the reference
ceiling planner: ``python benchmarks/student_compute.py [--envs ID ...]``.

The issue the students answer asks for a network that acts at least 1000 times faster than the
planner it imitates. For every id with a shipped ``dagger`` model (``agents/models/<id>/dagger``)
this rolls the student out for one episode of the id (seed 10 000) and times it on those
observations with :func:`agents.training.dagger.measure_compute`, torch on one thread, best of
three passes:

* the whole student one observation at a time (normalisation, the network, the law it corrects
  and the residual rule), as one cluster's flight computer would run it;
* the same on batches of 8 observations, per observation;
* its network alone, and the law alone.

The teacher's figure is the one the reference ceiling recorded when it was computed
(``agents/reference/ceiling.json``: seconds of planning per env and control step, one episode at
a time, with the machine it ran on); a student's speed-up is that over its own figure. The two
are measured on different runs of the same kind of machine, so run this on a quiet machine: a
loaded one inflates the student's time and understates the ratio. It prints the CPU model with
the table. About 20 s per id.
"""

from __future__ import annotations

import argparse
from typing import Any

import numpy as np

EPISODE_SEED = 10_000
BATCH = 8


def episode_observations(env_id: str, controller_name: str) -> tuple[np.ndarray, Any, Any]:
    """The (T, O) observations of one episode of ``env_id`` under its shipped ``controller_name``
    (seed :data:`EPISODE_SEED`), with the attached controller and its law (attached likewise)."""
    import gymnasium as gym
    from tether_gym_agents.controllers.registry import make_baseline
    from tether_gym_agents.policies import make_controller

    env = gym.make(env_id)
    student = make_controller(controller_name, env)
    law = make_baseline(student.residual_on, env)
    observation, _ = env.reset(seed=EPISODE_SEED)
    rows = [observation]
    while True:
        action, _ = student.predict(observation, deterministic=True)
        observation, _, terminated, truncated, _ = env.step(action)
        if terminated or truncated:
            break
        rows.append(observation)
    env.close()
    return np.asarray(rows, dtype=np.float32), student, law


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--envs", nargs="+", help="ids (default: every id with a shipped dagger model)")
    args = parser.parse_args()

    from tether_gym_agents.evaluation.ceiling import load_ceiling
    from tether_gym_agents.policies import shipped_models
    from tether_gym_agents.training.dagger import measure_compute

    import tether_gym
    from tether_gym.bench import cpu_model

    ceiling = load_ceiling()
    ids = args.envs or [env_id for env_id in tether_gym.ENV_IDS if "dagger" in shipped_models(env_id)]
    unknown = [env_id for env_id in ids if "dagger" not in shipped_models(env_id) or env_id not in ceiling]
    if unknown:
        parser.error(f"no shipped dagger model or no reference ceiling for {unknown}: pass ids that have both")
    print(f"CPU: {cpu_model()}; torch on one thread; batches of {BATCH}")
    print()
    print(
        "| id | planner per step (ceiling.json) | student, one observation | speed-up | student, batched | "
        "speed-up | network alone | law alone |"
    )
    print("|---|---|---|---|---|---|---|---|")
    for env_id in ids:
        observations, student, law = episode_observations(env_id, "dagger")
        timings = measure_compute(student, law, observations, BATCH)
        planner = ceiling[env_id].seconds_per_step
        print(
            f"| {env_id} | {planner * 1e3:.1f} ms | {timings['student_single'] * 1e6:.0f} µs | "
            f"{planner / timings['student_single']:,.0f}x | {timings['student_batched'] * 1e6:.0f} µs | "
            f"{planner / timings['student_batched']:,.0f}x | {timings['network_single'] * 1e6:.0f} µs | "
            f"{timings['law_single'] * 1e6:.0f} µs |",
            flush=True,
        )


if __name__ == "__main__":
    main()
