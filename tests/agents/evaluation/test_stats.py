"""The benchmark's statistics (``agents.evaluation.stats``) against cases worked out by hand.

The hand cases spell their arithmetic out (means, sums of squares, a t-table quantile) instead
of calling the functions under test or scipy, so a wrong formula in the module cannot agree
with itself here.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from agents.evaluation.stats import (
    aggregate_scores,
    best_eligible_baseline,
    normalised_scores,
    paired_difference,
    score_interval,
)

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
