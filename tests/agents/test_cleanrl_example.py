"""The single-file PPO example (``examples/cleanrl_ppo.py``) trains for a few thousand steps in a
fresh interpreter and scores the result on held-out episodes with ``agents.scoring``."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def test_the_cleanrl_example_trains_and_prints_a_score() -> None:
    result = subprocess.run(
        [
            sys.executable,
            str(ROOT / "examples" / "cleanrl_ppo.py"),
            "--total-timesteps",
            "4096",
            "--num-envs",
            "8",
            "--num-steps",
            "256",
            "--eval-episodes",
            "4",
        ],
        capture_output=True,
        text=True,
        timeout=300,
        cwd=ROOT,
    )
    assert result.returncode == 0, result.stderr[-3000:]
    out = result.stdout
    # Two updates of 8 x 256 steps; a 256-step rollout outlasts no 300-step episode, the second
    # one holds the first episode ends and with them the first next-step reset steps.
    assert "iteration 1/2  step 2048  episode return (last 0)" in out
    assert "iteration 2/2  step 4096  episode return (last 8)" in out and "trained 4096 steps" in out
    assert "cleanrl_ppo on TetherTetrahedron-v0, 4 held-out episodes (seeds 10000..10003" in out
    assert re.search(r"return: -?\d+\.\d ± \d+\.\d", out)
    assert re.search(r"vs best baseline \w+: [+-]\d+\.\d\d \[", out)
    assert re.search(r"normalised score: -?\d+\.\d \[-?\d+\.\d, -?\d+\.\d\]", out), out
