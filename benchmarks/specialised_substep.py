"""How fast the integrator's sub-step could run with the state kept in lanes and the topology
compiled in: ``python benchmarks/specialised_substep.py``.

``BatchSimulator`` advances large batches in SIMD lanes (``_advance_lanes`` in
``tether_gym/_kernels.py``): each interval gathers a block of 64 clusters from the per-cluster
tables, sub-steps it with one vector loop per node, axis and cable, and scatters it back. Its
loops read the cable's two nodes through indices known only at run time, so every number goes
through memory between the loops. This script measures the other end of that design, for the
integrator's issue of reaching 4x its speed before the lanes:

- **a sub-step generated for one topology**: Python source with one straight-line sub-step per
  lane (every node, axis and cable written out, the cable's nodes as constants), looped over the
  lanes; every number of a block lives in one flat array at offsets known when it compiles, so
  LLVM proves the rows apart, vectorises the lane loop and keeps a lane's positions and forces
  in registers for the whole sub-step;
- **no gather or scatter and no interval's end**: the block stays in that layout between
  intervals, and the velocity at the interval's end and the energy books are left out. The
  time is the hot path's alone: step size, kick and drift with their work and damping books,
  cable forces with breaking, peak tension and the critical step's estimate.

First it checks that the generated sub-step is the integrator's: one interval of the id's first
block from the same state gives the same positions, velocities, forces, tensions, peaks, books
and sub-step counts, to the bit, as ``_advance_lanes``. Then, in rounds on one thread, it times
the generated kernel and the integrator's lane driver (``advance_parallel_in_lanes``, gather,
scatter and the interval's end included) over intervals of 0.1 s and 1 s, each round after
measuring the roofline's limit (``tether_gym.roofline``). It prints the CPU model with the
numbers. Run it on a quiet machine: about 40 s with the default three rounds.

Only small clusters: the straight-line body grows with the cables, and numba's SSA pass ran out
of recursion depth on the beaded tetrahedron (46 nodes, 48 cables), after 84 s of compiling with
one lane per pass and 8 minutes with two.
"""

from __future__ import annotations

import argparse
import importlib.util
import math
import re
import statistics
import sys
import tempfile
import textwrap
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from tether_gym import _kernels as k

#: Clusters per block, as the integrator's lanes (``_kernels.LANE_WIDTH``).
WIDTH = 64
#: The most nodes a generated sub-step takes (see the module docstring).
MAX_NODES = 8
#: The rows of a block's state, in order: (name, rows per node, per cable or one per lane).
_STATE = (
    ("position", "axis"),
    ("velocity", "axis"),  # the half-step velocity
    ("force", "axis"),  # the internal force
    ("applied", "axis"),
    ("previous", "axis"),  # the previous interval's applied force
    ("tension", "cable"),
    ("intact", "cable"),
    ("peak", "cable"),
    ("last_step", "lane"),
    ("elapsed", "lane"),
    ("substeps", "lane"),
    ("work", "lane"),
    ("dissipated", "lane"),
    ("omega2", "lane"),
    ("step_min", "lane"),
    ("step_max", "lane"),
    ("running", "lane"),
    ("blend", "lane"),
    ("flag", "lane"),  # 1: non-finite, 2: refused for its sub-step budget
    ("mass", "node"),
    ("damping", "node"),
    ("damping_step", "lane"),
    ("stiffness", "cable"),
    ("rest", "cable"),
    ("pretension", "cable"),
    ("inverse_mass", "cable"),
    ("breaking", "cable"),
)


#: Which table column each of a block's rows comes from (and, for the results, goes back to):
#: the node table's three columns from each, per axis; the cable table's; the cluster table's.
_NODE_COLUMNS = {
    "position": k.POSITION,
    "velocity": k.HALF_STEP_VELOCITY,
    "force": k.INTERNAL_FORCE,
    "applied": k.APPLIED_FORCE,
    "previous": k.PREVIOUS_FORCE,
}
_CABLE_PARAMETERS = {
    "stiffness": k.STIFFNESS,
    "rest": k.REST_LENGTH,
    "pretension": k.PRETENSION,
    "inverse_mass": k.INV_SPLIT_MASS_SUM,
    "breaking": k.BREAKING_LOAD,
}
_CABLE_STATE = {"tension": k.TENSION, "intact": k.INTACT, "peak": k.PEAK_TENSION}
_CLUSTER_BOOKS = {
    "last_step": k.LAST_STEP,
    "work": k.WORK,
    "dissipated": k.DISSIPATED,
    "omega2": k.OMEGA2,
    "step_min": k.STEP_MIN,
    "step_max": k.STEP_MAX,
}


