"""DAgger distillation of the reference ceiling planner into a fast network: the trainer behind
``python -m agents.dagger`` (:func:`train_dagger`), its settings (:class:`DAggerSettings`, per id
in the package's ``hyperparams/dagger.yml``) and its parts (:func:`collect`, :func:`fit_student`,
:func:`measure_compute`).

**What it learns.** The teacher is the ceiling planner (:mod:`agents.evaluation.ceiling`: the
``mpc`` of :mod:`agents.controllers.mpc` with the id's long-horizon settings of
``hyperparams/ceiling.yml``). It costs 0.03-0.08 s of compute per env and control step. The
student is a residual policy on a scripted law (``residual_on``, the planner's own prior by
default): ``action = clip(law(obs) + clip(net(z), -1, 1), -1, 1)``, ``z`` the observation
normalised by statistics fixed from the first iteration's states. It starts at (about) the law
and learns the planner's correction: its regression targets are ``clip(teacher(s) - law(obs), -1,
1)`` on the states ``s`` it visits.

**What the student observes.** The env's observation and nothing else: the positions, velocities
and cable elongations the env gives every controller. The teacher is privileged: it reads the
env's true state and model (``env.unwrapped.task``), on the delayed-thrust id the commands still in
flight too, and plans 9 s ahead with them. The student sees none of that but what the observation
holds: on the delayed id the observation holds the commands in flight (``observe_commands``), so
the student sees them too, and its law predicts over the delay with them (a student trained
before the laws predicted learnt the correction to the law without the prediction).

**DAgger** (Ross, Gordon and Bagnell, 2011, "A reduction of imitation learning and structured
prediction to no-regret online learning"). Iteration 0 rolls the teacher out and labels its own
states. Iteration ``i > 0`` rolls out the mixture that takes, at every step and in every episode,
the teacher's action with probability ``beta_i = beta_decay ** i`` and the student's otherwise
(``beta_decay: 0``, the default, is the pure student after iteration 0), while the teacher labels
every visited state. The planner replans from the true state at every step, so it labels states
reached under any policy's actions. All labelled states are kept; after each iteration the
network is trained on all of them (Adam on the mean squared error, minibatches, ``epochs``
passes, warm-started from the previous iteration's weights) and evaluated on the evaluation seeds
(1 000 000 up, never the benchmark's held-out 10 000 up); the best evaluation is kept in ``best/``.

**Seeds.** The training episodes are seeds :data:`TRAINING_SEEDS_START` (200 000) up: the run of
seed ``s`` takes the block ``200 000 + 800 s`` .. ``+ 799``, iteration ``i``'s episodes the next
``episodes`` of it. They are apart from the tuning seeds (2 000 and 3 000 up), the held-out seeds
(10 000 up) and the evaluation seeds (1 000 000 up). The episodes of an iteration run as one batched
vector env: the planner costs 2-3 times less per episode on a batch than alone.

**Compute.** The run measures the teacher's planning time per env and control step (batched as
it ran) and the student's per step (:func:`measure_compute`): the whole student for one
observation at a time and batched as the teacher ran, and its network's forward pass alone; it
records them and their ratios to the teacher's in ``best/evaluations.json``.

The policy is stored in the safe format as the actor of SB3's ``ActorCriticPolicy`` (``net_arch:
{pi: <net_arch>, vf: []}``, its value head zero and unused) with ``algo: dagger`` and
``residual_on`` (:func:`save_student`), so :class:`agents.policies.TrainedPolicy`,
``agents.compare``, ``agents.benchmark`` and ``agents.ship`` load it like any trained model.
"""

from __future__ import annotations

import contextlib
import dataclasses
import time
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from tether_gym._optional import needs_extra

from ..common.checks import MAX_NUM_ENVS, check_int
from ..common.commands import command_line
from ..common.data import HYPERPARAMS_DIR
from ..common.files import atomic_write_text, holds_output_claims
from ..common.settings import load_settings
from ..controllers.mpc import MPCController, MPCSettings
from ..controllers.registry import BASELINES, make_baseline
from ..evaluation.ceiling import load_ceiling_settings
from ..policies.loaded import TrainedPolicy
from ..policies.normalization import NormalizationStatistics
from ..policies.spec import PolicySpec
from .runs import clear_earlier_run, prepare_run_dir, save_residual_policy
from .selection import EvaluationLog, baseline_returns, episode_returns, evaluation_seeds

with needs_extra("train", "the DAgger trainer"):
    import torch
    import yaml

