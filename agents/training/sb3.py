"""The SB3 training loop of ``python -m agents.train`` (:mod:`agents.train` describes the run
directory it writes): :func:`train` takes a :class:`~agents.training.config.TrainConfig` and runs
its steps in order, each checked before the next does any work:

1. the extras it needs (TensorBoard, the progress bar's);
2. the hyperparameters: the file's entry, the overrides and the command line's steps and envs,
   checked (:mod:`agents.training.hyperparams`);
3. the resume source and the run directory (:mod:`agents.training.runs`);
4. the training env (:func:`make_training_env`) and the model (new, or resumed);
5. ``config.yml``, the callbacks (:mod:`agents.training.callbacks`, and the seeded evaluation of
   :mod:`agents.training.selection`), and ``model.learn``;
6. the final policy, the evaluation log and the summary line.

The order of these steps, and of every random draw within them, is what makes a run with the same
seed write the same bytes: keep it."""

from __future__ import annotations

import time
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

import tether_gym
from tether_gym._optional import needs_extra, require
from tether_gym.sb3 import make_sb3_vec_env

from ..common.files import atomic_write_text, holds_output_claims
from ..policies.codecs import CLASS_KWARGS
from ..policies.format import ALGORITHMS, load_training_state, save_policy
from ..policies.pickled import load_pickled_model
from ..policies.spec import PolicySpec
from .callbacks import CriticWarmup, DifficultyCurriculum, SafePolicySaver
from .config import TrainConfig
from .hyperparams import (
    RUN_KEYS,
    SCHEDULE_KEYS,
    HyperparameterError,
    load_hyperparameters,
    schedule,
    validate_hyperparameters,
)
from .residual_env import ResidualVecEnv
from .runs import clear_earlier_run, prepare_run_dir, resume_source
from .selection import SeededEvaluation, print_evaluation_summary
from .shipping import model_name

with needs_extra("train", "training"):
    import yaml
    from stable_baselines3.common.base_class import BaseAlgorithm
    from stable_baselines3.common.callbacks import BaseCallback, CallbackList
    from stable_baselines3.common.vec_env import VecEnv, VecMonitor, VecNormalize

__all__ = [
    "algorithm_kwargs",
    "make_training_env",
    "policy_spec",
    "resolve_hyperparameters",
    "rollout_steps",
    "start_at_the_baseline",
    "train",
    "whole_rollouts",
]


@holds_output_claims
def train(config: TrainConfig) -> Path:
    """Train ``config.algo`` on ``config.env_id`` and return the run directory (see the module
    docstring for the steps, :mod:`agents.train` for what the directory holds).

    The config, the hyperparameters, the resume source and the run directory are all checked
    before any env is built: errors name the argument or key and the fix."""
    started = time.perf_counter()
    require_extras(config.progress_bar)
    hyperparams = resolve_hyperparameters(config)
    n_envs = int(hyperparams.get("n_envs", 1))
    spec = policy_spec(hyperparams)
    resume_kind, resume_path, keep = (
        resume_source(
            config.resume,
            config.trust_pickle,
            config.algo,
            config.env_id,
            spec=spec,
            normalize=bool(hyperparams.get("normalize", False)),
        )
        if config.resume is not None
        else (None, None, set())
    )
    name = model_name({"algo": config.algo, "multiagent": spec.multiagent})  # ppo or ppo_multiagent
    run = prepare_run_dir(config.out, config.env_id, name, config.seed, config.force)
    record = _run_record(config, hyperparams, resume_path)
    env_kwargs = hyperparams.get("env_kwargs")
    venv = make_training_env(
        config.env_id, n_envs, config.seed, hyperparams.get("normalize", False), env_kwargs, spec=spec
    )
    # The vector env's rows: n_envs, or n_envs clusters x their agents (timesteps count rows).
    rows = venv.num_envs
    model = _build_model(
        ALGORITHMS[config.algo], hyperparams, venv, config.seed, config.verbose, run, resume_kind, resume_path
    )
    venv = model.get_env()  # a pickle resume wraps the statistics it loaded around the env
    source = "--timesteps" if config.timesteps is not None else "n_timesteps"
    total = whole_rollouts(model, int(hyperparams["n_timesteps"]), source)
    hyperparams["n_timesteps"] = total  # config.yml records what runs, and reproduces it
    if config.force:
        clear_earlier_run(run, config.algo, keep)
    atomic_write_text(run / "config.yml", yaml.safe_dump(record, sort_keys=False))
    provenance = {"seed": config.seed, "command": config.command, "config": "config.yml of the run directory"}
    evaluation = _seeded_evaluation(config, run, provenance, spec, env_kwargs, rows, started)
    callbacks = _callbacks(config, hyperparams, run, provenance, spec, rows, evaluation, total)
    start = time.perf_counter()
    model.learn(
        total_timesteps=total,
        callback=CallbackList(callbacks),
        progress_bar=config.progress_bar,
        tb_log_name=config.algo,
        reset_num_timesteps=resume_kind is None,
    )
    if not evaluation.history:
        _evaluate_the_final_policy(evaluation, model, total, config.eval_freq, run)
    _save_the_final_policy(run, model, config.env_id, provenance, spec, record)
    _report(config, model, run, evaluation, time.perf_counter() - start)
    venv.close()
    return run


