"""The installed package: what the wheel holds, the installed import name of the agents, and the
console scripts. ``scripts/wheel_check.sh`` (in CI) installs the wheel and uses it; these tests
check the same contracts from the checkout, in seconds."""

from __future__ import annotations

import ast
import importlib
import os
import re
import shutil
import subprocess
import sys
import textwrap
import warnings
import zipfile
from pathlib import Path

import pytest

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - the project's dependency for Python 3.10
    import tomli as tomllib

from agents.common import commands

ROOT = Path(__file__).resolve().parents[2]
PYPROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))
#: The folders of the checkout and the names they are installed under.
INSTALLED_NAMES = {"tether_gym": "tether_gym", "agents": "tether_gym_agents"}


def _package_files(folder: Path) -> set[str]:
    """Every file under ``folder`` but the compiled caches (bytecode, numba's index and data)."""
    return {
        path.relative_to(folder).as_posix()
        for path in folder.rglob("*")
        if path.is_file() and "__pycache__" not in path.parts and path.suffix not in {".pyc", ".nbi", ".nbc"}
    }


def _agents_modules() -> list[Path]:
    """Every module of the agents package, in its rooms too."""
    return sorted((ROOT / "agents").rglob("*.py"))


@pytest.fixture(scope="module")
def wheel(tmp_path_factory: pytest.TempPathFactory) -> zipfile.ZipFile:
    """The wheel setuptools builds from a copy of the checkout's packaging files (built outside the
    checkout, so that no build/ or egg-info lands in it)."""
    source = tmp_path_factory.mktemp("source")
    for name in ("pyproject.toml", "README.md"):
        shutil.copy2(ROOT / name, source / name)
    for folder in INSTALLED_NAMES:
        shutil.copytree(ROOT / folder, source / folder, ignore=shutil.ignore_patterns("__pycache__"))
    out = tmp_path_factory.mktemp("dist")
    build = "import sys; from setuptools import build_meta; print(build_meta.build_wheel(sys.argv[1]))"
    result = subprocess.run(
        [sys.executable, "-c", build, str(out)], cwd=source, capture_output=True, text=True, timeout=300
    )
    assert result.returncode == 0, result.stderr[-3000:]
    return zipfile.ZipFile(out / result.stdout.strip().splitlines()[-1])


def test_the_wheel_holds_every_file_of_both_packages(wheel: zipfile.ZipFile) -> None:
    listed = set(wheel.namelist())
    for folder, installed in INSTALLED_NAMES.items():
        expected = {f"{installed}/{name}" for name in _package_files(ROOT / folder)}
        missing = sorted(expected - listed)
        assert not missing, (
            f"the wheel lacks {missing}: add a pattern for them to [tool.setuptools.package-data] "
            "(or their package to [tool.setuptools] packages) in pyproject.toml"
        )
    # The data the agents read: the hyperparameters, shipped policies with their manifests, py.typed.
    for name in (
        "tether_gym/py.typed",
        "tether_gym_agents/py.typed",
        "tether_gym_agents/hyperparams/ppo.yml",
        "tether_gym_agents/hyperparams/mpc.yml",
        "tether_gym_agents/models/TetherTetrahedron-v0/ppo/MANIFEST.sha256",
        "tether_gym_agents/models/TetherTetrahedron-v0/ppo/policy.safetensors",
    ):
        assert name in listed


def test_the_wheel_installs_no_generic_top_level_name(wheel: zipfile.ZipFile) -> None:
    top_level = {name.split("/")[0] for name in wheel.namelist() if not name.split("/")[0].endswith(".dist-info")}
    assert top_level == set(INSTALLED_NAMES.values())


def test_the_wheel_declares_the_console_scripts(wheel: zipfile.ZipFile) -> None:
    entry_points = next(name for name in wheel.namelist() if name.endswith(".dist-info/entry_points.txt"))
    text = wheel.read(entry_points).decode()
    for script, target in PYPROJECT["project"]["scripts"].items():
        assert f"{script} = {target}" in text


