"""Free damped vibration of the paper's tetrahedron from large initial conditions (paper, section 3).

Reproduces the numerical experiment of section 3 of the source paper: four satellites at the
corners of a regular tetrahedron, joined by six tension-only cables, released from large random
initial displacements (of order metres) and velocities (of order m/s) and left to vibrate with
the diagonal (mass-proportional) damping of the preset and no control.  The motion is strongly
nonlinear: cables keep going slack and snapping taut again.

Bias force.  The preset's cables carry a pretension N0, so the nominal tetrahedron is *not* an
equilibrium in free space: pretension alone pulls every satellite toward the centroid with
sqrt(6) N0 and the cluster would collapse.  As in the package's physics notes, each satellite
is held by the constant bias force ``p = f_int(nominal)`` (a steady outward thrust of
sqrt(6) N0 ~ 0.49 N for the default preset), which makes the nominal shape an equilibrium;
"free vibration" here means vibration about that held shape with the bias as the only external
force.  The rigid part of the random initial conditions (centroid shift, linear and angular
momentum) is removed so that the motion is deformation, not drift.

Pretension.  By default the cables carry N0 = 100 N (a pretension strain of 0.2 m), a
pretensioned net that vibrates about its shape with cables repeatedly going slack and snapping
taut, like the paper's Fig. 3; holding it takes a 245 N bias on each satellite, far beyond
cold-gas thrusters.  With the preset's own light pretension (``--N0 0.2``: a cable goes slack
once shortened by 0.4 mm, and the bias is 0.49 N) metre-scale initial conditions do not produce
an oscillation: the first snap throws the satellites inward at several m/s, almost every cable
stays slack, the cluster crumples by tens of metres while damping absorbs the energy, and the
bias re-expands it slowly.  That is the regime the thruster-control environments work in.

The run integrates ``sim.advance(interval, force=bias, record_steps=R)`` once per
interval (0.02 s by default), records the positions, the sub-step sizes, the slack cables and the energy account,
and writes three figures:

* ``paper_fig3.png``: x, y, z displacements (relative to nominal) of one corner satellite, with
  the spans during which at least one cable is slack shaded (compare with the paper's Fig. 3);
* ``substeps.png``: every integrator sub-step against time, together with the estimated
  critical step (closed form and the paper's finite-difference reference), the true linear
  limit ``2 / omega_max`` and the number of slack cables;
* ``energy.png``: kinetic and strain energy, energy dissipated by damping, work done by the
  bias force, and the energy-balance residual.

Run (well under a minute)::

    .venv/bin/python examples/paper_tetrahedron.py                # figures in outputs/
    .venv/bin/python examples/paper_tetrahedron.py --docs         # also docs/img/ for the README
    .venv/bin/python examples/paper_tetrahedron.py --seed 3 --disp 2 --vel 0.5 --duration 40
    .venv/bin/python examples/paper_tetrahedron.py --N0 0.2 --interval 0.1   # the light preset
"""

from __future__ import annotations

import argparse
import shutil
import time
from dataclasses import dataclass
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import tether_gym as tg  # noqa: E402
from tether_gym.analysis import max_frequency  # noqa: E402

DOCS_IMG = Path(__file__).resolve().parents[1] / "docs" / "img"
AXIS_NAMES = ("x", "y", "z")


@dataclass
class Run:
    """Everything recorded during one simulation, sampled at the end of each control interval."""

    cluster: tg.Cluster
    bias: np.ndarray  # (n, 3) N
    satellite: int
    t: np.ndarray  # (K+1,) s, sample times (t[0] = 0)
    displacement: np.ndarray  # (K+1, n, 3) m, positions minus nominal
    slack_count: np.ndarray  # (K+1,) number of slack cables
    max_tension: np.ndarray  # (K+1,) N, largest cable tension at the sample
    step_closed_form: np.ndarray  # (K+1,) s, estimated critical step (integrator's fast path)
    step_fd: np.ndarray  # (K+1,) s, paper's finite-difference reference estimate
    step_true: np.ndarray  # (K+1,) s, 2 / omega_max of the tangent problem (taut branch)
    kinetic: np.ndarray  # (K+1,) J
    strain: np.ndarray  # (K+1,) J
    dissipated: np.ndarray  # (K+1,) J
    work: np.ndarray  # (K+1,) J, work done by the bias force
    residual: np.ndarray  # (K+1,) J
    initial_energy: float  # J
    substep_end: np.ndarray  # (S,) s, time at the end of every sub-step
    substep_size: np.ndarray  # (S,) s
    safety_factor: float
    hold_drift: float  # m, drift of the held cluster released at rest at nominal
    nominal_strain: float  # J, strain energy of the pretensioned nominal shape
    initial_speed: float  # m/s, largest initial satellite speed
    seed: int


