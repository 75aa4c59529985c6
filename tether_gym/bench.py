"""Environment throughput: ``python -m tether_gym.bench``.

Measures, for the default id (or every id with ``--all-ids``):
- single-env steps/s through ``gymnasium.make`` with its default wrappers (order enforcing,
  passive env checker, time limit), for zero and uniformly random actions;
- native vector env steps/s (``gym.make_vec``) at several N, and Gymnasium's ``SyncVectorEnv``
  over single envs at N = 64 for comparison;
- the roofline (:mod:`tether_gym.roofline`): this CPU's limit for a sub-step's arithmetic on one
  thread, and the batched advance's measured rate at N = 1 024 as a **fraction of that limit**,
  for the default id and a beaded one;
- the share of PPO training time spent in the env (when stable-baselines3 is installed).
Episodes auto-reset throughout. Compilation is warmed up first and excluded.
"""

from __future__ import annotations

import argparse
import os
import platform
import time
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode

import tether_gym
from tether_gym._cli import program
from tether_gym._optional import available, install_line
from tether_gym.registration import DEFAULT_ENV_ID, ENV_IDS


def cpu_model() -> str:
    """The CPU's model name (Linux's /proc/cpuinfo), else what ``platform`` knows."""
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as info:
            for line in info:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def single_env_steps_per_second(env_id: str, steps: int, policy: str, seed: int = 0) -> float:
    """Steps/s of ``gym.make(env_id)`` over ``steps`` steps (resetting at episode ends)."""
    env = gym.make(env_id)
    rng = np.random.default_rng(seed)
    shape = tuple(env.action_space.shape or ())
    if isinstance(env.action_space, gym.spaces.Discrete):  # CartPole, measured beside for scale
        actions: Any = rng.integers(0, int(env.action_space.n), steps)
    elif policy == "zero":
        actions = np.zeros((steps,) + shape, dtype=np.float32)
    else:
        actions = rng.uniform(-1, 1, (steps,) + shape).astype(np.float32)
    env.reset(seed=seed)
    for action in actions[:50]:  # warm-up: compilation or cache load
        _, _, terminated, truncated, _ = env.step(action)
        if terminated or truncated:
            env.reset()
    env.reset(seed=seed)
    start = time.perf_counter()
    for action in actions:
        _, _, terminated, truncated, _ = env.step(action)
        if terminated or truncated:
            env.reset()
    return steps / (time.perf_counter() - start)


def vector_env_steps_per_second(env_id: str, num_envs: int, steps: int, sync: bool = False, **kwargs: Any) -> float:
    """Env steps/s (sub-env steps summed) of ``gym.make_vec`` with random actions."""
    # Same-step autoreset, the mode SB3 trains in and the one the recorded figures were taken in.
    autoreset: dict[str, Any] = {"autoreset_mode": AutoresetMode.SAME_STEP}
    if sync:
        envs = gym.make_vec(env_id, num_envs=num_envs, vectorization_mode="sync", vector_kwargs=autoreset, **kwargs)
    else:
        envs = gym.make_vec(env_id, num_envs=num_envs, **autoreset, **kwargs)
    rng = np.random.default_rng(0)
    actions = rng.uniform(-1, 1, (8,) + tuple(envs.action_space.shape or ())).astype(np.float32)
    envs.reset(seed=0)
    for k in range(5):
        envs.step(actions[k % 8])
    start = time.perf_counter()
    for k in range(steps):
        envs.step(actions[k % 8])
    elapsed = time.perf_counter() - start
    envs.close()
    return num_envs * steps / elapsed


#: Every disturbance and fault of the task switched on (for the cost of drawing them).
ALL_FAULTS = {
    "impulse_magnitude": 1.0,
    "periodic_amplitude": 0.2,
    "thrust_noise": 0.1,
    "thrust_delay": 1,
    "thruster_failure_probability": 0.5,
}