def test_runtime_files_are_read_from_inside_the_package() -> None:
    """Files found through ``__file__`` must lie in the package folder (which the wheel holds), not
    beside it in the checkout (which an installed package does not have): a module climbs at most
    to its package's root folder."""
    for folder in INSTALLED_NAMES:
        for path in sorted((ROOT / folder).rglob("*.py")):
            depth = len(path.relative_to(ROOT / folder).parts) - 1  # 0 for a module at the root
            for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
                if "__file__" not in line:
                    continue
                where = f"{path.relative_to(ROOT)}:{number}"
                climb = re.search(r"Path\(__file__\)\.resolve\(\)((?:\.parent)+)(?!s)", line)
                assert climb and climb.group(1).count(".parent") <= depth + 1, (
                    f"{where} reads a file outside its package folder: {line.strip()}"
                )
    # The files those paths name exist (a renamed folder would leave the wheel without them).
    from agents.common import data
    from agents.controllers import mpc

    assert mpc.MPC_SETTINGS_FILE.is_file()
    assert data.MODELS_DIR.is_dir() and any(data.MODELS_DIR.glob("*/*/MANIFEST.sha256"))
    assert (data.HYPERPARAMS_DIR / "ppo.yml").is_file()
    assert (data.REFERENCE_DIR / "reference_scores.json").is_file()
    assert all((data.PACKAGE_DIR / f"{command}.py").is_file() for command in ("train", "compare", "benchmark"))