__all__ = [
    "DAGGER_SETTINGS_FILE",
    "DATASET_FILE",
    "SEEDS_PER_RUN",
    "TRAINING_SEEDS_START",
    "DAggerSettings",
    "Labelled",
    "StudentFit",
    "build_student",
    "collect",
    "fit_student",
    "held_out_rows",
    "load_dagger_settings",
    "measure_compute",
    "observation_statistics",
    "save_student",
    "student_controller",
    "student_loss",
    "teacher_of",
    "train_dagger",
    "training_seeds",
]

#: The labelled states of a run, in its directory: observations, targets and the iteration of each.
DATASET_FILE = "dataset.npz"
#: Per-id DAgger settings (plain YAML, nothing evaluated).
DAGGER_SETTINGS_FILE = HYPERPARAMS_DIR / "dagger.yml"
#: First training seed, and the seeds set aside per run (seed s: TRAINING_SEEDS_START + s *
#: SEEDS_PER_RUN up): runs 0..999 stay within 200 000..999 999, below the evaluation seeds.
TRAINING_SEEDS_START = 200_000
SEEDS_PER_RUN = 800


@dataclasses.dataclass(frozen=True)
class DAggerSettings:
    """Settings of :func:`train_dagger` (see the module docstring); a run's ``config.yml`` records
    them as its ``hyperparams``."""

    residual_on: str | None = None
    """The scripted law the student corrects (a name of :data:`agents.controllers.registry.BASELINES`),
    or None: the teacher's prior, so that the student learns the planner's correction to it."""
    iterations: int = 8
    """DAgger iterations (iteration 0 rolls out the teacher)."""
    episodes: int = 8
    """Episodes per iteration, run at once in one batched vector env."""
    beta_decay: float = 0.0
    """Iteration i acts with the teacher's action with probability ``beta_decay ** i`` per step (1
    at iteration 0), else the student's; in [0, 1)."""
    net_arch: tuple[int, ...] = (64, 64)
    """Hidden layers of the student's network (tanh)."""
    epochs: int = 200
    """Passes over the aggregated data after each iteration."""
    learning_rate: float = 1e-3
    """Adam's step size."""
    batch_size: int = 256
    """States per minibatch."""
    eval_episodes: int = 32
    """Evaluation episodes after each iteration (seeds 1 000 000 up)."""
    validation_every: int = 0
    """Early stopping: every ``validation_every``-th labelled episode (counted over the run) is
    held out of the fit, and each fit keeps the weights of the epoch with the lowest error on the
    held-out episodes' states (the previous weights if no epoch improves on them), ``epochs``
    being the most passes. 0: no episode held out, every fit runs all ``epochs`` (the runs before
    this setting existed)."""
    teacher_samples: int | None = None
    """The teacher's sampled trajectories per planning step, instead of its ceiling settings'
    (ceiling.yml); None: those. Fewer samples make each label cheaper (the planner's cost is about
    proportional to them), so a run of the same length labels more states; the teacher is then
    weaker than the ceiling by what the id's measurements in dagger.yml say."""

    def __post_init__(self) -> None:
        if self.residual_on is not None and self.residual_on not in BASELINES:
            raise ValueError(
                f"dagger setting residual_on must be one of {sorted(BASELINES)} or null (the teacher's prior); "
                f"got {self.residual_on!r}"
            )
        counts = {"iterations": (1, SEEDS_PER_RUN), "epochs": (1, 100_000), "batch_size": (1, 1_000_000)}
        counts |= {"validation_every": (0, SEEDS_PER_RUN)}
        # The episodes of an iteration and of an evaluation run as one vector env: at most MAX_NUM_ENVS;
        # an evaluation needs 2 episodes for its paired interval.
        counts |= {"episodes": (1, MAX_NUM_ENVS), "eval_episodes": (2, MAX_NUM_ENVS)}
        for name, (least, most) in counts.items():
            object.__setattr__(self, name, check_int(f"dagger setting {name}", getattr(self, name), least, most))
        if self.iterations * self.episodes > SEEDS_PER_RUN:
            raise ValueError(
                f"dagger settings iterations x episodes ({self.iterations} x {self.episodes}) must be <= "
                f"{SEEDS_PER_RUN} (the run's block of training seeds): lower one of them"
            )
        arch = self.net_arch
        if not isinstance(arch, list | tuple) or not 1 <= len(arch) <= 16:
            raise ValueError(f"dagger setting net_arch must be a list of 1 to 16 layer sizes; got {arch!r}")
        sizes = tuple(check_int("dagger setting net_arch entry", size, 1, 4096) for size in arch)
        object.__setattr__(self, "net_arch", sizes)
        decay = self.beta_decay
        if isinstance(decay, bool) or not isinstance(decay, int | float) or not 0.0 <= decay < 1.0:
            raise ValueError(f"dagger setting beta_decay must be a number in [0, 1); got {decay!r}")
        if self.teacher_samples is not None:
            object.__setattr__(
                self, "teacher_samples", check_int("dagger setting teacher_samples", self.teacher_samples, 1, 100_000)
            )
        if self.validation_every == 1:
            raise ValueError(
                "dagger setting validation_every must be 0 (off) or at least 2: 1 would hold out every episode"
            )
        rate = self.learning_rate
        if isinstance(rate, bool) or not isinstance(rate, int | float) or not (np.isfinite(rate) and 0 < rate <= 1):
            raise ValueError(f"dagger setting learning_rate must be a number in (0, 1]; got {rate!r}")

    def beta(self, iteration: int) -> float:
        """The probability of the teacher's action at ``iteration`` (1 at iteration 0)."""
        return float(self.beta_decay**iteration)

    def record(self) -> dict[str, Any]:
        """The settings as plain YAML values (``config.yml``'s ``hyperparams``)."""
        return {**dataclasses.asdict(self), "net_arch": list(self.net_arch)}


