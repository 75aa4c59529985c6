"""The examples and benchmarks run end to end (short settings) and write what they promise."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

#: Each runs a whole script in a fresh interpreter (figures, videos, benchmarks): minutes in all.
pytestmark = pytest.mark.slow

ROOT = Path(__file__).resolve().parents[2]


def run(script: str, *args: str) -> str:
    result = subprocess.run(
        [sys.executable, str(ROOT / script), *args], capture_output=True, text=True, timeout=600, cwd=ROOT
    )
    assert result.returncode == 0, result.stderr
    return result.stdout


def test_paper_example_writes_its_figures(tmp_path: Path) -> None:
    out = run("examples/paper_tetrahedron.py", "--out", str(tmp_path), "--duration", "5")
    for name in ("paper_fig3.png", "substeps.png", "energy.png"):
        assert (tmp_path / name).stat().st_size > 10_000
    assert "fraction of time with at least one slack cable" in out


def test_critical_step_example_reports_safe_estimates(tmp_path: Path) -> None:
    out = run("examples/critical_step.py", "--out", str(tmp_path), "--cases", "20")
    assert (tmp_path / "critical_step.png").stat().st_size > 10_000
    assert "closed form" in out and "-> safe" in out


@pytest.mark.parametrize(
    "script", ["benchmarks/core_speed.py", "benchmarks/safety_factor.py", "benchmarks/energy_guard.py"]
)
def test_benchmarks_run_in_quick_mode(script: str, tmp_path: Path) -> None:
    args = ["--quick"] + (["--plot", str(tmp_path / "sf.png")] if "safety" in script else [])
    out = run(script, *args)
    assert "substeps/s" in out or "drift" in out or "largest relative residual at 0.1" in out


@pytest.mark.parametrize(
    ("script", "last_row"),
    [("benchmarks/tether_snaps.py", "  16   0.200  sagging   KV"), ("benchmarks/tether_cost.py", "   16    16")],
)
def test_tether_benchmarks_run_in_quick_mode(script: str, last_row: str) -> None:
    out = run(script, "--quick")
    assert last_row in out  # every case of the quick grid ran and printed its row
    assert "nan" not in out.lower()


def test_env_benchmark_runs() -> None:
    result = subprocess.run(
        [sys.executable, "-m", "tether_gym.bench", "--steps", "300", "--repeats", "1"],
        capture_output=True,
        text=True,
        timeout=600,
        cwd=ROOT,
    )
    assert result.returncode == 0, result.stderr
    assert "TetherTetrahedron-v0" in result.stdout and "steps/s" in result.stdout
    # The roofline section: this CPU's limit and the fraction of it the batched advance reaches.
    assert "roofline, one thread" in result.stdout and "fraction" in result.stdout
    rows = [line for line in result.stdout.splitlines() if " % (" in line and "1024" in line]
    assert len(rows) == 4, result.stdout  # two ids, the integrator and the SIMD-lane prototype
    for row in rows:
        median, spread = row.split(" % (")
        low, high = (float(bound) for bound in spread.rstrip(" %)").split("-"))
        # A fraction of the limit, below it, within the range of its rounds.
        assert 0.0 < low <= float(median.split()[-1]) <= high < 100.0, row


def test_thread_scaling_benchmark_runs() -> None:
    out = run("benchmarks/thread_scaling.py", "--seconds", "0.5", "--rounds", "1")
    for expected in (
        "1 thread",
        "2 threads (parallel kernel)",
        "2 processes of 1 thread",
        "threading layer",
        "kernel",
        "Python",
    ):
        assert expected in out, out


def test_viewer_benchmark_runs() -> None:
    out = run("benchmarks/viewer_speed.py", "--no-browser", "--controllers", "passive")
    for expected in ("x real time", "export: one episode recorded and written", "RecordVideo", "ms per frame"):
        assert expected in out, out


def test_env_demo_runs(tmp_path: Path) -> None:
    out = run("examples/env_demo.py", "--out", str(tmp_path), "--seeds", "1", "--gif-steps", "5")
    assert (tmp_path / "env_energy.png").stat().st_size > 10_000
    assert (tmp_path / "env_demo.gif").stat().st_size > 1_000
    assert "velocity feedback" in out


def test_student_compute_benchmark_runs() -> None:
    out = run("benchmarks/student_compute.py", "--envs", "TetherChain-v0")
    rows = [line for line in out.splitlines() if line.startswith("| TetherChain-v0 |")]
    assert len(rows) == 1 and "CPU:" in out, out
    speedups = [float(cell.strip().rstrip("x").replace(",", "")) for cell in rows[0].split("|")[4:7:2]]
    assert all(speedup > 1.0 for speedup in speedups), rows  # the student is faster than the planner


def test_planner_memory_benchmark_runs(tmp_path: Path) -> None:
    """The planner's memory variants and the random correction run, and the predictability
    table reads a dataset: a correction that follows its own last value (and not the observation)
    is predicted from that value and not from the observation."""
    rng = np.random.default_rng(0)
    episodes, steps = 8, 50
    targets = np.zeros((steps, episodes, 3))
    for t in range(1, steps):
        targets[t] = 0.95 * targets[t - 1] + 0.1 * rng.standard_normal((episodes, 3))
    # Stored step by step, as a DAgger run stores its states.
    np.savez(
        tmp_path / "dataset.npz",
        observations=rng.standard_normal((steps * episodes, 5)).astype(np.float32),
        targets=targets.reshape(-1, 3).astype(np.float32),
        episode=np.tile(np.arange(episodes), steps),
        held_out=np.tile(np.arange(episodes) % 4 == 0, steps),
    )
    out = run(
        "benchmarks/planner_memory.py",
        *("--env", "TetherTetrahedron-v0", "--seeds", "1", "--random", "0.1"),
        *("--plans", "2,none,1", "2,action,1", "--dataset", str(tmp_path / "dataset.npz")),
    )
    r2 = {
        line.split("|")[1].strip(): float(line.split("|")[2]) for line in out.splitlines() if line.startswith("| y[t]")
    }
    assert r2["y[t] from y[t-1]"] > 0.7 and r2["y[t] from the observation"] < 0.1, out
    for expected in ("CPU:", "(the prior)", "random correction, std 0.1", "memory: none", "memory: action"):
        assert expected in out, out


def test_specialised_substep_benchmark_matches_the_lanes() -> None:
    out = run("benchmarks/specialised_substep.py", "--batch", "64", "--rounds", "1")
    assert "against _advance_lanes: the same bits" in out, out
    rows = [line for line in out.splitlines() if line.rstrip().endswith(" %")]
    assert len(rows) == 4, out  # both kernels, both intervals
    for row in rows:
        assert 0 < float(row.split()[-2]) < 100, row


@pytest.mark.parametrize(
    ("env_id", "reason"),
    [
        ("TetherBeadedTetrahedron-v0", "46 nodes"),
        ("TetherSpinningTriangle-v0", "turning frame"),
        ("TetherNope-v0", "unknown id 'TetherNope-v0'"),
    ],
)
def test_specialised_substep_benchmark_refuses_what_it_cannot_generate(env_id: str, reason: str) -> None:
    result = subprocess.run(
        [sys.executable, str(ROOT / "benchmarks/specialised_substep.py"), "--env-id", env_id, "--batch", "64"],
        capture_output=True,
        text=True,
        timeout=600,
        cwd=ROOT,
    )
    assert result.returncode == 2 and reason in result.stderr, result.stderr