@pytest.mark.parametrize("path", _agents_modules(), ids=lambda path: str(path.relative_to(ROOT / "agents")))
def test_agents_modules_import_each_other_relatively(path: Path) -> None:
    """Installed, the folder is ``tether_gym_agents``: an absolute ``agents`` import (at the top or
    inside a function) would fail there, or load another project's ``agents``."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.level == 0:
            names = [node.module or ""]
        elif isinstance(node, ast.Import):
            names = [alias.name for alias in node.names]
        else:
            continue
        for name in names:
            assert name != "agents" and not name.startswith("agents."), (
                f"{path.name}:{node.lineno} imports {name} absolutely: use a relative import (from .x import y)"
            )


def test_console_scripts_match_the_command_modules() -> None:
    scripts = PYPROJECT["project"]["scripts"]
    for command, script in commands.SCRIPTS.items():
        assert scripts[script] == f"tether_gym_agents.common.commands:{command}"
        assert callable(getattr(commands, command))
        module = (ROOT / "agents" / f"{command}.py").read_text(encoding="utf-8")
        # The module parses with agents.common.cli's parser before its slow imports (tests/agents/common/test_cli.py
        # checks that its build_parser is that parser).
        assert 'if __name__ == "__main__":' in module and f'parse_before_imports("{command}")' in module
    agents_scripts = {name for name, target in scripts.items() if target.startswith("tether_gym_agents.")}
    assert agents_scripts == set(commands.SCRIPTS.values())
    # The core's command takes no package name of the agents.
    assert scripts["tether-gym-bench"] == "tether_gym.bench:main"


def test_program_names_the_running_console_script(monkeypatch: pytest.MonkeyPatch) -> None:
    from agents import compare, train

    assert train.build_parser().prog == "python -m agents.train"
    assert commands.command_line("train", ["--seed", "1", "a b"]) == "python -m agents.train --seed 1 'a b'"
    monkeypatch.setattr(commands, "_running_script", "tether-gym-train")
    assert train.build_parser().prog == "tether-gym-train"
    assert commands.command_line("train", ["--seed", "1"]) == "tether-gym-train --seed 1"
    # Another command named from inside the running one is still one the user can run.
    assert compare.build_parser().prog == "python -m agents.compare"
    with pytest.raises(ValueError, match="unknown command 'evaluate'"):
        commands.program("evaluate")


def test_a_console_script_runs_its_module_as_python_m_does(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setattr(commands, "_running_script", None)
    monkeypatch.setattr(sys, "argv", ["tether-gym-convert", "--help"])
    with warnings.catch_warnings():
        # agents.convert may be imported already by other tests; the console script runs it fresh.
        warnings.filterwarnings("ignore", "'agents.convert' found in sys.modules", RuntimeWarning)
        with pytest.raises(SystemExit) as stop:
            commands.convert()
    assert stop.value.code == 0
    assert capsys.readouterr().out.startswith("usage: tether-gym-convert ")
    assert sys.argv == ["tether-gym-convert", "--help"]  # runpy puts argv[0] back


def test_the_agents_work_under_their_installed_name(tmp_path: Path) -> None:
    """The checkout's folder imported as ``tether_gym_agents`` with ``agents`` made unimportable:
    every module imports, every command's parser, description and recorded command line names the
    installed package, and ``python -m tether_gym_agents.compare --help`` runs."""
    (tmp_path / "tether_gym_agents").symlink_to(ROOT / "agents", target_is_directory=True)
    check = textwrap.dedent(
        """
        import importlib, importlib.abc, pkgutil, runpy, sys

        class NoAgents(importlib.abc.MetaPathFinder):
            def find_spec(self, name, path=None, target=None):
                if name == "agents" or name.startswith("agents."):
                    raise ImportError(f"{name} imported: the installed package is tether_gym_agents")
                return None

        sys.meta_path.insert(0, NoAgents())
        import tether_gym_agents
        from tether_gym_agents.common import commands
        from tether_gym_agents.training import shipping
        from tether_gym_agents.policies import pickled

        names = [info.name for info in pkgutil.walk_packages(tether_gym_agents.__path__, "tether_gym_agents.")]
        modules = {name.removeprefix("tether_gym_agents."): importlib.import_module(name) for name in names}
        for command in commands.SCRIPTS:
            parser = modules[command].build_parser()
            assert parser.prog == f"python -m tether_gym_agents.{command}", parser.prog
            assert "python -m agents." not in (parser.description or "") + (parser.epilog or ""), command
        assert commands.command_line("train", ["--seed", "3"]) == "python -m tether_gym_agents.train --seed 3"
        record = {"env_id": "TetherTetrahedron-v0", "algo": "ppo", "seed": 3}
        assert shipping.reproduce_command(record, "m").startswith("python -m tether_gym_agents.train --algo ppo")
        try:
            pickled.refuse_untrusted("x.zip", "--trust-pickle")
        except pickled.PickleNotTrustedError as error:
            refusal = str(error)
        assert "python -m tether_gym_agents.convert" in refusal, refusal
        assert not [name for name in sys.modules if name == "agents" or name.startswith("agents.")]
        print("modules", len(modules))
        sys.argv = ["compare", "--help"]
        runpy.run_module("tether_gym_agents.compare", run_name="__main__", alter_sys=True)
        """
    )
    # The checkout stays on the path for tether_gym; its agents/ is what the blocker keeps out.
    environment = {**os.environ, "PYTHONPATH": os.pathsep.join([str(tmp_path), str(ROOT)])}
    result = subprocess.run(
        [sys.executable, "-c", check], cwd=tmp_path, env=environment, capture_output=True, text=True, timeout=600
    )
    assert result.returncode == 0, result.stderr[-3000:]
    first_line, help_text = result.stdout.split("\n", 1)
    assert first_line == f"modules {len(_agents_modules()) - 1}"  # all but the top __init__
    assert help_text.startswith("usage: python -m tether_gym_agents.compare ")
    assert "python -m tether_gym_agents.convert makes a safe copy" in " ".join(help_text.split())


@pytest.mark.parametrize(
    ("module", "script"),
    [
        ("tether_gym.bench", "tether-gym-bench"),
        ("tether_gym.compile", "tether-gym-compile"),
        ("tether_gym.view", "tether-gym-view"),
    ],
)
def test_the_core_commands_name_themselves_as_the_user_ran_them(
    module: str, script: str, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    command = importlib.import_module(module)
    for argv0, usage in (
        (f"/venv/bin/{script}", f"usage: {script} "),
        (f"/x/{module.split('.')[1]}.py", f"usage: python -m {module} "),
    ):
        monkeypatch.setattr(sys, "argv", [argv0, "--help"])
        with pytest.raises(SystemExit) as exit_info:
            command.main(["--help"])
        assert exit_info.value.code == 0 and capsys.readouterr().out.startswith(usage)
