"""Snaps of a slack beaded line: convergence in the segment count N and the safety factor.

What it measures
----------------
The issue's probe line: L = 100 m between two 50 kg satellites, a 2 kg tether (EA = 40 kN,
pretension 5 N), split into N segments with half a segment's mass lumped on each satellite.  Two
slack starts, each with the satellites flying apart at 0.5 m/s each, so that the line snaps taut,
whips its beads, and (undamped) snaps again and again:

* ``straight``: the line on its chord, every segment 1 % short of its reference length;
* ``sagging``: the satellites 98 m apart and the beads on a sine arc of 8.9 m (a line as long
  as its reference length, so it snaps at once).

Each start runs undamped and with a Kelvin-Voigt axial damping of the tether (``axial_damping``,
N*s/m) fixed once for all N: the damping ratio of the highest segment mode is ``zeta`` at
``N = 16`` and grows as ``zeta N / 16`` (a material damping damps high wavenumbers harder,
``zeta_k = c L omega_k / (2 EA)``), the physical regularisation of the snap's front.  A few
seeds add 1 cm of transverse noise on the beads, so that the lines are not exactly planar.

For every N in {4, 8, 16, 32, 64} and safety factor in {0.025, 0.05, 0.1, 0.2} (and, with the
opt-in, 0.3 and 0.5: the runaways), one ``BatchSimulator`` runs all cases of that N for
``--seconds`` in 0.01 s intervals, the runaway guard on.  It reports, per start and damping:

* the first snap's peak tension (largest segment tension in the first 2 s), N, median over seeds;
* the worst relative residual of the energy books over the run (``energy_guard.py``'s measure);
* the beads' peak speed over the satellites' peak speed (sampled at interval ends);
* how many cases the runaway guard flagged (status ``energy_runaway``).

Usage::

    python benchmarks/tether_snaps.py            # about 30 s on two shared cores
    python benchmarks/tether_snaps.py --quick    # N up to 16, two factors, 2 s
"""

from __future__ import annotations

import argparse
import math
import time
import warnings

import numpy as np

import tether_gym as tg
from tether_gym.simulator import BatchSimulator, UnstableSafetyFactorWarning
from tether_gym.tethers import Tether, build_cluster

LENGTH, SAT_MASS, LINE_MASS, EA, TENSION = 100.0, 50.0, 2.0, 40e3, 5.0
RUNAWAY = 3
SPEED = 0.5  # m/s, each satellite's speed away from the other
SAG = 8.9  # m, amplitude of the sagging start's sine arc
SAG_CHORD = 98.0  # m, the satellites' distance in the sagging start
NOISE = 0.01  # m, transverse noise on the beads
INTERVAL = 0.01  # s
FIRST_SNAP = 2.0  # s: the first snap's peak is taken over [0, FIRST_SNAP]
STARTS = ("straight", "sagging")


def kelvin_voigt_damping(zeta: float, at_segments: int = 16) -> float:
    """The tether's axial damping c (N*s/m) that gives its highest segment mode the damping ratio
    ``zeta`` when split into ``at_segments`` segments: the mode's ratio is ``N c / sqrt(EA m_t / L)``
    (a segment's dashpot ``N c`` over ``sqrt(k m)``, k = EA N / L, m = m_t / N)."""
    return zeta * math.sqrt(EA * LINE_MASS / LENGTH) / at_segments


def probe_line(segments: int, damping: float) -> tg.Cluster:
    """The probe's line along x, N segments, ``"half"`` lumping, axial damping in N*s/m."""
    spec = Tether((0, 1), EA=EA, segments=segments, mass=LINE_MASS, N0=TENSION, axial_damping=damping)
    return build_cluster([[0.0, 0.0, 0.0], [LENGTH, 0.0, 0.0]], SAT_MASS, [spec])


