"""The API reference's docstring rewriting (docs/hooks/griffe_sphinx_roles.py)."""

from __future__ import annotations

import sys
from pathlib import Path
from types import ModuleType

import pytest

from tests.helpers import load_file

ROOT = Path(__file__).resolve().parents[2]


def load_extension() -> ModuleType:
    pytest.importorskip("griffe", reason="the docs extra (mkdocstrings) is not installed")
    return load_file("docs_griffe_sphinx_roles", "docs/hooks/griffe_sphinx_roles.py")


def test_roles_become_inline_code() -> None:
    roles = load_extension().roles_to_code
    assert roles("see :class:`~tether_gym.envs.TetherClusterEnv` and :func:`make_cluster`") == (
        "see `TetherClusterEnv` and `make_cluster`"
    )
    assert roles(":py:meth:`a.b`, ``kept``") == "`a.b`, ``kept``"
    assert roles("Run::\n\n    python x.py") == "Run:\n\n    python x.py"


def test_grouped_parameters_get_one_entry_each() -> None:
    split = load_extension().split_grouped_parameters
    text = (
        "Summary: a, b: not in a section.\n\nArgs:\n    n: N.\n    preset, cluster, **task: as for X.\n"
        "        More on them.\n    first, second,\n        third: wrapped names.\n\nNotes after."
    )
    assert split(text) == (
        "Summary: a, b: not in a section.\n\nArgs:\n    n: N.\n    preset: as for X.\n        More on them.\n"
        "    cluster: as for X.\n        More on them.\n    **task: as for X.\n        More on them.\n"
        "    first: wrapped names.\n    second: wrapped names.\n    third: wrapped names.\n\nNotes after."
    )


def test_the_reference_pages_name_only_modules_that_exist() -> None:
    """Every ``::: target`` of docs/api/ imports (a renamed module would fail the build later,
    with a less direct message)."""
    import importlib

    sys.path.insert(0, str(ROOT))
    targets = []
    for page in sorted((ROOT / "docs" / "api").glob("*.md")):
        lines = page.read_text(encoding="utf-8").splitlines()
        targets += [line[4:].strip() for line in lines if line.startswith("::: ")]
    assert len(targets) > 30
    for target in targets:
        module_name, _, attribute = target.rpartition(".")
        try:
            importlib.import_module(target)
        except ModuleNotFoundError:
            module = importlib.import_module(module_name)
            assert hasattr(module, attribute), f"docs/api names {target}, which {module_name} does not have"