def load_dagger_settings(env_id: str | None, path: str | Path | None = None, **overrides: Any) -> DAggerSettings:
    """The DAgger settings of ``env_id``: its entry of the package's ``hyperparams/dagger.yml`` (or of
    ``path``, which may also be a run's ``config.yml``), else the file's ``default`` entry, with
    keyword ``overrides`` on top."""
    file = Path(path) if path is not None else DAGGER_SETTINGS_FILE
    return load_settings(DAggerSettings, file, env_id, "DAgger", overrides, run_algo="dagger")


def teacher_of(env_id: str, settings: DAggerSettings) -> MPCSettings:
    """The teacher of a run on ``env_id``: the id's ceiling planner (ceiling.yml), with the
    ``teacher_samples`` of ``settings`` where they are set."""
    if settings.teacher_samples is None:
        return load_ceiling_settings(env_id)
    return load_ceiling_settings(env_id, samples=settings.teacher_samples)


def training_seeds(seed: int, iteration: int, episodes: int) -> list[int]:
    """The reset seeds of iteration ``iteration``'s ``episodes`` episodes in the run of ``seed``."""
    start = TRAINING_SEEDS_START + seed * SEEDS_PER_RUN + iteration * episodes
    return list(range(start, start + episodes))


@dataclasses.dataclass
class Labelled:
    """The states of one iteration's episodes, labelled by the teacher.

    Attributes:
        observations: (N, O) float32 observations the episodes visited (each episode up to its end).
        episodes: (N,) int the episode of each row (0 .. E-1, in the order of the iteration's seeds).
        targets: (N, A) float32 ``clip(teacher - law, -1, 1)`` on each of them, normalised thrust.
        teacher_actions, law_actions: (N, A) float32 the teacher's and the law's actions there.
        returns: (E,) return of each episode under the policy that acted.
        teacher_seconds, teacher_steps: the teacher's planning time, s, over its env and control steps.
    """

    observations: np.ndarray
    episodes: np.ndarray
    targets: np.ndarray
    teacher_actions: np.ndarray
    law_actions: np.ndarray
    returns: np.ndarray
    teacher_seconds: float
    teacher_steps: int