def slack_start(cluster: tg.Cluster, start: str, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """(n, 3) positions (m) and velocities (m/s) of a slack start of the probe's line."""
    x = cluster.positions.copy()
    if start == "straight":
        x[:, 0] *= 0.99
    else:
        x[:, 0] = 0.5 * (LENGTH - SAG_CHORD) + x[:, 0] * SAG_CHORD / LENGTH
        x[:, 1] = SAG * np.sin(math.pi * (x[:, 0] - x[0, 0]) / SAG_CHORD)
    beads = cluster.is_bead
    x[beads, 1:] += rng.normal(0.0, NOISE, (int(beads.sum()), 2))
    v = np.zeros_like(x)
    v[0, 0], v[1, 0] = -SPEED, SPEED
    return x, v


def relative_residual(sim: BatchSimulator) -> np.ndarray:
    """(B,) |energy-balance residual| over the energy scale of the books, now."""
    return sim.energy().relative_residual


def run_batch(
    segments: int, factor: float, dampings: tuple[float, ...], seeds: int, seconds: float, guard: float
) -> dict[str, np.ndarray]:
    """All cases of one N at one safety factor in one batch: (start, damping, seed) in that order.
    Returns per-case arrays: first-snap peak tension (N), worst residual, bead/satellite speed
    ratio, runaway flag, and the run's largest tension (N) and bead speed (m/s)."""
    rng = np.random.default_rng(segments)
    clusters, x0, v0 = [], [], []
    for start in STARTS:
        for damping in dampings:
            cluster = probe_line(segments, damping)
            for _ in range(seeds):
                x, v = slack_start(cluster, start, rng)
                clusters.append(cluster)
                x0.append(x)
                v0.append(v)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UnstableSafetyFactorWarning)
        sim = BatchSimulator(
            clusters, safety_factor=factor, allow_unstable_safety_factor=factor > 0.2, energy_tolerance=guard
        )
    sim.reset(np.array(x0), np.array(v0))
    beads = clusters[0].is_bead
    count = len(clusters)
    first_peak, peak = np.zeros(count), np.zeros(count)
    worst = np.zeros(count)
    bead_speed, satellite_speed = np.zeros(count), np.zeros(count)
    steps = round(seconds / INTERVAL)
    first_steps = round(FIRST_SNAP / INTERVAL)
    for step in range(steps):
        stats = sim.advance(INTERVAL)
        healthy = sim.status == 0
        tension = stats.peak_tension.max(axis=1)
        peak = np.where(healthy, np.maximum(peak, tension), peak)
        if step < first_steps:
            first_peak = np.where(healthy, np.maximum(first_peak, tension), first_peak)
        speed = np.linalg.norm(sim.velocities, axis=2)
        bead_speed = np.where(healthy, np.maximum(bead_speed, speed[:, beads].max(axis=1)), bead_speed)
        satellite_speed = np.where(healthy, np.maximum(satellite_speed, speed[:, ~beads].max(axis=1)), satellite_speed)
        worst = np.where(healthy, np.maximum(worst, relative_residual(sim)), worst)
    return {
        "first_peak": first_peak,
        "residual": worst,
        "speed_ratio": bead_speed / satellite_speed,
        "flagged": sim.status == RUNAWAY,
        "peak": peak,
        "bead_speed": bead_speed,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="N = 4, 8, 16; factors 0.05 and 0.2; 2 s; 2 seeds")
    parser.add_argument("--seconds", type=float, default=None, help="simulated time per case, s (default 10)")
    parser.add_argument("--zeta", type=float, default=0.05, help="damping ratio of the highest mode at N = 16")
    parser.add_argument("--no-guard", action="store_true", help="turn the runaway guard off (what it would stop)")
    args = parser.parse_args()
    segment_counts: tuple[int, ...]
    factors: tuple[float, ...]
    if args.quick:
        segment_counts, factors, seeds, seconds = (4, 8, 16), (0.05, 0.2), 2, 2.0
    else:
        segment_counts, factors, seeds, seconds = (4, 8, 16, 32, 64), (0.025, 0.05, 0.1, 0.2, 0.3, 0.5), 4, 10.0
    if args.seconds is not None:
        seconds = args.seconds
    damping = kelvin_voigt_damping(args.zeta)
    dampings = (0.0, damping)
    print(
        f"probe line L={LENGTH:g} m, satellites {SAT_MASS:g} kg, m_t={LINE_MASS:g} kg, EA={EA:g} N, T={TENSION:g} N; "
        f"{seeds} seeds x {len(STARTS)} starts x {len(dampings)} dampings per batch, {seconds:g} s each"
    )
    print(
        f"Kelvin-Voigt: axial_damping {damping:.4g} N*s/m (highest segment mode's damping ratio "
        f"{args.zeta:g} at N = 16, {args.zeta:g} N / 16 at N)"
    )
    print(
        "first peak: median over seeds of the largest tension in the first 2 s (N); residual: worst relative "
        "energy residual; whip: beads' peak speed / satellites'; flagged: runaway guard (healthy cases only above)"
    )
    header = "   N  factor  start     damping  first peak (N)  residual  whip   flagged  max T (N)  max bead v (m/s)"
    print(header)
    guard = math.inf if args.no_guard else tg.simulator.ENERGY_RUNAWAY_TOLERANCE
    began = time.perf_counter()
    for segments in segment_counts:
        for factor in factors:
            result = run_batch(segments, factor, dampings, seeds, seconds, guard)
            for s, start in enumerate(STARTS):
                for d, value in enumerate(dampings):
                    rows = slice((s * len(dampings) + d) * seeds, (s * len(dampings) + d + 1) * seeds)
                    print(
                        f"{segments:4d}  {factor:6.3f}  {start:8s}  {'KV' if value else 'none':7s}  "
                        f"{np.median(result['first_peak'][rows]):14.1f}  {result['residual'][rows].max():8.2g}  "
                        f"{result['speed_ratio'][rows].max():5.1f}  "
                        f"{int(result['flagged'][rows].sum()):3d}/{seeds:<3d}  "
                        f"{result['peak'][rows].max():9.0f}  {result['bead_speed'][rows].max():16.1f}",
                        flush=True,
                    )
    print(f"done in {time.perf_counter() - began:.0f} s")


if __name__ == "__main__":
    main()
