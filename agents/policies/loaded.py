"""Controllers by name: the scripted baselines, and trained policies loaded from disk.

Trained policies are read from the safe format of :mod:`agents.policies.format` (JSON metadata,
safetensors weights, JSON normalisation statistics), which cannot run code on load. The
pickle-based SB3 files (``model.zip`` + ``vecnormalize.pkl``) are loaded only with
``trust_pickle=True`` (see :mod:`agents.policies.pickled`).

A trained policy records the id it was trained on (``policy.json``'s ``env_id``), and runs only
on envs of that id: ids of the same observation shape (the triangle and the spinning triangle)
are different tasks. :meth:`TrainedPolicy.attach` refuses another id with :class:`OtherIdError`
unless the user opts in (``allow_other_id=True``; ``--allow-other-id`` on the command line),
and then warns (:class:`OtherIdWarning`).
"""

from __future__ import annotations

import warnings
from pathlib import Path
from typing import Any

import gymnasium
import numpy as np

from ..common.commands import program
from ..common.data import MODELS_DIR
from ..controllers.registry import BASELINES, make_baseline
from .format import is_policy_dir, load_policy
from .layout import MANIFEST_FILE, METADATA_FILE
from .pickled import is_pickle_model, load_pickled_model, refuse_untrusted
from .spec import PolicySpec

__all__ = [
    "MODELS_DIR",
    "OtherIdError",
    "OtherIdWarning",
    "TrainedPolicy",
    "actor_mean_actions",
    "check_actions_fit",
    "env_action_space",
    "env_id_of",
    "gaussian_actor",
    "is_shipped",
    "make_controller",
    "shipped_models",
]


def is_shipped(directory: str | Path) -> bool:
    """Whether ``directory`` is inside the repository's :data:`MODELS_DIR` (then its manifest is
    required and verified on load)."""
    try:
        Path(directory).resolve().relative_to(MODELS_DIR)
    except ValueError:
        return False
    return True


class OtherIdError(ValueError):
    """A trained policy attached to an env of another id than the one it was trained on (without
    the opt-in ``allow_other_id``): ids of the same observation shape differ in masses, cables,
    frames and disturbances, so the policy would run, but on a task it never saw.

    Attributes: ``trained`` is the policy's id, ``running`` the env's.
    """

    def __init__(self, message: str, trained: str, running: str) -> None:
        super().__init__(message)
        self.trained, self.running = trained, running


class OtherIdWarning(UserWarning):
    """A trained policy runs on another id than its own (``allow_other_id=True``), or records no
    id at all, so that only its observation shape could be checked."""


def env_id_of(env: Any) -> str | None:
    """The registered id of ``env`` (a Gymnasium env or vector env, possibly wrapped, or the
    PettingZoo env of :mod:`tether_gym.multiagent`), or None when it has none (a hand-built env)."""
    for candidate in (env, getattr(env, "unwrapped", None)):
        spec_id = getattr(getattr(candidate, "spec", None), "id", None)
        if isinstance(spec_id, str):
            return spec_id
    own = getattr(env, "env_id", None)
    return own if isinstance(own, str) else None


def env_action_space(env: Any) -> gymnasium.spaces.Box | None:
    """The action space of one of ``env``'s clusters (a Gymnasium env or vector env, possibly
    wrapped, or an SB3 vector env), or None when it has no ``Box`` action space."""
    for name in ("single_action_space", "action_space"):
        space = getattr(env, name, None)
        if isinstance(space, gymnasium.spaces.Box):
            return space
    return None