def collect(
    env_id: str,
    seeds: Sequence[int],
    teacher_settings: MPCSettings,
    residual_on: str,
    student: TrainedPolicy | None,
    beta: float,
    rng: np.random.Generator,
    env_kwargs: dict[str, Any] | None = None,
) -> Labelled:
    """Roll out one iteration's episodes (one per seed, batched) and label every visited state.

    At every step and in every episode the teacher's action acts with probability ``beta``, the
    student's otherwise (``student`` None: ``beta`` must be 1). The draws come from ``rng``, one
    (E,) vector per step. ``env_kwargs``: keyword arguments of ``gym.make_vec`` (e.g. a shorter
    ``max_episode_steps``)."""
    import gymnasium as gym
    from gymnasium.vector import AutoresetMode

    if student is None and beta < 1.0:
        raise ValueError(f"collect: a beta of {beta} below 1 needs a student to act")
    count = len(seeds)
    envs = gym.make_vec(env_id, num_envs=count, **{"autoreset_mode": AutoresetMode.SAME_STEP, **dict(env_kwargs or {})})
    teacher = MPCController(envs, teacher_settings)
    law = make_baseline(residual_on, envs)
    if student is not None:
        student.attach(envs)
    observation, _ = envs.reset(seed=[int(seed) for seed in seeds])
    alive = np.ones(count, dtype=bool)
    returns = np.zeros(count)
    visited: list[np.ndarray] = []
    episode_rows: list[np.ndarray] = []
    teacher_rows: list[np.ndarray] = []
    law_rows: list[np.ndarray] = []
    while alive.any():
        teacher_action, _ = teacher.predict(observation)
        law_action, _ = law.predict(observation)
        visited.append(observation[alive].astype(np.float32))
        episode_rows.append(np.flatnonzero(alive))
        teacher_rows.append(np.asarray(teacher_action, dtype=np.float32)[alive])
        law_rows.append(np.asarray(law_action, dtype=np.float32)[alive])
        if student is None:
            action = teacher_action
        else:
            student_action, _ = student.predict(observation, deterministic=True)
            by_teacher = rng.random(count) < beta
            action = np.where(by_teacher[:, None], teacher_action, student_action).astype(np.float32)
        observation, reward, terminated, truncated, _ = envs.step(action)
        returns += np.where(alive, reward, 0.0)
        alive &= ~(terminated | truncated)
    envs.close()
    teacher_actions, law_actions = np.concatenate(teacher_rows), np.concatenate(law_rows)
    targets = np.clip(teacher_actions - law_actions, -1.0, 1.0).astype(np.float32)
    return Labelled(
        np.concatenate(visited),
        np.concatenate(episode_rows),
        targets,
        teacher_actions,
        law_actions,
        returns,
        teacher.compute_seconds,
        teacher.env_steps,
    )


def observation_statistics(observations: np.ndarray) -> NormalizationStatistics:
    """Fixed normalisation statistics (mean and variance, no reward scaling) of (N, O) observations."""
    return NormalizationStatistics.fixed(observations)


def build_student(env_id: str, net_arch: Sequence[int], seed: int) -> Any:
    """An SB3 PPO model whose ``ActorCriticPolicy`` (``net_arch: {pi: net_arch, vf: []}``) is the
    student, initialised from ``seed`` (SB3's orthogonal initialisation: the action head starts
    near zero, so the student starts near its law). Its value head is zeroed: DAgger has no critic."""
    from stable_baselines3 import PPO

    from tether_gym.sb3 import make_sb3_vec_env

    venv = make_sb3_vec_env(env_id, 1, seed=0)
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(seed)
        model = PPO(
            "MlpPolicy",
            venv,
            policy_kwargs={"net_arch": {"pi": list(net_arch), "vf": []}},
            device="cpu",
            n_steps=64,
            batch_size=64,
        )
    with torch.no_grad():
        for parameter in model.policy.value_net.parameters():
            parameter.zero_()
    model.policy.set_training_mode(False)
    venv.close()
    return model


@contextlib.contextmanager
def _one_torch_thread() -> Iterator[None]:
    """Run torch on one thread inside: a network this small gains nothing from more, and on a
    machine shared with other work the threads' synchronisation costs many times the arithmetic.
    The setting is restored on the way out."""
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        yield
    finally:
        torch.set_num_threads(threads)


def _student_outputs(policy: Any, features: torch.Tensor) -> torch.Tensor:
    """The actor's mean action (before SB3's clipping) for normalised observations (N, O)."""
    return policy.action_net(policy.mlp_extractor.forward_actor(policy.extract_features(features)))


def student_loss(policy: Any, features: np.ndarray, targets: np.ndarray) -> float:
    """The mean squared error of ``policy``'s clipped outputs on (N, O) normalised observations
    ``features`` against (N, A) ``targets`` (normalised thrust squared)."""
    x = torch.as_tensor(np.asarray(features, dtype=np.float32))
    y = torch.as_tensor(np.asarray(targets, dtype=np.float32))
    with _one_torch_thread(), torch.no_grad():
        return float(torch.nn.functional.mse_loss(_student_outputs(policy, x).clamp(-1.0, 1.0), y))


@dataclasses.dataclass(frozen=True)
class StudentFit:
    """What one :func:`fit_student` call did.

    Attributes:
        loss: mean squared error of the clipped outputs on the fitted data afterwards (normalised
            thrust squared).
        validation_loss: the same on the held-out data with the weights kept; None without them.
        validation_loss_before: on the held-out data before the fit; None without them.
        epochs_kept: the passes whose weights were kept (all of them without held-out data; 0 when
            no pass improved on the weights before the fit).
    """

    loss: float
    validation_loss: float | None = None
    validation_loss_before: float | None = None
    epochs_kept: int = 0


