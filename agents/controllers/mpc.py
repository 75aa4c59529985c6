"""``mpc``: a sampling-based model-predictive reference controller.

It plans with the project's own batched task as its model, so there is no second copy of the
dynamics. At every control step, for each environment of the batch it controls:

1. it snapshots the true state of the environment's cluster (:meth:`DampingTask.snapshot`) and
   restores it into ``samples`` slots of a planning task built from the same cluster and
   settings;
2. it rolls out ``samples`` candidate thrust sequences over ``horizon`` control steps. The
   first candidate is the warm-started nominal plan, the previous plan shifted by one step. The
   others add Gaussian noise of standard deviation ``noise`` (in normalised thrust) at
   ``knots`` knots, interpolated linearly over the horizon. With a ``prior`` (a scripted
   baseline), a plan is a residual on top of that controller's closed-loop action at every
   planned step, so the zero plan *is* the baseline: the planner then improves on the baseline
   over its horizon (policy rollout, in Bertsekas's sense), where open-loop sampling from zero
   thrust needs long horizons to find any damping action at all;
3. it scores each candidate with the task's own reward, summed with ``discount``, plus
   ``terminal_weight`` times the vibration term of the last planned step: a cost-to-go for
   the vibration left at the horizon, which would otherwise keep paying for ``terminal_weight``
   more steps at least;
4. it keeps the best candidate (predictive sampling, as in MuJoCo MPC, ``temperature = 0``), or
   the MPPI average weighted by ``exp(-cost / (temperature * spread))``, where ``spread`` is
   the standard deviation of the costs. This repeats for ``iterations`` refinements around the
   new nominal, with the noise halved each time;
5. it applies the plan's first action, and shifts the plan. Without ``warm_start`` it forgets
   the plan instead, and the next step plans again from the zero plan (the prior alone): each
   action is then a function of the state and the step's samples, with no plan carried between
   steps.

With a thrust delay the planner's rollouts carry the delay line (the commands in flight) as the
env does. Its prior acts on the state it is given, without the scripted laws' prediction over the
delay (:class:`agents.controllers.base.DelayPredictor`), unless ``predicting_prior`` is set: that
runs the model over the delay again at every planned step, 3.3 times the planning time per step on
``TetherDelayedTetrahedron-v0``, where the predicting law alone is better than the planner around
the law that does not predict.

It is **privileged**: it reads the environment's true state and model, not the observation. It
is the "best achievable" anchor of the benchmark, not a deployable controller. Its settings are
tuned per id in the package's ``hyperparams/mpc.yml``.

With tethers that have mass, the snapshot, the planning rollouts and the reward include the
beads: the planner steps them as the env does. Its cost grows with them (0.33 s per env and
control step on the beaded tetrahedron at 8 segments, against 0.016 s without beads), and the
per-id settings were tuned without beads. ``seconds_per_step`` reports its compute per
environment and control step.
"""

from __future__ import annotations

import dataclasses
import time
import zlib
from pathlib import Path
from typing import Any

import numpy as np

from tether_gym.envs.contract import Scalar
from tether_gym.envs.task import DampingTask, TaskState
from tether_gym.limits import is_whole_number

from ..common.data import HYPERPARAMS_DIR
from ..common.settings import load_settings

__all__ = ["MPC_SETTINGS_FILE", "MPCController", "MPCSettings", "load_mpc_settings"]

#: Per-id settings of the ``mpc`` controller (plain YAML, nothing evaluated).
MPC_SETTINGS_FILE = HYPERPARAMS_DIR / "mpc.yml"


