"""The implicit-axial prototype (benchmarks/implicit_axial.py): its quick mode runs end to end, its
explicit control is the project's integrator, its IMEX step elongates the axial period as the
trapezoidal rule does, and every kick solves the tension-only complementarity problem."""

from __future__ import annotations

import importlib.util
import math
import re
import subprocess
import sys
from pathlib import Path
from types import ModuleType

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

ROOT = Path(__file__).resolve().parents[2]
SCRIPT = ROOT / "benchmarks" / "implicit_axial.py"


def load_prototype() -> ModuleType:
    """The benchmark script as a module (it is not part of the package)."""
    spec = importlib.util.spec_from_file_location("implicit_axial", SCRIPT)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules["implicit_axial"] = module  # dataclasses look their module up by name
    spec.loader.exec_module(module)
    return module


def run(*args: str) -> str:
    result = subprocess.run([sys.executable, str(SCRIPT), *args], capture_output=True, text=True, timeout=600, cwd=ROOT)
    assert result.returncode == 0, result.stderr
    return result.stdout


def mode_row(out: str, label: str) -> list[float]:
    """The four relative errors of the modes table's N = 8 row of ``label``."""
    match = re.search(rf"^\s+8  {re.escape(label)}\s+(\S+)\s+(\S+)\s+(\S+)\s+(\S+)\s*$", out, re.MULTILINE)
    assert match, f"no modes row for {label!r}"
    return [float(v) for v in match.groups()]


@pytest.mark.slow
def test_quick_mode_runs_and_measures_what_it_claims() -> None:
    out = run("--quick")
    for table in ("1. Modes", "2. Energy", "3. Snaps"):
        assert table in out
    assert "nan" not in out.lower()
    # The control is the project's scheme written in the prototype's code: the same errors.
    assert mode_row(out, "prototype explicit 0.1") == mode_row(out, "project explicit 0.1")
    # Newmark's period elongation on the axial mode: Omega h = 2 atan(omega h / 2).
    prototype = load_prototype()
    omega_h = 8.0 * prototype.critical_step(8) * prototype.exact_omega(0, 1)
    elongation = 2.0 * math.atan(0.5 * omega_h) / omega_h - 1.0
    axial = mode_row(out, "IMEX newmark lift 8")[3] - mode_row(out, "space only")[3]
    assert axial == pytest.approx(elongation, rel=0.05)  # measured -6.55e-3 against -6.54e-3
    # Every snap case printed its row; the implicit-Euler variant damps the axial mode away.
    assert re.search(r"^\s+8  sagging\s+IMEX euler lift 8 ", out, re.MULTILINE)
    damped = re.search(r"^\s+IMEX euler lift 8\s+\S+\s+(\S+)\s*$", out, re.MULTILINE)
    assert damped and float(damped.group(1)) < 0.1


@pytest.mark.slow
def test_quick_cost_mode_runs() -> None:
    out = run("--quick", "--cost")
    assert re.search(r"^\s+8  IMEX newmark lift 4\s+\d+\s+[\d.]+", out, re.MULTILINE)


@st.composite
def chains(draw: st.DrawFn) -> tuple[np.ndarray, ...]:
    """A chain of 2-12 segments, bent and stretched or slackened at random, moving at random."""
    segments = draw(st.integers(2, 12))
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    rest = 100.0 / segments
    x = np.zeros((segments + 1, 3))
    x[:, 0] = rest * np.arange(segments + 1) * draw(st.floats(0.97, 1.03))
    x[1:-1] += rng.normal(0.0, draw(st.floats(0.0, 0.3)) * rest, (segments - 1, 3))
    v = rng.normal(0.0, draw(st.floats(0.0, 2.0)), x.shape)
    masses = np.r_[50.0, np.full(segments - 1, 2.0 / segments), 50.0] * rng.uniform(0.5, 2.0, segments + 1)
    k = np.full(segments, 40e3 / rest) * rng.uniform(0.5, 2.0, segments)
    p = rng.normal(0.0, 10.0, x.shape)
    h = draw(st.floats(1e-4, 0.3))
    return (
        x,
        v,
        1.0 / masses,
        k,
        np.full(segments, rest),
        np.full(segments, 5.0),
        p,
        np.array([h, h * draw(st.floats(0.5, 1.0))]),
    )


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(case=chains(), scheme=st.sampled_from(["explicit", "newmark", "euler"]))
def test_fuzz_every_kick_solves_the_tension_only_complementarity_problem(case: tuple, scheme: str) -> None:
    """Whatever the shape, motion and step: y >= 0, and each tension is the positive part of its
    predicted implicit tension ``N_taut(x) + k h (c1 G v + c2 G dv)``, with ``dv`` the kick itself."""
    prototype = load_prototype()
    x, v, inv_m, k, L0, N0, p, (h, h_mid) = case
    c1, c2 = prototype.SCHEMES[scheme]
    dv = np.empty_like(v)
    y = np.zeros_like(k)
    _, converged, _ = prototype._kick(x, v, inv_m, k, L0, N0, p, h_mid, h, c1, c2, dv, y)
    assert converged
    delta = np.diff(x, axis=0)
    length = np.linalg.norm(delta, axis=1)
    e = delta / length[:, None]
    rate = (e * np.diff(v, axis=0)).sum(axis=1)
    change = (e * np.diff(dv, axis=0)).sum(axis=1)
    predicted = N0 + k * (length - L0) + k * h * (c1 * rate + c2 * change)
    if c2 == 0.0:
        predicted = N0 + k * (length - L0)
    scale = np.abs(predicted).max() + np.abs(y).max() + 1.0
    assert (y >= 0.0).all()
    np.testing.assert_allclose(y, np.maximum(predicted, 0.0), rtol=0.0, atol=1e-9 * scale)
    # The kick is Newton's law with those tensions.
    force = p.copy()
    force[:-1] += y[:, None] * e
    force[1:] -= y[:, None] * e
    np.testing.assert_allclose(dv, h_mid * inv_m[:, None] * force, rtol=1e-12, atol=1e-15)
