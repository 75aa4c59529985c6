"""Environment throughput: ``python -m tether_gym.bench``.

Measures steps per second of the registered environments through ``gymnasium.make`` with its
default wrappers (order enforcing, passive env checker, time limit), auto-resetting at episode
ends, for zero and uniformly random actions.  Compilation is warmed up first and excluded.
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


if __name__ == "__main__":
    main()