def fit_student(
    policy: Any,
    features: np.ndarray,
    targets: np.ndarray,
    epochs: int,
    learning_rate: float,
    batch_size: int,
    seed: int,
    validation: tuple[np.ndarray, np.ndarray] | None = None,
) -> StudentFit:
    """Train ``policy``'s actor (its MLP and action head, in place) on (N, O) normalised
    observations ``features`` and (N, A) ``targets`` with Adam on the mean squared error, for
    ``epochs`` passes in minibatches shuffled by ``seed``.

    With ``validation`` ((M, O) normalised observations and (M, A) targets of episodes left out
    of ``features``), the error on them is measured before the first pass and after each, and
    the weights of the lowest are kept (early stopping): the student's states come from episodes
    it will never see again, and an error on the fitted states alone rewards memorising them."""
    x = torch.as_tensor(np.asarray(features, dtype=np.float32))
    y = torch.as_tensor(np.asarray(targets, dtype=np.float32))
    if x.ndim != 2 or y.ndim != 2 or x.shape[0] != y.shape[0] or x.shape[0] == 0:
        raise ValueError(f"features (N, O) and targets (N, A) must have N >= 1 rows alike; got {x.shape}, {y.shape}")
    sizes = (int(np.prod(policy.observation_space.shape)), int(np.prod(policy.action_space.shape)))
    if (x.shape[1], y.shape[1]) != sizes:
        raise ValueError(
            f"the student takes {sizes[0]} observation values and gives {sizes[1]} actions; got features of "
            f"{x.shape[1]} and targets of {y.shape[1]}: pass data of the student's id"
        )
    if validation is not None:
        held_x, held_y = (np.asarray(part, dtype=np.float32) for part in validation)
        if held_x.ndim != 2 or held_y.shape != (held_x.shape[0], sizes[1]) or held_x.shape[1:] != (sizes[0],):
            raise ValueError(
                f"validation must be (M, {sizes[0]}) features and (M, {sizes[1]}) targets with M >= 1 rows alike; "
                f"got {held_x.shape}, {held_y.shape}"
            )
        if held_x.shape[0] == 0:
            raise ValueError("validation holds no rows: pass None to fit without held-out data")
    parameters = [*policy.mlp_extractor.policy_net.parameters(), *policy.action_net.parameters()]
    optimizer = torch.optim.Adam(parameters, lr=learning_rate)
    generator = torch.Generator().manual_seed(seed)
    best_loss = before = student_loss(policy, held_x, held_y) if validation is not None else None
    best_weights = [parameter.detach().clone() for parameter in parameters] if validation is not None else None
    kept = 0
    policy.set_training_mode(True)
    with _one_torch_thread():
        for epoch in range(epochs):
            order = torch.randperm(x.shape[0], generator=generator)
            for start in range(0, x.shape[0], batch_size):
                rows = order[start : start + batch_size]
                loss = torch.nn.functional.mse_loss(_student_outputs(policy, x[rows]), y[rows])
                optimizer.zero_grad()
                loss.backward()
                optimizer.step()
            if validation is None:
                kept = epoch + 1
                continue
            held_loss = student_loss(policy, held_x, held_y)
            if held_loss < best_loss:
                best_loss, kept = held_loss, epoch + 1
                best_weights = [parameter.detach().clone() for parameter in parameters]
        if best_weights is not None:
            with torch.no_grad():
                for parameter, weights in zip(parameters, best_weights, strict=True):
                    parameter.copy_(weights)
        policy.set_training_mode(False)
    return StudentFit(student_loss(policy, features, targets), best_loss, before, kept)


def held_out_rows(episodes: np.ndarray, every: int) -> np.ndarray:
    """(N,) bool: the rows of the episodes held out of the fit for early stopping, every
    ``every``-th episode of the run (``episodes``: (N,) the episode of each row, counted over the
    run); none for ``every`` 0."""
    episodes = np.asarray(episodes)
    if every == 0:
        return np.zeros(episodes.shape, dtype=bool)
    return episodes % every == every - 1


def student_controller(model: Any, statistics: NormalizationStatistics, env_id: str, residual_on: str) -> TrainedPolicy:
    """The in-memory student as a controller, exactly as :class:`TrainedPolicy` loads it from
    disk (the same normalisation, SB3 ``predict`` and residual rule): it acts with the weights
    the model holds when ``predict`` is called. Attach it to an env before use."""
    return TrainedPolicy.from_parts(
        model.policy, statistics, env_id, algo="dagger", spec=PolicySpec(residual_on=residual_on)
    )


