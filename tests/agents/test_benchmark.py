"""The benchmark command (``python -m agents.benchmark``): its statistics against cases worked
out by hand, and smoke runs of the command on two ids with a few scripted controllers.

The hand cases spell their arithmetic out (means, sums of squares, a t-table quantile) instead
of calling the functions under test or scipy, so a wrong formula in the module cannot agree
with itself here.
"""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pytest

import agents.benchmark
from agents.benchmark import (
    aggregate_scores,
    benchmark,
    best_eligible_baseline,
    main,
    normalised_scores,
    paired_difference,
    score_interval,
)
from agents.evaluate import rollout
from agents.common.files import OutputError, OutputExistsError
from agents.policies import make_controller

#: Two-sided 95 % quantile of Student's t with 3 degrees of freedom, from a printed t table
#: (t_{0.975, 3} = 3.182446...).
T_975_DF3 = 3.1824463


def test_paired_difference_matches_a_hand_computation() -> None:
    controller = [-10.0, -12.0, -9.0, -15.0]
    baseline = [-11.0, -15.0, -10.0, -16.0]
    # d = controller - baseline = [1, 3, 1, 1]; mean 6/4 = 1.5; deviations -0.5, 1.5, -0.5, -0.5;
    # sum of squares 0.25 + 2.25 + 0.25 + 0.25 = 3; variance 3/(4-1) = 1; sd 1; se 1/sqrt(4) = 0.5.
    half_width = T_975_DF3 * 0.5
    paired = paired_difference(controller, baseline)
    assert paired.mean == pytest.approx(1.5, abs=1e-12)
    assert paired.std == pytest.approx(1.0, abs=1e-12)
    assert paired.half_width == pytest.approx(half_width, rel=1e-6)
    assert (paired.low, paired.high) == pytest.approx((1.5 - half_width, 1.5 + half_width), rel=1e-6)
    assert (paired.wins, paired.episodes) == (4, 4)
    # The other way round: the same interval mirrored, and no wins.
    reverse = paired_difference(baseline, controller)
    expected = (-1.5 - half_width, -1.5 + half_width, 0)
    assert (reverse.low, reverse.high, reverse.wins) == pytest.approx(expected)


def test_paired_difference_is_narrower_than_the_unpaired_intervals() -> None:
    """Why pairing: a controller that is better by 1 on every seed, whose returns spread over
    100 from seed to seed, is surely better (zero-width interval at +1)."""
    baseline = np.array([-100.0, -50.0, -200.0, -10.0, -75.0])
    paired = paired_difference(baseline + 1.0, baseline)
    assert paired.mean == pytest.approx(1.0) and paired.half_width == pytest.approx(0.0, abs=1e-12)
    assert paired.wins == 5


def test_paired_difference_refuses_mismatched_or_bad_input() -> None:
    with pytest.raises(ValueError, match="one value per seed"):
        paired_difference([1.0, 2.0, 3.0], [1.0, 2.0])
    with pytest.raises(ValueError, match="at least 2"):
        paired_difference([1.0], [2.0])
    with pytest.raises(ValueError, match="NaN or infinite"):
        paired_difference([1.0, math.nan], [2.0, 3.0])


def test_normalised_score_on_a_hand_case() -> None:
    passive = [-100.0, -50.0]
    mpc = [-20.0, -10.0]
    controller = [-60.0, -30.0]
    # Mean returns: passive -75, mpc -15: the reference gains 60 over passive.
    # Episode 1: 100 * (-60 - -100) / 60 = 66.67; episode 2: 100 * (-30 - -50) / 60 = 33.33.
    scores = normalised_scores(controller, passive, mpc)
    assert scores == pytest.approx([4000.0 / 60.0, 2000.0 / 60.0])
    # Their mean is the score of the means: 100 * (-45 - -75) / 60 = 50.
    assert scores.mean() == pytest.approx(50.0)
    assert normalised_scores(passive, passive, mpc) == pytest.approx([0.0, 0.0])
    assert normalised_scores(mpc, passive, mpc).mean() == pytest.approx(100.0)
    with pytest.raises(ValueError, match="not above passive"):
        normalised_scores(controller, passive, passive)


