"""Train an SB3 agent on a tether-gym id: ``python -m agents.train --algo ppo --env TetherTetrahedron-v0``.

Console script: ``tether-gym-train`` (``python -m tether_gym_agents.train`` when installed).
Hyperparameters come from the package's ``hyperparams/<algo>.yml`` (``agents/hyperparams`` in a
checkout, ``tether_gym_agents/hyperparams`` installed), keyed by env id (rl-zoo style, plain
YAML, nothing evaluated). Every entry is checked before training starts: an unknown key, a missing
``n_timesteps`` or a string where a number belongs is an error that names the key. Training runs
on the native vector env through the SB3 adapter, with ``VecNormalize`` when configured and
``VecMonitor`` for episode statistics. A run directory ``<out>/<env>/<algo>_seed<seed>/`` receives,
all of it in the safe policy format (:mod:`agents.safe_format`: JSON and safetensors, no pickle):

* ``config.yml``: the resolved hyperparameters, env id, seed and command line, and the steps
  trained (``num_timesteps``). SB3 trains whole rollouts (PPO: ``n_steps`` x ``n_envs`` steps),
  so ``n_timesteps`` is rounded up to a whole number of them, with a message, and recorded so;
* ``tensorboard/``: TensorBoard logs (``tensorboard --logdir <run>/tensorboard``);
* ``checkpoints/<algo>_<steps>_steps/``: the policy, its ``VecNormalize`` statistics and the
  optimizer state every ``--checkpoint-freq`` steps;
* ``best/``: the best policy on the evaluation episodes (with its statistics and optimizer
  state; a run shorter than ``--eval-freq`` evaluates its final policy once, so that ``best/``
  always holds one), and ``evaluations.json``: every evaluation's returns and paired difference from the
  best scripted baseline on the same seeds, and when training first beat it
  (:mod:`agents.selection`);
* ``policy.json``, ``policy.safetensors``, ``normalization.json``, ``training.*`` and
  ``MANIFEST.sha256``: the final policy.

``--resume DIR`` continues from a checkpoint directory, ``best/`` or a run directory: the weights,
optimizer states, timestep count and normalisation statistics are restored, and the timesteps
keep counting from there. Resuming from a pickle-based SB3 ``.zip`` (with its ``vecnormalize.pkl``)
needs ``--trust-pickle``, because unpickling runs any code a crafted file contains.

The run directory must be new: if it holds an earlier run (same ``--out``, env, algorithm and
seed), the command stops before any work unless ``--force`` is given, which deletes the earlier
run's models, ``best/`` and checkpoints (TensorBoard logs are kept) and then trains.

``--curriculum START FRACTION`` (or a ``curriculum: {start: ..., fraction: ...}`` entry) trains on
easier episodes first: the env's ``difficulty`` (initial-condition size, randomisation and
disturbances together) rises linearly from START to 1 over the first FRACTION of the run. The
evaluation episodes are always at difficulty 1.
"""

from __future__ import annotations

if __name__ == "__main__":  # --help and bad options answered before the slow imports below
    from .common.cli import parse_before_imports

    parse_before_imports("train")

import argparse
import sys
import time
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

import tether_gym
from tether_gym._optional import needs_extra, require
from tether_gym.registration import DEFAULT_ENV_ID, ENV_IDS
from tether_gym.sb3 import make_sb3_vec_env

from .common import cli
from .common.checks import check_int
from .common.commands import command_line, program
from .common.data import HYPERPARAMS_DIR
from .common.files import OutputError, atomic_write_text
from .pickled import PickleNotTrustedError, load_pickled_model
from .residual import ResidualVecEnv
from .safe_format import (
    ACTIVATIONS,
    ALGORITHMS,
    CLASS_KWARGS,
    PolicyFormatError,
    load_training_state,
    save_policy,
)
from .selection import SeededEvaluation
from .training.hyperparams import (
    RUN_KEYS,
    SCHEDULE_KEYS,
    HyperparameterError,
    load_hyperparameters,
    schedule,
    validate_hyperparameters,
)
from .training.runs import clear_earlier_run, prepare_run_dir, resume_source