def save_student(
    directory: Path,
    model: Any,
    env_id: str,
    residual_on: str,
    statistics: NormalizationStatistics,
    timesteps: int,
    provenance: dict[str, Any],
    extra_files: tuple[str, ...] = (),
    whole_directory: bool = False,
) -> Path:
    """Write the student in the safe format with ``algo: dagger`` and ``residual_on``. With
    ``whole_directory`` (``best/``), the save replaces ``directory`` as a whole, so an interrupt
    never leaves it half-written."""
    model.num_timesteps = int(timesteps)
    return save_residual_policy(
        directory, model, statistics, env_id, provenance, residual_on, "dagger", extra_files, whole_directory
    )


def measure_compute(
    student: TrainedPolicy, law: Any, observations: np.ndarray, batch: int, repeats: int = 3
) -> dict[str, float]:
    """Compute per control step, s, of the student and its parts on (N, O) ``observations``:

    * ``student_single``: the whole student (normalisation, SB3's ``predict``, the law and the
      residual rule) on one observation at a time, as one cluster's flight computer would run it;
    * ``student_batched``: the same per observation, on batches of ``batch`` (the teacher's batch);
    * ``network_single``: the network's forward pass alone (torch, no gradient) on one normalised
      observation: what the distillation adds to the law;
    * ``law_single``: the law alone (``law``, attached to an env of the id) on one observation.

    Torch runs on one thread. Each is the best of ``repeats`` passes over the observations (the
    least disturbed by other work)."""
    rows = np.asarray(observations, dtype=np.float32)
    if rows.ndim != 2 or len(rows) < batch or batch < 1:
        raise ValueError(f"measure_compute needs (N, O) observations with N >= batch >= 1; got {rows.shape}, {batch}")
    normalizer = student.normalizer
    features = torch.as_tensor(normalizer.normalize_obs(rows).astype(np.float32))
    policy = student.policy
    batches = [rows[start : start + batch] for start in range(0, len(rows) - batch + 1, batch)]

    def network(row: torch.Tensor) -> None:
        with torch.no_grad():
            _student_outputs(policy, row)

    passes = {
        "student_single": (lambda: [student.predict(row, deterministic=True) for row in rows], len(rows)),
        "student_batched": (lambda: [student.predict(b, deterministic=True) for b in batches], batch * len(batches)),
        "network_single": (lambda: [network(features[k : k + 1]) for k in range(len(rows))], len(rows)),
        "law_single": (lambda: [law.predict(row) for row in rows], len(rows)),
    }
    timings: dict[str, float] = {}
    with _one_torch_thread():  # as a flight computer's single core would run it
        for name, (work, count) in passes.items():
            best = np.inf
            for _ in range(repeats):
                start = time.perf_counter()
                work()
                best = min(best, (time.perf_counter() - start) / count)
            timings[name] = float(best)
    return timings


def _attached_law(name: str, env_id: str, env_kwargs: dict[str, Any]) -> Any:
    import gymnasium as gym

    env = gym.make(env_id, **env_kwargs)
    law = make_baseline(name, env)
    env.close()
    return law


def _attached(controller: TrainedPolicy, env_id: str, env_kwargs: dict[str, Any]) -> TrainedPolicy:
    import gymnasium as gym

    env = gym.make(env_id, **env_kwargs)
    controller.attach(env)
    env.close()
    return controller