def test_score_interval_is_paired_over_seeds() -> None:
    """Whatever seeds a resample draws, a controller that gains exactly half of the reference's
    gain on every seed scores 50: its interval is [50, 50], however much the seeds differ.
    A t interval on the per-episode scores would be wide here, since the gains differ 20-fold."""
    passive = np.array([-100.0, -50.0, -400.0, -20.0, -75.0])
    reference = passive + np.array([60.0, 30.0, 240.0, 12.0, 45.0])  # 60 % of passive's cost, each seed
    half = passive + 0.5 * (reference - passive)
    assert score_interval(half, passive, reference, reps=2000) == pytest.approx((50.0, 50.0))
    assert score_interval(reference, passive, reference, reps=2000) == pytest.approx((100.0, 100.0))
    assert score_interval(passive, passive, reference, reps=2000) == pytest.approx((0.0, 0.0))
    # A controller that is better than the reference on the high-energy seed only: the interval
    # contains its score of the means and is not degenerate.
    mixed = reference + np.array([-10.0, -5.0, 100.0, -2.0, -5.0])
    score = normalised_scores(mixed, passive, reference).mean()
    low, high = score_interval(mixed, passive, reference, reps=2000)
    assert low < score < high
    # A reference that is no better than passive on most resamples: no scale, no interval.
    noisy = passive + np.array([30.0, -29.0, 1.0, -1.0, 0.5])
    assert score_interval(half, passive, noisy, reps=2000) is None


def test_best_baseline_excludes_baselines_below_passive() -> None:
    # The default id's comparison before the slack-model LQR: the taut-model design lost formations and
    # scored far below passive, the case the eligibility rule is for.
    means = {"passive": -127.2, "velocity_feedback": -67.6, "lqr": -2091.0, "tension_aware": -68.4}
    best, notes = best_eligible_baseline(means)
    assert best == "velocity_feedback"
    assert notes == {
        "passive": "eligible",
        "velocity_feedback": "best",
        "lqr": "not eligible: mean return below passive's",
        "tension_aware": "eligible",
    }
    # When every scripted law loses to doing nothing, passive is the best baseline.
    best, notes = best_eligible_baseline({"passive": -10.0, "lqr": -11.0, "velocity_feedback": -10.5})
    assert best == "passive"
    assert notes["lqr"].startswith("not eligible") and notes["velocity_feedback"].startswith("not eligible")
    # A tie with passive is eligible; of equal means the first listed wins.
    best, notes = best_eligible_baseline({"passive": -10.0, "lqr": -10.0})
    assert best == "passive" and notes["lqr"] == "eligible"
    with pytest.raises(ValueError, match="passive"):
        best_eligible_baseline({"lqr": -1.0})


def test_aggregate_iqm_on_a_hand_case() -> None:
    # Eight ids, two episodes each; on every id passive returns (-100, -200) and the reference
    # (-50, -100): a mean gain of 75. The controller gains a fixed fraction of the reference's
    # gain on each seed, so its per-id scores are 100 x that fraction, whatever seeds are drawn:
    # -50, 0, 10, 20, 30, 40, 100 and 1000.
    ids = [f"id{k}" for k in range(8)]
    passive = np.array([-100.0, -200.0])
    reference = np.array([-50.0, -100.0])
    per_id_scores = [-50.0, 0.0, 10.0, 20.0, 30.0, 40.0, 100.0, 1000.0]
    controller = {
        env_id: passive + score / 100.0 * (reference - passive)
        for env_id, score in zip(ids, per_id_scores, strict=True)
    }
    zero = dict.fromkeys(ids, passive)
    ref = dict.fromkeys(ids, reference)
    result = aggregate_scores({"x": controller}, zero, ref, reps=300, seed=3)["x"]
    # The IQM drops the lowest and the highest quarter of the ids (two each: -50, 0 and 100, 1000)
    # and averages 10, 20, 30 and 40: 25. The mean of the eight: 1150 / 8 = 143.75.
    assert result["iqm"] == pytest.approx(25.0)
    assert result["mean"] == pytest.approx(143.75)
    # Every resample gives the same per-id scores: the intervals have no width.
    assert (result["iqm_low"], result["iqm_high"]) == pytest.approx((25.0, 25.0))
    assert (result["mean_low"], result["mean_high"]) == pytest.approx((143.75, 143.75))
    assert (result["ids"], result["env_ids"], result["episodes"]) == (8, ids, 2)