with needs_extra("train", "training"):
    import yaml
    from stable_baselines3.common.base_class import BaseAlgorithm
    from stable_baselines3.common.callbacks import BaseCallback, CallbackList
    from stable_baselines3.common.vec_env import VecEnv, VecMonitor, VecNormalize

__all__ = [
    "ACTIVATIONS",
    "ALGORITHMS",
    "HyperparameterError",
    "load_hyperparameters",
    "make_training_env",
    "train",
    "validate_hyperparameters",
]


def _algorithm_kwargs(hyperparams: Mapping[str, Any]) -> dict[str, Any]:
    """Constructor keyword arguments from a checked hyperparameter entry: schedules and
    policy_kwargs' class names turned into Python objects."""
    kwargs = {key: value for key, value in hyperparams.items() if key not in RUN_KEYS}
    for key in SCHEDULE_KEYS:
        if kwargs.get(key) is not None:
            kwargs[key] = schedule(kwargs[key], key)
    policy_kwargs = dict(kwargs.get("policy_kwargs") or {})
    for key, table in CLASS_KWARGS.items():
        if key in policy_kwargs:
            policy_kwargs[key] = table[policy_kwargs[key]]
    if policy_kwargs:
        kwargs["policy_kwargs"] = policy_kwargs
    return kwargs


def _action_noise(hyperparams: Mapping[str, Any], venv: VecEnv) -> dict[str, Any]:
    """``action_noise`` for SAC/TD3 from ``action_noise_std`` (Gaussian, that std in the [-1, 1]
    action units, the same on every action component), or nothing."""
    std = hyperparams.get("action_noise_std")
    if not std:
        return {}
    from stable_baselines3.common.noise import NormalActionNoise

    size = int(np.prod(venv.action_space.shape))
    return {"action_noise": NormalActionNoise(np.zeros(size), np.full(size, float(std)))}


def start_at_the_baseline(model: BaseAlgorithm) -> None:
    """Zero the last layer of ``model``'s actor, so that a residual policy's deterministic action
    is exactly 0 at the start of training: the closed loop starts as the baseline's. (SB3 already
    scales PPO's last layer by 0.01, but SAC and TD3 start with full-size random outputs, a
    random residual thrust of about a third of full thrust.)"""
    import torch

    if hasattr(model.policy, "action_net"):  # PPO
        layers = [model.policy.action_net]
    else:  # SAC (a Linear mu) or TD3 (mu ending in Linear, Tanh)
        mu = model.actor.mu
        layers = [mu if isinstance(mu, torch.nn.Linear) else [m for m in mu if isinstance(m, torch.nn.Linear)][-1]]
    with torch.no_grad():
        for layer in layers:
            layer.weight.zero_()
            layer.bias.zero_()
    if getattr(model, "actor_target", None) is not None:
        model.actor_target.load_state_dict(model.actor.state_dict())


def make_training_env(
    env_id: str,
    num_envs: int,
    seed: int,
    normalize: Any,
    env_kwargs: Mapping[str, Any] | None = None,
    training: bool = True,
    residual_on: str | None = None,
    multiagent: Mapping[str, Any] | None = None,
) -> VecEnv:
    """The native vector env of ``env_id`` through the SB3 adapter, with ``VecMonitor`` and, if
    ``normalize`` is truthy (a bool or ``VecNormalize`` keyword arguments), ``VecNormalize``;
    with ``residual_on`` (a baseline's name) the actions are corrections to that baseline's
    (:class:`agents.residual.ResidualVecEnv`); with ``multiagent`` (the multi-agent options) it
    is ``num_envs`` clusters x their agents, one row per agent, for a shared decentralised policy
    (:class:`tether_gym.multiagent.sb3.AgentVecEnv`)."""
    base: VecEnv
    if multiagent is not None:
        from tether_gym.multiagent.sb3 import make_agent_vec_env

        base = make_agent_vec_env(env_id, num_envs, seed=seed, **dict(env_kwargs or {}), **dict(multiagent))
    else:
        base = make_sb3_vec_env(env_id, num_envs, seed=seed, **dict(env_kwargs or {}))
    if residual_on is not None:
        base = ResidualVecEnv(base, residual_on)
    venv: VecEnv = VecMonitor(base)
    if normalize:
        options = dict(normalize) if isinstance(normalize, Mapping) else {}
        if not training:
            options.update(training=False, norm_reward=False)
        venv = VecNormalize(venv, **options)
    return venv


