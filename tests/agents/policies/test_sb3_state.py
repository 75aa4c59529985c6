"""agents.policies.sb3_state: an SB3 model's training state as data, both ways, and the only
module of agents/ that touches SB3's private attributes."""

from __future__ import annotations

import inspect
import json
import operator
import re
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import torch
from stable_baselines3 import PPO, SAC, TD3

from agents.policies import TrainedPolicy
from agents.policies.format import load_tensors, load_training_state, save_policy, tensor_bytes
from agents.policies.layout import PolicyFormatError
from agents.policies.reference import reference_observations
from agents.policies.sb3_state import TRAINING_STATE_FORMAT, capture_training_state, restore_training_state
from agents.training.sb3 import make_training_env
from tests.agents.helpers import ENV, SHORT, sb3_actions
from tether_gym.sb3 import make_sb3_vec_env

TRIANGLE = "TetherTriangle-v0"
AGENTS = Path(__file__).resolve().parents[3] / "agents"


def tiny_ppo(seed: int) -> PPO:
    venv = make_sb3_vec_env(TRIANGLE, 1, seed=seed, max_episode_steps=20)
    return PPO("MlpPolicy", venv, n_steps=16, batch_size=16, device="cpu", policy_kwargs={"net_arch": [8]}, seed=seed)


def sb3_private_names() -> set[str]:
    """The private attributes and methods of SB3's algorithms (instances and classes), as SB3
    itself has them: read from the installed version, not listed by hand."""
    venv = make_sb3_vec_env(TRIANGLE, 1, seed=0)
    names: set[str] = set()
    settings = {PPO: {"n_steps": 16, "batch_size": 16}, SAC: {"buffer_size": 10}, TD3: {"buffer_size": 10}}
    for cls, kwargs in settings.items():
        model = cls("MlpPolicy", venv, device="cpu", **kwargs)
        names |= set(vars(model)) | {name for name, _ in inspect.getmembers(cls)}
    venv.close()
    return {name for name in names if name.startswith("_") and not name.startswith(("__", "_abc"))}


def test_only_sb3_state_touches_sb3_private_attributes() -> None:
    names = sb3_private_names()
    assert {"_get_torch_save_params", "_n_updates", "_episode_num"} <= names  # what sb3_state itself uses
    alternatives = "|".join(map(re.escape, sorted(names)))
    use = re.compile(rf"\.({alternatives})\b|[\"']({alternatives})[\"']")
    found = [
        f"{path.relative_to(AGENTS.parent)}:{number}: {line.strip()}"
        for path in sorted(AGENTS.rglob("*.py"))
        if path.name != "sb3_state.py" or path.parent.name != "policies"
        for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), start=1)
        if use.search(line)
    ]
    assert not found, "SB3 private attributes used outside agents/policies/sb3_state.py:\n" + "\n".join(found)
    own = (AGENTS / "policies" / "sb3_state.py").read_text(encoding="utf-8")
    assert use.search(own), "the check finds nothing even where the private attributes are used"