@dataclass(frozen=True)
class Layout:
    """Where each number of a block lives: ``row(name, index)`` is its row of :data:`WIDTH` lanes
    in the block's flat ``(rows * WIDTH,)`` array."""

    nodes: int
    cables: int
    first_row: dict[str, int]
    rows: int

    @classmethod
    def of(cls, nodes: int, cables: int) -> Layout:
        per = {"axis": 3 * nodes, "node": nodes, "cable": cables, "lane": 1}
        first_row, row = {}, 0
        for name, kind in _STATE:
            first_row[name] = row
            row += per[kind]
        return cls(nodes, cables, first_row, row)

    def row(self, name: str, index: int = 0) -> int:
        return self.first_row[name] + index


def substep_source(topology: np.ndarray, interleave: int) -> tuple[str, Layout]:
    """Python source of ``advance_block(duration, safety_factor, max_step, max_substeps, block)``
    for the cables ``topology`` (M, 2): one control interval of a block of :data:`WIDTH` lanes,
    ``block`` the (rows * WIDTH,) float64 array of :class:`Layout`. Each sub-step is the lanes
    kernel's, operation for operation (the kick from rest after a reset and a cable's breaking
    energy are left out: the function raises if a cable breaks). ``interleave`` lanes share one
    pass of the loop body, so that their independent chains overlap."""
    pairs = [(int(i), int(j)) for i, j in np.asarray(topology)]
    layout = Layout.of(1 + max(max(pair) for pair in pairs), len(pairs))

    def at(name: str, index: int = 0) -> str:
        # Unsigned offsets: numba checks a signed index for wrap-around, which hides the
        # access pattern from LLVM's vectoriser.
        return f"block[np.uint64({layout.row(name, index) * WIDTH}) + lane]"

    lines = [
        f"last_step = {at('last_step')}",
        f"elapsed = {at('elapsed')}",
        f"taken = {at('substeps')}",
        f"running = {at('running')} != 0.0",
        f"omega2 = {at('omega2')}",
        f"damping_step = {at('damping_step')}",
        "h_stable = safety_factor * 2.0 / math.sqrt(omega2) if omega2 > 0.0 else math.inf",
        "h_stable = damping_step if h_stable > damping_step else h_stable",
        "h_stable = max_step if h_stable > max_step else h_stable",
        "remaining = duration - elapsed",
        "steps_wanted = remaining / h_stable - 1e-9",
        "refuse = running & ((taken >= max_substeps) | (steps_wanted > max_substeps - taken))",
        "steps_left = np.ceil(steps_wanted)",
        "ends = steps_left <= 1.0",
        "h = remaining if ends else remaining / steps_left",
        "h = h if running & (not refuse) else 0.0",
        "stepping = h > 0.0",
        "inverse_h_mid = 1.0 / (0.5 * (last_step + h))",
        f"blend = {at('blend')}",
        f"work = {at('work')}",
        f"dissipated = {at('dissipated')}",
    ]
    add = lines.append
    for i in range(layout.nodes):
        add(f"mass = {at('mass', i)}")
        add(f"damping = {at('damping', i)}")
        add("inertia = mass * inverse_h_mid")
        add("inverse_lhs = 1.0 / (inertia + 0.5 * damping)")
        add("rhs_factor = inertia - 0.5 * damping")
        add("speed2 = 0.0")
        for d in range(3):
            axis = 3 * i + d
            add(f"v_old = {at('velocity', axis)}")
            add(f"force = {at('force', axis)}")
            add(f"applied = {at('applied', axis)}")
            add(f"p_dual = applied + blend * ({at('previous', axis)} - applied)")
            add("kicked = (rhs_factor * v_old + p_dual - force) * inverse_lhs")
            add("v_new = kicked if stepping else v_old")
            add("dx = h * v_new")
            add(f"{at('velocity', axis)} = v_new")
            add(f"x{i}_{d} = {at('position', axis)} + dx if stepping else {at('position', axis)}")
            add(f"{at('position', axis)} = x{i}_{d}")
            add("work = work + applied * dx if stepping else work")
            add("speed2 += v_new * v_new")
            add(f"f{i}_{d} = 0.0 if stepping else force")
        add("lost = h * damping * speed2")
        add("dissipated = dissipated + lost if stepping else dissipated")
    add("omega2_max = 0.0")
    add("length_sum = 0.0")
    add("shortest = math.inf")
    for c, (i, j) in enumerate(pairs):
        add(f"stiffness = {at('stiffness', c)}")
        add(f"intact = {at('intact', c)}")
        add(f"peak = {at('peak', c)}")
        add("whole = intact != 0.0")
        add("counted = stepping & whole")
        for d, delta in enumerate(("dx", "dy", "dz")):
            add(f"{delta} = x{j}_{d} - x{i}_{d}")
        add("length = math.sqrt(dx * dx + dy * dy + dz * dz)")
        add("length_sum = length_sum + length if counted else length_sum")
        add("shortest = length if counted & (length < shortest) else shortest")
        add("inverse_length = 1.0 / length")
        add(f"n_taut = {at('pretension', c)} + stiffness * (length - {at('rest', c)})")
        add("n_cable = n_taut if (n_taut > 0.0) & whole else 0.0")
        add("geometric = n_cable * inverse_length")
        add("k_max = stiffness if stiffness >= geometric else geometric")
        add(f"w2 = k_max * {at('inverse_mass', c)}")
        add("omega2_max = w2 if counted & (w2 > omega2_max) else omega2_max")
        add(f"{at('peak', c)} = n_cable if stepping & (n_cable > peak) else peak")
        add(f"breaks = counted & (n_cable > {at('breaking', c)})")
        add("breaking_lanes += breaks")
        add(f"{at('intact', c)} = 0.0 if breaks else intact")
        add("n_cable = 0.0 if breaks else n_cable")
        add(f"{at('tension', c)} = n_cable if stepping else {at('tension', c)}")
        add("pulls = stepping & (n_cable != 0.0)")
        for d, delta in enumerate(("dx", "dy", "dz")):
            add(f"pull = n_cable * ({delta} * inverse_length)")
            add(f"f{i}_{d} = f{i}_{d} - pull if pulls else f{i}_{d}")
            add(f"f{j}_{d} = f{j}_{d} + pull if pulls else f{j}_{d}")
    for i in range(layout.nodes):
        for d in range(3):
            add(f"{at('force', 3 * i + d)} = f{i}_{d}")
    add(f"{at('work')} = work")
    add(f"{at('substeps')} = taken + 1.0 if stepping else taken")
    add(f"{at('last_step')} = h if stepping else last_step")
    add(f"{at('step_min')} = min({at('step_min')}, h) if stepping else {at('step_min')}")
    add(f"{at('step_max')} = max({at('step_max')}, h) if stepping else {at('step_max')}")
    add(f"{at('omega2')} = omega2_max if stepping else omega2")
    # The lanes' books add the cables' viscous power times h (none in the lanes) and the energy
    # breaking cables free (none here: a break raises); the same additions keep the same bits.
    add(f"{at('dissipated')} = dissipated + (h * 0.0 + 0.0) if stepping else dissipated")
    add("bad = stepping & (not ((abs(length_sum) < math.inf) & (shortest > 0.0)))")
    add("done = stepping & (bad | ends)")
    add(f"{at('elapsed')} = elapsed + h if stepping & (not done) else elapsed")
    add("still = running & (not done) & (not refuse)")
    add(f"{at('running')} = 1.0 if still else 0.0")
    add(f"{at('flag')} = 1.0 if bad else (2.0 if refuse else {at('flag')})")
    add("active += still")
    body = "\n".join(lines)
    # Each interleaved lane gets its own copy of the body's names.
    names = set(re.findall(r"^([a-z_][a-z_0-9]*) =", body, flags=re.M)) | {"lane"}
    pattern = re.compile(r"\b(" + "|".join(sorted(names, key=len, reverse=True)) + r")\b")
    copies = [
        f"lane_{copy} = np.uint64(k + {copy * WIDTH // interleave})\n" + pattern.sub(rf"\1_{copy}", body)
        for copy in range(interleave)
    ]
    source = f"""import math

import numpy as np
from numba import njit


@njit(error_model="numpy", nogil=True)
def advance_block(duration, safety_factor, max_step, max_substeps, block):
    first = True
    while True:
        active = 0
        breaking_lanes = 0
        for k in range({WIDTH // interleave}):
{textwrap.indent(chr(10).join(copies), " " * 12)}
        if first:  # the previous interval's force blends into the first sub-step only
            for k in range({WIDTH}):
                block[{layout.row("blend") * WIDTH} + k] = 0.0
            first = False
        if breaking_lanes > 0:
            raise ValueError("a cable broke: this benchmark leaves the breaking energy out")
        if active == 0:
            return
"""
    return source, layout