def test_aggregate_intervals_are_paired_and_seeded() -> None:
    rng = np.random.default_rng(0)
    ids = ["a", "b", "c"]
    energy = {env_id: rng.uniform(0.1, 5.0, 16) for env_id in ids}  # seed-to-seed spread of the scale
    zero = {env_id: -100.0 * energy[env_id] for env_id in ids}
    ref = {env_id: -40.0 * energy[env_id] + rng.normal(0.0, 5.0, 16) for env_id in ids}
    noisy = {env_id: -60.0 * energy[env_id] + rng.normal(0.0, 20.0, 16) for env_id in ids}
    result = aggregate_scores({"noisy": noisy, "reference": ref}, zero, ref, reps=500, seed=7)
    # The reference scores 100 in every resample, however its returns spread.
    reference_row = result["reference"]
    assert [reference_row[key] for key in ("iqm", "iqm_low", "iqm_high", "mean_low", "mean_high")] == pytest.approx(
        [100.0] * 5
    )
    row = result["noisy"]
    assert row["iqm_low"] < row["iqm"] < row["iqm_high"]
    assert row["mean_low"] < row["mean"] < row["mean_high"]
    # Seeded: the same numbers again, whatever other rows are computed with it.
    assert aggregate_scores({"noisy": noisy}, zero, ref, reps=500, seed=7)["noisy"] == row
    assert aggregate_scores({"noisy": noisy}, zero, ref, reps=500, seed=8)["noisy"] != row


def _without_mpc(monkeypatch: pytest.MonkeyPatch) -> None:
    """Make ``mpc`` unknown, as it is until the reference controller lands (and stays so for
    these tests after it has: they check how a missing controller is reported)."""

    def make(spec: str, env: Any, trust_pickle: bool = False, allow_other_id: bool = False) -> Any:
        if spec == "mpc":
            raise ValueError("unknown controller 'mpc' (test: as if it did not exist)")
        return make_controller(spec, env, trust_pickle=trust_pickle, allow_other_id=allow_other_id)

    monkeypatch.setattr(agents.benchmark, "make_controller", make)


SMOKE_IDS = ["TetherTetrahedron-v0", "TetherTriangle-v0"]