def rigid_free_initial_conditions(
    rng: np.random.Generator, nominal: np.ndarray, masses: np.ndarray, disp: float, vel: float
) -> tuple[np.ndarray, np.ndarray]:
    """Random displacements (std ``disp`` m) and velocities (std ``vel`` m/s), rigid parts removed.

    The centroid shift of the displacements and the linear and angular momentum of the velocities
    (about the centre of mass) are projected out, so the cluster starts in pure deformation.
    """
    dx = rng.normal(0.0, disp, nominal.shape)
    v = rng.normal(0.0, vel, nominal.shape)
    dx -= np.average(dx, axis=0, weights=masses)
    x0 = nominal + dx
    v -= np.average(v, axis=0, weights=masses)
    centre = np.average(x0, axis=0, weights=masses)
    r = x0 - centre
    angular_momentum = np.sum(masses[:, None] * np.cross(r, v), axis=0)
    inertia = sum(m * (r_i @ r_i * np.eye(3) - np.outer(r_i, r_i)) for m, r_i in zip(masses, r, strict=True))
    spin = np.linalg.solve(inertia, angular_momentum)
    v -= np.cross(spin, r)
    return x0, v


def simulate(
    seed: int, disp: float, vel: float, duration: float, interval: float, satellite: int, N0: float | None = None
) -> Run:
    """Integrate the held tetrahedron from random large initial conditions and record the run."""
    cluster = tg.make_cluster("tetrahedron") if N0 is None else tg.make_cluster("tetrahedron", N0=N0)
    nominal = cluster.positions
    sim = tg.Simulator(cluster)
    bias = sim.internal_forces(nominal)  # p = f_int(nominal): holds the pretensioned shape

    # Sanity check of the bias: released at rest at the nominal shape, the cluster must stay there.
    sim.reset(nominal)
    nominal_strain = float(sim.energy().strain)
    for _ in range(int(round(5.0 / interval))):
        sim.advance(interval, force=bias)
    hold_drift = float(np.abs(sim.positions - nominal).max())

    rng = np.random.default_rng(seed)
    x0, v0 = rigid_free_initial_conditions(rng, nominal, cluster.masses, disp, vel)
    sim.reset(positions=x0, velocities=v0)

    n_intervals = int(round(duration / interval))
    # Record more sub-steps per interval than the integrator can take at the default safety factor.
    max_per_interval = int(np.ceil(interval / (sim.batch.safety_factor * 0.5 * sim.critical_time_step()))) + 8

    samples: dict[str, list] = {
        key: []
        for key in (
            "displacement",
            "slack_count",
            "max_tension",
            "step_closed_form",
            "step_fd",
            "step_true",
            "kinetic",
            "strain",
            "dissipated",
            "work",
            "residual",
        )
    }

    def sample() -> None:
        x = sim.positions.copy()
        samples["displacement"].append(x - nominal)
        samples["slack_count"].append(int(sim.slack.sum()))
        samples["max_tension"].append(float(sim.tension.max()))
        samples["step_closed_form"].append(sim.critical_time_step("closed-form"))
        samples["step_fd"].append(sim.critical_time_step("finite-difference"))
        samples["step_true"].append(2.0 / max_frequency(cluster, x, taut_branch=True))
        report = sim.energy()
        for key in ("kinetic", "strain", "dissipated", "work", "residual"):
            samples[key].append(getattr(report, key))

    sample()
    initial_energy = sim.energy().initial
    step_sizes: list[np.ndarray] = []
    for _ in range(n_intervals):
        stats = sim.advance(interval, force=bias, record_steps=max_per_interval)
        if stats.substeps[0] > max_per_interval:
            raise RuntimeError(
                f"{stats.substeps[0]} sub-steps in one interval, more than the {max_per_interval} recorded"
            )
        step_sizes.append(stats.step_sizes[0, : stats.substeps[0]])
        sample()

    sizes = np.concatenate(step_sizes)
    return Run(
        cluster=cluster,
        bias=bias,
        satellite=satellite,
        t=interval * np.arange(n_intervals + 1),
        substep_end=np.cumsum(sizes),
        substep_size=sizes,
        safety_factor=sim.batch.safety_factor,
        initial_energy=float(initial_energy),
        hold_drift=hold_drift,
        nominal_strain=nominal_strain,
        initial_speed=float(np.linalg.norm(v0, axis=1).max()),
        seed=seed,
        **{key: np.array(value) for key, value in samples.items()},
    )


