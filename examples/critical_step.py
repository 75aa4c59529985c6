"""The integrator's critical-step estimate against the true largest frequency, for every preset.

The central-difference method is stable (linear limit) for steps ``h <= 2 / omega_max``
(paper eq. 13).  The integrator never assembles a stiffness matrix; it bounds ``omega_max`` by
the largest *element* frequency (Irons-Treharne, paper eqs. 15-16), with each satellite's mass
split equally among its cables and every cable on its taut branch.  This example checks that
estimate against the truth:

* true step ``2 / omega_max`` with ``omega_max`` from the assembled tangent problem
  (:func:`tether_gym.analysis.max_frequency`, ``taut_branch=True``: a slack cable counts as just
  taut, since it can snap taut within one step);
* the closed-form estimate (the integrator's fast path) and the paper's finite-difference
  reference (eqs. 19-21), both from :meth:`tether_gym.BatchSimulator.critical_time_step`;
* the unsafe variants the physics notes warn about, computed inline here: (i) the paper's
  formula (17) ``omega_e^2 = n_n lambda_max / m_e`` with ``m_e`` the sum of the *full* node
  masses, (ii) the same formula with split masses (exact only for equal end masses), and
  (iii) the mass-aware element frequency ``k (1/m_i + 1/m_j)`` but with the full node masses
  instead of the split ones.  All three use the exact element eigenvalue
  ``lambda_max = 2 max(EA/L0, N/L)`` rather than the paper's column-L1 bound of it.

It does so at each preset's nominal shape and for many random configurations per preset:
perturbed positions (uniform stretch or shrink plus random displacements, so that some, all
or no cables are slack) and random node masses with ratios up to 1:100 (``Cluster.replace``).
An estimate is safe when ``estimate / true <= 1``.

It prints a table per preset and the spread of ``estimate / true`` over the random cases, and
writes ``critical_step.png`` (estimated vs true step, and the distribution of the ratio).

Run (a few seconds)::

    .venv/bin/python examples/critical_step.py                 # figure in outputs/
    .venv/bin/python examples/critical_step.py --docs          # also docs/img/critical_step.png
    .venv/bin/python examples/critical_step.py --cases 500 --seed 1
"""

from __future__ import annotations

import argparse
import shutil
import time
from pathlib import Path

import matplotlib
import matplotlib.ticker

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import tether_gym as tg  # noqa: E402
from tether_gym.analysis import max_frequency  # noqa: E402

DOCS_IMG = Path(__file__).resolve().parents[1] / "docs" / "img"

#: Safe estimates (what the package does), with their plot labels.
SAFE_METHODS = {
    "closed-form": "closed form (integrator)",
    "finite-difference": "finite difference (paper's reference)",
}
#: Unsafe variants, computed inline in :func:`unsafe_steps`.
UNSAFE_METHODS = {
    "eq17-full": "(i) eq. 17, full node masses",
    "eq17-split": "(ii) eq. 17, split masses",
    "full-node": "(iii) $k(1/m_i+1/m_j)$, full node masses",
}
METHODS = {**SAFE_METHODS, **UNSAFE_METHODS}
#: Short column titles of the printed tables.
SHORT = {
    "closed-form": "closed form",
    "finite-difference": "finite difference",
    "eq17-full": "(i) eq.17 full masses",
    "eq17-split": "(ii) eq.17 split masses",
    "full-node": "(iii) full node masses",
}
STYLE = {
    "closed-form": dict(color="tab:blue", marker="o"),
    "finite-difference": dict(color="tab:green", marker="s"),
    "eq17-full": dict(color="tab:red", marker="^"),
    "eq17-split": dict(color="tab:orange", marker="v"),
    "full-node": dict(color="tab:purple", marker="D"),
}


def element_stiffness(cluster: tg.Cluster, positions: np.ndarray) -> np.ndarray:
    """(m,) the larger eigenvalue of each cable's 3x3 block, ``max(EA/L0, N/L)``, N/m, taut branch.

    The cable's 6x6 element stiffness has largest eigenvalue ``lambda_max = 2 * max(EA/L0, N/L)``.
    """
    i, j = cluster.cables[:, 0], cluster.cables[:, 1]
    length = np.linalg.norm(positions[j] - positions[i], axis=1)
    tension = np.maximum(cluster.N0 + cluster.stiffness * (length - cluster.L0), 0.0)
    return np.maximum(cluster.stiffness, tension / length)


