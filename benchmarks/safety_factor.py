"""Choose the integrator's default safety factor from measured energy drift.

What it measures
----------------
The sub-step of :class:`tether_gym.BatchSimulator` is ``safety_factor * 2 / omega_est``, a fraction
of the estimated linear stability limit.  The linear limit says nothing about what happens when a
cable snaps taut in the middle of a step: the tension-only force law has a kink, the leapfrog
scheme enters the taut branch at a random phase of its step grid, and every snap leaves a small
energy error of random sign.  With cables going slack and taut over and over, those errors add up
(a random walk, and for large steps a systematic gain), so the energy of an *undamped, unforced*
cluster -- which the exact solution conserves -- drifts.

For each safety factor this script integrates a batch of undamped clusters (``damping_rate=0``)
started from large random displacements of their satellites (the same seeds for every factor),
so that cables go slack and snap taut many times, over a long horizon, and reports:

* ``h/h_crit``   largest sub-step actually taken over the closed-form critical step (equal to the
                 factor: samples are taken every whole number of sub-steps);
* ``steps/s``    sub-steps per simulated second per cluster (the cost);
* ``any slack``  fraction of samples with at least one slack cable; ``all slack`` with every
                 cable slack (free flight);
* ``snaps/s``    slack-to-taut transitions per cluster per simulated second, counted between
                 samples (a lower bound: two snaps of one cable between samples count once);
* ``drift``      ``|E(t) - E0| / E0`` with ``E = kinetic + strain``: the worst over every seed and
                 sample up to ``--short-horizon`` and up to the full horizon, and the median over
                 seeds of each seed's worst;
* ``residual``   the worst ``|residual| / E0`` of the simulator's energy balance
                 (``kinetic + strain - initial + dissipated - work``).  Undamped and unforced it
                 equals ``E - E0``, so it must match the drift column; a second, damped and
                 thrust-driven batch (``--residual-horizon``) checks the bookkeeping of dissipated
                 energy and work, where the residual is the only error measure available.

It ends with a recommendation: the largest factor whose worst drift stays below ``--tolerance``
(1 %) over the full horizon, for every preset.  Runtime is well under two minutes on two cores;
``--quick`` shortens the horizon for a smoke test.

Usage::

    python benchmarks/safety_factor.py                 # full run (~1 min)
    python benchmarks/safety_factor.py --quick         # smoke test (seconds)
    python benchmarks/safety_factor.py --horizon 500 --batch 128 --plot outputs/sf.png
"""

from __future__ import annotations

import argparse
import math
import sys
import time
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

import tether_gym as tg

DEFAULT_FACTORS = (0.025, 0.05, 0.1, 0.15, 0.2, 0.25, 0.3, 0.4, 0.5, 0.6, 0.8, 0.9)


