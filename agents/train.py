"""Train an SB3 agent on a tether-gym id: ``python -m agents.train --algo ppo --env TetherTetrahedron-v0``.

Hyperparameters come from ``agents/hyperparams/<algo>.yml``, keyed by env id (rl-zoo style, plain
YAML, nothing evaluated). Training runs on the native vector env through the SB3 adapter, with
``VecNormalize`` when configured and ``VecMonitor`` for episode statistics. A run directory
``<out>/<env>/<algo>_seed<seed>/`` receives:

* ``config.yml``: the resolved hyperparameters, env id, seed and command line;
* ``tensorboard/``: TensorBoard logs (``tensorboard --logdir <run>/tensorboard``);
* ``checkpoints/``: the model and its ``VecNormalize`` statistics every ``--checkpoint-freq`` steps;
* ``best/``: the best model on the evaluation episodes (``best_model.zip`` + ``vecnormalize.pkl``),
  and ``evaluations.npz``;
* ``model.zip`` and ``vecnormalize.pkl``: the final model and its normalisation statistics.

``--resume <checkpoint.zip>`` continues a run from a checkpoint, with the ``VecNormalize``
statistics saved next to it, and keeps counting timesteps from there.

``--curriculum START FRACTION`` (or a ``curriculum: {start: ..., fraction: ...}`` entry) trains on
easier episodes first: the env's ``difficulty`` (initial-condition size, randomisation and
disturbances together) rises linearly from START to 1 over the first FRACTION of the run. The
evaluation episodes are always at difficulty 1.
"""

from __future__ import annotations

import argparse
import shlex
import sys
import time
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import torch
import yaml
from stable_baselines3 import PPO, SAC, TD3
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.callbacks import BaseCallback, CallbackList, CheckpointCallback, EvalCallback
from stable_baselines3.common.vec_env import VecEnv, VecMonitor, VecNormalize

import tether_gym
from tether_gym.registration import DEFAULT_ENV_ID, ENV_IDS
from tether_gym.sb3 import make_sb3_vec_env

__all__ = ["ALGORITHMS", "load_hyperparameters", "make_training_env", "train"]

HYPERPARAMS_DIR = Path(__file__).resolve().parent / "hyperparams"
ALGORITHMS: dict[str, type[BaseAlgorithm]] = {"ppo": PPO, "sac": SAC, "td3": TD3}
ACTIVATIONS: dict[str, type[torch.nn.Module]] = {"tanh": torch.nn.Tanh, "relu": torch.nn.ReLU, "elu": torch.nn.ELU}
#: Keys of a hyperparameter entry that are not passed to the algorithm's constructor.
RUN_KEYS = ("n_timesteps", "n_envs", "normalize", "policy", "env_kwargs", "curriculum")
#: Seeds of the evaluation episodes are offset from the training seed by this much, so that they
#: are never episodes the agent trained on.
EVAL_SEED_OFFSET = 1_000_000


def load_hyperparameters(algo: str, env_id: str, path: str | Path | None = None) -> dict[str, Any]:
    """The hyperparameters of ``algo`` for ``env_id``: the id's entry of the YAML file, or its
    ``default`` entry. ``path`` overrides ``agents/hyperparams/<algo>.yml``."""
    file = Path(path) if path is not None else HYPERPARAMS_DIR / f"{algo}.yml"
    if not file.is_file():
        raise FileNotFoundError(f"hyperparameter file {file} does not exist")
    with open(file) as stream:
        table = yaml.safe_load(stream) or {}
    if not isinstance(table, dict):
        raise ValueError(f"{file} must map env ids to hyperparameter dicts")
    entry = table.get(env_id, table.get("default"))
    if entry is None:
        raise KeyError(f"{file} has no entry for {env_id!r} and no 'default' entry; ids listed: {sorted(table)}")
    return dict(entry)