def shade_slack(ax: plt.Axes, t: np.ndarray, slack: np.ndarray, label: str | None = None) -> None:
    """Shade the spans of ``t`` where ``slack`` is true (each sample covers half an interval each side)."""
    ax.fill_between(
        t,
        0.0,
        1.0,
        where=slack,
        step="mid",
        transform=ax.get_xaxis_transform(),
        color="0.85",
        linewidth=0.0,
        label=label,
        zorder=0,
    )


def plot_displacements(run: Run, path: Path) -> None:
    """The paper's Fig. 3: displacement time histories of one corner satellite."""
    fig, axes = plt.subplots(3, 1, figsize=(9, 7.4), sharex=True)
    colours = ("tab:blue", "tab:orange", "tab:green")
    slack = run.slack_count > 0
    for d, ax in enumerate(axes):
        shade_slack(ax, run.t, slack, label="at least one cable slack" if d == 0 else None)
        ax.plot(
            run.t, run.displacement[:, run.satellite, d], color=colours[d], linewidth=1.0, label=f"$u_{AXIS_NAMES[d]}$"
        )
        ax.axhline(0.0, color="0.4", linewidth=0.6)
        ax.set_ylabel(f"$u_{AXIS_NAMES[d]}$ (m)")
        ax.grid(alpha=0.3)
    axes[0].legend(loc="upper right", fontsize=8)
    axes[-1].set_xlabel("time t (s)")
    axes[-1].set_xlim(run.t[0], run.t[-1])
    fig.suptitle(
        f"Tetrahedron, free damped vibration about the held nominal shape: satellite {run.satellite} "
        f"displacement from nominal\n(edge {run.cluster.L0[0]:g} m, {run.cluster.masses[0]:g} kg, "
        f"EA {run.cluster.EA[0] / 1e3:g} kN, N0 {run.cluster.N0[0]:g} N, damping C = "
        f"{run.cluster.damping[0] / run.cluster.masses[0]:g} 1/s x M; bias thrust "
        f"{np.linalg.norm(run.bias[0]):.3g} N outward on every satellite, no control;\n"
        f"initial displacement up to {np.linalg.norm(run.displacement[0], axis=1).max():.2f} m, "
        f"speed up to {run.initial_speed:.2f} m/s, seed {run.seed})",
        fontsize=10,
    )
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def plot_substeps(run: Run, path: Path) -> None:
    """Sub-step sizes against the estimated and true critical steps, with the slack-cable count."""
    fig, (ax, low) = plt.subplots(2, 1, figsize=(9, 6), sharex=True, gridspec_kw={"height_ratios": [2.3, 1]})
    ax.plot(
        run.t,
        run.step_true,
        color="black",
        linewidth=1.4,
        label=r"true linear limit $2/\omega_{max}$ (tangent stiffness, taut branch)",
    )
    ax.plot(
        run.t,
        run.step_closed_form,
        color="tab:blue",
        linewidth=1.5,
        label="estimated critical step, closed form (used by the integrator)",
    )
    ax.plot(
        run.t,
        run.step_fd,
        color="tab:purple",
        linestyle="--",
        linewidth=1.2,
        label="estimated critical step, paper's finite-difference reference",
    )
    ax.plot(
        run.t,
        run.safety_factor * run.step_closed_form,
        color="tab:blue",
        linestyle=":",
        linewidth=1.2,
        label=f"safety factor {run.safety_factor:g} x closed-form estimate (step cap)",
    )
    ax.plot(
        run.substep_end,
        run.substep_size,
        ".",
        color="tab:red",
        markersize=2.5,
        label=f"sub-steps taken ({run.substep_size.size}; {run.t[1] - run.t[0]:g} s intervals split evenly)",
    )
    ax.set_ylabel("time step (s)")
    ax.set_ylim(0.0, 1.45 * max(run.step_true.max(), run.step_closed_form.max()))
    ax.grid(alpha=0.3)
    ax.legend(loc="upper right", fontsize=7.5)
    ax.set_title("Integrator sub-steps and critical time step, tetrahedron in free damped vibration", fontsize=10)

    low.fill_between(run.t, run.slack_count, step="mid", color="tab:orange", alpha=0.35, linewidth=0.0)
    low.plot(run.t, run.slack_count, drawstyle="steps-mid", color="tab:orange", linewidth=0.8)
    low.set_ylabel(f"slack cables\n(of {run.cluster.num_cables})")
    low.set_ylim(0, run.cluster.num_cables + 0.3)
    low.set_yticks(range(0, run.cluster.num_cables + 1, 2))
    low.set_xlabel("time t (s)")
    low.set_xlim(run.t[0], run.t[-1])
    low.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def plot_energy(run: Run, path: Path) -> None:
    """Energy account over time and the energy-balance residual."""
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(9.5, 7), sharex=True, gridspec_kw={"height_ratios": [2.2, 1]})
    top.plot(run.t, run.kinetic, color="tab:red", linewidth=0.9, label="kinetic")
    top.plot(run.t, run.strain, color="tab:green", linewidth=0.9, label="strain (cables)")
    top.plot(run.t, run.dissipated, color="tab:blue", linewidth=1.5, label="dissipated by damping")
    top.plot(run.t, run.work, color="tab:purple", linewidth=1.0, label="work done by the bias force")
    top.plot(
        run.t,
        vibration_energy(run),
        color="black",
        linestyle="--",
        linewidth=1.1,
        label="vibration energy = kinetic + strain + bias potential\n   - strain of the pretensioned nominal shape",
    )
    top.axhline(
        run.initial_energy,
        color="0.5",
        linestyle=":",
        linewidth=1.0,
        label=f"initial kinetic + strain {run.initial_energy:.1f} J",
    )
    top.set_ylabel("energy (J)")
    top.legend(fontsize=8, loc="lower center", bbox_to_anchor=(0.5, 1.01), ncol=2, frameon=False)
    top.grid(alpha=0.3)
    bottom.plot(run.t, run.residual / run.initial_energy, color="black", linewidth=0.9)
    bottom.axhline(0.0, color="0.5", linewidth=0.6)
    bottom.set_ylabel("residual / initial energy")
    bottom.set_xlabel("time t (s)")
    bottom.grid(alpha=0.3)
    bottom.ticklabel_format(axis="y", style="sci", scilimits=(-2, 2))
    bottom.set_xlim(run.t[0], run.t[-1])
    fig.suptitle(
        "Energy account (residual = kinetic + strain - initial + dissipated - work; zero for the exact solution)",
        fontsize=10,
    )
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def vibration_energy(run: Run) -> np.ndarray:
    """(K+1,) energy above the held equilibrium, J: kinetic + strain + bias potential - nominal strain.

    The bias potential is ``-p . (x - x_nominal)``: minus the work done by the bias force since the
    start, minus ``p . u0`` for the initial displacement ``u0``; the strain energy of the pretensioned
    nominal shape is subtracted so that rest at the nominal shape has zero vibration energy.
    """
    bias_potential = -np.sum(run.bias * run.displacement[0]) - run.work
    return run.kinetic + run.strain + bias_potential - run.nominal_strain