def unguarded_batch(cluster: tg.Cluster, batch: int, factor: float) -> tg.BatchSimulator:
    """A batch at ``factor``, beyond the stable range too (its warning silenced), and without the
    runaway guard: this script measures the drift the guard would stop."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", tg.simulator.UnstableSafetyFactorWarning)
        return tg.BatchSimulator(
            cluster, batch, safety_factor=factor, allow_unstable_safety_factor=True, energy_tolerance=math.inf
        )


@dataclass
class DriftResult:
    """Measurements of one (preset, safety factor) run; drifts are relative to E0, per seed."""

    preset: str
    factor: float
    step_ratio: float  # largest sub-step / closed-form critical step
    step_ms: float  # largest sub-step, ms
    substeps_per_second: float  # per cluster per simulated second
    any_slack: float  # fraction of samples with >= 1 slack cable
    all_slack: float  # fraction of samples with every cable slack
    snaps_per_second: float  # slack -> taut transitions per cluster per simulated second
    drift_short: np.ndarray  # (B,) worst |E - E0| / E0 up to the short horizon
    drift: np.ndarray  # (B,) worst |E - E0| / E0 up to the full horizon
    residual: np.ndarray  # (B,) worst |residual| / E0 (undamped run)
    residual_damped: float  # worst |residual| / E0 of the damped, forced check (nan if skipped)
    diverged: int  # clusters flagged non-finite or over the sub-step limit
    wall_seconds: float


def initial_state(
    cluster: tg.Cluster, batch: int, amplitude: float, speed: float, seed: int
) -> tuple[np.ndarray, np.ndarray]:
    """(B, n, 3) positions and velocities: nominal shape plus Gaussian displacements of std
    ``amplitude`` m and velocities of std ``speed`` m/s, both with zero mass-weighted mean (the
    centre of mass stays put, so E0 is all deformation and rotation energy)."""
    rng = np.random.default_rng(seed)
    n = cluster.num_nodes
    weights = (cluster.masses / cluster.masses.sum())[None, :, None]
    displacement = amplitude * rng.standard_normal((batch, n, 3))
    displacement -= (weights * displacement).sum(axis=1, keepdims=True)
    # A draw that shortens every cable leaves the cluster slack and at rest, with no energy at all;
    # reversing it lengthens the cables instead (to first order).
    x = cluster.positions[None] + displacement
    lengths = np.linalg.norm(x[:, cluster.cables[:, 1]] - x[:, cluster.cables[:, 0]], axis=-1)
    all_slack = (cluster.N0 + cluster.stiffness * (lengths - cluster.L0) <= 0.0).all(axis=1)
    displacement[all_slack] *= -1.0
    velocity = speed * rng.standard_normal((batch, n, 3))
    velocity -= (weights * velocity).sum(axis=1, keepdims=True)
    return cluster.positions[None] + displacement, velocity


def measure_drift(
    preset: str,
    factor: float,
    *,
    batch: int,
    horizon: float,
    short_horizon: float,
    sample_interval: float,
    amplitude: float,
    speed: float,
    seed: int,
) -> DriftResult:
    """Integrate ``batch`` undamped clusters over ``horizon`` s, sampling every ``sample_interval`` s."""
    cluster = tg.make_cluster(preset, damping_rate=0.0)
    sim = unguarded_batch(cluster, batch, factor)
    positions, velocities = initial_state(cluster, batch, amplitude, speed, seed)
    sim.reset(positions, velocities)
    energy0 = sim.energy().initial
    if not (energy0 > 0.0).all():
        count = int(np.count_nonzero(energy0 <= 0.0))
        raise RuntimeError(f"{count} clusters start with no energy; change --seed")
    # ``advance`` splits each interval into equal sub-steps no longer than the stable one, which
    # rounds the step down (at a 0.25 s interval, factors 0.8 and 0.9 would both take 0.083 s).
    # Sample every whole number of target sub-steps instead, so the factor tested is the factor
    # taken.  (The closed-form critical step of these presets does not depend on the state while
    # tensions stay below EA * L / L0, so the critical step at the start holds throughout.)
    target_step = factor * float(sim.critical_time_step().min())
    interval = target_step * max(1, math.floor(sample_interval / target_step))

    samples = max(1, round(horizon / interval))
    short_samples = max(1, round(short_horizon / interval))
    drift = np.zeros(batch)
    drift_short = np.zeros(batch)
    residual = np.zeros(batch)
    substeps = 0
    step_max = 0.0
    step_ratio = 0.0
    any_slack = 0.0
    all_slack = 0.0
    snaps = 0
    slack_before = sim.slack.copy()
    start = time.perf_counter()
    for k in range(samples):
        stats = sim.advance(interval)
        substeps += int(stats.substeps.sum())
        ok = ~stats.diverged
        if ok.any():
            step_max = max(step_max, float(stats.step_max[ok].max()))
            step_ratio = max(step_ratio, float((stats.step_max / sim.critical_time_step())[ok].max()))
        report = sim.energy()
        with np.errstate(invalid="ignore"):
            rel = np.abs(report.total - energy0) / energy0
            rel_residual = np.abs(report.residual) / energy0
        rel = np.where(ok, rel, np.inf)  # a diverged cluster counts as unbounded drift
        drift = np.maximum(drift, rel)
        residual = np.maximum(residual, np.where(ok, rel_residual, np.inf))
        if k < short_samples:
            drift_short = drift.copy()
        slack = sim.slack
        any_slack += float(slack.any(axis=1).mean())
        all_slack += float(slack.all(axis=1).mean())
        snaps += int((slack_before & ~slack).sum())
        slack_before = slack.copy()
    wall = time.perf_counter() - start
    simulated = samples * interval
    return DriftResult(
        preset=preset,
        factor=factor,
        step_ratio=step_ratio,
        step_ms=1e3 * step_max,
        substeps_per_second=substeps / (batch * simulated),
        any_slack=any_slack / samples,
        all_slack=all_slack / samples,
        snaps_per_second=snaps / (batch * simulated),
        drift_short=drift_short,
        drift=drift,
        residual=residual,
        residual_damped=math.nan,
        diverged=int(np.count_nonzero(sim.status)),
        wall_seconds=wall,
    )


def measure_damped_residual(
    preset: str, factor: float, *, batch: int, horizon: float, amplitude: float, seed: int
) -> float:
    """Worst |residual| / E0 of a damped cluster (preset damping) under random thrust that changes
    every control interval of ~0.1 s (the env's pattern), so that dissipated energy and work both enter the
    balance.  Thrust of up to ~1 N per satellite, a strong cold-gas thruster."""
    cluster = tg.make_cluster(preset)
    sim = unguarded_batch(cluster, batch, factor)
    positions, velocities = initial_state(cluster, batch, amplitude, 0.0, seed)
    sim.reset(positions, velocities)
    energy0 = sim.energy().initial
    rng = np.random.default_rng(seed + 1)
    worst = np.zeros(batch)
    # Control intervals of about 0.1 s, a whole number of target sub-steps (see measure_drift).
    target_step = factor * float(sim.critical_time_step().min())
    interval = target_step * max(1, math.floor(0.1 / target_step))
    for _ in range(max(1, round(horizon / interval))):
        thrust = rng.uniform(-1.0, 1.0, size=(batch, cluster.num_nodes, 3))
        sim.advance(interval, thrust)
        worst = np.maximum(worst, np.abs(sim.energy().residual) / energy0)
    worst[sim.status != 0] = np.inf
    return float(worst.max())


def percent(value: float) -> str:
    """A relative quantity as a compact percentage, or as a multiple of E0 once it exceeds 10
    (``3.2e+04 E0``); ``inf`` for diverged runs, ``-`` for runs not made."""
    if math.isnan(value):
        return "-"
    if not math.isfinite(value):
        return "inf"
    if value >= 10.0:
        return f"{value:.2g} E0"
    return f"{100.0 * value:.3g}%"


def print_table(results: list[DriftResult], short_horizon: float, horizon: float) -> None:
    """One row per safety factor, grouped by preset."""
    header = (
        f"{'preset':<12}{'factor':>7}{'h/h_crit':>9}{'h [ms]':>8}{'steps/s':>9}{'any slack':>10}"
        f"{'all slack':>10}{'snaps/s':>8}  {'worst@' + format(short_horizon, 'g') + 's':>11}"
        f"{'worst drift':>12}{'median':>11}{'residual':>12}{'damped res.':>12}{'div.':>5}{'wall s':>7}"
    )
    print(header)
    print("-" * len(header))
    preset = None
    for r in results:
        if preset is not None and r.preset != preset:
            print()
        preset = r.preset
        print(
            f"{r.preset:<12}{r.factor:>7.3g}{r.step_ratio:>9.3f}{r.step_ms:>8.2f}"
            f"{r.substeps_per_second:>9.1f}{r.any_slack:>10.1%}{r.all_slack:>10.1%}"
            f"{r.snaps_per_second:>8.3f}  {percent(r.drift_short.max()):>11}"
            f"{percent(r.drift.max()):>12}{percent(float(np.median(r.drift))):>11}"
            f"{percent(r.residual.max()):>12}{percent(r.residual_damped):>12}"
            f"{r.diverged:>5}{r.wall_seconds:>7.1f}"
        )
    print(
        f"\nworst@{short_horizon:g}s / worst drift: max over seeds and samples of |E(t)-E0|/E0 up to "
        f"{short_horizon:g} s / {horizon:g} s (values >= 10 shown as multiples of E0).\n"
        "median: median over seeds of each seed's worst drift.  residual: worst |energy-balance "
        "residual|/E0 of the same undamped run (equals the drift by construction: a bookkeeping check).\n"
        "damped res.: worst |residual|/E0 with the preset's damping and random thrust changed every "
        "~0.1 s.  div.: clusters flagged as diverged."
    )


def recommend(results: list[DriftResult], tolerance: float, attribute: str) -> dict[str, float | None]:
    """Per preset, the largest factor whose worst drift (``attribute``) stays below ``tolerance``,
    requiring every smaller factor to pass too (a factor that passes only by luck above a failing
    one is not trusted)."""
    chosen: dict[str, float | None] = {}
    for preset in dict.fromkeys(r.preset for r in results):
        best = None
        for r in sorted((r for r in results if r.preset == preset), key=lambda r: r.factor):
            if float(getattr(r, attribute).max()) < tolerance:
                best = r.factor
            else:
                break
        chosen[preset] = best
    return chosen


def save_plot(results: list[DriftResult], tolerance: float, short_horizon: float, horizon: float, path: Path) -> None:
    """Worst and median drift against the safety factor, log y, one colour per preset."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7.5, 4.8))
    for index, preset in enumerate(dict.fromkeys(r.preset for r in results)):
        colour = f"C{index}"  # matplotlib's default colour cycle
        rows = [r for r in results if r.preset == preset]
        factors = [r.factor for r in rows]
        cap = 1e9  # diverged (infinite) runs are drawn at this height
        worst = [min(float(r.drift.max()), cap) for r in rows]
        median = [min(float(np.median(r.drift)), cap) for r in rows]
        short = [min(float(r.drift_short.max()), cap) for r in rows]
        ax.semilogy(factors, worst, "o-", color=colour, label=f"{preset}: worst over {horizon:g} s")
        ax.semilogy(factors, median, "s--", color=colour, alpha=0.7, label=f"{preset}: median seed")
        ax.semilogy(factors, short, "^:", color=colour, alpha=0.7, label=f"{preset}: worst over {short_horizon:g} s")
    ax.axhline(tolerance, color="k", lw=0.8, ls="--", label=f"tolerance {tolerance:.0%}")
    ax.axvline(tg.DEFAULT_SAFETY_FACTOR, color="grey", lw=0.8, ls=":", label="current default")
    ax.set_xlabel("safety factor (sub-step / closed-form critical step)")
    ax.set_ylabel("relative energy drift |E(t) - E0| / E0")
    ax.set_title("Undamped slack/snap clusters: energy drift vs safety factor")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7, ncol=2)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)
    plt.close(fig)


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(
        description="Energy drift of undamped, repeatedly slackening and snapping clusters against the "
        "integrator's safety factor; recommends the default.",
        formatter_class=argparse.ArgumentDefaultsHelpFormatter,
    )
    parser.add_argument("--presets", nargs="+", default=["tetrahedron", "hub"], choices=tg.preset_names())
    parser.add_argument("--factors", nargs="+", type=float, default=list(DEFAULT_FACTORS))
    parser.add_argument("--batch", type=int, default=64, help="random seeds integrated together (B)")
    parser.add_argument("--horizon", type=float, default=2000.0, help="simulated time per run, s")
    parser.add_argument(
        "--short-horizon", type=float, default=100.0, help="also report the worst drift up to this time, s"
    )
    parser.add_argument(
        "--sample-interval",
        type=float,
        default=0.25,
        help="energy and slack are sampled about this often, s (below a taut phase, ~0.3 s)",
    )
    parser.add_argument("--amplitude", type=float, default=2.0, help="std of the initial displacements, m")
    parser.add_argument("--speed", type=float, default=0.0, help="std of the initial velocities, m/s")
    parser.add_argument(
        "--residual-horizon",
        type=float,
        default=100.0,
        help="length of the damped, thrust-driven residual check, s (0 to skip)",
    )
    parser.add_argument("--tolerance", type=float, default=0.01, help="acceptable worst relative drift")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--plot", default="outputs/safety_factor.png", help="PNG path ('' to skip)")
    parser.add_argument("--quick", action="store_true", help="smoke test: 50 s horizon, 16 seeds, 10 s residual check")
    args = parser.parse_args(argv)
    if args.quick:
        args.horizon, args.short_horizon, args.batch, args.residual_horizon = 50.0, 10.0, 16, 10.0
    args.short_horizon = min(args.short_horizon, args.horizon)
    if args.batch < 1 or args.horizon <= 0 or args.sample_interval <= 0:
        parser.error("--batch, --horizon and --sample-interval must be positive")
    if not all(0.0 < f <= 1.0 for f in args.factors):
        parser.error("safety factors must be in (0, 1]")
    args.factors = sorted(args.factors)
    return args


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    print("command:", " ".join([Path(sys.argv[0]).name, *(sys.argv[1:] if argv is None else argv)]))
    print(
        f"presets {args.presets}, undamped, B={args.batch} seeds, horizon {args.horizon:g} s, samples every <= "
        f"{args.sample_interval:g} s (whole sub-steps), displacements std {args.amplitude:g} m, "
        f"velocities std {args.speed:g} m/s"
    )
    # Compile the kernels (serial and parallel paths) before any timing.
    warm = tg.BatchSimulator(tg.make_cluster("tetrahedron"), max(args.batch, 16))
    warm.advance(0.1)
    tg.BatchSimulator(tg.make_cluster("tetrahedron"), 1).advance(0.1)

    results: list[DriftResult] = []
    start = time.perf_counter()
    for preset in args.presets:
        for factor in args.factors:
            result = measure_drift(
                preset,
                factor,
                batch=args.batch,
                horizon=args.horizon,
                short_horizon=args.short_horizon,
                sample_interval=args.sample_interval,
                amplitude=args.amplitude,
                speed=args.speed,
                seed=args.seed,
            )
            if args.residual_horizon > 0:
                result.residual_damped = measure_damped_residual(
                    preset,
                    factor,
                    batch=args.batch,
                    horizon=args.residual_horizon,
                    amplitude=args.amplitude,
                    seed=args.seed,
                )
            results.append(result)
    print(f"total {time.perf_counter() - start:.1f} s wall\n")
    print_table(results, args.short_horizon, args.horizon)

    if args.plot:
        save_plot(results, args.tolerance, args.short_horizon, args.horizon, Path(args.plot))
        print(f"\nplot saved to {args.plot}")

    tol = f"{args.tolerance:.0%}"
    print(
        f"\nRecommendation: the largest factor whose worst drift stays below {tol} (every smaller factor passing too)"
    )
    full = recommend(results, args.tolerance, "drift")
    short = recommend(results, args.tolerance, "drift_short")
    for preset in full:
        print(
            f"  {preset:<12} over {args.horizon:g} s: {full[preset]}    "
            f"over the first {args.short_horizon:g} s: {short[preset]}"
        )
    for label, chosen in ((f"{args.horizon:g} s", full), (f"{args.short_horizon:g} s", short)):
        if all(f is not None for f in chosen.values()):
            factor = min(chosen.values())  # type: ignore[type-var]
            # Sub-steps per simulated second scale as 1 / factor.
            print(
                f"  => over {label}: safety factor {factor:g} "
                f"({tg.DEFAULT_SAFETY_FACTOR / factor:.2g}x the sub-steps of the current default)"
            )
        else:
            print(f"  => over {label}: no tested factor keeps every preset below {tol}; test smaller factors")
    print(f"  current DEFAULT_SAFETY_FACTOR = {tg.DEFAULT_SAFETY_FACTOR:g}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
