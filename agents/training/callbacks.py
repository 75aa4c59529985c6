"""The SB3 callbacks of the training loop (:mod:`agents.training.sb3`; :mod:`agents.train_rllib`
saves through :class:`SafePolicySaver` too): a critic-only burn-in (:class:`CriticWarmup`), saving
policies in the safe format (:class:`SafePolicySaver`), and a difficulty curriculum
(:class:`DifficultyCurriculum`). The evaluation on fixed seeds is :mod:`agents.training.selection`'s."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

from tether_gym._optional import needs_extra

from ..common.files import atomic_directory
from ..policies.format import save_policy
from ..policies.layout import POLICY_FILES
from ..policies.spec import PolicySpec

with needs_extra("train", "training"):
    from stable_baselines3.common.base_class import BaseAlgorithm
    from stable_baselines3.common.callbacks import BaseCallback

__all__ = ["CriticWarmup", "DifficultyCurriculum", "SafePolicySaver", "actor_parameters"]


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

    Why: a residual policy starts exactly at its baseline (:func:`agents.training.sb3.start_at_the_baseline`), and a
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
    calls (checkpoints). ``spec`` is how the policy's outputs become actions (recorded in
    ``policy.json``); ``training_state`` whether to save the optimizer state too."""

    def __init__(
        self,
        directory: Path,
        env_id: str,
        provenance: Mapping[str, Any],
        every: int | None = None,
        prefix: str = "",
        spec: PolicySpec | None = None,
        training_state: bool = True,
    ) -> None:
        super().__init__()
        self.directory, self.env_id, self.provenance = directory, env_id, dict(provenance)
        self.every, self.prefix = every, prefix
        self.spec = spec if spec is not None else PolicySpec()
        #: Whether to save the optimizer state (False where the model only carries the weights).
        self.training_state = training_state

    def _on_step(self) -> bool:
        if self.every is None:
            self._save(self.directory)
        elif self.n_calls % self.every == 0:
            self._save(self.directory / f"{self.prefix}_{self.num_timesteps}_steps")
        return True

    def _save(self, directory: Path) -> None:
        # The whole save lands at once (a new directory renamed into place): an interrupt leaves the
        # earlier best/ whole, verifying against its manifest, never half-replaced. The policy files
        # of the earlier save are replaced; anything else there (best/evaluations.json) is carried over.
        directory.parent.mkdir(parents=True, exist_ok=True)
        with atomic_directory(directory, ours=POLICY_FILES) as staging:
            save_policy(
                staging,
                self.model,
                self.model.get_vec_normalize_env(),
                self.env_id,
                self.provenance,
                training_state=self.training_state,
                spec=self.spec,
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