def unsafe_steps(cluster: tg.Cluster, positions: np.ndarray) -> dict[str, float]:
    """Critical steps ``2 / max_e(omega_e)`` of the unsafe element-frequency variants, s."""
    k_max = element_stiffness(cluster, positions)
    lambda_max = 2.0 * k_max  # largest eigenvalue of the 6x6 element stiffness
    nodes_per_element = 2.0  # n_n^e of eq. 17
    m_i, m_j = cluster.masses[cluster.cables[:, 0]], cluster.masses[cluster.cables[:, 1]]
    split = cluster.masses / cluster.degree
    s_i, s_j = split[cluster.cables[:, 0]], split[cluster.cables[:, 1]]
    omega2 = {
        # (i) paper eq. 17 with m_e = the full node masses: no mass split, wrong for unequal masses.
        "eq17-full": nodes_per_element * lambda_max / (m_i + m_j),
        # (ii) paper eq. 17 with the split masses: exact only when the two split masses are equal.
        "eq17-split": nodes_per_element * lambda_max / (s_i + s_j),
        # (iii) mass-aware element frequency, but each cable given the full node masses.
        "full-node": k_max * (1.0 / m_i + 1.0 / m_j),
    }
    return {name: float(2.0 / np.sqrt(value.max())) for name, value in omega2.items()}


def evaluate(clusters: list[tg.Cluster], positions: np.ndarray) -> dict[str, np.ndarray]:
    """Every critical-step figure, s, for clusters of one topology at positions (B, n, 3)."""
    batch = tg.BatchSimulator(clusters)
    batch.reset(positions)
    result: dict[str, np.ndarray] = {
        "true": np.array(
            [2.0 / max_frequency(c, x, taut_branch=True) for c, x in zip(clusters, positions, strict=True)]
        ),
        "closed-form": batch.critical_time_step("closed-form"),
        "finite-difference": batch.critical_time_step("finite-difference"),
        "slack": batch.slack.sum(axis=1),
        "all_slack": batch.slack.all(axis=1),
        "mass_ratio": np.array([c.masses.max() / c.masses.min() for c in clusters]),
    }
    unsafe = [unsafe_steps(c, x) for c, x in zip(clusters, positions, strict=True)]
    for name in UNSAFE_METHODS:
        result[name] = np.array([u[name] for u in unsafe])
    return result


def random_cases(cluster: tg.Cluster, count: int, rng: np.random.Generator) -> tuple[list[tg.Cluster], np.ndarray]:
    """``count`` randomised copies of ``cluster`` (masses) and perturbed positions (count, n, 3).

    Positions: the nominal shape scaled about its centroid by 1 + U(-1 %, +2 %) (shrinking
    slackens cables, stretching tautens them), plus Gaussian displacements with a std
    log-uniform between 0.1 % and 5 % of the mean cable length.  Masses: a quarter of the cases
    keep the preset's masses; in the others the lightest and heaviest nodes differ by a factor
    10**U(0, 2) (mass ratios up to 1:100) and the remaining nodes are log-uniform in between.
    """
    n = cluster.num_nodes
    centre = cluster.positions.mean(axis=0)
    cable_length = float(cluster.L0.mean())
    typical_mass = float(np.exp(np.log(cluster.masses).mean()))
    clusters: list[tg.Cluster] = []
    positions = np.empty((count, n, 3))
    for b in range(count):
        scale = 1.0 + rng.uniform(-0.01, 0.02)
        noise = cable_length * 10.0 ** rng.uniform(-3.0, np.log10(0.05))
        positions[b] = centre + scale * (cluster.positions - centre) + rng.normal(0.0, noise, (n, 3))
        if b % 4 == 0:
            clusters.append(cluster)
        else:
            width = rng.uniform(0.0, 2.0)  # decades: max mass ratio 10**width <= 100
            fractions = rng.uniform(size=n)
            low, high = rng.choice(n, size=2, replace=False)
            fractions[low], fractions[high] = 0.0, 1.0  # the band's ends: mass ratio exactly 10**width
            masses = typical_mass * 10.0 ** (width * (fractions - 0.5))
            clusters.append(cluster.replace(masses=masses))
    return clusters, positions


def ratio_stats(ratio: np.ndarray) -> str:
    """min / median / max of a ratio array and the share of unsafe (> 1) values."""
    return f"{ratio.min():.3f}  {np.median(ratio):.3f}  {ratio.max():.3f}  {100.0 * np.mean(ratio > 1.0 + 1e-12):5.1f}%"