def require_extras(progress_bar: bool) -> None:
    """Check that the packages training needs beyond SB3 are installed: TensorBoard, and with
    ``progress_bar`` tqdm and rich. SB3 finds these missing only when training starts, and then
    names its own extra, not ours."""
    require("tensorboard", "train", "the training's TensorBoard logs")
    if progress_bar:
        for module in ("tqdm", "rich"):
            require(module, "train", "the progress bar (or pass --no-progress)")


def resolve_hyperparameters(config: TrainConfig) -> dict[str, Any]:
    """The run's checked hyperparameters: the file's entry for the id (:func:`load_hyperparameters`),
    with ``config.overrides`` and the command line's ``timesteps`` and ``num_envs`` in place of the
    file's, checked again together."""
    hyperparams = load_hyperparameters(config.algo, config.env_id, config.hyperparams_file)
    hyperparams.update(config.overrides or {})
    if config.timesteps is not None:
        hyperparams["n_timesteps"] = config.timesteps
    if config.num_envs is not None:
        hyperparams["n_envs"] = config.num_envs
    return validate_hyperparameters(config.algo, hyperparams, where="hyperparameters (with overrides)")


def policy_spec(hyperparams: Mapping[str, Any]) -> PolicySpec:
    """The policy's spec from checked hyperparameters (``residual_on``, ``multiagent``); a
    HyperparameterError when both are set: a residual policy is centralised."""
    multiagent = hyperparams.get("multiagent")
    if multiagent is not None and hyperparams.get("residual_on") is not None:
        raise HyperparameterError("'multiagent' and 'residual_on' do not combine: a residual policy is centralised")
    return PolicySpec(residual_on=hyperparams.get("residual_on"), multiagent=multiagent)


def _run_record(config: TrainConfig, hyperparams: dict[str, Any], resume_path: Path | None) -> dict[str, Any]:
    """What ``config.yml`` records (in this key order); it holds ``hyperparams`` itself, so that
    the steps rounded to whole rollouts, set later, are what it records."""
    return {
        "algo": config.algo,
        "env_id": config.env_id,
        "seed": config.seed,
        "hyperparams": hyperparams,
        "command": config.command,
        "resumed_from": str(resume_path) if resume_path else None,
        "tether_gym_version": tether_gym.__version__,
    }


def _seeded_evaluation(
    config: TrainConfig,
    run: Path,
    provenance: Mapping[str, Any],
    spec: PolicySpec,
    env_kwargs: Mapping[str, Any] | None,
    rows: int,
    started: float,
) -> SeededEvaluation:
    """The evaluation every ``--eval-freq`` env steps on the evaluation seeds, which saves the best
    policy to ``run/best`` and logs there (``rows``: the vector env's rows, which the steps count)."""
    return SeededEvaluation(
        config.env_id,
        config.eval_episodes,
        every=config.eval_freq // rows,
        log_dir=run / "best",
        on_new_best=SafePolicySaver(run / "best", config.env_id, provenance, spec=spec),
        started=started,
        env_kwargs=env_kwargs,
        spec=spec,
        verbose=1 if config.progress_bar or config.verbose else 0,
    )


