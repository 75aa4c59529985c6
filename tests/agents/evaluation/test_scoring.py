"""Scoring a policy against reference scores (``agents.evaluation.scoring``): the converter from a
benchmark.json, the statistics of :func:`score_policy` against the benchmark's own numbers, and
its errors.

The tests run on a small benchmark of their own (one id, 8 episodes of 20 steps, with mpc), so
that they take seconds; tests/agents/test_reference_scores.py checks the shipped file.
"""

from __future__ import annotations

import copy
import dataclasses
import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import agents.scoring
from agents.common.cli import HELD_OUT_SEED
from agents.common.files import OutputExistsError
from agents.controllers.registry import BASELINES
from agents.evaluation.benchmark import BenchmarkConfig, benchmark
from agents.evaluation.scoring import (
    FORMAT,
    ReferenceDataError,
    load_reference,
    merge_reference,
    reference_from_benchmark,
    run_of,
    score_policy,
    score_returns,
    write_reference,
)
from agents.policies import TrainedPolicy, shipped_models
from agents.scoring import main

ENV_ID = "TetherTetrahedron-v0"
#: Enough episodes that the bootstrap's percentiles depend on its seed (4 give too few distinct resamples).
EPISODES = 8
SMALL_CONTROLLERS = ["passive", "lqr", "local_tension_aware", "mpc", "ars"]