def single_env_breakdown(env_id: str, steps: int, seed: int = 0) -> tuple[float, float, float]:
    """Seconds per step of one env, zero actions: through ``gym.make`` (its wrappers), of the
    unwrapped env, and of its compiled task step alone (forces, integration, observation and
    reward in one numba call, timed inside the same steps). The rest of the unwrapped step is the
    Python around that call: argument checks, the info dict, the observation's copy."""
    env = gym.make(env_id)
    env.reset(seed=seed)
    action = np.zeros(tuple(env.action_space.shape or ()), np.float32)
    from tether_gym.envs import _task_kernels

    unwrapped: Any = env.unwrapped
    kernel = _task_kernels.step_serial
    inside = [0.0]

    def timed(*args: Any, **kwargs: Any) -> Any:
        began = time.perf_counter()
        result = kernel(*args, **kwargs)
        inside[0] += time.perf_counter() - began
        return result

    def run(stepper: Any) -> float:
        env.reset(seed=seed)
        began = time.perf_counter()
        for _ in range(steps):
            _, _, terminated, truncated, _ = stepper(action)
            if terminated or truncated:
                env.reset()
        return (time.perf_counter() - began) / steps

    run(env.step)  # warm-up
    wrapped = run(env.step)
    bare = run(unwrapped.step)
    _task_kernels.step_serial = timed
    try:
        run(unwrapped.step)
    finally:
        _task_kernels.step_serial = kernel
    return wrapped, bare, inside[0] / steps


#: The ids whose batched advance the roofline section measures: the default, and tethers with mass.
ROOFLINE_IDS = (DEFAULT_ENV_ID, "TetherBeadedTetrahedron-v0")


def advance_rate(env_id: str, batch: int, intervals: int, prototype: bool = False, seed: int = 0) -> tuple[float, Any]:
    """Cluster sub-steps per second on one thread over ``intervals`` control intervals from the
    id's own random initial states, holding the force that keeps the nominal shape: of
    ``BatchSimulator.advance``, or with ``prototype`` of :mod:`tether_gym.portable`'s SIMD-lane
    kernel on the same state. Returns the rate and the cluster."""
    import numba

    from tether_gym.portable import PortableBatch

    envs = gym.make_vec(env_id, num_envs=batch)
    envs.reset(seed=seed)
    task = envs.unwrapped.task  # type: ignore[attr-defined]
    sim, interval = task.sim, float(task.config.control_interval)
    force = np.broadcast_to(task.force, sim.positions_.shape).copy()
    portable = PortableBatch(sim) if prototype else None
    if portable is not None:
        portable.set_force(force)

    def advance() -> int:
        if portable is None:
            return int(sim.advance(interval, force).substeps.sum())
        portable.advance(interval, "lanes")
        return int(portable.substeps.sum())

    threads = numba.get_num_threads()
    numba.set_num_threads(1)
    try:
        advance()  # warm-up: compilation or cache load
        started = time.perf_counter()
        substeps = sum(advance() for _ in range(intervals))
        seconds = time.perf_counter() - started
    finally:
        numba.set_num_threads(threads)
    cluster = task.cluster
    envs.close()
    return substeps / seconds, cluster


