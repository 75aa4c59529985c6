"""What a policy directory may cost to load, and whether its actions fit the env it runs on.

The loader computes the size of the network ``policy.json`` describes (agents.policies.size)
and checks it against a limit and against the weights file before anything is built; a policy's
action count and bounds are checked against the env when it is attached.
"""

from __future__ import annotations

import functools
import itertools
import json
import math
import subprocess
import sys
import textwrap
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from stable_baselines3 import PPO

from agents.policies import TrainedPolicy, make_controller, shipped_models
from agents.policies.format import _policy_class, load_policy, save_policy
from agents.policies.layout import PolicyFormatError
from agents.policies.size import MAX_LAYERS, MAX_POLICY_PARAMETERS, parameter_count
from tether_gym import ENV_IDS
from tether_gym.sb3 import make_sb3_vec_env

TRIANGLE = "TetherTriangle-v0"
ROOT = Path(__file__).resolve().parents[3]


def tiny_policy_dir(directory: Path) -> Path:
    """A linear PPO policy of the triangle (21 observations, 9 actions), without a manifest, so
    that its files can be edited: under 8 KB in all."""
    venv = make_sb3_vec_env(TRIANGLE, 1, seed=0, max_episode_steps=20)
    model = PPO(
        "MlpPolicy",
        venv,
        n_steps=16,
        batch_size=16,
        device="cpu",
        policy_kwargs={"net_arch": {"pi": [], "vf": []}},
        seed=0,
    )
    save_policy(directory, model, None, TRIANGLE)
    (directory / "MANIFEST.sha256").unlink()
    return directory


def edit_metadata(directory: Path, **changes: Any) -> Path:
    path = directory / "policy.json"
    metadata = json.loads(path.read_text())
    metadata.update(changes)
    path.write_text(json.dumps(metadata))
    return directory


@pytest.mark.parametrize("algo", ["ppo", "ars", "sac", "td3"])
def test_the_counted_parameters_are_those_sb3_builds(algo: str) -> None:
    """The count from policy.json alone is SB3's own, over net_arch's forms and the settings that
    add parameters: a count that is off would refuse good files or let large ones through."""
    observation = gym.spaces.Box(-1, 1, (7,), np.float32)
    action = gym.spaces.Box(-1, 1, (3,), np.float32)
    actor_critic = algo in ("ppo", "ars")
    critic = "vf" if actor_critic else "qf"
    arches = [None, [], [5], [5, 4], {"pi": [6], critic: [2, 3]}, {"pi": [], critic: [4]}]
    policy_class = _policy_class(algo, "MlpPolicy", "test")
    checked = 0
    for arch, sde, full_std, critics in itertools.product(arches, [False, True], [True, False], [None, 3]):
        kwargs: dict[str, Any] = {"net_arch": arch}
        if algo != "td3":
            kwargs["use_sde"] = sde
        elif sde:
            continue
        if sde and actor_critic:
            kwargs["full_std"] = full_std
        elif not full_std:
            continue
        if critics is not None:
            if actor_critic:
                continue
            kwargs["n_critics"] = critics
        built = policy_class(observation, action, lambda _: 0.0, **kwargs)
        expected = sum(tensor.numel() for tensor in built.state_dict().values())
        assert parameter_count(algo, kwargs, 7, 3, "test") == expected, kwargs
        checked += 1
    assert checked >= 12


def test_a_network_above_the_limit_or_too_deep_is_refused_by_name() -> None:
    with pytest.raises(
        PolicyFormatError, match=r"policy.json: policy_kwargs: the network it describes has .* parameters"
    ):
        parameter_count("ppo", {"net_arch": [4096, 4096]}, 30, 12, "policy.json: policy_kwargs")
    with pytest.raises(PolicyFormatError, match=f"has {MAX_LAYERS + 1} layers"):
        parameter_count("ppo", {"net_arch": [1] * (MAX_LAYERS + 1)}, 30, 12, "policy.json")
    with pytest.raises(PolicyFormatError, match="n_critics must be an integer"):
        parameter_count("sac", {"n_critics": 10**9}, 30, 12, "policy.json")
    with pytest.raises(PolicyFormatError, match=r"net_arch.pi must be a list of positive layer sizes"):
        parameter_count("ppo", {"net_arch": {"pi": ["64"]}}, 30, 12, "policy.json")
    # The limit is well above every shipped model and the SAC settings on the largest id.
    assert parameter_count("sac", {"net_arch": [256, 256]}, 54, 21, "sac") < MAX_POLICY_PARAMETERS / 8
    for env_id in ENV_IDS:
        for directory in shipped_models(env_id).values():
            metadata = json.loads((directory / "policy.json").read_text())
            sizes = [math.prod(metadata[key]["shape"]) for key in ("observation_space", "action_space")]
            assert (
                parameter_count(metadata["algo"], metadata["policy_kwargs"], *sizes, "x")
                < MAX_POLICY_PARAMETERS / 40  # the DAgger 256x256 student: 83 k
            )


