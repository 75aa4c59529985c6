"""The benchmark's two tracks, its use of the shipped reference ceiling (read, never rerun), its
quick mode and its run-time estimate. The ceiling columns are checked by hand against the
per-episode returns of a tiny run (short episodes, scripted controllers only) and a small
synthetic ceiling file."""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import scipy.stats
from hypothesis import given, settings
from hypothesis import strategies as st

import agents.evaluation.benchmark
import agents.evaluation.report
import tether_gym.registration
from agents.benchmark import build_parser, main
from agents.controllers.mpc import MPCSettings
from agents.evaluation.benchmark import (
    FULL_EPISODES,
    QUICK_EPISODES,
    SECONDS_PER_EPISODE_STEP,
    BenchmarkConfig,
    benchmark,
    track_ids,
)
from agents.evaluation.ceiling import CeilingRun, SeedNoise, write_ceiling
from agents.evaluation.plots import plot_excess_costs
from tether_gym.registration import ENV_IDS

STANDARD_ID = "TetherTetrahedron-v0"
#: The hard track these tests run the machinery on: the massless id that was once on it stands in
#: for the registry's track for the module, as an episode of tethers with mass costs several times
#: the compute.
HARD_TRACK = ("TetherDelayedTetrahedron-v0",)


@pytest.fixture(autouse=True, scope="module")
def _a_hard_track() -> Iterator[None]:
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(tether_gym.registration, "HARD_TRACK", HARD_TRACK)
        yield