def summarise(run: Run, interval: float) -> str:
    """A short text summary of the run."""
    sizes = run.substep_size
    vibration = vibration_energy(run)
    largest = np.linalg.norm(run.displacement, axis=2).max()
    residual = run.residual / run.initial_energy
    breaking = float(run.cluster.breaking_load.min())
    lines = [
        f"tetrahedron preset: {run.cluster.num_nodes} satellites of {run.cluster.masses[0]:g} kg, "
        f"{run.cluster.num_cables} cables, k = EA/L0 = {run.cluster.stiffness[0]:g} N/m, "
        f"N0 = {run.cluster.N0[0]:g} N",
        f"bias force p = f_int(nominal): {np.linalg.norm(run.bias, axis=1).max():.3f} N outward on each "
        f"satellite (sqrt(6) N0); held at rest for 5 s the cluster drifts {run.hold_drift:.1e} m",
        f"initial conditions (seed {run.seed}): largest displacement "
        f"{np.linalg.norm(run.displacement[0], axis=1).max():.2f} m, largest speed {run.initial_speed:.2f} m/s, "
        f"initial energy {run.initial_energy:.2f} J, duration {run.t[-1]:g} s in {interval:g} s intervals",
        f"sub-steps: {sizes.size}  (min {sizes.min():.5f} s, mean {sizes.mean():.5f} s, "
        f"max {sizes.max():.5f} s; safety factor {run.safety_factor:g})",
        f"critical step: closed form {run.step_closed_form.min():.4f}-{run.step_closed_form.max():.4f} s, "
        f"finite-difference {run.step_fd.min():.4f}-{run.step_fd.max():.4f} s, "
        f"true 2/omega_max {run.step_true.min():.4f}-{run.step_true.max():.4f} s",
        f"fraction of time with at least one slack cable: {np.mean(run.slack_count > 0):.3f} "
        f"(mean {run.slack_count.mean():.2f} of {run.cluster.num_cables} cables slack; sampled every "
        f"{interval:g} s)",
        f"largest sampled cable tension: {run.max_tension.max():.1f} N (breaking load {breaking:g} N)",
        f"largest displacement of any satellite from nominal: {largest:.2f} m",
        f"final energy fraction: vibration energy (kinetic + strain + bias potential - nominal strain) "
        f"{vibration[-1]:.3g} J / initial {vibration[0]:.4g} J = {vibration[-1] / vibration[0]:.2e} "
        f"(kinetic + strain alone: {(run.kinetic[-1] + run.strain[-1]) / run.initial_energy:.2e})",
        f"energy-balance residual / initial energy: final {residual[-1]:+.2e}, max |.| {np.abs(residual).max():.2e}",
    ]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(
        description=__doc__.split("\n\n")[0], formatter_class=argparse.ArgumentDefaultsHelpFormatter
    )
    parser.add_argument("--out", type=Path, default=Path("outputs"), help="output directory for the PNGs")
    parser.add_argument("--docs", action="store_true", help="also write the figures to docs/img/")
    parser.add_argument("--seed", type=int, default=7, help="seed of the random initial conditions")
    parser.add_argument("--disp", type=float, default=1.0, help="std of the initial displacements per component, m")
    parser.add_argument("--vel", type=float, default=1.0, help="std of the initial velocities per component, m/s")
    parser.add_argument("--duration", type=float, default=50.0, help="simulated time, s")
    parser.add_argument(
        "--interval",
        type=float,
        default=0.02,
        help="sampling interval (one advance call), s; short enough to see the snaps",
    )
    parser.add_argument(
        "--N0",
        type=float,
        default=100.0,
        help="cable pretension, N: 100 N makes a pretensioned net that vibrates about its "
        "shape as in the paper; the preset's own 0.2 N (light, thruster-held) crumples",
    )
    parser.add_argument(
        "--satellite", type=int, default=0, choices=range(4), help="corner satellite whose displacements are plotted"
    )
    args = parser.parse_args(argv)

    start = time.perf_counter()
    run = simulate(args.seed, args.disp, args.vel, args.duration, args.interval, args.satellite, args.N0)
    args.out.mkdir(parents=True, exist_ok=True)
    written = []
    for name, plot in (
        ("paper_fig3.png", plot_displacements),
        ("substeps.png", plot_substeps),
        ("energy.png", plot_energy),
    ):
        path = args.out / name
        plot(run, path)
        written.append(path)
        if args.docs:
            DOCS_IMG.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(path, DOCS_IMG / name)
            written.append(DOCS_IMG / name)
    print(summarise(run, args.interval))
    print(f"wrote {', '.join(str(p) for p in written)}  ({time.perf_counter() - start:.1f} s)")


if __name__ == "__main__":
    main()