@pytest.mark.slow
def test_benchmark_command_smoke(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    _without_mpc(monkeypatch)
    out = tmp_path / "bench"
    arguments = [
        "--envs",
        *SMOKE_IDS,
        "--episodes",
        "4",
        "--reference",
        "tension_aware",
        "--bootstrap-reps",
        "200",
        "--out",
        str(out),
    ]
    results = main([*arguments, "--controllers", "velocity_feedback", "tension_aware", "mpc"])
    for name in agents.benchmark.TABLE_FILES:
        assert (out / name).stat().st_size > 0
    for name in agents.benchmark.PLOT_FILES:
        assert (out / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    report = (out / "benchmark.md").read_text()
    data = json.loads((out / "benchmark.json").read_text())
    assert data == json.loads(json.dumps(agents.benchmark._json_ready(results)))
    assert data["settings"]["seeds"] == [10_000, 10_001, 10_002, 10_003]
    assert "passive" in data["per_id"][SMOKE_IDS[0]]["controllers"]  # added: the score's zero
    for env_id in SMOKE_IDS:
        assert f"### {env_id}" in report
        entry = data["per_id"][env_id]
        assert entry["missing"] == [
            {"controller": "mpc", "reason": "unknown controller 'mpc' (test: as if it did not exist)"}
        ]
        controllers = entry["controllers"]
        assert list(controllers) == ["passive", "velocity_feedback", "tension_aware"]
        assert controllers["passive"]["normalised_scores"] == [0.0] * 4
        reference_score = controllers["tension_aware"]["normalised_score"]
        assert (reference_score["mean"], reference_score["low"], reference_score["high"]) == pytest.approx(
            (100.0, 100.0, 100.0)
        )
        best = entry["best_baseline"]
        assert best == max(
            ("passive", "velocity_feedback", "tension_aware"), key=lambda name: controllers[name]["mean_return"]
        )
        for name, item in controllers.items():
            if name == best:
                assert item["paired_vs_best"] is None
                continue
            differences = np.array(item["returns"]) - np.array(controllers[best]["returns"])
            assert item["paired_vs_best"]["mean"] == pytest.approx(differences.mean())
    # The episodes are the comparison's: agents.evaluate.rollout on the same seeds gives the same returns.
    env_id = SMOKE_IDS[0]
    probe = gym.make_vec(env_id, num_envs=1)
    direct = rollout(make_controller("velocity_feedback", probe), env_id, range(10_000, 10_004))
    probe.close()
    direct_returns = direct.rewards.sum(axis=1).tolist()
    assert data["per_id"][env_id]["controllers"]["velocity_feedback"]["returns"] == direct_returns
    # episodes.csv holds every per-episode return, to the last digit.
    with open(out / "episodes.csv", newline="") as stream:
        rows = list(csv.DictReader(stream))
    assert len(rows) == len(SMOKE_IDS) * 3 * 4
    from_csv = [
        float(row["return"]) for row in rows if row["env_id"] == env_id and row["controller"] == "velocity_feedback"
    ]
    assert from_csv == direct_returns
    aggregate = data["aggregate"]
    assert set(aggregate) == {"passive", "velocity_feedback", "tension_aware", agents.benchmark.BEST_BASELINE_ROW}
    assert aggregate["passive"]["iqm"] == 0.0 and aggregate["velocity_feedback"]["ids"] == 2
    assert "| velocity_feedback | 2/2 |" in report
    assert "| id | passive | velocity_feedback | tension_aware |" in report  # the reference once
    # A second run refuses to overwrite the first, and replaces it with --force (to the same numbers,
    # the bootstrap included: it is seeded).
    with pytest.raises(OutputExistsError, match="--force"):
        main([*arguments, "--controllers", "velocity_feedback", "tension_aware"])
    again = main([*arguments, "--controllers", "velocity_feedback", "tension_aware", "--force"])
    assert again["aggregate"] == results["aggregate"]

    def numbers(result: dict[str, Any]) -> dict[str, Any]:
        """Every per-id number but the wall times."""
        return {
            env_id: {
                name: {key: value for key, value in item.items() if not key.startswith("wall")}
                for name, item in entry["controllers"].items()
            }
            for env_id, entry in result["per_id"].items()
        }

    assert numbers(again) == numbers(results)


def test_benchmark_says_the_score_is_not_available_without_mpc(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    _without_mpc(monkeypatch)
    results = benchmark(
        env_ids=[SMOKE_IDS[1]],
        controllers=["passive", "velocity_feedback"],
        episodes=3,
        out=tmp_path,
        bootstrap_reps=200,
    )
    entry = results["per_id"][SMOKE_IDS[1]]
    assert entry["score"] == "not available: mpc did not run on this id"
    assert all(item["normalised_score"] is None for item in entry["controllers"].values())
    assert results["aggregate"] == {}
    report = (tmp_path / "benchmark.md").read_text()
    assert "Not available: the normalised score needs mpc" in report
    assert "| TetherTriangle-v0 | n/a | n/a |" in report
    assert (tmp_path / "aggregate.png").stat().st_size > 0  # a figure that says why it is empty


def test_bad_output_or_controller_is_refused_before_any_rollout(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    def no_rollout(*args: Any, **kwargs: Any) -> None:
        raise AssertionError("a rollout ran before the arguments were checked")

    monkeypatch.setattr(agents.benchmark, "rollout", no_rollout)
    a_file = tmp_path / "file"
    a_file.write_text("not a directory")
    with pytest.raises(OutputError, match="is a file"):
        main(["--envs", SMOKE_IDS[0], "--out", str(a_file)])
    with pytest.raises(OutputError, match="inside"):
        main(["--envs", SMOKE_IDS[0], "--out", str(a_file / "below")])
    link = tmp_path / "link"
    link.symlink_to(tmp_path / "elsewhere")
    with pytest.raises(OutputError, match="symlink"):
        main(["--envs", SMOKE_IDS[0], "--out", str(link)])
    earlier = tmp_path / "earlier"
    earlier.mkdir()
    (earlier / "benchmark.md").write_text("an earlier benchmark")
    with pytest.raises(OutputExistsError, match="--force"):
        main(["--envs", SMOKE_IDS[0], "--out", str(earlier)])
    (earlier / "aggregate.png").symlink_to(tmp_path / "target.png")
    with pytest.raises(OutputError, match="symlink"):
        main(["--envs", SMOKE_IDS[0], "--out", str(earlier), "--force"])
    assert (earlier / "benchmark.md").read_text() == "an earlier benchmark"
    with pytest.raises(ValueError, match="unknown controllers \\['pasive'\\]"):
        main(["--envs", SMOKE_IDS[0], "--controllers", "pasive", "--out", str(tmp_path / "new")])
    with pytest.raises(ValueError, match="reference"):
        benchmark(env_ids=[SMOKE_IDS[0]], reference="passive", out=tmp_path / "new")
    with pytest.raises(SystemExit):  # argparse: --episodes must be at least 2
        main(["--episodes", "1", "--out", str(tmp_path / "new")])