def _schedule(value: Any, name: str) -> float | Callable[[float], float]:
    """A number, or "lin_<number>": linear decay from that number to 0 over training."""
    if isinstance(value, str):
        if not value.startswith("lin_"):
            raise ValueError(f"{name} must be a number or 'lin_<number>'; got {value!r}")
        start = float(value[4:])
        return lambda progress_remaining: progress_remaining * start
    return float(value)


def _algorithm_kwargs(hyperparams: Mapping[str, Any]) -> dict[str, Any]:
    """Constructor keyword arguments from a hyperparameter entry: schedules and policy_kwargs
    turned into Python objects."""
    kwargs = {key: value for key, value in hyperparams.items() if key not in RUN_KEYS}
    for key in ("learning_rate", "clip_range"):
        if key in kwargs:
            kwargs[key] = _schedule(kwargs[key], key)
    policy_kwargs = dict(kwargs.get("policy_kwargs") or {})
    if "activation_fn" in policy_kwargs:
        name = policy_kwargs["activation_fn"]
        if name not in ACTIVATIONS:
            raise ValueError(f"policy_kwargs.activation_fn must be one of {sorted(ACTIVATIONS)}; got {name!r}")
        policy_kwargs["activation_fn"] = ACTIVATIONS[name]
    if policy_kwargs:
        kwargs["policy_kwargs"] = policy_kwargs
    return kwargs


def make_training_env(
    env_id: str, num_envs: int, seed: int, normalize: Any, env_kwargs: Mapping[str, Any] | None = None,
    training: bool = True,
) -> VecEnv:
    """The native vector env of ``env_id`` through the SB3 adapter, with ``VecMonitor`` and, if
    ``normalize`` is truthy (a bool or ``VecNormalize`` keyword arguments), ``VecNormalize``."""
    venv: VecEnv = VecMonitor(make_sb3_vec_env(env_id, num_envs, seed=seed, **dict(env_kwargs or {})))
    if normalize:
        options = dict(normalize) if isinstance(normalize, Mapping) else {}
        if not training:
            options.update(training=False, norm_reward=False)
        venv = VecNormalize(venv, **options)
    return venv


class SaveNormalizationOnBest(BaseCallback):
    """Saves the training env's ``VecNormalize`` statistics next to each new best model, so that
    ``best/`` can be loaded on its own."""

    def __init__(self, path: Path) -> None:
        super().__init__()
        self.path = path

    def _on_step(self) -> bool:
        normalizer = self.model.get_vec_normalize_env()
        if normalizer is not None:
            normalizer.save(str(self.path))
        return True


class DifficultyCurriculum(BaseCallback):
    """Raises the training env's difficulty linearly from ``start`` to 1 over the first
    ``fraction`` of ``total`` timesteps (``env_method("set_difficulty", d)``, which takes effect at
    each sub-env's next reset), and logs it as ``curriculum/difficulty``.

    Args:
        start: difficulty at timestep 0, in [0, 1].
        fraction: fraction of the run over which it reaches 1, in (0, 1].
        total: the run's total timesteps.
    """

    def __init__(self, start: float, fraction: float, total: int) -> None:
        super().__init__()
        if not (0.0 <= start <= 1.0 and 0.0 < fraction <= 1.0 and total > 0):
            raise ValueError(
                f"curriculum needs start in [0, 1] and fraction in (0, 1]; got start={start!r}, fraction={fraction!r}"
            )
        self.start, self.fraction, self.total = float(start), float(fraction), int(total)
        self.difficulty = -1.0

    def difficulty_at(self, timesteps: int) -> float:
        """The scheduled difficulty after ``timesteps`` env steps."""
        progress = min(1.0, timesteps / (self.fraction * self.total))
        return self.start + (1.0 - self.start) * progress

    def _on_training_start(self) -> None:
        self._update()

    def _on_step(self) -> bool:
        self._update()
        return True

    def _update(self) -> None:
        target = self.difficulty_at(self.num_timesteps)
        if abs(target - self.difficulty) >= 0.01 or (target == 1.0 and self.difficulty != 1.0):
            self.training_env.env_method("set_difficulty", target)
            self.difficulty = target
            self.logger.record("curriculum/difficulty", target)