@holds_output_claims
def train_dagger(
    env_id: str,
    seed: int = 1,
    out: str | Path = "runs",
    settings: DAggerSettings | None = None,
    teacher: MPCSettings | None = None,
    force: bool = False,
    progress: bool = True,
    command: str | None = None,
    env_kwargs: dict[str, Any] | None = None,
) -> Path:
    """Distil the ceiling planner into a residual network with DAgger (see the module
    docstring); returns the run directory.

    Args:
        env_id: a registered tether-gym id with ceiling settings (``hyperparams/ceiling.yml``).
        seed: the run's seed, 0..999: it initialises the network, draws the minibatches and the
            beta mixture, and picks the block of training seeds.
        out: parent of the run directory ``<out>/<env_id>/dagger_seed<seed>``.
        settings: default: ``load_dagger_settings(env_id)``.
        teacher: the planner's settings (default: the id's ceiling settings, with the settings'
            ``teacher_samples`` where it is set).
        force: replace an earlier run in the same directory.
        progress: print a line per iteration.
        command: the command line recorded in ``config.yml``.
        env_kwargs: keyword arguments of the envs (``gym.make``) of training and evaluation, e.g.
            a shorter ``max_episode_steps`` for a test; recorded in ``config.yml``.
    """
    import tether_gym
    from tether_gym.registration import ENV_IDS

    from ..evaluation.scoring import machine_description
    from ..evaluation.stats import paired_difference

    if env_id not in ENV_IDS:
        raise ValueError(f"unknown env id {env_id!r}; choose one of {', '.join(ENV_IDS)}")
    seed = check_int("seed", seed, 0, 999)
    kwargs = dict(env_kwargs or {})
    s = settings if settings is not None else load_dagger_settings(env_id)
    teacher_settings = teacher if teacher is not None else teacher_of(env_id, s)
    if not isinstance(teacher_settings, MPCSettings):
        raise TypeError(f"teacher must be MPCSettings; got {type(teacher_settings).__name__}")
    if s.residual_on is None:
        if teacher_settings.prior == "none":
            raise ValueError(
                f"dagger setting residual_on is null (the teacher's prior), but {env_id}'s teacher plans without a "
                "prior: name the law the student corrects"
            )
        s = dataclasses.replace(s, residual_on=teacher_settings.prior)
    law_name: str = s.residual_on  # type: ignore[assignment]
    run = prepare_run_dir(out, env_id, "dagger", seed, force)
    if force:
        clear_earlier_run(run, "dagger", set())
    record = {
        "algo": "dagger",
        "env_id": env_id,
        "seed": seed,
        "hyperparams": s.record(),
        "teacher": dataclasses.asdict(teacher_settings),
        "env_kwargs": kwargs,
        "training_seeds": [training_seeds(seed, 0, 1)[0], training_seeds(seed, s.iterations - 1, s.episodes)[-1]],
        "command": command or command_line("dagger", ["--env", env_id, "--seed", str(seed)]),
        "tether_gym_version": tether_gym.__version__,
    }
    atomic_write_text(run / "config.yml", yaml.safe_dump(record, sort_keys=False))
    provenance = {"seed": seed, "command": record["command"], "config": "config.yml of the run directory"}
    started = time.perf_counter()

    eval_seeds = evaluation_seeds(s.eval_episodes)
    by_name, bar = baseline_returns(env_id, eval_seeds, kwargs)
    law_returns = by_name[law_name]
    # A first "best" must beat the law the student starts near.
    log = EvaluationLog(env_id, eval_seeds, by_name, bar, started, best_mean=float(law_returns.mean()))
    if progress:
        means = ", ".join(f"{name} {r.mean():.2f}" for name, r in by_name.items())
        print(f"dagger {env_id} seed {seed}: evaluation seeds {eval_seeds[0]}..{eval_seeds[-1]}: {means}", flush=True)
    rng = np.random.default_rng(seed)
    model = build_student(env_id, s.net_arch, seed)
    student: TrainedPolicy | None = None
    statistics: NormalizationStatistics | None = None
    observations: list[np.ndarray] = []
    targets: list[np.ndarray] = []
    episode_ids: list[np.ndarray] = []  # per row, its episode counted over the run
    teacher_seconds, teacher_steps, timesteps = 0.0, 0, 0
    best_iteration = -1
    for iteration in range(s.iterations):
        beta = s.beta(iteration)
        seeds = training_seeds(seed, iteration, s.episodes)
        data = collect(env_id, seeds, teacher_settings, law_name, student, beta, rng, kwargs)
        teacher_seconds += data.teacher_seconds
        teacher_steps += data.teacher_steps
        timesteps += len(data.observations)
        observations.append(data.observations)
        targets.append(data.targets)
        episode_ids.append(iteration * s.episodes + data.episodes)
        if statistics is None:  # fixed from the teacher's own states of iteration 0
            statistics = observation_statistics(data.observations)
            student = _attached(student_controller(model, statistics, env_id, law_name), env_id, kwargs)
        assert student is not None
        # The student's error on the states it has just visited, before it is refitted on them: what
        # it had not learnt of the teacher where it goes (None at iteration 0, before any fit: JSON
        # null, as the strict readers that ship a run refuse NaN).
        new_loss = (
            student_loss(model.policy, statistics.normalize_obs(data.observations), data.targets) if iteration else None
        )
        all_observations = np.concatenate(observations)
        features = statistics.normalize_obs(all_observations).astype(np.float32)
        all_targets = np.concatenate(targets)
        held_out = held_out_rows(np.concatenate(episode_ids), s.validation_every)
        fit = fit_student(
            model.policy,
            features[~held_out],
            all_targets[~held_out],
            s.epochs,
            s.learning_rate,
            s.batch_size,
            seed=seed * 1000 + iteration,
            validation=(features[held_out], all_targets[held_out]) if held_out.any() else None,
        )
        loss = fit.loss
        returns = episode_returns(student, env_id, eval_seeds, kwargs)
        versus_law = paired_difference(returns, law_returns)
        entry, _, new_best = log.add(
            returns,
            timesteps,
            iteration=iteration,
            beta=beta,
            states=int(len(all_observations)),
            loss=loss,
            loss_on_new_states=new_loss,
            validation_states=int(held_out.sum()),
            validation_loss=fit.validation_loss,
            validation_loss_before=fit.validation_loss_before,
            epochs_kept=fit.epochs_kept,
            # The loss against the targets' own spread: the fraction of the correction not learnt.
            target_variance=float(all_targets.var(axis=0).mean()),
            rollout_return=float(data.returns.mean()),
            difference_vs_law=versus_law.mean,
            difference_vs_law_low=versus_law.low,
            difference_vs_law_high=versus_law.high,
        )
        if new_best:
            best_iteration = iteration
            save_student(run / "best", model, env_id, law_name, statistics, timesteps, provenance, whole_directory=True)
        log.write(run / "best")
        if progress:
            wall = time.perf_counter() - started
            left = wall / (iteration + 1) * (s.iterations - iteration - 1)
            print(
                f"iteration {iteration + 1}/{s.iterations} (beta {beta:.2f}): {s.episodes} episodes, rollout return "
                f"{data.returns.mean():.2f}, {len(all_observations):,} states, loss {loss:.4g} (targets' variance "
                f"{entry['target_variance']:.4g}; on the new states before the fit "
                f"{'n/a' if new_loss is None else f'{new_loss:.4g}'}"
                + (
                    ""
                    if fit.validation_loss is None
                    else f"; on {int(held_out.sum()):,} held-out states {fit.validation_loss:.4g} after "
                    f"{fit.epochs_kept} of {s.epochs} epochs"
                )
                + "); eval "
                f"{entry['mean_return']:.2f} vs {law_name} {law_returns.mean():.2f}: {versus_law.mean:+.2f} "
                f"[{versus_law.low:+.2f}, {versus_law.high:+.2f}]"
                + (" (new best)" if new_best else "")
                + f"; {wall / 60:.1f} min, about {left / 60:.1f} min left",
                flush=True,
            )
    assert statistics is not None and student is not None
    sample = np.concatenate(observations)[:: max(1, timesteps // 320)][:320]
    compute = measure_compute(student, _attached_law(law_name, env_id, kwargs), sample, s.episodes)
    teacher_per_step = teacher_seconds / max(teacher_steps, 1)
    compute_record = {
        "teacher_seconds_per_step": teacher_per_step,
        "teacher_batch": s.episodes,
        **{f"{name}_seconds_per_step": value for name, value in compute.items()},
        **{f"speedup_{name}": teacher_per_step / value for name, value in compute.items() if name != "law_single"},
        "machine": machine_description(),
    }
    log.finish(timesteps, best_iteration=best_iteration, compute=compute_record)
    save_student(run, model, env_id, law_name, statistics, timesteps, provenance, extra_files=("config.yml",))
    # The labelled states, for analysis and refits without rerunning the planner (plain arrays: no pickle).
    np.savez_compressed(
        run / DATASET_FILE,
        observations=np.concatenate(observations),
        targets=np.concatenate(targets),
        iteration=np.concatenate([np.full(len(rows), k) for k, rows in enumerate(observations)]),
        episode=np.concatenate(episode_ids),
        held_out=held_out_rows(np.concatenate(episode_ids), s.validation_every),
    )
    if best_iteration < 0:  # never above the law: best/ is the law itself (a zero action head)
        with torch.no_grad():
            for parameter in model.policy.action_net.parameters():
                parameter.zero_()
        save_student(run / "best", model, env_id, law_name, statistics, 0, provenance, whole_directory=True)
    log.write(run / "best")
    last = log.history[-1]
    print(
        f"trained dagger on {env_id} for {s.iterations} iterations ({timesteps:,} labelled states) in "
        f"{log.finished['wall_time_s'] / 60:.1f} min; best evaluation {log.best_mean:.2f} at iteration "
        f"{best_iteration} against {law_name} {law_returns.mean():.2f} (last: {last['difference_vs_law']:+.2f} "
        f"[{last['difference_vs_law_low']:+.2f}, {last['difference_vs_law_high']:+.2f}]); compute per step: "
        f"planner {teacher_per_step * 1e3:.1f} ms (batch {s.episodes}), student {compute['student_single'] * 1e6:.0f} "
        f"us alone ({compute_record['speedup_student_single']:.0f}x), {compute['student_batched'] * 1e6:.0f} us "
        f"batched ({compute_record['speedup_student_batched']:.0f}x), its network {compute['network_single'] * 1e6:.0f}"
        f" us ({compute_record['speedup_network_single']:.0f}x); run directory {run}",
        flush=True,
    )
    return run