def merge(results: dict[str, dict[str, np.ndarray]]) -> dict[str, np.ndarray]:
    """Concatenate the per-preset result arrays."""
    keys = next(iter(results.values())).keys()
    return {key: np.concatenate([r[key] for r in results.values()]) for key in keys}


def plot(results: dict[str, dict[str, np.ndarray]], path: Path, cases: int) -> None:
    """Scatter of estimated vs true step and box plots of the ratio, unsafe variants in warm colours."""
    merged = merge(results)
    true = merged["true"]
    fig, (left, right) = plt.subplots(1, 2, figsize=(12.5, 5.8), gridspec_kw={"width_ratios": [1.1, 1]})

    estimates = np.concatenate([merged[name] for name in METHODS])
    lo = min(true.min(), estimates.min()) / 1.25
    hi = max(true.max(), estimates.max()) * 1.25
    left.fill_between([lo, hi], [lo, hi], [hi, hi], color="tab:red", alpha=0.07, linewidth=0)
    left.text(lo * 1.08, hi / 1.08, "unsafe: estimate > true limit", color="tab:red", fontsize=9, va="top")
    left.plot([lo, hi], [lo, hi], color="black", linewidth=1.0, label="y = x (estimate = true limit)")
    # Unsafe variants first, the safe estimates on top (closed form last, most visible).
    for name in [*UNSAFE_METHODS, "finite-difference", "closed-form"]:
        style = STYLE[name]
        left.scatter(
            true,
            merged[name],
            s=7,
            alpha=0.45,
            color=style["color"],
            marker=style["marker"],
            linewidths=0,
            label=METHODS[name],
        )
    left.set_xscale("log")
    left.set_yscale("log")
    left.set_xlim(lo, hi)
    left.set_ylim(lo, hi)
    for axis in (left.xaxis, left.yaxis):
        axis.set_major_locator(matplotlib.ticker.FixedLocator([0.03, 0.05, 0.1, 0.2, 0.3, 0.5, 1.0]))
        axis.set_major_formatter(matplotlib.ticker.FormatStrFormatter("%g"))
        axis.set_minor_formatter(matplotlib.ticker.NullFormatter())
    left.set_xlabel(r"true critical step $2/\omega_{max}$ (s)")
    left.set_ylabel("estimated critical step (s)")
    left.legend(fontsize=7.5, loc="lower right", markerscale=2.5)
    left.grid(alpha=0.3, which="both")
    left.set_title(f"{len(true)} random configurations ({cases} per preset, {len(results)} presets)", fontsize=10)

    names = list(METHODS)
    ratios = [merged[name] / true for name in names]
    right.axhspan(1.0, 100.0, color="tab:red", alpha=0.07, linewidth=0)
    boxes = right.boxplot(ratios, whis=(0, 100), widths=0.55, patch_artist=True, medianprops=dict(color="black"))
    for patch, name in zip(boxes["boxes"], names, strict=True):
        patch.set_facecolor(STYLE[name]["color"])
        patch.set_alpha(0.55)
    jitter = np.random.default_rng(0)
    for position, (name, ratio) in enumerate(zip(names, ratios, strict=True), start=1):
        right.scatter(
            position + jitter.uniform(-0.18, 0.18, ratio.size),
            ratio,
            s=3,
            alpha=0.3,
            color=STYLE[name]["color"],
            linewidths=0,
        )
    right.axhline(1.0, color="black", linewidth=1.0)
    right.set_yscale("log")
    right.set_ylim(min(r.min() for r in ratios) / 1.15, max(r.max() for r in ratios) * 1.15)
    right.yaxis.set_major_locator(
        matplotlib.ticker.FixedLocator([0.5, 0.6, 0.7, 0.8, 0.9, 1.0, 1.25, 1.5, 2.0, 2.5, 3.0, 4.0, 5.0])
    )
    right.yaxis.set_major_formatter(matplotlib.ticker.FormatStrFormatter("%g"))
    right.yaxis.set_minor_locator(matplotlib.ticker.NullLocator())
    right.set_xticks(range(1, len(names) + 1))
    right.set_xticklabels([METHODS[n].replace(", ", ",\n").replace(" (", "\n(") for n in names], fontsize=7.5)
    right.set_ylabel("estimated step / true critical step")
    right.grid(alpha=0.3, axis="y")
    right.set_title("ratio estimate / true (> 1 is unsafe); whiskers span min to max", fontsize=10)
    fig.suptitle(
        "Critical time step: element-by-element estimates vs the assembled tangent problem "
        "(taut branch; random shapes, mass ratios up to 1:100)",
        fontsize=10.5,
    )
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(
        description=__doc__.split("\n\n")[0], formatter_class=argparse.ArgumentDefaultsHelpFormatter
    )
    parser.add_argument("--out", type=Path, default=Path("outputs"), help="output directory for the PNG")
    parser.add_argument("--docs", action="store_true", help="also write the figure to docs/img/")
    parser.add_argument("--seed", type=int, default=0, help="seed of the random configurations")
    parser.add_argument("--cases", type=int, default=300, help="random configurations per preset")
    args = parser.parse_args(argv)
    start = time.perf_counter()
    rng = np.random.default_rng(args.seed)

    header = (
        f"{'preset':<12} {'n':>2} {'m':>3} {'true (s)':>9} {'closed (s)':>10} {'FD (s)':>8} "
        f"{'closed/true':>11} {'FD/true':>8} {'(i)/true':>8} {'(ii)/true':>9} {'(iii)/true':>10}"
    )
    print("Nominal shapes (all cables taut, preset masses): critical step 2/omega_max, ratio estimate/true")
    print(header)
    print("-" * len(header))
    results: dict[str, dict[str, np.ndarray]] = {}
    for name in tg.preset_names():
        cluster = tg.make_cluster(name)
        nominal = evaluate([cluster], cluster.positions[None])
        t = nominal["true"][0]
        print(
            f"{name:<12} {cluster.num_nodes:>2} {cluster.num_cables:>3} {t:9.4f} "
            f"{nominal['closed-form'][0]:10.4f} {nominal['finite-difference'][0]:8.4f} "
            f"{nominal['closed-form'][0] / t:11.3f} {nominal['finite-difference'][0] / t:8.3f} "
            f"{nominal['eq17-full'][0] / t:8.3f} {nominal['eq17-split'][0] / t:9.3f} "
            f"{nominal['full-node'][0] / t:10.3f}"
        )
        clusters, positions = random_cases(cluster, args.cases, rng)
        results[name] = evaluate(clusters, positions)

    print(
        f"\nRandom configurations ({args.cases} per preset): ratio estimate/true (min, median, max) "
        "and share of unsafe cases (ratio > 1)"
    )
    print(f"{'':<12} {'slack':>7} {'max mass':>9}" + "".join(f" | {short:^29}" for short in SHORT.values()))
    print(f"{'preset':<12} {'cables':>7} {'ratio':>9}" + " | min    median max    unsafe" * len(SHORT))
    for name, r in results.items():
        slack = r["slack"]
        cables, ratio = f"{slack.min()}-{slack.max()}", f"1:{r['mass_ratio'].max():.0f}"
        line = f"{name:<12} {cables:>7} {ratio:>9}"
        line += "".join(f" | {ratio_stats(r[key] / r['true'])}" for key in SHORT)
        print(line)

    merged = merge(results)
    total = merged["true"].size
    print(
        f"\nAll {total} random cases ({np.mean(merged['slack'] > 0):.0%} with at least one slack cable, "
        f"{np.mean(merged['all_slack']):.0%} with every cable slack, "
        f"{np.mean(merged['slack'] == 0):.0%} all taut; mass ratios up to 1:{merged['mass_ratio'].max():.0f}):"
    )
    for key in METHODS:
        ratio = merged[key] / merged["true"]
        unsafe = np.mean(ratio > 1.0 + 1e-12)
        verdict = "safe" if unsafe == 0.0 else f"UNSAFE in {unsafe:.0%} of cases"
        print(
            f"  {SHORT[key]:<24} estimate/true min {ratio.min():.3f}  median {np.median(ratio):.3f}  "
            f"max {ratio.max():.3f}  -> {verdict}"
        )
    fd_above = int(np.sum(merged["finite-difference"] > merged["closed-form"] * (1 + 1e-9)))
    print(f"  finite-difference step larger than the closed form's in {fd_above} of {total} cases (documented: never)")

    args.out.mkdir(parents=True, exist_ok=True)
    path = args.out / "critical_step.png"
    plot(results, path, args.cases)
    written = [path]
    if args.docs:
        DOCS_IMG.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(path, DOCS_IMG / "critical_step.png")
        written.append(DOCS_IMG / "critical_step.png")
    print(f"wrote {', '.join(str(p) for p in written)}  ({time.perf_counter() - start:.1f} s)")


if __name__ == "__main__":
    main()