def train(
    algo: str = "ppo",
    env_id: str = DEFAULT_ENV_ID,
    seed: int = 0,
    out: str | Path = "runs",
    timesteps: int | None = None,
    num_envs: int | None = None,
    hyperparams_file: str | Path | None = None,
    overrides: Mapping[str, Any] | None = None,
    resume: str | Path | None = None,
    eval_freq: int = 50_000,
    eval_episodes: int = 32,
    checkpoint_freq: int = 250_000,
    progress_bar: bool = True,
    verbose: int = 0,
    command: str | None = None,
) -> Path:
    """Train ``algo`` on ``env_id`` and return the run directory (see the module docstring).

    ``timesteps`` and ``num_envs`` override the file's ``n_timesteps``/``n_envs``; ``overrides``
    replaces any other entries. ``eval_freq`` and ``checkpoint_freq`` count total env steps
    (over all envs). ``command`` is recorded in ``config.yml`` (the command line, when run as
    ``python -m agents.train``)."""
    if algo not in ALGORITHMS:
        raise ValueError(f"unknown algorithm {algo!r}; choose one of {sorted(ALGORITHMS)}")
    if env_id not in ENV_IDS:
        raise ValueError(f"unknown env id {env_id!r}; tether-gym ids are {list(ENV_IDS)}")
    hyperparams = load_hyperparameters(algo, env_id, hyperparams_file)
    hyperparams.update(overrides or {})
    if timesteps is not None:
        hyperparams["n_timesteps"] = int(timesteps)
    if num_envs is not None:
        hyperparams["n_envs"] = int(num_envs)
    n_envs = int(hyperparams.get("n_envs", 1))
    total = int(hyperparams["n_timesteps"])
    if n_envs < 1 or total < 1:
        raise ValueError(f"n_envs and n_timesteps must be positive; got {n_envs} and {total}")
    run = Path(out) / env_id / f"{algo}_seed{seed}"
    run.mkdir(parents=True, exist_ok=True)
    record = {
        "algo": algo, "env_id": env_id, "seed": seed, "hyperparams": hyperparams,
        "command": command,
        "tether_gym_version": tether_gym.__version__,
    }
    with open(run / "config.yml", "w") as stream:
        yaml.safe_dump(record, stream, sort_keys=False)

    normalize = hyperparams.get("normalize", False)
    env_kwargs = hyperparams.get("env_kwargs")
    venv = make_training_env(env_id, n_envs, seed, normalize, env_kwargs)
    eval_envs = min(eval_episodes, 64)
    eval_venv = make_training_env(env_id, eval_envs, seed + EVAL_SEED_OFFSET, normalize, env_kwargs, training=False)
    cls = ALGORITHMS[algo]
    if resume is not None:
        checkpoint = Path(resume)
        if not checkpoint.is_file():
            raise FileNotFoundError(f"checkpoint {checkpoint} does not exist")
        if normalize:
            statistics = _normalization_file_of(checkpoint)
            venv = VecNormalize.load(str(statistics), venv.venv if isinstance(venv, VecNormalize) else venv)
            venv.training = True
        model = cls.load(str(checkpoint), env=venv, device="cpu", tensorboard_log=str(run / "tensorboard"))
        reset_num_timesteps = False
    else:
        model = cls(
            hyperparams.get("policy", "MlpPolicy"), venv, seed=seed, device="cpu", verbose=verbose,
            tensorboard_log=str(run / "tensorboard"), **_algorithm_kwargs(hyperparams),
        )
        reset_num_timesteps = True
    (run / "best").mkdir(exist_ok=True)
    callback_items: list[BaseCallback] = [
        CheckpointCallback(
            save_freq=max(checkpoint_freq // n_envs, 1), save_path=str(run / "checkpoints"), name_prefix=algo,
            save_vecnormalize=bool(normalize),
        ),
        EvalCallback(
            eval_venv, n_eval_episodes=eval_episodes, eval_freq=max(eval_freq // n_envs, 1),
            best_model_save_path=str(run / "best"), log_path=str(run / "best"), deterministic=True,
            callback_on_new_best=SaveNormalizationOnBest(run / "best" / "vecnormalize.pkl") if normalize else None,
            verbose=verbose,
        ),
    ]
    curriculum = hyperparams.get("curriculum")
    if curriculum:
        callback_items.append(DifficultyCurriculum(curriculum["start"], curriculum["fraction"], total))
    callbacks = CallbackList(callback_items)
    start = time.perf_counter()
    model.learn(
        total_timesteps=total, callback=callbacks, progress_bar=progress_bar, tb_log_name=algo,
        reset_num_timesteps=reset_num_timesteps,
    )
    model.save(str(run / "model.zip"))
    if normalize:
        model.get_vec_normalize_env().save(str(run / "vecnormalize.pkl"))
    elapsed = time.perf_counter() - start
    print(f"trained {algo} on {env_id} for {model.num_timesteps:,} steps in {elapsed / 60:.1f} min "
          f"({model.num_timesteps / max(elapsed, 1e-9):,.0f} steps/s); run directory {run}")
    venv.close()
    eval_venv.close()
    return run


def _normalization_file_of(checkpoint: Path) -> Path:
    """The VecNormalize statistics saved with a checkpoint: ``<prefix>_vecnormalize_<steps>_steps.pkl``
    next to ``<prefix>_<steps>_steps.zip`` (CheckpointCallback's names), or ``vecnormalize.pkl``
    in the same directory."""
    stem = checkpoint.stem
    if stem.endswith("_steps"):
        prefix, steps = stem[: -len("_steps")].rsplit("_", 1)
        candidate = checkpoint.with_name(f"{prefix}_vecnormalize_{steps}_steps.pkl")
        if candidate.is_file():
            return candidate
    candidate = checkpoint.with_name("vecnormalize.pkl")
    if candidate.is_file():
        return candidate
    raise FileNotFoundError(f"no VecNormalize statistics found next to {checkpoint}")


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--algo", default="ppo", choices=sorted(ALGORITHMS))
    parser.add_argument("--env", default=DEFAULT_ENV_ID, choices=list(ENV_IDS))
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", default="runs", help="parent of the run directory")
    parser.add_argument("--timesteps", type=int, help="override n_timesteps")
    parser.add_argument("--n-envs", type=int, help="override n_envs")
    parser.add_argument("--hyperparams", help="YAML file instead of agents/hyperparams/<algo>.yml")
    parser.add_argument("--resume", help="checkpoint .zip to continue from")
    parser.add_argument(
        "--curriculum", nargs=2, type=float, metavar=("START", "FRACTION"),
        help="raise the difficulty from START to 1 over the first FRACTION of the run",
    )
    parser.add_argument("--eval-freq", type=int, default=50_000, help="env steps between evaluations")
    parser.add_argument("--eval-episodes", type=int, default=32)
    parser.add_argument("--checkpoint-freq", type=int, default=250_000, help="env steps between checkpoints")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar (for logs)")
    parser.add_argument("--verbose", type=int, default=0)
    args = parser.parse_args(argv)
    train(
        algo=args.algo, env_id=args.env, seed=args.seed, out=args.out, timesteps=args.timesteps,
        num_envs=args.n_envs, hyperparams_file=args.hyperparams, resume=args.resume, eval_freq=args.eval_freq,
        overrides={"curriculum": {"start": args.curriculum[0], "fraction": args.curriculum[1]}} if args.curriculum else None,
        eval_episodes=args.eval_episodes, checkpoint_freq=args.checkpoint_freq,
        progress_bar=not args.no_progress, verbose=args.verbose,
        command=shlex.join(["python", "-m", "agents.train", *(sys.argv[1:] if argv is None else argv)]),
    )


if __name__ == "__main__":
    main()
