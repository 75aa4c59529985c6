"""The README's snippets say what the project does: every id in them resolves without a prior
import, the SB3 snippet trains with the tuned PPO settings of the hyperparameter file, and the
install lines are the ones CI runs. (``scripts/wheel_check.sh`` runs the install lines and every
Python snippet with the installed wheel; these tests read them.)"""

from __future__ import annotations

import ast
import re
from pathlib import Path
from typing import Any

import pytest

from agents.training.hyperparams import load_hyperparameters
from tether_gym.registration import DEFAULT_ENV_ID, ENV_IDS

ROOT = Path(__file__).resolve().parents[2]
README = (ROOT / "README.md").read_text(encoding="utf-8")
PYTHON_SNIPPETS = re.findall(r"^```python\n(.*?)^```", README, re.MULTILINE | re.DOTALL)


def _calls(source: str, name: str) -> list[ast.Call]:
    """Every call of ``name`` (a plain name or an attribute) in ``source``."""
    calls = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Call):
            func = node.func
            called = func.id if isinstance(func, ast.Name) else func.attr if isinstance(func, ast.Attribute) else ""
            if called == name:
                calls.append(node)
    return calls


def _sb3_snippet() -> str:
    matches = [snippet for snippet in PYTHON_SNIPPETS if "PPO(" in snippet]
    assert len(matches) == 1, f"expected one README snippet that builds PPO, found {len(matches)}"
    return matches[0]


def test_every_python_snippet_parses() -> None:
    assert len(PYTHON_SNIPPETS) >= 3
    for snippet in PYTHON_SNIPPETS:
        ast.parse(snippet)


@pytest.mark.parametrize("function", ["make", "make_vec"])
def test_gymnasium_ids_carry_the_module_prefix(function: str) -> None:
    """``gym.make("tether_gym:Id")`` imports tether_gym, which registers the ids; Gymnasium 1.x has
    no plugin entry point that would do it otherwise."""
    for snippet in PYTHON_SNIPPETS:
        for call in _calls(snippet, function):
            first = call.args[0]
            assert isinstance(first, ast.Constant) and isinstance(first.value, str)
            module, _, env_id = first.value.rpartition(":")
            assert module == "tether_gym" and env_id in ENV_IDS, f"gym.{function}({first.value!r}) in the README"


def _keyword_values(call: ast.Call) -> dict[str, Any]:
    values: dict[str, Any] = {}
    for keyword in call.keywords:
        if keyword.arg is None:
            continue
        try:
            values[keyword.arg] = ast.literal_eval(keyword.value)
        except ValueError:
            values[keyword.arg] = keyword.value
    return values


def test_the_sb3_snippet_uses_the_tuned_ppo_settings() -> None:
    snippet = _sb3_snippet()
    tuned = load_hyperparameters("ppo", DEFAULT_ENV_ID)
    (ppo,) = _calls(snippet, "PPO")
    given = _keyword_values(ppo)
    for key in ("n_steps", "batch_size"):
        assert given[key] == tuned[key], key
    kwargs = tuned["policy_kwargs"]
    assert given["policy_kwargs"]["net_arch"] == kwargs["net_arch"]
    assert given["policy_kwargs"]["log_std_init"] == kwargs["log_std_init"]
    # SB3's MlpPolicy default activation is tanh, the tuned one; anything else must be spelt out.
    assert kwargs["activation_fn"] == "tanh" or "activation_fn" in given["policy_kwargs"]
    # lin_1.0e-3: a linear decay from 1e-3, written as a lambda of the progress left.
    rate = given["learning_rate"]
    assert tuned["learning_rate"] == "lin_1.0e-3" and isinstance(rate, ast.Lambda)
    assert ast.literal_eval(rate.body.left) == 1e-3  # type: ignore[attr-defined]
    for key in ("n_epochs", "gamma", "gae_lambda", "clip_range", "ent_coef", "max_grad_norm"):
        # The rest are SB3's defaults in the tuned file, so the snippet leaves them out.
        assert (
            key in given
            or tuned[key]
            == {
                "n_epochs": 10,
                "gamma": 0.99,
                "gae_lambda": 0.95,
                "clip_range": 0.2,
                "ent_coef": 0.0,
                "max_grad_norm": 0.5,
            }[key]
        ), key
    (env,) = _calls(snippet, "make_sb3_vec_env")
    assert _keyword_values(env)["num_envs"] == tuned["n_envs"]
    (learn,) = _calls(snippet, "learn")
    learned = _keyword_values(learn)
    assert learned["progress_bar"] is True
    rollout = tuned["n_envs"] * tuned["n_steps"]
    assert learned["total_timesteps"] % rollout == 0, "a whole number of rollouts, so SB3 runs exactly that many steps"


def test_the_install_lines_pin_the_install_scripts_torch() -> None:
    section = README.split("## Install as a package", 1)[1].split("\n## ", 1)[0]
    (install,) = re.findall(r"^```bash\n(.*?)^```", section, re.MULTILINE | re.DOTALL)
    pins = set(re.findall(r"torch==[0-9.]*[0-9]", (ROOT / "scripts" / "install.sh").read_text(encoding="utf-8")))
    assert len(pins) == 1 and pins <= set(re.findall(r"torch==[0-9.]*[0-9]", install))
    assert "tether-gym-compile" in install, "the README recommends compiling the kernels after installing"