@dataclasses.dataclass(frozen=True)
class MPCSettings:
    """Settings of :class:`MPCController` (see the module docstring).

    Attributes:
        samples: candidate thrust sequences per environment and iteration, >= 2 (the first is
            the nominal plan).
        horizon: control steps planned ahead (the prediction horizon), >= 1.
        control_horizon: the first steps of the horizon whose commands are planned, in
            0..horizon (0: all of them). Past it the plan is zero: with a ``prior`` the rollout
            then simply continues under that controller, which estimates the cost-to-go of each
            candidate by the prior's own closed loop (the rollout algorithm).
        knots: knots of the perturbations, interpolated linearly over the control horizon, in
            1..control horizon.
        noise: standard deviation of the knot perturbations, in normalised thrust (actions
            lie in [-1, 1]).
        iterations: refinements per control step, each around the last one's plan.
        temperature: MPPI temperature, in units of the standard deviation of the candidates'
            costs; 0 keeps the best candidate (predictive sampling).
        discount: weight of step h's reward is ``discount**h``.
        terminal_weight: weight of the vibration term of the horizon's last step, in steps.
        prior: a scripted baseline (``agents.controllers.registry.BASELINES``) whose closed-loop action the
            plans are residuals on, or ``"none"``: plans are the actions themselves.
        predicting_prior: the prior acts on the state its command meets over a thrust delay
            (:class:`agents.controllers.base.DelayPredictor`; the env must observe its commands in
            flight) instead of on the state it is given; 3.3 times the planning time per step on
            the delayed tetrahedron.
        warm_start: start each step's search from the previous plan, shifted (the default); false:
            from the zero plan, so that no plan is carried from step to step (a teacher whose
            action a memoryless student can learn from the state).
        seed: seed of the controller's own noise.
    """

    samples: int = 32
    horizon: int = 10
    control_horizon: int = 0
    knots: int = 3
    noise: float = 0.4
    iterations: int = 1
    temperature: float = 0.0
    discount: float = 1.0
    terminal_weight: float = 0.0
    prior: str = "none"
    predicting_prior: bool = False
    warm_start: bool = True
    seed: int = 0

    def __post_init__(self) -> None:
        whole = {
            "samples": (2, 100_000),
            "horizon": (1, 10_000),
            "control_horizon": (0, self.horizon),
            "knots": (1, self.control_horizon or self.horizon),
            "iterations": (1, 100),
            "seed": (0, 2**63 - 1),
        }
        for name, (low, high) in whole.items():
            value = getattr(self, name)
            if not is_whole_number(value) or not low <= value <= high:
                raise ValueError(f"mpc setting {name} must be a whole number in {low}..{high}; got {value!r}")
        from .registry import BASELINES

        if self.prior != "none" and self.prior not in BASELINES:
            raise ValueError(f"mpc setting prior must be 'none' or one of {sorted(BASELINES)}; got {self.prior!r}")
        for name in ("predicting_prior", "warm_start"):
            if not isinstance(getattr(self, name), bool):
                raise ValueError(f"mpc setting {name} must be true or false; got {getattr(self, name)!r}")
        if self.predicting_prior and self.prior == "none":
            raise ValueError("mpc setting predicting_prior needs a prior to predict with; name one, or drop it")
        real = {"noise": (0.0, 10.0), "temperature": (0.0, 1e6), "discount": (0.0, 1.0), "terminal_weight": (0.0, 1e6)}
        for name, (low, high) in real.items():
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not low <= value <= high:
                raise ValueError(f"mpc setting {name} must be a number in [{low}, {high}]; got {value!r}")


def load_mpc_settings(env_id: str | None, path: str | Path | None = None, **overrides: Any) -> MPCSettings:
    """The ``mpc`` settings of ``env_id``: its entry of the package's ``hyperparams/mpc.yml`` (or of
    ``path``), else the file's ``default`` entry, with keyword ``overrides`` on top."""
    file = Path(path) if path is not None else MPC_SETTINGS_FILE
    return load_settings(MPCSettings, file, env_id, "mpc", overrides)


