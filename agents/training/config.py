"""What one SB3 training run is asked to do: :class:`TrainConfig`, the arguments of
``python -m agents.train`` (and of :func:`agents.training.sb3.train`) as one frozen record,
checked when it is made, before any file is read or env built."""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from tether_gym.registration import DEFAULT_ENV_ID, ENV_IDS

from ..common.checks import MAX_NUM_ENVS, MAX_TRAINING_SEED, check_int
from ..policies.format import ALGORITHMS

__all__ = ["TrainConfig"]


@dataclasses.dataclass(frozen=True)
class TrainConfig:
    """One SB3 training run (see :mod:`agents.train` for what it writes). Every field is checked
    when the config is made: a ``ValueError`` names the field and the accepted values."""

    algo: str = "ppo"
    """The SB3 algorithm: ``ppo``, ``sac`` or ``td3`` (its hyperparameters: ``hyperparams/<algo>.yml``)."""

    env_id: str = DEFAULT_ENV_ID
    """The tether-gym id trained on."""

    seed: int = 0
    """The training seed, >= 0: the env's, the model's, and the run directory's ``<algo>_seed<seed>``."""

    out: str | Path = "runs"
    """The folder that receives the run directory ``<out>/<env>/<algo>_seed<seed>/``."""

    timesteps: int | None = None
    """Env steps to train (>= 1, over all envs), in place of the file's ``n_timesteps``; rounded up
    to whole rollouts (:func:`agents.training.sb3.rollout_steps`). None: the file's."""

    num_envs: int | None = None
    """Parallel envs (>= 1), in place of the file's ``n_envs``. None: the file's."""

    hyperparams_file: str | Path | None = None
    """The hyperparameter file (or a run's ``config.yml``) in place of the package's
    ``hyperparams/<algo>.yml``."""

    overrides: Mapping[str, Any] | None = dataclasses.field(default=None, hash=False)
    """Hyperparameters that replace the file's entries (checked like the file). None: none."""

    resume: str | Path | None = None
    """A checkpoint directory, ``best/`` or run directory to continue from (or, with
    :attr:`trust_pickle`, a pickle-based SB3 ``.zip``). None: a new model."""

    eval_freq: int = 50_000
    """Env steps (over all envs, >= 1) between evaluations on the evaluation seeds."""

    eval_episodes: int = 32
    """Episodes (>= 2, for the paired difference's interval) of each evaluation, one per evaluation seed."""

    checkpoint_freq: int = 250_000
    """Env steps (over all envs, >= 1) between checkpoints in ``checkpoints/``."""

    progress_bar: bool = True
    """Whether to show SB3's progress bar (and print each evaluation)."""

    verbose: int = 0
    """SB3's verbosity (>= 0)."""

    command: str | None = None
    """The command line, recorded in ``config.yml`` (None when called from Python)."""

    force: bool = False
    """Whether to replace an earlier run in the same run directory (TensorBoard logs are kept)."""

    trust_pickle: bool = False
    """Whether :attr:`resume` may be a pickle-based SB3 ``.zip`` (unpickling runs any code a
    crafted file contains)."""

    def __post_init__(self) -> None:
        if self.algo not in ALGORITHMS:
            raise ValueError(f"unknown algorithm {self.algo!r}; choose one of {sorted(ALGORITHMS)}")
        if self.env_id not in ENV_IDS:
            raise ValueError(f"unknown env id {self.env_id!r}; tether-gym ids are {list(ENV_IDS)}")
        # As Python ints: a numpy integer passes the check, and config.yml records these values.
        # Two evaluation episodes at least: each evaluation's paired difference has a t interval.
        minimums = {"seed": 0, "eval_freq": 1, "eval_episodes": 2, "checkpoint_freq": 1, "verbose": 0}
        for name, minimum in minimums.items():
            maximum = {"seed": MAX_TRAINING_SEED, "eval_episodes": MAX_NUM_ENVS}.get(name)
            object.__setattr__(self, name, check_int(name, getattr(self, name), minimum, maximum))
        for name in ("timesteps", "num_envs"):
            if getattr(self, name) is not None:
                object.__setattr__(
                    self, name, check_int(name, getattr(self, name), 1, MAX_NUM_ENVS if name == "num_envs" else None)
                )
