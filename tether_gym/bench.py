"""Environment throughput: ``python -m tether_gym.bench``.

Measures, for the default id (or every id with ``--all-ids``):
- single-env steps/s through ``gymnasium.make`` with its default wrappers (order enforcing,
  passive env checker, time limit), for zero and uniformly random actions;
- native vector env steps/s (``gym.make_vec``) at several N, and Gymnasium's ``SyncVectorEnv``
  over single envs at N = 64 for comparison;
- the share of PPO training time spent in the env (when stable-baselines3 is installed).
Episodes auto-reset throughout. Compilation is warmed up first and excluded.
"""

from __future__ import annotations

import argparse
import os
import platform
import time

import gymnasium as gym
import numpy as np

import tether_gym
from tether_gym.registration import DEFAULT_ENV_ID, ENV_IDS


def single_env_steps_per_second(env_id: str, steps: int, policy: str, seed: int = 0) -> float:
    """Steps/s of ``gym.make(env_id)`` over ``steps`` steps (resetting at episode ends)."""
    env = gym.make(env_id)
    rng = np.random.default_rng(seed)
    shape = env.action_space.shape
    actions = (
        np.zeros((steps,) + shape, dtype=np.float32)
        if policy == "zero"
        else rng.uniform(-1, 1, (steps,) + shape).astype(np.float32)
    )
    env.reset(seed=seed)
    for action in actions[:50]:  # warm-up: compilation or cache load
        env.step(action)
    env.reset(seed=seed)
    start = time.perf_counter()
    for action in actions:
        _, _, terminated, truncated, _ = env.step(action)
        if terminated or truncated:
            env.reset()
    return steps / (time.perf_counter() - start)


def vector_env_steps_per_second(env_id: str, num_envs: int, steps: int, sync: bool = False,
                                **kwargs: object) -> float:
    """Env steps/s (sub-env steps summed) of ``gym.make_vec`` with random actions."""
    mode = "sync" if sync else None
    envs = gym.make_vec(env_id, num_envs=num_envs, vectorization_mode=mode, **kwargs)
    rng = np.random.default_rng(0)
    actions = rng.uniform(-1, 1, (8,) + envs.action_space.shape).astype(np.float32)
    envs.reset(seed=0)
    for k in range(5):
        envs.step(actions[k % 8])
    start = time.perf_counter()
    for k in range(steps):
        envs.step(actions[k % 8])
    elapsed = time.perf_counter() - start
    envs.close()
    return num_envs * steps / elapsed


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--steps", type=int, default=30_000, help="timed steps per measurement")
    parser.add_argument("--repeats", type=int, default=3, help="measurements per case (the best is shown)")
    parser.add_argument("--all-ids", action="store_true", help="every registered id, not only the default")
    args = parser.parse_args(argv)
    print(f"tether-gym {tether_gym.__version__}, gymnasium {gym.__version__}, numpy {np.__version__}, "
          f"python {platform.python_version()}, {os.cpu_count()} cores")
    print(f"single env through gym.make (default wrappers), {args.steps} steps, best of {args.repeats}")
    print(f"{'id':<24}{'actions':<10}{'steps/s':>12}")
    for env_id in ENV_IDS if args.all_ids else [DEFAULT_ENV_ID]:
        for policy in ("zero", "random"):
            best = max(single_env_steps_per_second(env_id, args.steps, policy, seed) for seed in range(args.repeats))
            print(f"{env_id:<24}{policy:<10}{best:>12,.0f}")
    print()
    print(f"vector envs, random actions, env steps/s (sub-env steps summed), best of {args.repeats}")
    print(f"{'id':<24}{'vectorisation':<34}{'N':>6}{'steps/s':>14}")
    for env_id in ENV_IDS if args.all_ids else [DEFAULT_ENV_ID]:
        cases = [("native", n, {}) for n in (1, 64, 1024, 4096)]
        cases += [("native, safety_factor 0.2", 1024, {"safety_factor": 0.2}), ("SyncVectorEnv", 64, {})]
        for label, n, kwargs in cases:
            steps = max(20, min(2000, 200_000 // n))
            best = max(
                vector_env_steps_per_second(env_id, n, steps, sync=label == "SyncVectorEnv", **kwargs)
                for _ in range(args.repeats)
            )
            print(f"{env_id:<24}{label:<34}{n:>6}{best:>14,.0f}")


if __name__ == "__main__":
    main()