def _callbacks(
    config: TrainConfig,
    hyperparams: Mapping[str, Any],
    run: Path,
    provenance: Mapping[str, Any],
    spec: PolicySpec,
    rows: int,
    evaluation: SeededEvaluation,
    total: int,
) -> list[BaseCallback]:
    """The callbacks of ``model.learn``, in the order they run: checkpoints, the seeded evaluation
    (which saves ``best/``), the critic warm-up and the curriculum when the hyperparameters ask."""
    callbacks: list[BaseCallback] = [
        SafePolicySaver(
            run / "checkpoints",
            config.env_id,
            provenance,
            every=max(config.checkpoint_freq // rows, 1),
            prefix=config.algo,
            spec=spec,
        ),
        evaluation,
    ]
    if hyperparams.get("critic_warmup"):
        callbacks.append(CriticWarmup(hyperparams["critic_warmup"]))
    curriculum = hyperparams.get("curriculum")
    if curriculum:
        callbacks.append(DifficultyCurriculum(curriculum["start"], curriculum["fraction"], total))
    return callbacks


def _evaluate_the_final_policy(
    evaluation: SeededEvaluation, model: BaseAlgorithm, total: int, eval_freq: int, run: Path
) -> None:
    """Evaluate once after training where no evaluation ran: ``best/`` is chosen among
    evaluations, and a run shorter than ``--eval-freq`` would leave none."""
    print(
        f"no evaluation ran in {total:,} steps (--eval-freq {eval_freq:,}): evaluating the final policy "
        f"for {run / 'best'}",
        flush=True,
    )
    evaluation.num_timesteps = model.num_timesteps
    evaluation.evaluate()


def _save_the_final_policy(
    run: Path,
    model: BaseAlgorithm,
    env_id: str,
    provenance: Mapping[str, Any],
    spec: PolicySpec,
    record: dict[str, Any],
) -> None:
    """``config.yml`` completed by the steps trained, then the final policy with its training state
    into ``run``, its manifest covering ``config.yml``."""
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
        spec=spec,
    )


def _report(config: TrainConfig, model: BaseAlgorithm, run: Path, evaluation: SeededEvaluation, elapsed: float) -> None:
    """Close the evaluation log (``best/evaluations.json``) and print the run's summary: steps,
    time and speed (``elapsed``: seconds of ``model.learn`` and after), and the best evaluation."""
    evaluation.finish(model.num_timesteps)
    print(
        f"trained {config.algo} on {config.env_id} for {model.num_timesteps:,} steps in {elapsed / 60:.1f} min "
        f"({model.num_timesteps / max(elapsed, 1e-9):,.0f} steps/s); run directory {run}"
    )
    print_evaluation_summary(evaluation)


def make_training_env(
    env_id: str,
    num_envs: int,
    seed: int,
    normalize: Any,
    env_kwargs: Mapping[str, Any] | None = None,
    training: bool = True,
    spec: PolicySpec | None = None,
) -> VecEnv:
    """The native vector env of ``env_id`` through the SB3 adapter, with ``VecMonitor`` and, if
    ``normalize`` is truthy (a bool or ``VecNormalize`` keyword arguments), ``VecNormalize``.
    ``spec`` (default: a centralised policy acting directly) says what the actions are: with its
    ``residual_on`` (a baseline's name) they are corrections to that baseline's
    (:class:`agents.training.residual_env.ResidualVecEnv`); with its ``multiagent`` options the env
    is ``num_envs`` clusters x their agents, one row per agent, for a shared decentralised policy
    (:class:`tether_gym.multiagent.sb3.AgentVecEnv`)."""
    spec = spec if spec is not None else PolicySpec()
    base: VecEnv
    if spec.multiagent is not None:
        from tether_gym.multiagent.sb3 import make_agent_vec_env

        base = make_agent_vec_env(env_id, num_envs, seed=seed, **dict(env_kwargs or {}), **dict(spec.multiagent))
    else:
        base = make_sb3_vec_env(env_id, num_envs, seed=seed, **dict(env_kwargs or {}))
    if spec.residual_on is not None:
        base = ResidualVecEnv(base, spec.residual_on)
    venv: VecEnv = VecMonitor(base)
    if normalize:
        options = dict(normalize) if isinstance(normalize, Mapping) else {}
        if not training:
            options.update(training=False, norm_reward=False)
        venv = VecNormalize(venv, **options)
    return venv


def algorithm_kwargs(hyperparams: Mapping[str, Any]) -> dict[str, Any]:
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


def whole_rollouts(model: BaseAlgorithm, total: int, source: str) -> int:
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
        **algorithm_kwargs(hyperparams),
        **_action_noise(hyperparams, venv),
    )
    if hyperparams.get("residual_on") is not None and resume_kind is None:
        start_at_the_baseline(model)
    if resume_kind == "safe":
        assert resume_path is not None
        load_training_state(
            model, resume_path, venv if isinstance(venv, VecNormalize) else None, spec=policy_spec(hyperparams)
        )
    return model


def _algo_of(cls: type[BaseAlgorithm]) -> str:
    return next(name for name, candidate in ALGORITHMS.items() if candidate is cls)
