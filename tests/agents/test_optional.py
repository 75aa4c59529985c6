"""tether_gym._optional: a missing optional module fails with the extra that installs it."""

from __future__ import annotations

import subprocess
import sys
import types
from pathlib import Path

import pytest

from tether_gym._optional import MissingExtraError, available, install_line, needs_extra, require

ROOT = Path(__file__).resolve().parents[2]


def test_require_returns_an_installed_module() -> None:
    assert require("json", "train", "a test") is sys.modules["json"]


def test_a_missing_module_names_the_extra_and_the_purpose(monkeypatch: pytest.MonkeyPatch) -> None:
    # None in sys.modules makes `import yaml` fail as if it were not installed.
    monkeypatch.setitem(sys.modules, "yaml", None)
    with pytest.raises(MissingExtraError) as caught:
        require("yaml", "train", "reading the hyperparameter files")
    message = str(caught.value)
    assert 'pip install "tether-gym[train]"' in message
    assert "reading the hyperparameter files" in message
    assert "pyyaml" in message  # the pip name, not the import name
    assert caught.value.name == "yaml" and caught.value.extra == "train"
    # Code that catches ImportError or ModuleNotFoundError keeps working.
    assert isinstance(caught.value, ModuleNotFoundError)


def test_a_missing_parent_package_of_a_submodule(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "matplotlib", None)
    monkeypatch.delitem(sys.modules, "matplotlib.pyplot", raising=False)
    with pytest.raises(MissingExtraError, match=r"matplotlib is not installed.*tether-gym\[plots\]"):
        require("matplotlib.pyplot", "plots", "the plots")


def test_a_broken_install_is_not_blamed_on_the_extra(monkeypatch: pytest.MonkeyPatch) -> None:
    # A module that is installed but imports something absent: the extra would not fix that.
    broken = types.ModuleType("tether_gym_test_broken")
    monkeypatch.setitem(sys.modules, "tether_gym_test_missing_dependency", None)

    def fail_inside() -> None:
        import tether_gym_test_missing_dependency  # noqa: F401

    with pytest.raises(ModuleNotFoundError) as caught:
        monkeypatch.setattr("importlib.import_module", lambda name: fail_inside())
        require(broken.__name__, "train", "a test")
    assert not isinstance(caught.value, MissingExtraError)


def test_available(monkeypatch: pytest.MonkeyPatch) -> None:
    assert available("json")
    monkeypatch.setitem(sys.modules, "yaml", None)
    assert not available("yaml")


def test_install_line_is_quoted_for_the_shell() -> None:
    assert install_line("multiagent") == 'pip install "tether-gym[multiagent]"'


def test_needs_extra_names_the_extra_of_a_missing_import(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "stable_baselines3", None)
    with pytest.raises(MissingExtraError, match=r"stable_baselines3 is not installed.*tether-gym\[train\]"):
        with needs_extra("train", "training"):
            from stable_baselines3 import PPO  # noqa: F401
    # Imports that succeed pass through, and an error raised deeper keeps its own extra.
    with needs_extra("train", "training"):
        import json  # noqa: F401
    monkeypatch.setitem(sys.modules, "matplotlib", None)
    with pytest.raises(MissingExtraError) as caught:
        with needs_extra("train", "training"):
            require("matplotlib", "plots", "the plots")
    assert caught.value.extra == "plots"


def test_needs_extra_leaves_the_projects_own_modules_alone(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "tether_gym.no_such_module", None)
    with pytest.raises(ModuleNotFoundError) as caught:
        with needs_extra("train", "training"):
            import tether_gym.no_such_module  # noqa: F401
    assert not isinstance(caught.value, MissingExtraError)


@pytest.mark.parametrize(
    ("blocked", "code", "expected"),
    [
        ("stable_baselines3", "import agents.train", ["stable_baselines3", 'pip install "tether-gym[train]"']),
        ("torch", "import agents.policies", ["torch", 'pip install "tether-gym[train]"']),
        (
            # PyYAML is imported when a settings file is first read, so that reading JSON needs only the core.
            "yaml",
            "import pathlib; from agents.common.reading import read_yaml; "
            "read_yaml(pathlib.Path('agents/hyperparams/ppo.yml'))",
            ["yaml", "reading the settings files", 'pip install "tether-gym[train]"'],
        ),
        ("scipy", "import agents.controllers.centralised", ["scipy", "LQR", 'pip install "tether-gym[train]"']),
        (
            "tensorboard",
            "import tempfile; from agents.training.config import TrainConfig; from agents.training.sb3 import train; "
            "train(TrainConfig('ppo', out=tempfile.mkdtemp(), timesteps=64))",
            ["tensorboard", "TensorBoard logs", 'pip install "tether-gym[train]"'],
        ),
        (
            "rich",
            "import tempfile; from agents.training.config import TrainConfig; from agents.training.sb3 import train; "
            "train(TrainConfig('ppo', out=tempfile.mkdtemp(), timesteps=64))",
            ["rich", "--no-progress", 'pip install "tether-gym[train]"'],
        ),
        (
            "matplotlib",
            "import agents.common.files, tempfile; "
            "agents.common.files.prepare_table_outputs(tempfile.mkdtemp(), [], [], True, False, 'x')",
            ["matplotlib", "--no-plots", 'pip install "tether-gym[plots]"'],
        ),
    ],
)
def test_the_agents_name_the_extra_of_a_missing_module(blocked: str, code: str, expected: list[str]) -> None:
    """Each optional module made unimportable (None in sys.modules) before anything is imported."""
    probe = (
        f"import sys\nsys.modules[{blocked!r}] = None\n"
        "from tether_gym._optional import MissingExtraError\n"
        f"try:\n    {code}\nexcept MissingExtraError as error:\n    print(error)\nelse:\n    print('imported')\n"
    )
    result = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, timeout=300, cwd=ROOT)
    assert result.returncode == 0, result.stderr[-2000:]
    for text in expected:
        assert text in result.stdout, (text, result.stdout)


def test_a_console_script_reports_a_missing_extra_without_a_traceback() -> None:
    probe = (
        "import sys\nsys.modules['stable_baselines3'] = None\n"
        "sys.argv = ['tether-gym-train', '--timesteps', '64']\n"
        "from agents.common import commands\ncommands.train()\n"
    )
    result = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, timeout=300, cwd=ROOT)
    assert result.returncode == 1
    assert "Traceback" not in result.stderr
    assert result.stderr.startswith("tether-gym-train: error: stable_baselines3 is not installed")
    assert 'pip install "tether-gym[train]"' in result.stderr