def check_actions_fit(
    action_space: gymnasium.spaces.Box,
    env: Any,
    label: str,
    decentralised: bool = False,
    trained_on: str | None = None,
    entry: str = "policy.json: action_space",
) -> None:
    """Refuse ``env`` (a ValueError naming ``label``, the policy's file or directory) when a
    policy with ``action_space`` does not fit it: another number of actions, or other bounds (a
    policy's actions are clipped or rescaled into its own bounds, so other bounds would be
    clipped again by the env, unseen by the saturation count). A ``decentralised`` policy acts
    per satellite, its actions repeated over the env's satellites. An env whose action space is
    not a ``Box`` (nothing tether-gym makes) is not checked; ``trained_on`` (the policy's id) and
    ``entry`` (where its action space is recorded) are for the message."""
    space = env_action_space(env)
    if space is None:
        return
    low, high = np.ravel(action_space.low).astype(np.float64), np.ravel(action_space.high).astype(np.float64)
    env_low, env_high = np.ravel(space.low).astype(np.float64), np.ravel(space.high).astype(np.float64)
    repeats = 1
    if decentralised and low.size and env_low.size % low.size == 0:
        repeats = env_low.size // low.size  # one agent per satellite, each with the policy's actions
    name = env_id_of(env) or "the env"
    if low.size * repeats != env_low.size:
        per = " per satellite" if decentralised else ""
        raise ValueError(
            f"{label} acts with {low.size} actions{per} ({entry}.shape {list(action_space.shape)}), "
            f"but {name} takes {env_low.size}: pass a model trained on this id"
            + (f" (it was trained on {trained_on})" if trained_on else "")
        )
    if not (np.array_equal(np.tile(low, repeats), env_low) and np.array_equal(np.tile(high, repeats), env_high)):
        raise ValueError(
            f"{label} acts within bounds [{low.min():g}, {high.max():g}] ({entry}.low/high), "
            f"but {name} takes actions in [{env_low.min():g}, {env_high.max():g}]: its actions would be clipped "
            "again, unseen; pass a model trained on this id, or one saved with the env's action space"
        )