def test_an_empty_track_is_refused_with_the_tracks_that_have_ids(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(tether_gym.registration, "HARD_TRACK", ())
    assert track_ids("hard") == []
    with pytest.raises(ValueError, match=r"the hard track has no ids at present .* pass --track standard or all"):
        BenchmarkConfig(track="hard")
    assert BenchmarkConfig(track="all").track == "all"


#: A few control steps per episode: the rollouts take a fraction of a second.
SHORT = {"max_episode_steps": 15}
FIRST_SEED = 10_000
#: The synthetic ceiling's seeds on the hard ids: a subset of the run's 4 (10 000..10 003), not its first.
CEILING_SEEDS = [10_001, 10_002, 10_003]
CEILING_RETURNS = dict(
    zip(HARD_TRACK, ([-0.31, -0.42, -0.27], [-0.22, -0.35, -0.29], [-0.25, -0.33, -0.3]), strict=False)
)


def _ceiling_run(env_id: str, seeds: list[int], returns: list[float], env_kwargs: dict[str, Any]) -> CeilingRun:
    """A ceiling entry with made-up returns (what the benchmark reads from the shipped file)."""
    return CeilingRun(
        env_id=env_id,
        settings=dataclasses.asdict(MPCSettings()),
        env_kwargs=dict(env_kwargs),
        seeds=np.asarray(seeds, dtype=np.int64),
        returns=np.asarray(returns, dtype=np.float64),
        seconds_per_step=0.1,
        wall_seconds=1.0,
        seed_noise=SeedNoise.from_returns(seeds[:2], [0, 1], [returns[:2], returns[:2]]),
        commit="test",
        date="2026-12-02T00:00:00Z",
        machine="test machine",
        command="test",
    )


def _no_planner(monkeypatch: pytest.MonkeyPatch) -> list[str]:
    """Fail the test if the benchmark builds the ceiling's planner (it must read the file); returns
    the names of the controllers it made, in order."""
    made: list[str] = []
    real = agents.evaluation.benchmark.make_controller

    def make(spec: str, env: Any, **kwargs: Any) -> Any:
        made.append(spec)
        assert spec != "mpc", "the benchmark built mpc where it must read the ceiling data"
        return real(spec, env, **kwargs)

    monkeypatch.setattr(agents.evaluation.benchmark, "make_controller", make)
    return made


def test_the_tracks_select_their_ids_and_refuse_conflicting_envs() -> None:
    assert track_ids("hard") == list(HARD_TRACK)
    assert track_ids("standard") == [env_id for env_id in ENV_IDS if env_id not in HARD_TRACK]
    assert track_ids("all") == list(ENV_IDS)
    assert BenchmarkConfig(env_ids=[HARD_TRACK[0]], track="hard").env_ids == (HARD_TRACK[0],)
    with pytest.raises(ValueError, match=rf"--envs names \['{STANDARD_ID}'\], which are not on the hard track"):
        BenchmarkConfig(env_ids=[HARD_TRACK[0], STANDARD_ID], track="hard")
    with pytest.raises(ValueError, match="not on the standard track"):
        BenchmarkConfig(env_ids=[HARD_TRACK[-1]], track="standard")
    with pytest.raises(ValueError, match="track .* must be one of"):
        BenchmarkConfig(track="medium")
    assert build_parser().parse_args([]).track == "all"
    with pytest.raises(SystemExit):
        build_parser().parse_args(["--track", "medium"])


def test_the_track_runs_only_its_ids_and_states_the_run_time(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    class Stop(Exception):
        pass

    ran: list[str] = []

    def first_rollout(controller: Any, env_id: str, *args: Any, **kwargs: Any) -> None:
        ran.append(env_id)
        raise Stop

    monkeypatch.setattr(agents.evaluation.benchmark, "rollout", first_rollout)
    made = _no_planner(monkeypatch)
    with pytest.raises(Stop):
        main(["--track", "hard", "--quick", "--no-plots", "--out", str(tmp_path / "hard")])
    printed = capsys.readouterr().out
    assert "QUICK MODE" in printed
    assert f"benchmark: {len(HARD_TRACK)} ids (0 standard, {len(HARD_TRACK)} hard)" in printed
    assert ran == [HARD_TRACK[0]]
    # The estimate is the cost model's, over the rollouts it loaded (300 steps each on the hard ids,
    # massless tethers): no mpc in the quick mode.
    assert all(ENV_IDS[env_id][1] == 300 for env_id in HARD_TRACK)
    line = next(text for text in printed.splitlines() if text.startswith("benchmark:"))
    rollouts = len(made)
    expected = rollouts * QUICK_EPISODES * 300 * SECONDS_PER_EPISODE_STEP[(False, False)]
    clock = agents.evaluation.report.clock(expected + agents.evaluation.benchmark.OVERHEAD_SECONDS)
    assert f"{rollouts} rollouts of {QUICK_EPISODES} episodes" in line
    assert f"estimated run time about {clock}" in line
    assert f"({rollouts * QUICK_EPISODES * 300} episode steps" in line


def test_the_quick_mode_settings() -> None:
    quick = BenchmarkConfig(quick=True)
    assert (quick.episodes, quick.controllers, quick.seed) == (QUICK_EPISODES, None, FIRST_SEED)
    assert BenchmarkConfig().episodes == FULL_EPISODES == 64
    assert BenchmarkConfig(episodes=5).episodes == 5
    with pytest.raises(ValueError, match="--quick fixes the episodes .*drop --episodes"):
        BenchmarkConfig(quick=True, episodes=16)
    with pytest.raises(ValueError, match="drop --controllers"):
        BenchmarkConfig(quick=True, controllers=["lqr"])
    args = build_parser().parse_args(["--quick"])
    assert (args.quick, args.episodes) == (True, None)
    # mpc costs about a hundred times a law per step: the estimate of a full run is dominated by it.
    assert SECONDS_PER_EPISODE_STEP[(True, False)] > 50 * SECONDS_PER_EPISODE_STEP[(False, False)]
    assert "--quick" in build_parser().format_help() and "full run" in build_parser().format_help()


def _t_interval(values: np.ndarray) -> tuple[float, float]:
    half = scipy.stats.t.ppf(0.975, values.size - 1) * values.std(ddof=1) / np.sqrt(values.size)
    return float(values.mean() - half), float(values.mean() + half)


def test_the_ceiling_columns_are_the_hand_computed_excess_costs(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    made = _no_planner(monkeypatch)
    file = tmp_path / "ceiling.json"
    runs = [_ceiling_run(env_id, CEILING_SEEDS, CEILING_RETURNS[env_id], SHORT) for env_id in HARD_TRACK]
    # The standard id's ceiling holds one seed of the run only: said and skipped, never invented.
    runs.append(_ceiling_run(STANDARD_ID, [10_003, 10_070], [-0.5, -0.6], SHORT))
    write_ceiling(runs, file)
    controllers = ["passive", "velocity_feedback", "lqr"]
    results = benchmark(
        BenchmarkConfig(
            env_ids=[STANDARD_ID, *HARD_TRACK],
            controllers=controllers,
            episodes=4,
            env_kwargs=SHORT,
            bootstrap_reps=200,
            ceiling_file=file,
            plots=False,
            out=tmp_path / "out",
        )
    )
    assert "mpc" not in made
    ceiling = results["ceiling"]
    standard, hard = ceiling["tracks"]["standard"], ceiling["tracks"]["hard"]
    assert standard["per_id"] == {} and standard["aggregate"] == {}
    assert standard["coverage"][STANDARD_ID].startswith("skipped: the benchmark's seeds (10000..10003) hold 1 of")
    per_id_means: dict[str, dict[str, float]] = {}
    for env_id in HARD_TRACK:
        entry = hard["per_id"][env_id]
        assert entry["seeds"] == CEILING_SEEDS
        assert hard["coverage"][env_id] == "on 3 of the ceiling's 3 seeds (10001..10003)"
        rows = [seed - FIRST_SEED for seed in CEILING_SEEDS]
        ceiling_returns = np.array(CEILING_RETURNS[env_id])
        returns = {
            name: np.array(results["per_id"][env_id]["controllers"][name]["returns"])[rows] for name in controllers
        }
        excess: dict[str, float] = {}
        for name in controllers:
            costs = (-returns[name]) / (-ceiling_returns) - 1.0
            got = entry["controllers"][name]
            assert got["excess_cost"]["mean"] == pytest.approx(costs.mean(), rel=1e-12)
            assert (got["excess_cost"]["low"], got["excess_cost"]["high"]) == pytest.approx(_t_interval(costs))
            assert got["excess_cost"]["beats"] == int(np.sum(returns[name] > ceiling_returns))
            score = 100 * (returns[name].mean() - returns["passive"].mean())
            score /= ceiling_returns.mean() - returns["passive"].mean()
            assert got["ceiling_score"]["mean"] == pytest.approx(score, rel=1e-9)
            excess[name] = float(costs.mean())
        law = min(["velocity_feedback", "lqr"], key=lambda name: excess[name])
        assert entry["best_law"] == law
        assert entry["room_left"]["mean"] == pytest.approx(excess[law], rel=1e-12)
        assert entry["controllers"]["ceiling"]["excess_cost"]["mean"] == 0.0
        per_id_means[env_id] = excess
    # The hard track's aggregate: with 1 or 2 ids, the IQM is their mean (25 % of 2 trims nothing).
    for name in controllers:
        aggregate = hard["aggregate"][name]["excess"]
        expected = np.mean([per_id_means[env_id][name] for env_id in HARD_TRACK])
        assert aggregate["ids"] == len(HARD_TRACK)
        assert aggregate["iqm"] == pytest.approx(expected, rel=1e-12)
        assert aggregate["mean"] == pytest.approx(expected, rel=1e-12)
    # The standard track's normalised-score aggregate never mixes in a hard id.
    assert results["tracks"]["hard"]["ids"] == list(HARD_TRACK)
    assert results["tracks"]["standard"]["aggregate_ids"] == [STANDARD_ID]
    # The files: benchmark.json holds it, benchmark.md has a table per track.
    data = json.loads((tmp_path / "out" / "benchmark.json").read_text())
    assert (
        data["ceiling"]["tracks"]["hard"]["per_id"][HARD_TRACK[0]]["best_law"]
        == hard["per_id"][HARD_TRACK[0]]["best_law"]
    )
    report = (tmp_path / "out" / "benchmark.md").read_text()
    assert (
        "## Standard track: 1 ids" in report
        and f"## Hard track (room left over the best scripted law): {len(HARD_TRACK)} ids" in report
    )
    assert "### Hard track (room left over the best scripted law): excess cost over the ceiling" in report
    first = hard["per_id"][HARD_TRACK[0]]
    room = first["room_left"]
    cell = f"{100 * room['mean']:+.1f} % [{100 * room['low']:+.1f}, {100 * room['high']:+.1f}]"
    assert f"| {HARD_TRACK[0]} | 3 | {first['best_law']} | {cell} |" in report
    assert f"- {STANDARD_ID}: skipped: the benchmark's seeds" in report
    plot_excess_costs(results, tmp_path / "excess_costs.png")
    assert (tmp_path / "excess_costs.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_a_named_ceiling_file_must_exist(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError, match="--ceiling-file .*no such file"):
        main(["--envs", STANDARD_ID, "--ceiling-file", str(tmp_path / "nope.json"), "--out", str(tmp_path / "o")])


def test_the_standard_aggregate_is_over_its_massless_ids(tmp_path: Path) -> None:
    """A beaded id is reported per id but left out of the standard track's aggregate (as in the
    reference scores); the aggregate's numbers are those of the massless ids alone."""
    beaded = "TetherBeadedChain-v0"
    settings = dict(
        controllers=["passive", "velocity_feedback", "lqr"],
        reference="lqr",
        episodes=3,
        env_kwargs=SHORT,
        bootstrap_reps=200,
        plots=False,
        ceiling_file=tmp_path / "ceiling.json",
    )
    seeds = [FIRST_SEED, FIRST_SEED + 1, FIRST_SEED + 2]
    write_ceiling(
        [_ceiling_run(env_id, seeds, [-0.3, -0.4, -0.5], SHORT) for env_id in (STANDARD_ID, beaded)],
        tmp_path / "ceiling.json",
    )
    both = benchmark(BenchmarkConfig(env_ids=[STANDARD_ID, beaded], out=tmp_path / "both", **settings))
    alone = benchmark(BenchmarkConfig(env_ids=[STANDARD_ID], out=tmp_path / "alone", **settings))
    standard = both["tracks"]["standard"]
    assert standard["ids"] == [STANDARD_ID, beaded] and standard["aggregate_ids"] == [STANDARD_ID]
    assert list(standard["left_out"]) == [beaded]
    assert both["per_id"][beaded]["controllers"]["velocity_feedback"]["normalised_score"] is not None
    assert both["aggregate_ids"] == 1 and both["aggregate"] == alone["aggregate"]
    # The same for the excess costs over the ceiling: the beaded id's are reported, outside the aggregate.
    ceiling = both["ceiling"]["tracks"]["standard"]
    assert list(ceiling["per_id"]) == [STANDARD_ID, beaded]
    assert ceiling["aggregate"]["lqr"]["excess"]["env_ids"] == [STANDARD_ID]
    assert ceiling["aggregate"] == alone["ceiling"]["tracks"]["standard"]["aggregate"]
    assert (
        "Outside the aggregate: TetherBeadedChain-v0 (beaded tethers"
        in (tmp_path / "both" / "benchmark.md").read_text()
    )


@settings(max_examples=60, deadline=None)
@given(
    env_ids=st.lists(st.sampled_from(list(ENV_IDS)), min_size=1, max_size=len(ENV_IDS), unique=True),
    track=st.sampled_from(["standard", "hard", "all"]),
)
def test_any_envs_and_track_are_run_or_refused_by_name(env_ids: list[str], track: str) -> None:
    """Property: --envs with --track runs exactly the ids named when all are on the track, and is
    otherwise refused with every id off the track named (never a silent subset)."""
    off_track = [env_id for env_id in env_ids if env_id not in track_ids(track)]
    if not off_track:
        assert BenchmarkConfig(env_ids=env_ids, track=track).env_ids == tuple(env_ids)
        return
    with pytest.raises(ValueError) as error:
        BenchmarkConfig(env_ids=env_ids, track=track)
    assert f"--envs names {off_track}, which are not on the {track} track" in str(error.value)