def compile_block(topology: np.ndarray, interleave: int, directory: Path) -> tuple[Callable[..., None], Layout]:
    """Write :func:`substep_source` to ``directory`` and import it: the generated kernel, not yet
    compiled (numba compiles it at the first call), and its layout."""
    source, layout = substep_source(topology, interleave)
    path = directory / f"specialised_substep_{interleave}.py"
    path.write_text(source)
    spec = importlib.util.spec_from_file_location(path.stem, path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.advance_block, layout


def gather(sim: Any, start: int, layout: Layout) -> np.ndarray:
    """The block of clusters ``start`` to ``start + WIDTH`` of ``sim``'s tables in ``layout``."""
    nodes, cables, clusters = sim.node_table, sim.cable_table, sim.cluster_table
    members = slice(start, start + WIDTH)
    if np.any(clusters[members, k.LAST_STEP] == 0.0):
        raise ValueError("a cluster starts from rest (just reset): the generated sub-step has no kick from rest")
    block = np.zeros((layout.rows, WIDTH))
    for i in range(layout.nodes):
        for d in range(3):
            for name, column in _NODE_COLUMNS.items():
                block[layout.row(name, 3 * i + d)] = nodes[members, i, column + d]
        block[layout.row("mass", i)] = nodes[members, i, k.MASS]
        block[layout.row("damping", i)] = nodes[members, i, k.DAMPING]
    for c in range(layout.cables):
        for name, column in (_CABLE_PARAMETERS | _CABLE_STATE).items():
            # Each peak starts at the tension, as in the lanes.
            block[layout.row(name, c)] = cables[members, c, k.TENSION if name == "peak" else column]
    for name, column in _CLUSTER_BOOKS.items():
        block[layout.row(name)] = clusters[members, column]
    safety_factor = sim.kernel_settings[k.SAFETY_FACTOR]
    block[layout.row("damping_step")] = [k._damping_step(nodes[b], safety_factor) for b in range(start, start + WIDTH)]
    return block.reshape(-1)


def start_interval(block: np.ndarray, layout: Layout) -> None:
    """The per-lane books of a new interval, as the lanes kernel sets them."""
    rows = block.reshape(layout.rows, WIDTH)
    rows[layout.row("elapsed")] = 0.0
    rows[layout.row("substeps")] = 0.0
    rows[layout.row("running")] = 1.0
    rows[layout.row("step_min")] = math.inf
    rows[layout.row("step_max")] = 0.0


def _simulator(env_id: str, batch: int) -> tuple[Any, float]:
    """The id's simulator at ``batch`` clusters after one control step from its random initial
    states (so no lane starts from rest), with each cluster's previous force equal to its applied
    force (so the first sub-step's blend changes nothing) and small random forces applied."""
    import gymnasium as gym

    envs = gym.make_vec(env_id, num_envs=batch)
    envs.reset(seed=0)
    envs.step(np.zeros(envs.action_space.shape, dtype=envs.action_space.dtype))
    task = envs.unwrapped.task  # type: ignore[attr-defined]
    sim = task.sim
    force = np.random.default_rng(1).normal(0.0, 0.05, sim.applied_force.shape)
    sim.node_table[:, :, k.APPLIED_FORCE : k.APPLIED_FORCE + 3] = force
    sim.node_table[:, :, k.PREVIOUS_FORCE : k.PREVIOUS_FORCE + 3] = force
    return sim, float(task.config.control_interval)


def _topology_and_tables(sim: Any) -> tuple[np.ndarray, ...]:
    """The integrator kernels' arguments after the settings: the cables' node pairs, then the
    node, cable, cluster and counter tables."""
    return sim.cables, sim.node_table, sim.cable_table, sim.cluster_table, sim.counter_table


def check_bits(advance_block: Callable[..., None], layout: Layout, env_id: str) -> list[str]:
    """One interval of the id's first block, generated kernel against ``_advance_lanes`` from the
    same state: the numbers that differ in any bit (an empty list when none does)."""
    sim, interval = _simulator(env_id, WIDTH)
    settings = sim.kernel_settings
    block = gather(sim, 0, layout)
    start_interval(block, layout)
    block.reshape(layout.rows, WIDTH)[layout.row("blend")] = 0.5  # any blend: previous == applied
    advance_block(interval, settings[k.SAFETY_FACTOR], settings[k.MAX_STEP], settings[k.MAX_SUBSTEPS], block)
    members = np.arange(WIDTH, dtype=np.int64)
    k._advance_lanes(interval, settings, *_topology_and_tables(sim), np.empty((WIDTH, 0)), members)
    rows = block.reshape(layout.rows, WIDTH)
    outputs = ("position", "velocity", "force")
    pairs = [
        (f"{name} {i}.{d}", rows[layout.row(name, 3 * i + d)], sim.node_table[:, i, _NODE_COLUMNS[name] + d])
        for name in outputs
        for i in range(layout.nodes)
        for d in range(3)
    ]
    pairs += [
        (f"{name} {c}", rows[layout.row(name, c)], sim.cable_table[:, c, column])
        for name, column in _CABLE_STATE.items()
        for c in range(layout.cables)
    ]
    pairs += [(name, rows[layout.row(name)], sim.cluster_table[:, column]) for name, column in _CLUSTER_BOOKS.items()]
    pairs.append(("substeps", rows[layout.row("substeps")], sim.counter_table[:, k.SUBSTEPS].astype(float)))
    return [name for name, generated, lanes in pairs if generated.tobytes() != lanes.tobytes()]


def _ns_per_substep(advance: Callable[[], int], intervals: int) -> float:
    started = time.perf_counter()
    substeps = sum(advance() for _ in range(intervals))
    return 1e9 * (time.perf_counter() - started) / substeps


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--env-id", default=None, help="a registered id (default: the default id)")
    parser.add_argument("--batch", type=int, default=1024, help=f"clusters, a multiple of {WIDTH} (default 1024)")
    parser.add_argument("--rounds", type=int, default=3, help="timing rounds (default 3)")
    parser.add_argument("--interleave", type=int, choices=(1, 2, 4), default=1, help="lanes per loop pass (default 1)")
    args = parser.parse_args(argv)

    import numba

    import tether_gym
    from tether_gym.bench import cpu_model
    from tether_gym.registration import ENV_IDS
    from tether_gym.roofline import measure_limits, substep_limit_ns

    env_id = args.env_id or tether_gym.DEFAULT_ENV_ID
    if env_id not in ENV_IDS:
        parser.error(f"unknown id {env_id!r}: use one of {', '.join(ENV_IDS)}")
    if args.batch <= 0 or args.batch % WIDTH:
        parser.error(f"--batch must be a positive multiple of {WIDTH}, got {args.batch}")
    sim, interval = _simulator(env_id, args.batch)
    if sim.node_table.shape[1] > MAX_NODES:
        parser.error(
            f"{env_id} has {sim.node_table.shape[1]} nodes: a generated sub-step takes at most {MAX_NODES} "
            "(its straight-line body grows with the cables; see the module docstring)"
        )
    if not all(k._lane_ready(sim.cable_table[b], sim.cluster_table[b]) for b in range(args.batch)):
        parser.error(f"{env_id} has axial damping or a turning frame, which the lanes do not carry")
    numba.set_num_threads(1)
    print(f"{env_id}, N = {args.batch}, one thread, {args.interleave} lanes per loop pass; CPU: {cpu_model()}")

    with tempfile.TemporaryDirectory() as directory:
        advance_block, layout = compile_block(sim.cables, args.interleave, Path(directory))
        started = time.perf_counter()
        differing = check_bits(advance_block, layout, env_id)
        print(f"compiled the generated sub-step in {time.perf_counter() - started:.1f} s")
        if differing:
            sys.exit(f"the generated sub-step differs from _advance_lanes in: {', '.join(differing)}")
        print(
            "one interval of the first block, against _advance_lanes: the same bits (positions, velocities, "
            "forces, tensions, peaks, books, sub-step counts)"
        )
        assembly = advance_block.inspect_asm(advance_block.signatures[0]).lower()
        registers = sorted(set(re.findall(r"vsqrtpd[^\n]*%(zmm|ymm|xmm)", assembly)))
        print(f"packed square roots in the generated kernel: {', '.join(registers) or 'none (not vectorised)'}")

        settings = sim.kernel_settings
        blocks = [gather(sim, start, layout) for start in range(0, args.batch, WIDTH)]
        substep_rows = slice(layout.row("substeps") * WIDTH, (layout.row("substeps") + 1) * WIDTH)
        every_cluster = np.ones(args.batch, dtype=np.bool_)
        no_record = np.empty((args.batch, 0))

        def generated(duration: float) -> Callable[[], int]:
            def advance() -> int:
                substeps = 0
                for block in blocks:
                    start_interval(block, layout)
                    advance_block(
                        duration, settings[k.SAFETY_FACTOR], settings[k.MAX_STEP], settings[k.MAX_SUBSTEPS], block
                    )
                    substeps += int(block[substep_rows].sum())
                return substeps

            return advance

        def lanes(duration: float) -> Callable[[], int]:
            def advance() -> int:
                k.advance_parallel_in_lanes(duration, every_cluster, settings, *_topology_and_tables(sim), no_record)
                return int(sim.counter_table[:, k.SUBSTEPS].sum())

            return advance

        # Each row: (kernel, interval multiple, intervals timed).
        rows = [("generated", 1, 100), ("lanes", 1, 100), ("generated", 10, 10), ("lanes", 10, 10)]
        for kernel, multiple, _ in rows:  # warm-up: compilation or cache load
            (generated if kernel == "generated" else lanes)(interval * multiple)()
        cluster = _cluster(env_id)
        times: dict[tuple[str, int], list[float]] = {(kernel, multiple): [] for kernel, multiple, _ in rows}
        fractions: dict[tuple[str, int], list[float]] = {key: [] for key in times}
        for _ in range(args.rounds):
            for kernel, multiple, intervals in rows:
                limit = substep_limit_ns(cluster, measure_limits(seconds=0.3, repeats=3))
                ns = _ns_per_substep((generated if kernel == "generated" else lanes)(interval * multiple), intervals)
                times[(kernel, multiple)].append(ns)
                fractions[(kernel, multiple)].append(limit / ns)
    print(f"\n{'kernel':<52}{'interval, s':>12}{'ns per sub-step (rounds)':>34}{'of the limit':>14}")
    names = {
        "generated": "generated sub-step, state kept in lanes",
        "lanes": "integrator's lanes (gather, scatter, interval end)",
    }
    for (kernel, multiple), ns in times.items():
        rounds = " / ".join(f"{value:.1f}" for value in ns)
        print(
            f"{names[kernel]:<52}{interval * multiple:>12.1f}{rounds:>34}"
            f"{100 * statistics.median(fractions[(kernel, multiple)]):>12.0f} %"
        )


def _cluster(env_id: str) -> Any:
    """The cluster of ``env_id``, for the roofline's limit."""
    import gymnasium as gym

    envs = gym.make_vec(env_id, num_envs=1)
    cluster = envs.unwrapped.task.cluster  # type: ignore[attr-defined]
    envs.close()
    return cluster


if __name__ == "__main__":
    main()