class TrainedPolicy:
    """A trained SB3 policy with its ``VecNormalize`` observation statistics, as a policy with the
    baselines' interface (``predict(observation, deterministic=True)``, for one observation or a
    batch).

    Args:
        path: a policy directory in the safe format (a run directory written by
            ``agents.train``, its ``best/``, a checkpoint directory, or a shipped model), or its
            ``policy.json``. A pickle-based SB3 ``.zip`` (or a directory holding ``model.zip`` and
            ``vecnormalize.pkl``) is loaded only with ``trust_pickle``.
        best: load the run directory's ``best/`` policy instead of the final one.
        name: the name shown in tables (default: the algorithm, e.g. ``"ppo"``).
        trust_pickle: allow loading pickle-based SB3 files, which can run arbitrary code; a
            :class:`agents.policies.pickled.PickleTrustWarning` is emitted when it happens.
        allow_other_id: let :meth:`attach` put the policy on an env of another id than the one
            it was trained on (``env_id``), with an :class:`OtherIdWarning`; without it that is an
            :class:`OtherIdError`.

    Raises:
        FileNotFoundError: nothing loadable at ``path``.
        agents.policies.pickled.PickleNotTrustedError: a pickle-based model without ``trust_pickle``.
        agents.policies.layout.PolicyFormatError: a malformed policy directory, or (ChecksumError) a
            file that does not match its manifest.
    """

    def __init__(
        self,
        path: str | Path,
        best: bool = False,
        name: str | None = None,
        trust_pickle: bool = False,
        allow_other_id: bool = False,
    ) -> None:
        self.allow_other_id = bool(allow_other_id)
        path = Path(path)
        if path.is_file() and is_policy_dir(path.parent) and path.suffix not in (".zip", ".pkl"):
            path = path.parent  # policy.json, policy.safetensors, ...: their directory
        if best and path.is_dir() and not (path / "best").is_dir():
            raise FileNotFoundError(f"{path} has no best/ directory: pass best=False for its final policy")
        directory = path / "best" if best and path.is_dir() else path
        if is_policy_dir(directory):
            loaded = load_policy(directory, require_manifest=is_shipped(directory))
            self.policy = loaded.policy
            self.normalizer: Any = loaded.normalizer
            self.algo: str = loaded.metadata["algo"]
            self.env_id: str | None = loaded.metadata["env_id"]
            self.metadata: dict[str, Any] = loaded.metadata
            self.path = directory
        elif is_pickle_model(path):
            if not trust_pickle:
                refuse_untrusted(path)
            model, normalizer, config, files = load_pickled_model(path, trust_pickle=True, best=best)
            self.policy = model.policy
            self.normalizer = normalizer
            self.algo = config["algo"]
            self.env_id = config.get("env_id")
            self.metadata = {"algo": self.algo, "env_id": self.env_id, "num_timesteps": int(model.num_timesteps)}
            self.path = files[0]
        elif path.exists():
            raise FileNotFoundError(
                f"{directory} holds no trained policy: pass a directory written by {program('train')} or "
                f"{program('convert')} "
                f"(it has {METADATA_FILE})"
            )
        else:
            raise FileNotFoundError(f"no trained policy at {path}: no such file or directory")
        self._adopt(name)

    def _adopt(self, name: str | None) -> None:
        self.name = name or self.algo
        # The other ids this policy was warned about: once per id, not at every attach.
        self._other_ids_warned: set[str | None] = set()
        self.observation_shape: tuple[int, ...] = tuple(self.policy.observation_space.shape)
        self.observation_size = int(np.prod(self.observation_shape))
        #: How the network's outputs become actions: its residual baseline and multi-agent options.
        self.spec = PolicySpec.from_metadata(self.metadata)
        #: The baseline whose actions the policy corrects (agents.controllers.residual), or None.
        self.residual_on: str | None = self.spec.residual_on
        self.baseline: Any = None
        #: A shared decentralised policy's multi-agent options (agents.controllers.decentralised), or None.
        self.multiagent: dict[str, Any] | None = self.spec.multiagent
        self.observer: Any = None
        #: Whether deterministic actions come from :func:`actor_mean_actions` rather than SB3's predict.
        self.direct_actions = gaussian_actor(self.policy)

    @classmethod
    def from_parts(
        cls,
        policy: Any,
        normalizer: Any,
        env_id: str,
        algo: str,
        spec: PolicySpec | None = None,
        name: str | None = None,
    ) -> TrainedPolicy:
        """A TrainedPolicy around an in-memory SB3 ``policy`` and its observation ``normalizer``
        (a ``VecNormalize`` or None), e.g. the model being trained; nothing is copied, so it acts
        with the weights and statistics they hold when ``predict`` is called. ``spec`` says how
        its outputs become actions (default: a centralised policy whose outputs are its actions)."""
        spec = spec or PolicySpec()
        self = cls.__new__(cls)
        self.allow_other_id = False
        self.policy, self.normalizer, self.algo, self.env_id = policy, normalizer, algo, env_id
        self.metadata = {"algo": algo, "env_id": env_id, "residual_on": spec.residual_on, "multiagent": spec.multiagent}
        self.path = Path(f"<in-memory {algo} policy>")
        self._adopt(name)
        return self

    def attach(self, env: Any, allow_other_id: bool | None = None) -> None:
        """Check that ``env`` (a tether-gym env or vector env) is of the id the policy was trained
        on, then build the baseline a residual policy adds its corrections to, or the local
        observer of a decentralised policy (:class:`agents.controllers.decentralised.LocalObserver`), from it.

        Args:
            env: the env the policy will act in.
            allow_other_id: run on another id than the policy's own, with an
                :class:`OtherIdWarning` (default: the ``allow_other_id`` the policy was loaded
                with).

        Raises:
            OtherIdError: ``env`` is of another id, without ``allow_other_id``.
        """
        self.check_env_id(env, self.allow_other_id if allow_other_id is None else allow_other_id)
        self.check_env_actions(env)
        if self.multiagent is not None:
            from ..controllers.decentralised import LocalObserver

            try:
                self.observer = LocalObserver(env, self.multiagent)
            except ValueError as error:
                # The options come from the policy's file: say which file and entry.
                raise ValueError(f"{self.path}: {METADATA_FILE}: multiagent: {error}") from error
            if self.observer.observation_size != self.observation_size:
                raise ValueError(
                    f"{self.path} takes local observations of size {self.observation_size}, but the agents of "
                    f"this env have {self.observer.observation_size}: pass a model trained on this id"
                )
        if self.residual_on is not None:
            from ..controllers.registry import make_baseline

            self.baseline = make_baseline(self.residual_on, env)

    def check_env_actions(self, env: Any) -> None:
        """Refuse ``env`` when the policy's actions do not fit it (:func:`check_actions_fit`)."""
        entry = f"{METADATA_FILE}: action_space" if is_policy_dir(self.path) else "its action_space"
        check_actions_fit(
            self.policy.action_space, env, str(self.path), self.multiagent is not None, self.env_id, entry=entry
        )

    def check_env_id(self, env: Any, allow_other_id: bool = False) -> None:
        """Refuse ``env`` when its id is not the one the policy was trained on, unless
        ``allow_other_id`` (then warn). A policy that records no id (an old or hand-made file)
        and an env without one are let through with a warning: only shapes can be compared."""
        trained, running = self.env_id, env_id_of(env)
        if trained is not None and trained == running:
            return
        if trained is not None and running is not None and not allow_other_id:
            raise OtherIdError(
                f"{self.path} was trained on {trained}, not {running}: pass a model trained on {running}, or opt in "
                f"to run it on another id with --allow-other-id (allow_other_id=True in Python)",
                trained,
                running,
            )
        if running in self._other_ids_warned:
            return  # said once for this id: not again at every attach
        self._other_ids_warned.add(running)
        if trained is None or running is None:
            missing = f"{self.path} records no env id" if trained is None else "the env has no registered id"
            message = (
                f"{missing}: cannot check that the policy runs on the id it was trained on; only its observation "
                "shape is checked"
            )
        else:
            message = (
                f"{self.path} was trained on {trained} and runs on {running} (allow_other_id): its results there are "
                "not those of a policy trained on that id"
            )
        warnings.warn(message, OtherIdWarning, stacklevel=3)

    @property
    def saturation_fraction(self) -> float:
        """Always 0: the policy's actions are squashed or clipped into [-1, 1] by SB3 itself."""
        return 0.0

    def reset_statistics(self) -> None:
        """Nothing to reset (for the baselines' interface)."""

    def predict(
        self,
        observation: np.ndarray,
        state: Any = None,
        episode_start: np.ndarray | None = None,
        deterministic: bool = True,
    ) -> tuple[np.ndarray, Any]:
        """The policy's ``predict`` on the normalised observation: ``(actions, state)``.

        ``observation`` is (obs_dim,) or (N, obs_dim), in the env's units; actions are
        (act_dim,) or (N, act_dim), in [-1, 1]. A decentralised policy acts on the local
        observations of the env it is attached to, one agent per row, and returns the joint
        actions."""
        if self.multiagent is not None:
            return self._predict_decentralised(observation, deterministic), None
        obs = np.asarray(observation, dtype=np.float32)
        if obs.shape[-1:] != (self.observation_size,) or obs.ndim not in (1, 2):
            raise ValueError(
                f"observation must have shape ({self.observation_size},) or (N, {self.observation_size}) "
                f"for this model; got {obs.shape}"
            )
        if not np.all(np.isfinite(obs)):
            raise ValueError("observation has NaN or infinite entries: the policy's actions would be garbage")
        raw = obs
        if self.normalizer is not None:
            obs = self.normalizer.normalize_obs(obs).astype(np.float32)
        if deterministic and state is None and self.direct_actions:
            actions = actor_mean_actions(self.policy, obs)
        else:
            actions, state = self.policy.predict(
                obs, state=state, episode_start=episode_start, deterministic=deterministic
            )
        if self.residual_on is None:
            return actions, state
        if self.baseline is None:
            raise RuntimeError(
                f"{self.path} is a residual policy on {self.residual_on!r}: attach(env) it to a tether-gym env "
                "first (make_controller does)"
            )
        from ..controllers.residual import residual_actions

        return residual_actions(self.baseline, raw, actions), state

    def act_local(self, local: np.ndarray, deterministic: bool = True) -> np.ndarray:
        """(..., 3) commands of a decentralised policy from (..., size) local observations (of
        the multi-agent env, or :class:`agents.controllers.decentralised.LocalObserver`)."""
        obs = np.asarray(local, dtype=np.float32)
        rows = obs.reshape(-1, obs.shape[-1])
        if self.normalizer is not None:
            rows = self.normalizer.normalize_obs(rows).astype(np.float32)
        actions, _ = self.policy.predict(rows, deterministic=deterministic)
        return np.asarray(actions, dtype=np.float32).reshape(obs.shape[:-1] + (3,))

    def _predict_decentralised(self, observation: np.ndarray, deterministic: bool) -> np.ndarray:
        if self.observer is None:
            raise RuntimeError(
                f"{self.path} is a decentralised policy: attach(env) it to the tether-gym env whose observations "
                "it is given (make_controller and agents.evaluation.rollout.rollout do)"
            )
        local, single = self.observer.observe(observation)
        joint = self.act_local(local, deterministic).reshape(local.shape[0], -1)
        return joint[0] if single else joint