@pytest.fixture(scope="module")
def small_benchmark(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A benchmark.json of one id, 8 held-out episodes of 20 steps, with mpc (the score's 100)."""
    out = tmp_path_factory.mktemp("benchmark")
    benchmark(
        BenchmarkConfig(
            env_ids=[ENV_ID],
            controllers=SMALL_CONTROLLERS,
            episodes=EPISODES,
            env_kwargs={"max_episode_steps": 20},
            bootstrap_reps=100,
            plots=False,
            out=out,
        )
    )
    return out / "benchmark.json"


@pytest.fixture(scope="module")
def small_reference(small_benchmark: Path) -> dict[str, Any]:
    return reference_from_benchmark(json.loads(small_benchmark.read_text()), "abc1234", "2026-01-01T00:00:00Z", "test")


def _benchmark_entry(path: Path, name: str) -> dict[str, Any]:
    return json.loads(path.read_text())["per_id"][ENV_ID]["controllers"][name]


@pytest.mark.parametrize("name", SMALL_CONTROLLERS)
def test_scoring_a_benchmark_controller_reproduces_its_numbers(
    name: str, small_benchmark: Path, small_reference: dict[str, Any]
) -> None:
    """A fresh rollout of each controller through score_policy gives the benchmark's numbers
    exactly (the rollouts are deterministic, the statistics are the benchmark's)."""
    expected = _benchmark_entry(small_benchmark, name)
    score = score_policy(name, ENV_ID, reference=small_reference)
    assert score.returns.tolist() == expected["returns"]
    assert score.mean_return == expected["mean_return"]
    assert score.return_ci95 == expected["return_ci95"]
    assert score.failures == expected["failures"]
    assert score.normalised_score == expected["normalised_score"]["mean"]
    assert (score.normalised_score_low, score.normalised_score_high) == (
        expected["normalised_score"]["low"],
        expected["normalised_score"]["high"],
    )
    best = small_reference["per_id"][ENV_ID]["best_baseline"]
    if name == best:
        assert expected["paired_vs_best"] is None
    else:
        assert dataclasses.asdict(score.paired_vs_best) == expected["paired_vs_best"]
    # The definitions, spelled out: paired mean and score of the means from the reference's returns.
    returns = {c: np.array(e["returns"]) for c, e in small_reference["per_id"][ENV_ID]["controllers"].items()}
    assert score.paired_vs_best.mean == pytest.approx(np.mean(returns[name] - returns[best]), abs=1e-12)
    gap = returns["mpc"].mean() - returns["passive"].mean()
    assert score.normalised_score == pytest.approx(100 * (returns[name].mean() - returns["passive"].mean()) / gap)


def test_the_best_baseline_against_itself_and_the_anchors(small_reference: dict[str, Any]) -> None:
    best = small_reference["per_id"][ENV_ID]["best_baseline"]
    assert best in BASELINES
    paired = score_policy(best, ENV_ID, reference=small_reference).paired_vs_best
    assert (paired.mean, paired.low, paired.high, paired.wins, paired.episodes) == (0.0, 0.0, 0.0, 0, EPISODES)
    mpc = score_policy("mpc", ENV_ID, reference=small_reference)
    # 100 up to rounding: the mean of per-episode scores, and each resample's ratio of equal means.
    assert (mpc.normalised_score, mpc.normalised_score_low, mpc.normalised_score_high) == pytest.approx(
        (100.0, 100.0, 100.0), abs=1e-12
    )


def test_a_zero_action_function_scores_as_passive(small_reference: dict[str, Any]) -> None:
    """A function policy of zero thrust is passive: score 0 with the interval [0, 0], and worse
    than the best baseline on every seed."""

    def do_nothing(observation: np.ndarray) -> np.ndarray:
        assert observation.shape == (EPISODES, 30)  # 4 satellites x 6, 6 cables
        return np.zeros((observation.shape[0], 12))

    score = score_policy(do_nothing, ENV_ID, reference=small_reference)
    assert score.name == "do_nothing"
    assert score.returns.tolist() == small_reference["per_id"][ENV_ID]["controllers"]["passive"]["returns"]
    assert (score.normalised_score, score.normalised_score_low, score.normalised_score_high) == (0.0, 0.0, 0.0)
    assert score.paired_vs_best.mean < 0 and score.paired_vs_best.wins == 0 and not score.beats_best_baseline
    assert "normalised score: 0.0 [0.0, 0.0]" in score.summary()


def test_objects_with_predict_score_as_their_names(small_reference: dict[str, Any]) -> None:
    """A TrainedPolicy (and so an SB3-style predict) scores as the shipped model of that name."""
    policy = TrainedPolicy(shipped_models(ENV_ID)["ars"], name="my ars")
    score = score_policy(policy, ENV_ID, reference=small_reference)
    assert score.name == "my ars"
    assert score.returns.tolist() == small_reference["per_id"][ENV_ID]["controllers"]["ars"]["returns"]


def test_a_subset_of_the_seeds_gives_the_same_episodes(small_reference: dict[str, Any]) -> None:
    """Episode returns do not depend on which other seeds run beside them, so a subset is
    paired with the reference's returns of the same seeds."""
    seeds = [HELD_OUT_SEED + 3, HELD_OUT_SEED + 1]
    score = score_policy("lqr", ENV_ID, seeds=seeds, reference=small_reference)
    full = small_reference["per_id"][ENV_ID]["controllers"]["lqr"]["returns"]
    assert score.seeds == tuple(seeds)
    assert score.returns.tolist() == [full[3], full[1]]
    assert "lqr on TetherTetrahedron-v0, 2 held-out episodes (chosen seeds;" in score.summary()
    first = score_policy("lqr", ENV_ID, episodes=2, reference=small_reference)
    assert first.seeds == (HELD_OUT_SEED, HELD_OUT_SEED + 1) and first.returns.tolist() == full[:2]


@pytest.mark.parametrize(
    ("arguments", "message"),
    [
        ({"episodes": EPISODES + 1}, "from 2 (for an interval) to 8"),
        ({"episodes": 1}, "from 2 (for an interval) to 8"),
        ({"seeds": [HELD_OUT_SEED, 5]}, "hold no returns for seeds [5]"),
        ({"seeds": [HELD_OUT_SEED, HELD_OUT_SEED]}, "at least 2 distinct"),
        ({"seeds": [HELD_OUT_SEED + 0.5, HELD_OUT_SEED + 1]}, "a list of integer seeds"),
        ({"episodes": 2, "seeds": [HELD_OUT_SEED, HELD_OUT_SEED + 1]}, "not both"),
    ],
)
def test_seeds_the_reference_does_not_hold_are_refused(
    arguments: dict[str, Any], message: str, small_reference: dict[str, Any]
) -> None:
    def never(observation: np.ndarray) -> np.ndarray:
        raise AssertionError("the request is refused before any rollout")

    with pytest.raises(ReferenceDataError) as error:
        score_policy(never, ENV_ID, reference=small_reference, **arguments)
    assert message in str(error.value)


def test_bad_policies_and_ids_are_refused(small_reference: dict[str, Any]) -> None:
    with pytest.raises(ReferenceDataError, match="hold no id 'TetherChain-v0'; they hold TetherTetrahedron-v0"):
        score_policy("lqr", "TetherChain-v0", reference=small_reference)
    with pytest.raises(ValueError, match=r"must return \(8, 12\)"):
        score_policy(lambda observation: np.zeros(12), ENV_ID, reference=small_reference)
    with pytest.raises(TypeError, match="policy must be a function"):
        score_policy(42, ENV_ID, reference=small_reference)
    with pytest.raises(ValueError, match="returns must be 8 finite numbers"):
        score_returns([1.0, 2.0], ENV_ID, [HELD_OUT_SEED + e for e in range(EPISODES)], reference=small_reference)


def test_the_converter_refuses_numbers_its_returns_do_not_give(small_benchmark: Path) -> None:
    results = json.loads(small_benchmark.read_text())
    tampered = copy.deepcopy(results)
    tampered["per_id"][ENV_ID]["controllers"]["lqr"]["returns"][0] += 1e-9
    with pytest.raises(ReferenceDataError, match="lqr: the statistics of its returns"):
        reference_from_benchmark(tampered, "abc1234", "2026-01-01T00:00:00Z")
    wrong_best = copy.deepcopy(results)
    wrong_best["per_id"][ENV_ID]["best_baseline"] = "passive"
    with pytest.raises(ReferenceDataError, match="the best baseline is"):
        reference_from_benchmark(wrong_best, "abc1234", "2026-01-01T00:00:00Z")
    with pytest.raises(ReferenceDataError, match="commit must be a git commit hash"):
        reference_from_benchmark(results, "HEAD", "2026-01-01T00:00:00Z")
    del results["settings"]["seeds"]
    with pytest.raises(ReferenceDataError, match=r"lacks \['seeds'\]"):
        reference_from_benchmark(results, "abc1234", "2026-01-01T00:00:00Z")


def test_the_documented_import_path_keeps_score_policy() -> None:
    """``from tether_gym_agents.scoring import score_policy`` (the README's path of earlier
    releases) is the evaluation room's function."""
    assert agents.scoring.score_policy is score_policy


def test_the_command_writes_a_file_that_loads(small_benchmark: Path, tmp_path: Path) -> None:
    out = tmp_path / "reference.json"
    written = main([str(small_benchmark), "--commit", "abc1234", "--out", str(out), "--machine", "test machine"])
    loaded = load_reference(out)
    assert loaded == written
    assert (loaded["format"], loaded["commit"], loaded["machine"]) == (FORMAT, "abc1234", "test machine")
    assert loaded["command"].startswith("agents.evaluation.benchmark.benchmark(BenchmarkConfig(")
    assert loaded["date"].endswith("Z")
    assert loaded["env_kwargs"] == {"max_episode_steps": 20}
    with pytest.raises(OutputExistsError, match="pass --force"):
        write_reference(small_benchmark, "abc1234", out)
    write_reference(small_benchmark, "abc1234", out, force=True)
    out.write_text(json.dumps({"format": "something else"}))
    with pytest.raises(ReferenceDataError, match="is not a 'tether-gym reference scores' file"):
        load_reference(out)
    with pytest.raises(FileNotFoundError, match="python -m agents.scoring BENCHMARK_JSON"):
        load_reference(tmp_path / "absent.json")


@pytest.mark.parametrize(
    ("text", "message"),
    [
        # json kept the last of two entries: a reference could carry two sets of scores for one id.
        ('{"format": "a", "format": "b"}', "the key 'format' appears twice in one object"),
        ("[" * 100_000, "nests lists or objects more than 64 deep"),  # was a bare RecursionError
        ('{"zero": NaN}', "non-finite number NaN is not allowed"),  # json accepts NaN literals
        (b"\xff\xfe{}", "is not valid JSON"),  # was a bare UnicodeDecodeError
    ],
)
def test_a_malformed_reference_file_is_refused_naming_it(tmp_path: Path, text: str | bytes, message: str) -> None:
    file = tmp_path / "reference_scores.json"
    file.write_bytes(text if isinstance(text, bytes) else text.encode())
    with pytest.raises(ReferenceDataError, match=f"reference_scores.json .*{message}"):
        load_reference(file)
    with pytest.raises(ReferenceDataError, match=f"reference_scores.json .*{message}"):
        write_reference(file, "abc1234", out=tmp_path / "out.json")


@pytest.fixture(scope="module")
def other_id_reference(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[str, Any]]:
    """A benchmark of another id alone, on the settings of ``small_benchmark``, and its reference."""
    out = tmp_path_factory.mktemp("benchmark_chain")
    benchmark(
        BenchmarkConfig(
            env_ids=["TetherChain-v0"],
            controllers=["passive", "lqr", "mpc"],
            episodes=EPISODES,
            env_kwargs={"max_episode_steps": 20},
            bootstrap_reps=100,
            plots=False,
            out=out,
        )
    )
    results = json.loads((out / "benchmark.json").read_text())
    return out / "benchmark.json", reference_from_benchmark(results, "def5678", "2026-02-02T00:00:00Z", "other")


def test_a_benchmark_of_new_ids_is_added_with_its_own_run(
    small_benchmark: Path, small_reference: dict[str, Any], other_id_reference: tuple[Path, dict[str, Any]]
) -> None:
    bench, addition = other_id_reference
    merged = merge_reference(small_reference, addition)
    assert list(merged["per_id"]) == [ENV_ID, "TetherChain-v0"]
    assert merged["per_id"]["TetherChain-v0"] == addition["per_id"]["TetherChain-v0"]
    assert merged["per_id"][ENV_ID] == small_reference["per_id"][ENV_ID]
    # The aggregate is the base's, over the ids it was computed on.
    assert (merged["aggregate"], merged["aggregate_ids"]) == (small_reference["aggregate"], [ENV_ID])
    assert run_of(merged, "TetherChain-v0")["commit"] == "def5678" and run_of(merged, ENV_ID)["commit"] != "def5678"
    assert run_of(merged, "TetherChain-v0")["machine"] == "other"
    # A controller of the added id scores to its numbers there, naming the addition's run.
    score = score_policy("lqr", "TetherChain-v0", reference=merged)
    assert score.returns.tolist() == addition["per_id"]["TetherChain-v0"]["controllers"]["lqr"]["returns"]
    assert score.reference_commit == "def5678"
    # Adding the id again replaces the earlier addition instead of keeping two.
    again = merge_reference(merged, {**addition, "commit": "0123abc"})
    assert [entry["ids"] for entry in again["additions"]] == [["TetherChain-v0"]]
    assert run_of(again, "TetherChain-v0")["commit"] == "0123abc"
    # A rerun of every id of the aggregate becomes the file's own run and keeps the other ids' additions.
    rerun = merge_reference(merged, {**small_reference, "commit": "fedcba9"})
    assert (rerun["commit"], rerun["aggregate_ids"], rerun["aggregate"]) == ("fedcba9", [ENV_ID], merged["aggregate"])
    assert [entry["ids"] for entry in rerun["additions"]] == [["TetherChain-v0"]]
    assert rerun["per_id"] == merged["per_id"] and run_of(rerun, "TetherChain-v0")["commit"] == "def5678"
    assert run_of(rerun, ENV_ID)["commit"] == "fedcba9"
    # Replacing some of the aggregate's ids but not all would mix two runs in one aggregate.
    two_ids = {**merged, "aggregate_ids": [ENV_ID, "TetherChain-v0"], "additions": []}
    partial = r"\['TetherTetrahedron-v0'\] are ids of the reference's aggregate, but "
    with pytest.raises(ReferenceDataError, match=partial):
        merge_reference(two_ids, small_reference)
    with pytest.raises(ReferenceDataError, match="the addition's episodes is 4, the reference's 8"):
        merge_reference(small_reference, {**addition, "episodes": 4})
    with pytest.raises(ReferenceDataError, match="is itself a merged file"):
        merge_reference(small_reference, {**merged, "per_id": addition["per_id"], "aggregate_ids": []})
    # Numbers that the returns do not give are refused on the way in.
    broken = copy.deepcopy(addition)
    broken["per_id"]["TetherChain-v0"]["controllers"]["lqr"]["mean_return"] += 1.0
    with pytest.raises(ReferenceDataError, match="TetherChain-v0 lqr: the statistics of its returns"):
        merge_reference(small_reference, broken)


def test_the_command_adds_a_benchmark_to_a_reference_file(
    small_benchmark: Path,
    other_id_reference: tuple[Path, dict[str, Any]],
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    bench, _ = other_id_reference
    out = tmp_path / "reference.json"
    base = main([str(small_benchmark), "--commit", "abc1234", "--out", str(out)])
    merged = main([str(bench), "--commit", "def5678", "--out", str(out), "--add-to", str(out), "--force"])
    assert load_reference(out) == merged and list(merged["per_id"]) == [ENV_ID, "TetherChain-v0"]
    assert merged["per_id"][ENV_ID] == base["per_id"][ENV_ID]
    assert "added TetherChain-v0 (commit def5678" in capsys.readouterr().out
    # The aggregate's ids rerun: the file's own run, the addition of the other id kept, and said so.
    rerun = main([str(small_benchmark), "--commit", "fedcba9", "--out", str(out), "--add-to", str(out), "--force"])
    assert (rerun["commit"], [entry["ids"] for entry in rerun["additions"]]) == ("fedcba9", [["TetherChain-v0"]])
    assert f"{ENV_ID} rerun (commit fedcba9" in capsys.readouterr().out