def test_the_training_state_goes_back_into_a_fresh_model(tmp_path: Path) -> None:
    model = tiny_ppo(seed=0)
    model.learn(32)  # two updates: Adam has moments and a step count
    tensors, meta = capture_training_state(model)
    assert meta["format"] == TRAINING_STATE_FORMAT
    meta = json.loads(json.dumps(meta, allow_nan=False))  # plain JSON data, as training.json holds it
    updates = model.n_epochs * (model.num_timesteps // model.n_steps)  # PPO counts epochs of each rollout
    assert meta["counters"] == {"num_timesteps": model.num_timesteps, "n_updates": updates, "episode_num": 0}
    fresh = tiny_ppo(seed=1)
    restore_training_state(fresh, meta, tensors, "ppo", tmp_path / "training.json", tmp_path / "training.safetensors")
    assert fresh.num_timesteps == model.num_timesteps
    ours, theirs = fresh.policy.optimizer.state_dict(), model.policy.optimizer.state_dict()
    assert ours["param_groups"] == theirs["param_groups"]
    assert theirs["state"] and ours["state"].keys() == theirs["state"].keys()
    for index, entries in theirs["state"].items():
        for key, value in entries.items():
            assert torch.equal(torch.as_tensor(ours["state"][index][key]), torch.as_tensor(value)), (index, key)


def test_a_restored_state_saves_the_same_bytes_whatever_order_the_tensors_came_in(tmp_path: Path) -> None:
    """safetensors gives a file's tensors back in an order that changes between processes; the
    restored optimizer, and so the next checkpoint's training.json, must not depend on it."""
    model = tiny_ppo(seed=0)
    model.learn(32)
    tensors, meta = capture_training_state(model)
    meta = json.loads(json.dumps(meta, allow_nan=False))
    saved = json.dumps(meta, sort_keys=False)
    where = (tmp_path / "training.json", tmp_path / "training.safetensors")
    shuffled = dict(reversed(list(tensors.items())))  # the worst order: every index before its predecessors
    assert list(shuffled) != list(tensors)
    for order in (tensors, shuffled):
        fresh = tiny_ppo(seed=1)
        restore_training_state(fresh, meta, order, "ppo", *where)
        again_tensors, again = capture_training_state(fresh)
        assert json.dumps(json.loads(json.dumps(again, allow_nan=False)), sort_keys=False) == saved
        assert list(fresh.policy.optimizer.state_dict()["state"]) == list(model.policy.optimizer.state_dict()["state"])


def test_tensors_load_in_sorted_order(tmp_path: Path) -> None:
    names = [f"policy.optimizer/state/{index}/exp_avg" for index in (12, 0, 7, 1, 10)]
    data = tensor_bytes({name: torch.zeros(1) for name in names})
    assert list(load_tensors(data, tmp_path / "training.safetensors")) == sorted(names)


def test_a_state_that_does_not_fit_the_model_is_refused(tmp_path: Path) -> None:
    model = tiny_ppo(seed=0)
    model.learn(16)
    tensors, meta = capture_training_state(model)
    where = (tmp_path / "training.json", tmp_path / "training.safetensors")
    with pytest.raises(PolicyFormatError, match=r"the checkpoint has optimizers \['other.optimizer'\]"):
        restore_training_state(tiny_ppo(1), {**meta, "optimizers": {"other.optimizer": {}}}, tensors, "ppo", *where)
    with pytest.raises(PolicyFormatError, match="'counters'"):
        restore_training_state(tiny_ppo(1), {k: v for k, v in meta.items() if k != "counters"}, tensors, "ppo", *where)


def test_sac_round_trip_and_resume_state(tmp_path: Path) -> None:
    venv = make_training_env(ENV, 2, seed=0, normalize={"norm_obs": True, "norm_reward": False}, env_kwargs=SHORT)
    kwargs = dict(
        learning_starts=20,
        batch_size=16,
        gradient_steps=1,
        buffer_size=1000,
        seed=0,
        device="cpu",
        policy_kwargs={"net_arch": [16, 16]},
    )
    model = SAC("MlpPolicy", venv, **kwargs)
    model.learn(60)
    directory = save_policy(tmp_path / "sac", model, venv, ENV, training_state=True)
    observations = reference_observations(
        500, model.observation_space, venv.obs_rms.mean, venv.obs_rms.var, np.random.default_rng(2)
    )
    assert (
        TrainedPolicy(directory).predict(observations)[0].tobytes() == sb3_actions(model, venv, observations).tobytes()
    )
    fresh_venv = make_training_env(ENV, 2, seed=5, normalize={"norm_obs": True, "norm_reward": False}, env_kwargs=SHORT)
    fresh = SAC("MlpPolicy", fresh_venv, **kwargs)
    load_training_state(fresh, directory, fresh_venv)
    assert fresh.num_timesteps == model.num_timesteps
    assert torch.equal(fresh.log_ent_coef, model.log_ent_coef)
    for name in ("actor.optimizer", "critic.optimizer", "ent_coef_optimizer"):
        ours, theirs = (operator.attrgetter(name)(m).state_dict() for m in (fresh, model))
        assert ours["param_groups"] == theirs["param_groups"]
        for index, entries in theirs["state"].items():
            for key, value in entries.items():
                assert torch.equal(ours["state"][index][key], value), (name, index, key)
    np.testing.assert_array_equal(fresh_venv.obs_rms.mean, venv.obs_rms.mean)


def test_a_saved_optimizer_with_another_number_of_param_groups_is_refused(tmp_path: Path) -> None:
    """Extra saved param groups must not be dropped quietly: the optimizer would resume with
    settings that are not the ones it was saved with."""
    from agents.policies.sb3_state import _optimizer_state

    optimizer = torch.optim.Adam(torch.nn.Linear(2, 1).parameters())
    group = {
        key: list(v) if isinstance(v, tuple) else v for key, v in optimizer.state_dict()["param_groups"][0].items()
    }
    # The fitting case is accepted.
    _optimizer_state(optimizer, {"param_groups": [group]}, {}, "actor.optimizer", tmp_path, tmp_path)
    for groups in ([group, dict(group)], []):
        with pytest.raises(PolicyFormatError, match=f"has {len(groups)} param groups; this model's optimizer has 1"):
            _optimizer_state(optimizer, {"param_groups": groups}, {}, "actor.optimizer", tmp_path, tmp_path)


def trained_state() -> tuple[dict[str, torch.Tensor], dict]:
    model = tiny_ppo(seed=0)
    model.learn(32)
    tensors, meta = capture_training_state(model)
    return tensors, json.loads(json.dumps(meta, allow_nan=False))


def corrupted(meta: dict, path: tuple[str | int, ...], value: object) -> dict:
    """A deep copy of ``meta`` with the entry at ``path`` set to ``value``."""
    copy = json.loads(json.dumps(meta))
    target = copy
    for key in path[:-1]:
        target = target[key]
    target[path[-1]] = value
    return copy


MOMENT = "policy.optimizer/state/0/exp_avg"
GROUP = ("optimizers", "policy.optimizer", "param_groups", 0)
Tensors = dict[str, torch.Tensor]


def renamed(tensors: Tensors, old: str, new: str) -> Tensors:
    return {new if key == old else key: value for key, value in tensors.items()}


#: name -> (what it does to (tensors, training.json), the error it must raise)
BAD_STATES: dict[str, tuple[Any, str]] = {
    "misshapen": (
        lambda t, m: ({**t, MOMENT: torch.zeros(3)}, m),
        r"tensor 'policy.optimizer/state/0/exp_avg' is \(3,\) torch.float32; the parameter it belongs to",
    ),
    "float64": (
        lambda t, m: ({**t, MOMENT: t[MOMENT].double()}, m),
        r"is \(9,\) torch.float64; the parameter it belongs to needs \(9,\) torch.float32",
    ),
    "step_shape": (
        lambda t, m: ({**t, "policy.optimizer/state/0/step": torch.zeros(2)}, m),
        r"tensor 'policy.optimizer/state/0/step' is \(2,\)",
    ),
    "missing_moment": (
        lambda t, m: ({k: v for k, v in t.items() if not k.endswith("exp_avg_sq")}, m),
        r"parameter 0: missing \['exp_avg_sq'\]",
    ),
    "bad_index": (
        lambda t, m: (renamed(t, MOMENT, "policy.optimizer/state/x/exp_avg"), m),
        r"parameter index 'x' is not one of this optimizer's",
    ),
    "far_index": (
        lambda t, m: (renamed(t, MOMENT, "policy.optimizer/state/99/exp_avg"), m),
        r"parameter index '99' is not one of this optimizer's",
    ),
    "unknown_tensor": (
        lambda t, m: ({**t, "stray": torch.zeros(1)}, m),
        r"tensors \['stray'\] belong to no optimizer or variable",
    ),
    "partial": (
        lambda t, m: ({k: v for k, v in t.items() if "/state/0/" not in k}, m),
        r"has state for parameters \[1, 2",
    ),
    "lr_text": (
        lambda t, m: (t, corrupted(m, (*GROUP, "lr"), "0.001")),
        r"param_groups\[0\].lr must be float like .*; got '0.001'",
    ),
    "betas_text": (
        lambda t, m: (t, corrupted(m, (*GROUP, "betas"), "0.9, 0.999")),
        r"param_groups\[0\].betas must be tuple",
    ),
    "flag_number": (lambda t, m: (t, corrupted(m, (*GROUP, "amsgrad"), 1)), r"param_groups\[0\].amsgrad must be bool"),
    "params": (lambda t, m: (t, corrupted(m, (*GROUP, "params"), [0, 1])), r"param_groups\[0\].params must be \[0, 1"),
    "unknown_group_entry": (
        lambda t, m: (t, corrupted(m, (*GROUP, "momentum_of_doom"), 1.0)),
        r"param_groups\[0\] must have params and entries of",
    ),
    "scalar_text": (
        lambda t, m: (t, corrupted(m, ("optimizers", "policy.optimizer", "scalars"), {"0": {"step": "three"}})),
        r"scalars.0.step must be a number or null; got 'three'",
    ),
    "negative_counter": (
        lambda t, m: (t, corrupted(m, ("counters", "num_timesteps"), -1)),
        r"counters.num_timesteps must be a count >= 0; got -1",
    ),
    "text_counter": (
        lambda t, m: (t, corrupted(m, ("counters", "n_updates"), "2")),
        r"'n_updates' must be int; got '2'",
    ),
    # Indices that name parameter 0 a second time: the last one read would have been kept.
    "padded_index": (
        lambda t, m: ({**t, "policy.optimizer/state/00/exp_avg": torch.zeros_like(t[MOMENT])}, m),
        r"parameter index '00' is not one of this optimizer's",
    ),
    "unicode_index": (
        lambda t, m: (renamed(t, MOMENT, "policy.optimizer/state/\u0660/exp_avg"), m),
        r"parameter index '\u0660' is not one of this optimizer's",
    ),
    "step_twice": (
        lambda t, m: (t, corrupted(m, ("optimizers", "policy.optimizer", "scalars"), {"0": {"step": 3}})),
        r"scalars.0.step is also a tensor of .*training.safetensors",
    ),
    # Content no optimizer writes, which made the first step NaN.
    "negative_square": (
        lambda t, m: ({**t, "policy.optimizer/state/0/exp_avg_sq": -torch.ones_like(t[MOMENT])}, m),
        r"'policy.optimizer/state/0/exp_avg_sq' is an average of squares and has negative entries",
    ),
    "negative_step": (
        lambda t, m: ({**t, "policy.optimizer/state/0/step": torch.tensor(-5.0)}, m),
        r"'policy.optimizer/state/0/step' must be a whole number of steps >= 0; got -5.0",
    ),
    "fractional_step": (
        lambda t, m: ({**t, "policy.optimizer/state/0/step": torch.tensor(2.5)}, m),
        r"must be a whole number of steps >= 0; got 2.5",
    ),
    "beta_of_one": (
        lambda t, m: (t, corrupted(m, (*GROUP, "betas"), [1.0, 0.999])),
        r"param_groups\[0\]: Adam refuses these settings \(Invalid beta parameter at index 0: 1.0\)",
    ),
    "capturable": (
        lambda t, m: (t, corrupted(m, (*GROUP, "capturable"), True)),
        r"param_groups\[0\].capturable is True; this run's Adam has False",
    ),
}


@pytest.mark.parametrize("change", sorted(BAD_STATES))
def test_a_resume_state_with_bad_content_is_refused_by_name_and_leaves_the_model_as_it_was(
    tmp_path: Path, change: str
) -> None:
    """Misshapen or mistyped optimizer moments and text where numbers belong were accepted and
    failed later inside torch, or not at all; each is refused naming the file and the entry, and
    nothing of the refused state is written."""
    mutate, message = BAD_STATES[change]
    tensors, meta = mutate(*trained_state())
    fresh = tiny_ppo(seed=1)
    before = json.dumps(fresh.policy.optimizer.state_dict()["param_groups"])
    with pytest.raises(PolicyFormatError, match=message) as raised:
        restore_training_state(
            fresh, meta, tensors, "ppo", tmp_path / "training.json", tmp_path / "training.safetensors"
        )
    assert "training.json" in str(raised.value) or "training.safetensors" in str(raised.value)
    assert fresh.num_timesteps == 0 and not fresh.policy.optimizer.state_dict()["state"]
    assert json.dumps(fresh.policy.optimizer.state_dict()["param_groups"]) == before


def test_a_refused_checkpoint_directory_leaves_the_model_and_statistics_as_they_were(tmp_path: Path) -> None:
    """load_training_state read, checked and wrote file by file: a bad training.safetensors left
    the weights already overwritten. Now nothing is written until every file is checked."""
    venv = make_training_env(ENV, 2, seed=0, normalize={"norm_obs": True, "norm_reward": False}, env_kwargs=SHORT)
    model = PPO("MlpPolicy", venv, n_steps=16, batch_size=32, device="cpu", seed=0, policy_kwargs={"net_arch": [8]})
    model.learn(32)
    directory = save_policy(tmp_path / "checkpoint", model, venv, ENV, training_state=True)
    (directory / "MANIFEST.sha256").unlink()
    tensors = load_tensors((directory / "training.safetensors").read_bytes(), directory / "training.safetensors")
    tensors[MOMENT] = torch.zeros(2)
    (directory / "training.safetensors").write_bytes(tensor_bytes(tensors))
    fresh_venv = make_training_env(ENV, 2, seed=5, normalize={"norm_obs": True, "norm_reward": False}, env_kwargs=SHORT)
    fresh = PPO(
        "MlpPolicy", fresh_venv, n_steps=16, batch_size=32, device="cpu", seed=1, policy_kwargs={"net_arch": [8]}
    )
    weights = {key: value.clone() for key, value in fresh.policy.state_dict().items()}
    mean = fresh_venv.obs_rms.mean.copy()
    with pytest.raises(PolicyFormatError, match="training.safetensors: tensor 'policy.optimizer/state/0/exp_avg'"):
        load_training_state(fresh, directory, fresh_venv)
    assert all(torch.equal(weights[key], value) for key, value in fresh.policy.state_dict().items())
    np.testing.assert_array_equal(fresh_venv.obs_rms.mean, mean)
    assert fresh.num_timesteps == 0


@pytest.mark.parametrize(
    ("options", "named"),
    [
        ({"norm_obs": True, "norm_reward": True}, "norm_reward: False (the run's: True)"),
        ({"norm_obs": False, "norm_reward": False}, "norm_obs: True (the run's: False)"),
        ({"norm_obs": True, "norm_reward": False, "clip_obs": 5.0}, "clip_obs: 10.0 (the run's: 5.0)"),
        ({"norm_obs": True, "norm_reward": False, "epsilon": 1e-4}, "epsilon: 1e-08 (the run's: 0.0001)"),
    ],
)
def test_a_checkpoint_normalised_otherwise_than_the_run_is_refused(
    tmp_path: Path, options: dict[str, Any], named: str
) -> None:
    """The checkpoint's normaliser settings silently replaced the run's 'normalize' options: a run
    asking for norm_reward (or clip_obs 5) continued with the checkpoint's. They change what the
    weights mean, so a difference is refused, naming normalization.json, the setting and both values."""
    venv = make_training_env(ENV, 2, seed=0, normalize={"norm_obs": True, "norm_reward": False}, env_kwargs=SHORT)
    model = PPO("MlpPolicy", venv, n_steps=16, batch_size=32, device="cpu", seed=0, policy_kwargs={"net_arch": [8]})
    model.learn(32)
    directory = save_policy(tmp_path / "checkpoint", model, venv, ENV, training_state=True)
    fresh_venv = make_training_env(ENV, 2, seed=5, normalize=options, env_kwargs=SHORT)
    fresh = PPO(
        "MlpPolicy", fresh_venv, n_steps=16, batch_size=32, device="cpu", seed=1, policy_kwargs={"net_arch": [8]}
    )
    with pytest.raises(PolicyFormatError, match=rf"normalization.json records {re.escape(named)}"):
        load_training_state(fresh, directory, fresh_venv)
    assert fresh.num_timesteps == 0 and fresh_venv.norm_reward == options["norm_reward"]
    same = make_training_env(ENV, 2, seed=5, normalize={"norm_obs": True, "norm_reward": False}, env_kwargs=SHORT)
    resumed = PPO("MlpPolicy", same, n_steps=16, batch_size=32, device="cpu", seed=1, policy_kwargs={"net_arch": [8]})
    load_training_state(resumed, directory, same)
    assert resumed.num_timesteps == model.num_timesteps
