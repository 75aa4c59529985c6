"""The tutorial runs end to end, and docs/tutorial.md shows what it prints now."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from .test_figures import load_figures

ROOT = Path(__file__).resolve().parents[2]


def embedded_output() -> str:
    figures = load_figures()
    text = (ROOT / "docs" / "tutorial.md").read_text(encoding="utf-8")
    start, end = figures.block_markers("getting_started output")
    block = text[text.index(start) + len(start) : text.index(end)].strip()
    assert block.startswith("```text\n") and block.endswith("\n```"), "the tutorial's output block lost its fence"
    return block[len("```text\n") : -len("\n```")]


def test_getting_started_runs_and_prints_what_the_tutorial_shows(tmp_path: Path) -> None:
    # From another directory: the script imports the agents by their installed name.
    process = subprocess.run(
        [sys.executable, str(ROOT / "examples" / "getting_started.py")],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )
    assert process.returncode == 0, process.stderr
    assert process.stdout.rstrip() == embedded_output(), (
        "docs/tutorial.md shows another output than examples/getting_started.py prints now: run "
        "bash scripts/figures.sh --only tutorial"
    )
    # Each step of the tutorial printed its part.
    for step in ("1. cluster 'tetrahedron'", "2. TetherTetrahedron-v0", "3. 16 held-out episodes"):
        assert step in process.stdout
