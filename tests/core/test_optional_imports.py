"""Every optional dependency that tether_gym imports fails, when it is missing, with an error that
names the pip extra which installs it; the core package needs none of them."""

from __future__ import annotations

import importlib
import subprocess
import sys
import textwrap
from collections.abc import Callable
from typing import Any

import gymnasium as gym
import numpy as np
import pytest

from tether_gym._optional import MissingExtraError

#: The optional modules tether_gym imports, by the extra that installs them.
OPTIONAL = {"matplotlib": "plots", "pettingzoo": "multiagent", "stable_baselines3": "train"}


def block(monkeypatch: pytest.MonkeyPatch, package: str) -> None:
    """Make ``package`` and every submodule unimportable, as if it were not installed (a
    submodule already imported would otherwise be found in sys.modules without its parent)."""
    for name in [name for name in sys.modules if name == package or name.startswith(package + ".")]:
        monkeypatch.setitem(sys.modules, name, None)
    monkeypatch.setitem(sys.modules, package, None)


def fresh_import(monkeypatch: pytest.MonkeyPatch, module: str) -> Any:
    """Import ``module`` anew (its cached copy is put back after the test)."""
    monkeypatch.delitem(sys.modules, module, raising=False)
    return importlib.import_module(module)


def render_a_frame() -> Any:
    env = gym.make("TetherTetrahedron-v0", render_mode="rgb_array")
    env.reset(seed=0)
    return env.render()


def show_a_window() -> Any:
    return gym.make("TetherTetrahedron-v0", render_mode="human").reset(seed=0)


def parallel_env(monkeypatch: pytest.MonkeyPatch) -> Any:
    from tether_gym.multiagent import parallel_env

    monkeypatch.delitem(sys.modules, "tether_gym.multiagent.parallel", raising=False)
    return parallel_env("TetherHub-v0")


CASES: list[tuple[str, str, Callable[[pytest.MonkeyPatch], Any]]] = [
    ("matplotlib", "render_mode='rgb_array'", lambda mp: render_a_frame()),
    ("matplotlib", "render_mode='human'", lambda mp: show_a_window()),
    ("pettingzoo", "PettingZoo", parallel_env),
    ("pettingzoo", "PettingZoo", lambda mp: fresh_import(mp, "tether_gym.multiagent.parallel")),
    ("stable_baselines3", "tether_gym.sb3", lambda mp: fresh_import(mp, "tether_gym.sb3")),
    ("stable_baselines3", "AgentVecEnv", lambda mp: fresh_import(mp, "tether_gym.multiagent.sb3")),
]


@pytest.mark.parametrize(("missing", "purpose", "use"), CASES, ids=[f"{m}-{p}" for m, p, _ in CASES])
def test_a_missing_optional_module_names_its_extra(
    monkeypatch: pytest.MonkeyPatch, missing: str, purpose: str, use: Callable[[pytest.MonkeyPatch], Any]
) -> None:
    pytest.importorskip(missing)  # the path is installed; what is tested is its absence
    block(monkeypatch, missing)
    with pytest.raises(MissingExtraError) as caught:
        use(monkeypatch)
    extra = OPTIONAL[missing]
    message = str(caught.value)
    assert f"{missing} is not installed" in message
    assert f'pip install "tether-gym[{extra}]"' in message
    assert purpose in message
    assert caught.value.extra == extra
    assert isinstance(caught.value, ImportError)  # `except ImportError` still catches it


def test_the_core_package_needs_no_optional_module() -> None:
    """With every optional module of every extra blocked (in a fresh interpreter, since the
    test process has them loaded): import tether_gym, run an env, a vector env and the
    multi-agent engine."""
    blocked = [*OPTIONAL, "moviepy", "scipy", "torch", "ray", "yaml"]
    check = textwrap.dedent(
        f"""
        import sys
        for name in {blocked!r}:
            sys.modules[name] = None
        import gymnasium as gym
        import numpy as np
        import tether_gym
        from tether_gym.multiagent import AgentBatch
        import tether_gym.analysis, tether_gym.bench
        env = gym.make("TetherTetrahedron-v0")
        env.reset(seed=0)
        env.step(np.zeros(12))
        envs = gym.make_vec("TetherTetrahedron-v0", num_envs=2)
        envs.reset(seed=0)
        envs.step(np.zeros((2, 12)))
        loaded = [name for name in {blocked!r} if sys.modules.get(name) is not None]
        assert not loaded, loaded
        print("ok")
        """
    )
    result = subprocess.run([sys.executable, "-c", check], capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stderr[-3000:]
    assert result.stdout.strip().endswith("ok")


def test_the_blocked_modules_come_back(monkeypatch: pytest.MonkeyPatch) -> None:
    # The tests above leave the real modules in place afterwards (monkeypatch restores them).
    pytest.importorskip("matplotlib")
    frame = render_a_frame()
    assert isinstance(frame, np.ndarray) and frame.dtype == np.uint8