def print_roofline(repeats: int) -> None:
    """The roofline section: each id's rate as a fraction of its limit, in paired rounds.

    This virtual machine's speed drifts by up to 3x over seconds (the undamped cable's limit
    measured 1.2 ns in one run and 3.4 ns in the next), so a limit measured once and rates
    measured later gave fractions of 18 % and 35 % for the same code. Each round therefore
    measures the limit right before the rate it divides, and the section prints the median of
    the rounds' fractions with their range beside the best rate."""
    from tether_gym.roofline import measure_limits, substep_limit_ns

    rounds = max(repeats, 1)
    print(
        f"\nroofline, one thread (tether_gym.roofline: the sub-step's arithmetic, L1-resident data); {rounds} rounds "
        "per row, each the limit measured right before the rate it divides"
    )
    print(
        f"{'id':<34}{'kernel':<11}{'N':>6}{'sub-steps/s':>14}{'ns/sub-step':>13}{'limit, ns':>11}"
        f"{'fraction (median, range)':>28}"
    )
    batch = 1024
    limits = None
    for env_id in ROOFLINE_IDS:
        # The integrator, then tether_gym.portable's SIMD-lane prototype of its hot path on the same states.
        for kernel in ("advance", "lanes"):
            rates, limit_ns, fractions = [], [], []
            for _ in range(rounds):
                limits = measure_limits(seconds=0.3, repeats=3)
                rate, cluster = advance_rate(
                    env_id, batch, 100 if "Beaded" not in env_id else 10, prototype=kernel == "lanes"
                )
                rates.append(rate)
                limit_ns.append(substep_limit_ns(cluster, limits))
                fractions.append(limit_ns[-1] * rate / 1e9)
            best, limit, fraction = max(rates), float(np.median(limit_ns)), float(np.median(fractions))
            print(
                f"{env_id:<34}{kernel:<11}{batch:>6}{best:>14,.0f}{1e9 / best:>13.1f}{limit:>11.1f}"
                f"{100 * fraction:>12.1f} % ({100 * min(fractions):.1f}-{100 * max(fractions):.1f} %)"
            )
    if limits is not None:
        print(
            f"(the last round's limits: undamped cable {limits.cable_ns:.2f} ns, damped cable "
            f"{limits.viscous_cable_ns:.2f} ns, node {limits.node_ns:.2f} ns; {limits.simd} doubles per SIMD "
            "instruction)"
        )


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(
        prog=program("tether_gym.bench", "tether-gym-bench"), description=__doc__.split("\n\n")[0]
    )
    parser.add_argument("--steps", type=int, default=30_000, help="timed steps per measurement")
    parser.add_argument("--repeats", type=int, default=3, help="measurements per case (the best is shown)")
    parser.add_argument("--all-ids", action="store_true", help="every registered id, not only the default")
    parser.add_argument("--roofline-only", action="store_true", help="only the roofline section (about 45 s)")
    args = parser.parse_args(argv)
    print(
        f"tether-gym {tether_gym.__version__}, gymnasium {gym.__version__}, numpy {np.__version__}, "
        f"python {platform.python_version()}, {os.cpu_count()} cores"
    )
    print(f"CPU: {cpu_model()}")
    if args.roofline_only:
        print_roofline(args.repeats)
        return
    env_ids = list(ENV_IDS) if args.all_ids else [DEFAULT_ENV_ID]
    width = max(len(env_id) for env_id in env_ids) + 2  # the id column fits the longest id
    print(f"single env through gym.make (default wrappers), {args.steps} steps, best of {args.repeats}")
    print(f"{'id':<{width}}{'actions':<10}{'steps/s':>12}")
    for env_id in env_ids:
        for policy in ("zero", "random"):
            best = max(single_env_steps_per_second(env_id, args.steps, policy, seed) for seed in range(args.repeats))
            print(f"{env_id:<{width}}{policy:<10}{best:>12,.0f}")
    cartpole = max(
        single_env_steps_per_second("CartPole-v1", args.steps, "random", seed) for seed in range(args.repeats)
    )
    print(f"{'CartPole-v1 (same run)':<{width}}{'random':<10}{cartpole:>12,.0f}")
    wrapped, bare, kernel = min(
        (single_env_breakdown(DEFAULT_ENV_ID, args.steps // 3, seed) for seed in range(args.repeats)),
        key=lambda times: times[0],
    )
    print(
        f"{DEFAULT_ENV_ID}, one step (zero actions): {1e6 * wrapped:.1f} us through gym.make, {1e6 * bare:.1f} us "
        f"unwrapped, of which {1e6 * kernel:.1f} us in the compiled task step: {1e6 * (bare - kernel):.1f} us of "
        f"Python around it, {1e6 * (wrapped - bare):.1f} us in gym's wrappers"
    )
    print()
    print(f"vector envs, random actions, env steps/s (sub-env steps summed), best of {args.repeats}")
    print(f"{'id':<{width}}{'vectorisation':<38}{'N':>6}{'steps/s':>14}")
    for env_id in env_ids:
        cases: list[tuple[str, int, dict[str, Any]]] = [("native", n, {}) for n in (1, 64, 1024, 4096)]
        cases += [
            ("native, safety_factor 0.2", 1024, {"safety_factor": 0.2}),
            ("native, every disturbance and fault", 1024, ALL_FAULTS),
            ("SyncVectorEnv", 64, {}),
        ]
        for label, n, kwargs in cases:
            steps = max(20, min(2000, 200_000 // n))
            best = max(
                vector_env_steps_per_second(env_id, n, steps, sync=label == "SyncVectorEnv", **kwargs)
                for _ in range(args.repeats)
            )
            print(f"{env_id:<{width}}{label:<38}{n:>6}{best:>14,.0f}")
    print_roofline(args.repeats)
    if not available("stable_baselines3"):
        print(f"\nPPO share: stable-baselines3 is not installed ({install_line('train')})")
        return
    num_envs, timesteps = 16, 16 * 128 * 4
    from tether_gym.sb3 import ppo_env_share

    with_env, zero_cost, inside, share = ppo_env_share(DEFAULT_ENV_ID, num_envs, timesteps)
    print(f"\nPPO (MlpPolicy, SB3 defaults but n_steps 128), {timesteps} steps on {num_envs} envs of {DEFAULT_ENV_ID}:")
    print(
        f"  training with the env {with_env:.2f} s, with a zero-cost env {zero_cost:.2f} s "
        f"(difference {with_env - zero_cost:+.2f} s)"
    )
    print(f"  time inside the env's reset/step {inside:.3f} s -> env share {100 * share:.1f} %")


if __name__ == "__main__":
    main()