class MPCController:
    """Sampling-based model-predictive control of every environment of a (vector) env.

    Args:
        env: the env it controls: a tether-gym single or vector env (wrapped or not). It reads
            the true state of ``env.unwrapped.task``. The evaluation calls :meth:`attach` with
            the env it actually steps.
        settings: the :class:`MPCSettings` (default: those of the env's id).

    ``predict(observation)`` takes the observation only to check the batch size; the actions
    come from the plans. An environment whose episode has just started (time 0) starts from a
    zero plan.
    """

    name = "mpc"
    #: It reads the true state: a reference, not a deployable controller.
    privileged = True

    def __init__(self, env: Any, settings: MPCSettings | None = None) -> None:
        env_id = getattr(getattr(env, "spec", None), "id", None)
        self.settings = settings if settings is not None else load_mpc_settings(env_id)
        self.compute_seconds = 0.0
        self.env_steps = 0
        self.attach(env)

    def attach(self, env: Any) -> None:
        """Control ``env`` from now on: build the planning task for its batch and clear the plans."""
        task = getattr(getattr(env, "unwrapped", env), "task", None)
        if not isinstance(task, DampingTask):
            raise TypeError(f"mpc controls tether-gym envs (with a DampingTask); got {type(env).__name__}")
        s = self.settings
        self.task = task
        self.prior = None
        if s.prior != "none":
            from .registry import make_baseline

            # By default the prior acts on the state it is given: the planner simulates the delay line
            # itself, and a predicting prior runs the model over the delay again at every planned step.
            self.prior = make_baseline(s.prior, env, predict_delay=s.predicting_prior)
        self.batch = task.num_clusters
        self.action_size = task.action_size
        self.planner = DampingTask(task.cluster, self.batch * s.samples, task.config)
        self.rows = np.repeat(np.arange(self.batch), s.samples)
        self.plan = np.zeros((self.batch, s.horizon, self.action_size))
        # One generator per environment, reseeded at each episode start from the episode's initial
        # state: an episode gets the same plans whatever the batch size and its slot in it.
        self.rngs = [np.random.default_rng(s.seed) for _ in range(self.batch)]
        # Planning rollouts of tasks with disturbances or noise draw from the controller's own
        # generators: the plan is scored on one sample of them.
        self.planner_rngs = [np.random.default_rng([s.seed, k]) for k in range(self.planner.num_clusters)]
        planned = s.control_horizon or s.horizon
        knot_times = np.linspace(0.0, planned - 1, s.knots) if s.knots > 1 else np.zeros(1)
        steps = np.arange(s.horizon, dtype=float)
        # (horizon, knots) linear interpolation weights over the control horizon (a single knot
        # holds its value), zero past it.
        self.interpolation = (
            np.stack([np.interp(steps, knot_times, np.eye(s.knots)[k]) for k in range(s.knots)], axis=1)
            if s.knots > 1
            else np.ones((s.horizon, 1))
        )
        self.interpolation[planned:] = 0.0
        self.planned_steps = planned
        self.weights = s.discount**steps

    @property
    def seconds_per_step(self) -> float:
        """Planning time per environment and control step so far, s."""
        return self.compute_seconds / max(self.env_steps, 1)

    @property
    def saturation_fraction(self) -> float:
        """Always 0: plans are clipped into [-1, 1] before they are scored."""
        return 0.0

    def reset_statistics(self) -> None:
        """Restart the compute-time count."""
        self.compute_seconds = 0.0
        self.env_steps = 0

    def predict(
        self,
        observation: np.ndarray,
        state: Any = None,
        episode_start: np.ndarray | None = None,
        deterministic: bool = True,
    ) -> tuple[np.ndarray, Any]:
        """The first action of each environment's plan, (E, action_size) float32 (or
        (action_size,) for a single observation), after planning from the true states."""
        obs = np.asarray(observation)
        single = obs.ndim == 1
        rows = 1 if single else obs.shape[0]
        if rows != self.batch:
            raise ValueError(
                f"mpc controls {self.batch} environment(s) but got {rows} observation(s); attach it to the env "
                "that is being stepped (MPCController.attach)"
            )
        start = time.perf_counter()
        fresh = self.task.sim.time == 0.0
        self.plan[fresh] = 0.0
        for e in np.flatnonzero(fresh):
            self.rngs[e] = np.random.default_rng([self.settings.seed, self._episode_key(e)])
        snapshot = self.task.snapshot().select(self.rows)
        noise = self.settings.noise
        for _ in range(self.settings.iterations):
            candidates = self._candidates(noise)
            costs = self._rollout(snapshot, candidates)
            self.plan = self._update(candidates, costs)
            noise *= 0.5
        action = self._actions(self.task, self.plan[:, 0]).astype(np.float32)
        if self.settings.warm_start:
            # Shift: the last planned command is held for the new last planned step.
            self.plan = np.concatenate([self.plan[:, 1:], self.plan[:, -1:]], axis=1)
            self.plan[:, self.planned_steps :] = 0.0
        else:
            self.plan[:] = 0.0
        self.compute_seconds += time.perf_counter() - start
        self.env_steps += self.batch
        return (action[0] if single else action), None

    def _candidates(self, noise: float) -> np.ndarray:
        """(E, samples, horizon, A) thrust sequences in [-1, 1]; sample 0 is the nominal plan."""
        s = self.settings
        knots = np.stack([rng.standard_normal((s.samples, s.knots, self.action_size)) for rng in self.rngs]) * noise
        knots[:, 0] = 0.0
        perturbation = np.einsum("hk,eska->esha", self.interpolation, knots)
        # Residuals on a prior may reach +-2 (a full command against the prior's); actions +-1.
        bound = 1.0 if self.prior is None else 2.0
        return np.clip(self.plan[:, None] + perturbation, -bound, bound)

    def _episode_key(self, index: int) -> int:
        """A 32-bit key of environment ``index``'s current (initial) state."""
        sim = self.task.sim
        return zlib.crc32(sim.positions[index].tobytes() + sim.velocities[index].tobytes())

    def _actions(self, task: DampingTask, plan_step: np.ndarray) -> np.ndarray:
        """The commands of one planned step, (rows, A): the plan itself, or the prior's
        closed-loop action on ``task``'s noise-free observation plus the plan's residual."""
        if self.prior is None:
            return plan_step
        prior, _ = self.prior.predict(task.observation.astype(np.float32))
        return np.clip(prior + plan_step, -1.0, 1.0)

    def _rollout(self, snapshot: TaskState, candidates: np.ndarray) -> np.ndarray:
        """(E, samples) costs, minus the discounted sum of the task's rewards of each candidate."""
        planner = self.planner
        if planner.difficulty != self.task.difficulty:
            planner.set_difficulty(self.task.difficulty)
        planner.restore(snapshot)
        flat = candidates.reshape(self.batch * self.settings.samples, self.settings.horizon, self.action_size)
        total = np.zeros(flat.shape[0])
        rngs = self.planner_rngs if planner.perturbed else None
        for h in range(self.settings.horizon):
            # The env receives float32 actions: rounding the planned ones alike keeps the
            # planner's rollouts bit-identical to what the env would do with them.
            actions = self._actions(planner, flat[:, h]).astype(np.float32).astype(np.float64)
            planner.step(actions, rngs=rngs)
            total += self.weights[h] * planner.scalars[:, Scalar.REWARD]
        total += self.settings.terminal_weight * self.weights[-1] * planner.scalars[:, Scalar.REWARD_VIBRATION]
        return -total.reshape(self.batch, self.settings.samples)

    def _update(self, candidates: np.ndarray, costs: np.ndarray) -> np.ndarray:
        """The new nominal plan of each environment: the best candidate, or the MPPI average."""
        if self.settings.temperature == 0.0:
            return candidates[np.arange(self.batch), np.argmin(costs, axis=1)]
        spread = costs.std(axis=1, keepdims=True)
        scale = self.settings.temperature * np.where(spread > 0.0, spread, 1.0)
        logits = -(costs - costs.min(axis=1, keepdims=True)) / scale
        weights = np.exp(logits)
        weights /= weights.sum(axis=1, keepdims=True)
        return np.einsum("es,esha->eha", weights, candidates)

    def __repr__(self) -> str:
        s = self.settings
        return (
            f"MPCController(samples={s.samples}, horizon={s.horizon}, knots={s.knots}, noise={s.noise}, "
            f"iterations={s.iterations}, temperature={s.temperature}, prior={s.prior}, batch={self.batch})"
        )