def test_weights_that_do_not_hold_the_described_network_are_refused_before_it_is_built(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    directory = edit_metadata(
        tiny_policy_dir(tmp_path / "p"),
        policy_kwargs={"net_arch": {"pi": [64], "vf": []}, "use_sde": False},
    )
    built: list[Any] = []
    policy_class = PPO.policy_aliases["MlpPolicy"]
    original = policy_class.__init__

    @functools.wraps(original)
    def spy(self: Any, *args: Any, **kwargs: Any) -> None:
        built.append(args)
        original(self, *args, **kwargs)

    monkeypatch.setattr(policy_class, "__init__", spy)
    with pytest.raises(PolicyFormatError, match=r"policy.safetensors holds 229 values, but the network that .* has"):
        load_policy(directory)
    assert not built


def test_an_unbounded_action_space_is_refused(tmp_path: Path) -> None:
    directory = tiny_policy_dir(tmp_path / "p")
    metadata = json.loads((directory / "policy.json").read_text())
    metadata["action_space"]["high"][0] = "inf"
    edit_metadata(directory, action_space=metadata["action_space"])
    with pytest.raises(PolicyFormatError, match=r"policy.json: action_space is unbounded"):
        load_policy(directory)


#: Run in a fresh interpreter: loads each directory named on the command line after a warm-up
#: load, and prints what each cost (peak resident memory above the warm-up's, and wall time).
MEASURE = textwrap.dedent(
    """
    import json, resource, sys, time
    from agents.policies.format import load_policy
    from agents.policies.layout import PolicyFormatError
    load_policy(sys.argv[1])  # imports, lazy initialisations
    results = {}
    for directory in sys.argv[2:]:
        peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
        start = time.perf_counter()
        try:
            load_policy(directory)
            outcome = "loaded"
        except PolicyFormatError as error:
            outcome = "refused: " + str(error)
        results[directory] = {
            "outcome": outcome,
            "seconds": time.perf_counter() - start,
            "mb": (resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - peak) / 1024,
        }
    print(json.dumps(results))
    """
)


@pytest.mark.slow
def test_a_crafted_policy_directory_of_a_few_kb_costs_under_a_second_and_100_mb(tmp_path: Path) -> None:
    """The issue's case: a 2 KB policy.json asking for a 4096 x 4096 network cost 22 s and 700 MB
    before any shape check. Each crafted directory here is under 8 KB; each loads, or is refused
    with a PolicyFormatError, in under 1 s and 100 MB, measured in a fresh process."""
    original = tiny_policy_dir(tmp_path / "original")
    cases: dict[str, dict[str, Any]] = {
        "huge_layers": {"policy_kwargs": {"net_arch": {"pi": [4096, 4096], "vf": [4096, 4096]}, "use_sde": False}},
        "deep": {"policy_kwargs": {"net_arch": [2048] * MAX_LAYERS, "use_sde": False}},
        "too_deep": {"policy_kwargs": {"net_arch": [1] * 1000, "use_sde": False}},
        "wide_sde": {"policy_kwargs": {"net_arch": [1, 100_000_000], "use_sde": True, "full_std": True}},
        "sac_critics": {"algo": "sac", "policy_kwargs": {"net_arch": [2048, 2048], "n_critics": 16}},
        "off_by_one": {"policy_kwargs": {"net_arch": {"pi": [1], "vf": []}, "use_sde": False}},
    }
    directories = [str(original)]
    for name, changes in cases.items():
        directory = tmp_path / name
        directory.mkdir()
        for file in original.iterdir():
            (directory / file.name).write_bytes(file.read_bytes())
        edit_metadata(directory, **changes)
        assert sum(file.stat().st_size for file in directory.iterdir()) < 8192
        directories.append(str(directory))
    completed = subprocess.run(
        [sys.executable, "-c", MEASURE, str(original), *directories],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=300,
        check=False,
    )
    assert completed.returncode == 0, completed.stderr[-3000:]
    results = json.loads(completed.stdout.strip().splitlines()[-1])
    assert results[str(original)]["outcome"] == "loaded"
    for directory in directories[1:]:
        assert results[directory]["outcome"].startswith("refused: "), (directory, results[directory])
    for directory, cost in results.items():
        assert cost["seconds"] < 1.0 and cost["mb"] < 100, (directory, cost)


def test_a_policy_with_the_wrong_number_of_actions_or_other_bounds_is_refused_on_the_env(tmp_path: Path) -> None:
    """The comparison failed mid-run on another action count, and reported "0 % clipped" for
    actions of 50: both are refused when the policy is attached, naming the file's entry."""
    directory = tiny_policy_dir(tmp_path / "p")
    tetrahedron = gym.make("tether_gym:TetherTetrahedron-v0")
    with pytest.raises(ValueError, match=r"acts with 9 actions \(policy.json: action_space.shape \[9\]\), but "):
        make_controller(str(directory), tetrahedron, allow_other_id=True)
    metadata = json.loads((directory / "policy.json").read_text())
    metadata["action_space"]["low"] = [-50.0] * 9
    metadata["action_space"]["high"] = [50.0] * 9
    edit_metadata(directory, action_space=metadata["action_space"])
    triangle = gym.make(f"tether_gym:{TRIANGLE}")
    with pytest.raises(ValueError, match=r"acts within bounds \[-50, 50\] \(policy.json: action_space.low/high\)"):
        make_controller(str(directory), triangle)
    vector = gym.make_vec(f"tether_gym:{TRIANGLE}", num_envs=2)
    with pytest.raises(ValueError, match="action_space.low/high"):
        TrainedPolicy(directory).attach(vector)


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_every_shipped_model_fits_the_actions_of_its_own_id(env_id: str) -> None:
    """Centralised, residual and decentralised (3 actions a satellite) policies alike."""
    env = gym.make(f"tether_gym:{env_id}")
    for name in shipped_models(env_id):
        controller = make_controller(name, env)
        assert isinstance(controller, TrainedPolicy)


layers = st.lists(st.integers(1, 12), max_size=3)


@pytest.mark.slow
@settings(max_examples=40, deadline=None, derandomize=True)
@given(
    algo=st.sampled_from(["ppo", "ars", "sac", "td3"]),
    arch=st.one_of(st.none(), layers, st.fixed_dictionaries({"pi": layers, "critic": layers})),
    sde=st.booleans(),
    full_std=st.booleans(),
    critics=st.integers(1, 4),
    sizes=st.tuples(st.integers(1, 40), st.integers(1, 12)),
)
def test_the_counted_parameters_are_sb3s_for_any_settings(
    algo: str, arch: Any, sde: bool, full_std: bool, critics: int, sizes: tuple[int, int]
) -> None:
    """The grid above, as a property over random layer sizes, spaces and settings."""
    actor_critic = algo in ("ppo", "ars")
    if isinstance(arch, dict):
        arch = {"pi": arch["pi"], ("vf" if actor_critic else "qf"): arch["critic"]}
    kwargs: dict[str, Any] = {"net_arch": arch}
    if algo != "td3":
        kwargs["use_sde"] = sde
    if actor_critic and sde:
        kwargs["full_std"] = full_std
    if not actor_critic:
        kwargs["n_critics"] = critics
    observation = gym.spaces.Box(-1, 1, (sizes[0],), np.float32)
    action = gym.spaces.Box(-1, 1, (sizes[1],), np.float32)
    built = _policy_class(algo, "MlpPolicy", "test")(observation, action, lambda _: 0.0, **kwargs)
    expected = sum(tensor.numel() for tensor in built.state_dict().values())
    assert parameter_count(algo, kwargs, *sizes, "test") == expected


def test_bad_multiagent_options_in_policy_json_are_refused_naming_the_file(tmp_path: Path) -> None:
    source = shipped_models("TetherTetrahedron-v0")["ppo_multiagent"]
    directory = tmp_path / "p"
    directory.mkdir()
    for file in source.iterdir():
        if file.name != "MANIFEST.sha256":
            (directory / file.name).write_bytes(file.read_bytes())
    edit_metadata(directory, multiagent={"bogus": 1})
    env = gym.make("tether_gym:TetherTetrahedron-v0")
    with pytest.raises(ValueError, match=r"p: policy.json: multiagent: unknown multi-agent option\(s\) \['bogus'\]"):
        make_controller(str(directory), env)
