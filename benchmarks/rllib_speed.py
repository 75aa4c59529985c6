"""Training speed on Ray RLlib against the number of env runners, beside SB3's PPO on the same settings.

What it measures
----------------
For each number of env runners (default 0, 1 and 2), PPO as ``agents.train_rllib`` builds it from
``agents/hyperparams/rllib_ppo.yml`` (native vector env in every runner, ``--envs-per-runner``
sub-envs each): one iteration to warm up (Ray actors, numba's cache, torch), then ``--iterations``
iterations timed. It prints the env steps trained per wall second (sampling *and* the PPO update:
the training throughput).

``--sb3`` adds SB3's PPO as ``agents.train`` runs it from ``agents/hyperparams/ppo.yml`` (the same
64 envs x 256 steps per update, 10 epochs, 128x128 networks), timed over the same number of
updates after one to warm up: the same work on the same machine under the same load, so the ratio
of the two is meaningful even when the machine is shared.

Every number depends on the machine and on what else runs on it: report the load
(``uptime``) with it. Needs the rllib extra (``.venv-rllib``, made by ``bash scripts/test_rllib.sh``).

Usage::

    nice -n 10 .venv-rllib/bin/python benchmarks/rllib_speed.py --sb3
    .venv-rllib/bin/python benchmarks/rllib_speed.py --runners 0 2 --iterations 5 --num-cpus 2
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from agents.training.rllib import build_config, lifetime_steps, load_rllib_hyperparameters  # noqa: E402
from tether_gym.registration import DEFAULT_ENV_ID, ENV_IDS  # noqa: E402


def rllib_speed(env_id: str, runners: int, envs: int, iterations: int) -> float:
    """Env steps/s over ``iterations`` timed iterations."""
    hyperparams = load_rllib_hyperparameters(env_id)
    algo = build_config(env_id, hyperparams, runners, envs, seed=0).build_algo()
    try:
        algo.train()  # warm-up
        before, started = lifetime_steps(algo), time.perf_counter()
        for _ in range(iterations):
            algo.train()
        return (lifetime_steps(algo) - before) / (time.perf_counter() - started)
    finally:
        algo.stop()


def sb3_speed(env_id: str, iterations: int) -> float:
    """Env steps/s of SB3's PPO with ``agents/hyperparams/ppo.yml``'s settings over ``iterations`` updates."""
    from stable_baselines3 import PPO

    from agents.training.hyperparams import load_hyperparameters
    from agents.training.sb3 import algorithm_kwargs, make_training_env

    hyperparams = load_hyperparameters("ppo", env_id)
    n_envs = int(hyperparams["n_envs"])
    venv = make_training_env(env_id, n_envs, 0, hyperparams.get("normalize", False))
    model = PPO("MlpPolicy", venv, seed=0, device="cpu", **algorithm_kwargs(hyperparams))
    per_update = n_envs * int(hyperparams["n_steps"])
    model.learn(per_update)  # warm-up
    started = time.perf_counter()
    model.learn(per_update * iterations, reset_num_timesteps=False)
    elapsed = time.perf_counter() - started
    venv.close()
    return per_update * iterations / elapsed


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--env", default=DEFAULT_ENV_ID, choices=list(ENV_IDS))
    parser.add_argument("--runners", type=int, nargs="+", default=[0, 1, 2], help="numbers of env runners")
    parser.add_argument("--envs-per-runner", type=int, default=64)
    parser.add_argument("--iterations", type=int, default=3, help="timed iterations (updates) per setting")
    parser.add_argument("--num-cpus", type=int, default=2, help="CPUs of the local Ray instance")
    parser.add_argument("--sb3", action="store_true", help="also time SB3's PPO (agents.train) on the same work")
    args = parser.parse_args()

    import ray

    ray.init(num_cpus=args.num_cpus, include_dashboard=False, log_to_driver=False, configure_logging=False)
    print(f"{args.env}; load average before: {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores", flush=True)
    print("| trainer | env runners | envs in all | env steps/s |\n|---|---|---|---|", flush=True)
    try:
        for runners in args.runners:
            speed = rllib_speed(args.env, runners, args.envs_per_runner, args.iterations)
            envs = args.envs_per_runner * max(runners, 1)
            print(f"| RLlib | {runners} | {envs} | {speed:,.0f} |", flush=True)
    finally:
        ray.shutdown()
    if args.sb3:
        print(f"| SB3 (agents.train) | - | 64 | {sb3_speed(args.env, args.iterations):,.0f} |", flush=True)
    print(f"load average after: {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