def gaussian_actor(policy: Any) -> bool:
    """Whether ``policy`` is an SB3 ``ActorCriticPolicy`` whose deterministic action is its
    diagonal Gaussian's mean, clipped to a ``Box`` (PPO's, A2C's, the DAgger student's):
    :func:`actor_mean_actions` then computes SB3's ``predict`` directly."""
    from stable_baselines3.common.distributions import DiagGaussianDistribution
    from stable_baselines3.common.policies import ActorCriticPolicy

    return (
        isinstance(policy, ActorCriticPolicy)
        and isinstance(policy.action_dist, DiagGaussianDistribution)
        and isinstance(policy.action_space, gymnasium.spaces.Box)
        and isinstance(policy.observation_space, gymnasium.spaces.Box)
        and not policy.squash_output
    )


def actor_mean_actions(policy: Any, observation: np.ndarray) -> np.ndarray:
    """``policy.predict(observation, deterministic=True)[0]`` of a :func:`gaussian_actor`, to the
    bit: the same torch operations on the same float32 rows (features, the actor's MLP, its
    action head, then the clip to the action space), without what ``predict`` does besides on
    every call (switching every module to evaluation mode, building a distribution object).
    Those cost several times the arithmetic of a small network acting on one observation.

    ``observation``: (obs_dim,) or (N, obs_dim) float32, as the network takes it (normalised);
    returns (act_dim,) or (N, act_dim)."""
    import torch
    from stable_baselines3.common.policies import BasePolicy

    if policy.training:  # dropout or batch norm would act otherwise; SB3's predict switches too
        policy.set_training_mode(False)
    # A fresh copy, as predict makes: torch's matrix kernels can round differently on rows that
    # start at another memory alignment (a row inside a larger array).
    rows = np.array(observation).reshape((-1, *policy.observation_space.shape))
    with torch.no_grad():
        features = BasePolicy.extract_features(policy, torch.as_tensor(rows), policy.pi_features_extractor)
        means = policy.action_net(policy.mlp_extractor.forward_actor(features))
    actions = np.clip(
        means.cpu().numpy().reshape((-1, *policy.action_space.shape)), policy.action_space.low, policy.action_space.high
    )
    return actions if np.ndim(observation) > 1 else actions.squeeze(axis=0)