# ---------------------------------------------------------------------------------------------
# Callbacks
# ---------------------------------------------------------------------------------------------


def actor_parameters(model: BaseAlgorithm) -> list[Any]:
    """The parameters of ``model``'s actor alone (torch tensors): PPO's policy branch, action
    head and log-std; SAC's and TD3's actor network. Shared layers (a shared feature extractor
    with parameters, shared hidden layers) are left out: they serve the critic too."""
    import torch

    policy = model.policy
    if hasattr(policy, "action_net"):  # PPO's ActorCriticPolicy
        log_std = getattr(policy, "log_std", None)
        extra = [log_std] if isinstance(log_std, torch.nn.Parameter) else []
        modules = [policy.mlp_extractor.policy_net, policy.action_net]
        return [p for module in modules for p in module.parameters()] + extra
    return list(model.actor.parameters())


class CriticWarmup(BaseCallback):
    """Freezes the actor for the first ``steps`` env steps, so that only the critic (PPO's value
    function, SAC's and TD3's Q networks) learns, then releases it.

    Why: a residual policy starts exactly at its baseline (:func:`start_at_the_baseline`), and a
    critic that has learned nothing yet gives it random gradients. Updating the actor from the
    first batch moves it away from a strong baseline before the critic can say which way is up
    (a TD3 residual on LQR fell 46 below LQR in 20 000 steps, ``docs/benchmark.md``). Residual
    policy learning (Silver et al., 2018, arXiv:1812.06298) trains the critic alone for a
    burn-in period for this reason.

    The freeze is ``requires_grad = False`` on :func:`actor_parameters`: their gradients stay
    ``None``, which the optimisers skip, so the actor's weights, its Adam state and (for TD3) its
    target network stay exactly as they were. It is applied before every update (at the end of
    each rollout) and logged as ``train/actor_frozen``.
    """

    def __init__(self, steps: int) -> None:
        super().__init__()
        if steps < 0:
            raise ValueError(f"critic_warmup must be >= 0 env steps; got {steps!r}")
        self.steps = int(steps)
        self.frozen: bool | None = None

    def _on_training_start(self) -> None:
        self._update()

    def _on_rollout_end(self) -> None:
        self._update()

    def _on_step(self) -> bool:
        return True

    def _update(self) -> None:
        frozen = self.num_timesteps < self.steps
        if frozen != self.frozen:
            for parameter in actor_parameters(self.model):
                parameter.requires_grad_(not frozen)
            self.frozen = frozen
        self.logger.record("train/actor_frozen", float(frozen))


class SafePolicySaver(BaseCallback):
    """Saves the model, the training env's ``VecNormalize`` statistics and the optimizer state in
    the safe format: into ``directory`` on every call (as EvalCallback's ``callback_on_new_best``),
    or, with ``every`` steps, into ``directory/<prefix>_<timesteps>_steps/`` every ``every``
    calls (checkpoints)."""

    def __init__(
        self,
        directory: Path,
        env_id: str,
        provenance: Mapping[str, Any],
        every: int | None = None,
        prefix: str = "",
        residual_on: str | None = None,
        training_state: bool = True,
        multiagent: Mapping[str, Any] | None = None,
    ) -> None:
        super().__init__()
        self.directory, self.env_id, self.provenance = directory, env_id, dict(provenance)
        self.every, self.prefix, self.residual_on = every, prefix, residual_on
        #: Whether to save the optimizer state (False where the model only carries the weights).
        self.training_state = training_state
        self.multiagent = multiagent

    def _on_step(self) -> bool:
        if self.every is None:
            self._save(self.directory)
        elif self.n_calls % self.every == 0:
            self._save(self.directory / f"{self.prefix}_{self.num_timesteps}_steps")
        return True

    def _save(self, directory: Path) -> None:
        save_policy(
            directory,
            self.model,
            self.model.get_vec_normalize_env(),
            self.env_id,
            self.provenance,
            training_state=self.training_state,
            residual_on=self.residual_on,
            multiagent=self.multiagent,
        )


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