def shipped_models(env_id: str) -> dict[str, Path]:
    """The repository's trained models for ``env_id``: name -> policy directory (those with a
    ``policy.json`` and a ``MANIFEST.sha256``)."""
    root = MODELS_DIR / env_id
    if not root.is_dir():
        return {}
    return {
        run.name: run
        for run in sorted(root.iterdir())
        if (run / METADATA_FILE).is_file() and (run / MANIFEST_FILE).is_file()
    }


def make_controller(spec: str, env: Any, trust_pickle: bool = False, allow_other_id: bool = False) -> Any:
    """A controller from a name: a baseline (``passive``, ``velocity_feedback``, ``lqr``,
    ``tension_aware``), the privileged model-predictive reference ``mpc`` (agents.controllers.mpc), a
    shipped model of the env's id (e.g. ``ppo``), or a path to a policy directory (a
    pickle-based SB3 model only with ``trust_pickle``; a policy trained on another id than
    ``env``'s only with ``allow_other_id``, which the returned policy keeps for later attaches).

    Raises ValueError naming ``spec`` when it is none of these, or when the policy's
    observations do not fit ``env``'s; :class:`OtherIdError` (a ValueError) for a policy of
    another id without ``allow_other_id``."""
    if not isinstance(spec, str) or not spec:
        raise ValueError(f"controller must be a non-empty name or path; got {spec!r}")
    if spec in BASELINES:
        return make_baseline(spec, env)
    if spec == "mpc":
        from ..controllers.mpc import MPCController

        return MPCController(env)
    env_id = getattr(getattr(env, "spec", None), "id", None)
    shipped = shipped_models(env_id) if env_id is not None else {}
    if spec in shipped:
        controller = TrainedPolicy(shipped[spec], name=spec, allow_other_id=allow_other_id)
    elif Path(spec).exists():
        if is_pickle_model(spec) and not trust_pickle:
            refuse_untrusted(spec, opt_in="--trust-pickle")
        controller = TrainedPolicy(spec, trust_pickle=trust_pickle, allow_other_id=allow_other_id)
    else:
        known = sorted(BASELINES) + ["mpc"] + sorted(shipped)
        raise ValueError(
            f"unknown controller {spec!r}: not one of {known}, and no such file or directory "
            f"(pass a baseline name, a shipped model name, or the path of a policy directory)"
        )
    controller.attach(env)
    observation_space = getattr(env, "single_observation_space", None) or getattr(env, "observation_space", None)
    shape = tuple(getattr(observation_space, "shape", ()) or ())
    if shape and shape != controller.observation_shape and controller.multiagent is None:
        raise ValueError(
            f"controller {spec!r} takes observations of shape {controller.observation_shape}, but "
            f"{env_id or 'the env'} gives {shape}: pass a model trained on this id"
            + (f" (it was trained on {controller.env_id})" if controller.env_id else "")
        )
    return controller