# ---------------------------------------------------------------------------------------------
# Training
# ---------------------------------------------------------------------------------------------


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
    force: bool = False,
    trust_pickle: bool = False,
) -> Path:
    """Train ``algo`` on ``env_id`` and return the run directory (see the module docstring).

    ``timesteps`` and ``num_envs`` override the file's ``n_timesteps``/``n_envs`` (the steps are
    rounded up to whole rollouts, see :func:`rollout_steps`); ``overrides``
    replaces any other entries (and is checked like the file). ``eval_freq`` and
    ``checkpoint_freq`` count total env steps (over all envs). ``command`` is recorded in
    ``config.yml`` (the command line, when run as ``python -m agents.train``). ``force``
    replaces an earlier run in the same run directory; ``trust_pickle`` allows ``resume`` to be
    a pickle-based SB3 ``.zip``.

    Every argument, the hyperparameters, the resume source and the run directory are checked
    before any env is built: errors name the argument or key and the fix."""
    started = time.perf_counter()
    if algo not in ALGORITHMS:
        raise ValueError(f"unknown algorithm {algo!r}; choose one of {sorted(ALGORITHMS)}")
    if env_id not in ENV_IDS:
        raise ValueError(f"unknown env id {env_id!r}; tether-gym ids are {list(ENV_IDS)}")
    check_int("seed", seed, 0)
    check_int("eval_freq", eval_freq, 1)
    check_int("eval_episodes", eval_episodes, 1)
    check_int("checkpoint_freq", checkpoint_freq, 1)
    check_int("verbose", verbose, 0)
    # SB3 finds these missing only when training starts, and then names its own extra, not ours.
    require("tensorboard", "train", "the training's TensorBoard logs")
    if progress_bar:
        for module in ("tqdm", "rich"):
            require(module, "train", "the progress bar (or pass --no-progress)")
    hyperparams = load_hyperparameters(algo, env_id, hyperparams_file)
    hyperparams.update(overrides or {})
    if timesteps is not None:
        hyperparams["n_timesteps"] = check_int("timesteps", timesteps, 1)
    if num_envs is not None:
        hyperparams["n_envs"] = check_int("num_envs", num_envs, 1)
    hyperparams = validate_hyperparameters(algo, hyperparams, where="hyperparameters (with overrides)")
    n_envs = int(hyperparams.get("n_envs", 1))
    total = int(hyperparams["n_timesteps"])
    resume_kind, resume_path, keep = (
        resume_source(resume, trust_pickle, algo, env_id) if resume is not None else (None, None, set())
    )
    multiagent = hyperparams.get("multiagent")
    if multiagent is not None and hyperparams.get("residual_on") is not None:
        raise HyperparameterError("'multiagent' and 'residual_on' do not combine: a residual policy is centralised")
    from .ship import model_name

    run = prepare_run_dir(out, env_id, model_name({"algo": algo, "multiagent": multiagent}), seed, force)

    record = {
        "algo": algo,
        "env_id": env_id,
        "seed": seed,
        "hyperparams": hyperparams,
        "command": command,
        "resumed_from": str(resume_path) if resume_path else None,
        "tether_gym_version": tether_gym.__version__,
    }
    normalize = hyperparams.get("normalize", False)
    env_kwargs = hyperparams.get("env_kwargs")
    residual_on = hyperparams.get("residual_on")
    venv = make_training_env(
        env_id, n_envs, seed, normalize, env_kwargs, residual_on=residual_on, multiagent=multiagent
    )
    # The vector env's rows: n_envs, or n_envs clusters x their agents (timesteps count rows).
    rows = venv.num_envs
    cls = ALGORITHMS[algo]
    model = _build_model(cls, hyperparams, venv, seed, verbose, run, resume_kind, resume_path)
    venv = model.get_env()  # a pickle resume wraps the statistics it loaded around the env
    total = _whole_rollouts(model, total, "--timesteps" if timesteps is not None else "n_timesteps")
    hyperparams["n_timesteps"] = total  # config.yml records what runs, and reproduces it
    if force:
        clear_earlier_run(run, algo, keep)
    atomic_write_text(run / "config.yml", yaml.safe_dump(record, sort_keys=False))
    provenance = {"seed": seed, "command": command, "config": "config.yml of the run directory"}
    callback_items: list[BaseCallback] = [
        SafePolicySaver(
            run / "checkpoints",
            env_id,
            provenance,
            every=max(checkpoint_freq // rows, 1),
            prefix=algo,
            residual_on=residual_on,
            multiagent=multiagent,
        ),
    ]
    evaluation = SeededEvaluation(
        env_id,
        eval_episodes,
        every=eval_freq // rows,
        log_dir=run / "best",
        on_new_best=SafePolicySaver(run / "best", env_id, provenance, residual_on=residual_on, multiagent=multiagent),
        started=started,
        env_kwargs=env_kwargs,
        residual_on=residual_on,
        multiagent=multiagent,
        verbose=1 if progress_bar or verbose else 0,
    )
    callback_items.append(evaluation)
    if hyperparams.get("critic_warmup"):
        callback_items.append(CriticWarmup(hyperparams["critic_warmup"]))
    curriculum = hyperparams.get("curriculum")
    if curriculum:
        callback_items.append(DifficultyCurriculum(curriculum["start"], curriculum["fraction"], total))
    start = time.perf_counter()
    model.learn(
        total_timesteps=total,
        callback=CallbackList(callback_items),
        progress_bar=progress_bar,
        tb_log_name=algo,
        reset_num_timesteps=resume_kind is None,
    )
    if not evaluation.history:
        # best/ is chosen among evaluations: a run shorter than --eval-freq would leave none.
        print(
            f"no evaluation ran in {total:,} steps (--eval-freq {eval_freq:,}): evaluating the final policy "
            f"for {run / 'best'}",
            flush=True,
        )
        evaluation.num_timesteps = model.num_timesteps
        evaluation.evaluate()
    record["num_timesteps"] = int(model.num_timesteps)  # counted from the start of a resumed run
    atomic_write_text(run / "config.yml", yaml.safe_dump(record, sort_keys=False))
    save_policy(
        run,
        model,
        model.get_vec_normalize_env(),
        env_id,
        provenance,
        training_state=True,
        extra_files=["config.yml"],
        residual_on=residual_on,
        multiagent=multiagent,
    )
    elapsed = time.perf_counter() - start
    evaluation.finish(model.num_timesteps)
    print(
        f"trained {algo} on {env_id} for {model.num_timesteps:,} steps in {elapsed / 60:.1f} min "
        f"({model.num_timesteps / max(elapsed, 1e-9):,.0f} steps/s); run directory {run}"
    )
    print_evaluation_summary(evaluation)
    venv.close()
    return run


def rollout_steps(model: BaseAlgorithm) -> tuple[int, str] | None:
    """The env steps (over all rows of the vector env) that one iteration of ``model.learn``
    collects, and how they come about, for a message; None when it varies (an off-policy
    ``train_freq`` counted in episodes). ``learn`` stops only between iterations, so it trains a
    whole number of them: at least one, whatever ``total_timesteps`` asks."""
    from stable_baselines3.common.on_policy_algorithm import OnPolicyAlgorithm
    from stable_baselines3.common.type_aliases import TrainFrequencyUnit

    if isinstance(model, OnPolicyAlgorithm):
        return model.n_steps * model.n_envs, f"rollouts of n_steps {model.n_steps} x {model.n_envs} envs"
    train_freq = getattr(model, "train_freq", None)
    if train_freq is None or train_freq.unit != TrainFrequencyUnit.STEP:
        return None
    return train_freq.frequency * model.n_envs, f"train_freq {train_freq.frequency} steps x {model.n_envs} envs"


def _whole_rollouts(model: BaseAlgorithm, total: int, source: str) -> int:
    """``total`` env steps rounded up to whole iterations of ``model.learn`` (see
    :func:`rollout_steps`), which is what it would train anyway; says so when it rounds."""
    chunk = rollout_steps(model)
    if chunk is None or total % chunk[0] == 0:
        return total
    rounded = -(-total // chunk[0]) * chunk[0]
    print(
        f"{source} {total:,} rounded up to {rounded:,} env steps: training runs whole {chunk[1]} "
        f"= {chunk[0]:,} steps (give a multiple of {chunk[0]:,} to train exactly that)",
        flush=True,
    )
    return rounded


def print_evaluation_summary(evaluation: SeededEvaluation) -> None:
    """One line: the best evaluation return against the bar, and when training first beat it."""
    if not evaluation.history:
        return
    beat = evaluation.first_beat.get(evaluation.bar)
    print(
        f"best evaluation return {evaluation.best_mean:.2f} against {evaluation.bar} "
        f"{evaluation.baseline_returns[evaluation.bar].mean():.2f} on the evaluation seeds; "
        + (
            f"first beat it at {beat['timesteps']:,} steps, {beat['wall_time_s']:.0f} s after the command started"
            if beat
            else "never beat it"
        )
    )


def _build_model(
    cls: type[BaseAlgorithm],
    hyperparams: Mapping[str, Any],
    venv: VecEnv,
    seed: int,
    verbose: int,
    run: Path,
    resume_kind: str | None,
    resume_path: Path | None,
) -> BaseAlgorithm:
    """A new model, or one resumed from a safe checkpoint directory or (trusted) SB3 ``.zip``."""
    if resume_kind == "pickle":
        assert resume_path is not None
        normalized = isinstance(venv, VecNormalize)
        model, normalizer, _, _ = load_pickled_model(
            resume_path,
            trust_pickle=True,
            algo=_algo_of(cls),
            env=venv.venv if normalized else venv,
            tensorboard_log=str(run / "tensorboard"),
        )
        if normalized != (normalizer is not None):
            raise FileNotFoundError(
                f"--resume {resume_path}: the hyperparameters' 'normalize' is {'on' if normalized else 'off'}, but "
                f"{'no' if normalized else 'a'} VecNormalize statistics file was found next to it"
            )
        if normalizer is not None:
            normalizer.training = True
        return model
    model = cls(
        hyperparams.get("policy", "MlpPolicy"),
        venv,
        seed=seed,
        device="cpu",
        verbose=verbose,
        tensorboard_log=str(run / "tensorboard"),
        **_algorithm_kwargs(hyperparams),
        **_action_noise(hyperparams, venv),
    )
    if hyperparams.get("residual_on") is not None and resume_kind is None:
        start_at_the_baseline(model)
    if resume_kind == "safe":
        assert resume_path is not None
        load_training_state(model, resume_path, venv if isinstance(venv, VecNormalize) else None)
    return model


def _algo_of(cls: type[BaseAlgorithm]) -> str:
    return next(name for name, candidate in ALGORITHMS.items() if candidate is cls)


def build_parser() -> argparse.ArgumentParser:
    """The command line of ``train`` (defined in :mod:`agents.common.cli`, which the console script parses
    with before this module's slow imports)."""
    return cli.build_parser("train")


def _overrides(args: argparse.Namespace) -> dict[str, Any] | None:
    """The hyperparameters the command line sets: the curriculum, and ``--multiagent`` (the
    file's ``multiagent`` options, or the defaults)."""
    overrides: dict[str, Any] = {}
    if args.curriculum:
        overrides["curriculum"] = {"start": args.curriculum[0], "fraction": args.curriculum[1]}
    if args.multiagent:
        file = args.hyperparams or HYPERPARAMS_DIR / f"{args.algo}_multiagent.yml"
        overrides["multiagent"] = load_hyperparameters(args.algo, args.env, file).get("multiagent") or {}
    return overrides or None


def main(argv: list[str] | None = None) -> Path:
    args = build_parser().parse_args(argv)
    return train(
        algo=args.algo,
        env_id=args.env,
        seed=args.seed,
        out=args.out,
        timesteps=args.timesteps,
        num_envs=args.n_envs,
        hyperparams_file=args.hyperparams
        or (HYPERPARAMS_DIR / f"{args.algo}_multiagent.yml" if args.multiagent else None),
        resume=args.resume,
        eval_freq=args.eval_freq,
        overrides=_overrides(args),
        eval_episodes=args.eval_episodes,
        checkpoint_freq=args.checkpoint_freq,
        progress_bar=not args.no_progress,
        verbose=args.verbose,
        force=args.force,
        trust_pickle=args.trust_pickle,
        command=command_line("train", sys.argv[1:] if argv is None else argv),
    )


if __name__ == "__main__":
    try:
        main()
    except (PickleNotTrustedError, OutputError, PolicyFormatError, HyperparameterError, ValueError, OSError) as error:
        sys.exit(f"{program('train')}: error: {error}")
