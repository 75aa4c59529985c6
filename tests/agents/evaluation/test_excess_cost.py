"""The excess cost over the reference ceiling, against cases worked out by hand.

``agents.evaluation.stats`` (per seed, its t interval, rliable's aggregate over ids),
``agents.evaluation.scoring.score_returns`` (a Score's ceiling fields), the table of
``agents.evaluation.ceiling_report`` and ``python -m agents.scoring --ceiling``. The hand cases spell
their arithmetic out instead of calling the functions under test, so a wrong formula in the module
cannot agree with itself here. The reference scores and ceiling data are small synthetic ones: the
numbers are chosen, not measured, so that every expectation is exact arithmetic.
"""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agents.controllers.mpc import MPCSettings
from agents.evaluation.ceiling import CEILING_FORMAT, CEILING_FORMAT_VERSION
from agents.evaluation.ceiling_report import BEST_LAW_ROW, CEILING, ceiling_markdown, ceiling_table
from agents.evaluation.scoring import FORMAT, FORMAT_VERSION, ReferenceDataError, score_returns
from agents.evaluation.stats import (
    aggregate_excess_costs,
    aggregate_scores,
    excess_cost,
    excess_costs,
    gap_closed,
    rliable_modules,
)
from agents.scoring import ceiling_report, main

#: Two-sided 95 % quantiles of Student's t, from a printed t table: t_{0.975, 1} = 12.7062047...,
#: t_{0.975, 3} = 3.1824463...
T_975_DF1 = 12.7062047
T_975_DF3 = 3.1824463


# ---------------------------------------------------------------------------------------- per id


def test_excess_costs_and_their_interval_on_a_hand_case() -> None:
    # (-R) / (-R[ceiling]) - 1 per seed: 2/1 - 1 = 1.0 and 3/2 - 1 = 0.5; mean 0.75; deviations
    # +-0.25; variance (0.0625 + 0.0625) / (2 - 1) = 0.125; se = sqrt(0.125 / 2) = 0.25.
    assert excess_costs([-2.0, -3.0], [-1.0, -2.0]) == pytest.approx([1.0, 0.5], abs=1e-15)
    cost = excess_cost([-2.0, -3.0], [-1.0, -2.0])
    assert cost.mean == pytest.approx(0.75, abs=1e-15)
    assert cost.std == pytest.approx(math.sqrt(0.125), rel=1e-12)
    assert cost.half_width == pytest.approx(T_975_DF1 * 0.25, rel=1e-7)
    assert (cost.low, cost.high) == pytest.approx((0.75 - T_975_DF1 * 0.25, 0.75 + T_975_DF1 * 0.25), rel=1e-7)
    assert (cost.beats, cost.episodes) == (0, 2)


def test_the_gap_closed_on_a_hand_case() -> None:
    # Ceiling costs 10, 20, 14. The law's excess costs 12/10 - 1 = 0.2, 26/20 - 1 = 0.3, 17/14 - 1 =
    # 3/14: mean (0.5 + 3/14) / 3 = 5/21. The controller's 0.1, 0.15, 1/14: mean (0.25 + 1/14) / 3 =
    # 9/84. Closed: 1 - (9/84) / (5/21) = 1 - 9/20 = 0.55.
    ceiling, law, controller = [-10.0, -20.0, -14.0], [-12.0, -26.0, -17.0], [-11.0, -23.0, -15.0]
    gap = gap_closed(controller, law, ceiling, reps=2000, seed=1)
    assert gap is not None
    assert (gap.fraction, gap.episodes) == (pytest.approx(0.55, abs=1e-12), 3)
    # The percentile bootstrap's ends are values the statistic takes on resamples of the 3 seeds:
    # the law itself closes 0 on every one, the ceiling 1, and the interval holds the estimate.
    assert gap.low <= gap.fraction <= gap.high
    # Resampling seed 0 alone (0.1 of 0.2 closed: 0.5) and seed 1 alone (0.15 of 0.3: 0.5) bound it below.
    assert gap.low == pytest.approx(0.5, abs=1e-9)
    assert gap_closed(law, law, ceiling, reps=200) == dataclasses.replace(gap, fraction=0.0, low=0.0, high=0.0)
    assert gap_closed(ceiling, law, ceiling, reps=200).fraction == pytest.approx(1.0, abs=1e-15)
    # A controller above the law's cost closes a negative part; a law at the ceiling leaves no gap.
    assert gap_closed([-13.0, -29.0, -19.0], law, ceiling, reps=200).fraction < 0.0
    assert gap_closed(controller, ceiling, ceiling, reps=200) is None
    with pytest.raises(ValueError, match="one return per seed"):
        gap_closed(controller[:2], law, ceiling)


def test_excess_cost_counts_the_seeds_that_beat_the_ceiling() -> None:
    # 11/10 - 1 = 0.1, 12/10 - 1 = 0.2, 9/10 - 1 = -0.1 (cheaper than the ceiling), 20/16 - 1 = 0.25.
    # Mean 0.45 / 4 = 0.1125; deviations -0.0125, 0.0875, -0.2125, 0.1375; their squares sum to
    # 0.00015625 + 0.00765625 + 0.04515625 + 0.01890625 = 0.071875; variance 0.071875 / 3;
    # se = sqrt(variance / 4).
    cost = excess_cost([-11.0, -12.0, -9.0, -20.0], [-10.0, -10.0, -10.0, -16.0])
    se = math.sqrt(0.071875 / 3 / 4)
    assert cost.mean == pytest.approx(0.1125, abs=1e-15)
    assert cost.half_width == pytest.approx(T_975_DF3 * se, rel=1e-7)
    assert (cost.beats, cost.episodes) == (1, 4)
    # The ceiling against itself: 0 on every seed, an interval of no width, no seed beaten.
    itself = excess_cost([-10.0, -16.0], [-10.0, -16.0])
    assert (itself.mean, itself.low, itself.high, itself.beats) == (0.0, 0.0, 0.0, 0)


@pytest.mark.parametrize("ceiling", [[-1.0, 0.0], [-1.0, 2.5], [0.0, 0.0]])
def test_a_ceiling_return_that_is_not_a_cost_is_refused(ceiling: list[float]) -> None:
    with pytest.raises(ValueError, match=r"ceiling's return is .* \(>= 0\).*must be above 0.*python -m agents.ceiling"):
        excess_costs([-2.0, -3.0], ceiling)


def test_mismatched_or_bad_returns_are_refused() -> None:
    with pytest.raises(ValueError, match="one return per seed on both sides"):
        excess_costs([-2.0, -3.0, -4.0], [-1.0, -2.0])
    with pytest.raises(ValueError, match="at least 2"):
        excess_cost([-2.0], [-1.0])
    with pytest.raises(ValueError, match="NaN or infinite"):
        excess_costs([-2.0, math.nan], [-1.0, -2.0])


costs = st.floats(1e-3, 1e6, allow_nan=False, allow_infinity=False)
factors = st.floats(0.25, 4.0, allow_nan=False, allow_infinity=False)


@settings(max_examples=200, deadline=None, derandomize=True)
@given(pairs=st.lists(st.tuples(costs, factors), min_size=2, max_size=20), scale=st.floats(1e-3, 1e3))
def test_excess_cost_is_the_relative_cost_whatever_the_scale(pairs: list[tuple[float, float]], scale: float) -> None:
    """A controller whose cost is k[e] times the ceiling's on seed e has excess cost k[e] - 1 there,
    beats the ceiling where k[e] < 1, and keeps both when every return is scaled (a ratio of
    costs has no units)."""
    ceiling = np.array([-cost for cost, _ in pairs])
    factor = np.array([k for _, k in pairs])
    returns = factor * ceiling
    assert excess_costs(returns, ceiling) == pytest.approx(factor - 1.0, rel=1e-12, abs=1e-12)
    cost = excess_cost(returns, ceiling)
    assert cost.beats == int(np.sum(returns > ceiling)) and cost.episodes == len(pairs)
    assert cost.low <= cost.mean <= cost.high
    assert excess_costs(scale * returns, scale * ceiling) == pytest.approx(factor - 1.0, rel=1e-9, abs=1e-12)


@settings(max_examples=100, deadline=None, derandomize=True)
@given(ceiling=st.lists(st.floats(-1e6, 1e6, allow_nan=False), min_size=2, max_size=10), data=st.data())
def test_any_ceiling_return_at_or_above_zero_is_refused_by_name(ceiling: list[float], data: st.DataObject) -> None:
    returns = data.draw(st.lists(st.floats(-1e6, 0.0), min_size=len(ceiling), max_size=len(ceiling)))
    if all(value < 0 for value in ceiling):
        assert excess_costs(returns, ceiling).shape == (len(ceiling),)
    else:
        with pytest.raises(ValueError, match=r"ceiling's return .*recompute the ceiling data"):
            excess_costs(returns, ceiling)


# ---------------------------------------------------------------------------------------- over ids


def test_aggregate_iqm_of_excess_costs_on_a_hand_case() -> None:
    # Eight ids, two seeds each, the ceiling returning (-10, -20) on every id. The controller costs
    # a fixed fraction more than the ceiling on both seeds of an id, so its per-id excess costs are
    # -0.05, 0, 0.01, 0.02, 0.03, 0.04, 0.1 and 1.0 whatever seeds a resample draws.
    ids = [f"id{k}" for k in range(8)]
    ceiling = np.array([-10.0, -20.0])
    fractions = [-0.05, 0.0, 0.01, 0.02, 0.03, 0.04, 0.1, 1.0]
    controller = {env_id: ceiling * (1.0 + fraction) for env_id, fraction in zip(ids, fractions, strict=True)}
    result = aggregate_excess_costs({"x": controller}, dict.fromkeys(ids, ceiling), reps=300, seed=3)["x"]
    # The IQM drops the two lowest (-0.05, 0) and the two highest (0.1, 1.0) and averages 0.01,
    # 0.02, 0.03 and 0.04: 0.025. The mean of the eight: 1.15 / 8 = 0.14375.
    assert result["iqm"] == pytest.approx(0.025, abs=1e-12)
    assert result["mean"] == pytest.approx(0.14375, abs=1e-12)
    assert (result["iqm_low"], result["iqm_high"]) == pytest.approx((0.025, 0.025), abs=1e-12)
    assert (result["mean_low"], result["mean_high"]) == pytest.approx((0.14375, 0.14375), abs=1e-12)
    assert (result["ids"], result["env_ids"], result["episodes"]) == (8, ids, 2)


def test_the_aggregate_iqm_is_rliable_s_to_the_bit() -> None:
    """The bootstrap's statistic computes the IQM with numpy (scipy's wrapper costs 0.7 ms a call):
    on 1 to 9 ids it equals rliable's ``aggregate_iqm`` of the per-id values exactly, for the
    excess costs and for the normalised scores."""
    _, metrics = rliable_modules()
    rng = np.random.default_rng(5)
    for count in range(1, 10):
        ids = [f"id{k}" for k in range(count)]
        ceiling = {env_id: -rng.uniform(1.0, 50.0, 4) for env_id in ids}
        passive = {env_id: 5.0 * ceiling[env_id] for env_id in ids}
        controller = {env_id: ceiling[env_id] * rng.uniform(1.0, 2.0, 4) for env_id in ids}
        excess = aggregate_excess_costs({"x": controller}, ceiling, reps=100)["x"]
        per_id = np.array([[np.mean(controller[env_id] / ceiling[env_id] - 1.0) for env_id in ids]])
        assert excess["iqm"] == float(metrics.aggregate_iqm(per_id)), count
        scores = aggregate_scores({"x": controller}, passive, ceiling, reps=100)["x"]
        per_id_scores = np.array(
            [
                [
                    100.0 * np.mean(controller[env_id] - passive[env_id]) / np.mean(ceiling[env_id] - passive[env_id])
                    for env_id in ids
                ]
            ]
        )
        assert scores["iqm"] == pytest.approx(float(metrics.aggregate_iqm(per_id_scores)), rel=1e-13), count


def _stratified_bootstrap_means(costs: np.ndarray, reps: int, seed: int) -> np.ndarray:
    """(reps,) the mean over ids of the per-id mean excess costs of seeds drawn with replacement
    within each id: a stratified bootstrap written out here with numpy's own generator, independent
    of rliable's."""
    rng = np.random.default_rng(seed)
    episodes, ids = costs.shape
    picks = rng.integers(0, episodes, size=(reps, episodes, ids))
    return costs[picks, np.arange(ids)].mean(axis=1).mean(axis=1)


def test_aggregate_interval_is_the_stratified_bootstrap_s_whichever_way_is_better() -> None:
    """Lower is better for an excess cost: the interval must still be the 2.5 % and 97.5 %
    quantiles of the resampled statistic, low end first. An independent bootstrap of the mean over
    ids (numpy's generator, not rliable's) gives the same ends to within its Monte Carlo error
    (about 1 % of the width at 20 000 replications)."""
    rng = np.random.default_rng(0)
    ids = ["a", "b", "c"]
    ceiling = {env_id: -rng.uniform(10.0, 60.0, 16) for env_id in ids}
    controller = {env_id: ceiling[env_id] * (1.0 + rng.uniform(0.0, 0.4, 16)) for env_id in ids}
    result = aggregate_excess_costs({"x": controller, "ceiling": ceiling}, ceiling, reps=20_000, seed=7)
    row = result["x"]
    costs = np.stack([controller[env_id] / ceiling[env_id] - 1.0 for env_id in ids], axis=1)  # (16, 3)
    assert row["mean"] == pytest.approx(costs.mean(), rel=1e-12)
    low, high = np.quantile(_stratified_bootstrap_means(costs, 20_000, 1), [0.025, 0.975])
    width = high - low
    assert row["mean_low"] == pytest.approx(low, abs=0.04 * width)
    assert row["mean_high"] == pytest.approx(high, abs=0.04 * width)
    assert row["mean_low"] < row["mean"] < row["mean_high"]
    assert row["iqm_low"] < row["iqm"] < row["iqm_high"]
    # The ceiling against itself: 0 in every resample.
    assert [result["ceiling"][key] for key in ("iqm", "iqm_low", "iqm_high", "mean_low", "mean_high")] == [0.0] * 5
    # A controller that costs 10 % of the ceiling's cost more on every seed has every resample's
    # statistic 0.1 higher (the same resamples: seeded, and independent of the other rows).
    worse = {env_id: controller[env_id] + 0.1 * ceiling[env_id] for env_id in ids}
    shifted = aggregate_excess_costs({"worse": worse}, ceiling, reps=20_000, seed=7)["worse"]
    for key in ("iqm", "iqm_low", "iqm_high", "mean", "mean_low", "mean_high"):
        assert shifted[key] == pytest.approx(row[key] + 0.1, abs=1e-12), key


def test_aggregate_refuses_what_it_cannot_pair() -> None:
    ceiling = {"a": np.array([-1.0, -2.0]), "b": np.array([-1.0, -2.0, -3.0])}
    with pytest.raises(ValueError, match="different episode counts"):
        aggregate_excess_costs({"x": {"a": [-2.0, -3.0], "b": [-2.0, -3.0, -4.0]}}, ceiling, reps=100)
    with pytest.raises(ValueError, match="'x' on a: .*must be above 0"):
        aggregate_excess_costs({"x": {"a": [-2.0, -3.0]}}, {"a": np.array([-1.0, 0.0])}, reps=100)
    with pytest.raises(ValueError, match="where the ceiling has none"):
        aggregate_excess_costs({"x": {"c": [-2.0, -3.0]}}, ceiling, reps=100)


# ---------------------------------------------------------------------------------------- synthetic data

#: Six held-out seeds in the reference, of which the ceiling ran the first four.
SEEDS = [10, 11, 12, 13, 14, 15]
CEILING_SEEDS = [10, 11, 12, 13]
#: Per id and controller: (kind, returns on SEEDS). On the ceiling's seeds passive costs 100, 50,
#: 80, 70; the ceiling 20, 10, 16, 14 (a fifth of passive's); law_a 3 times the ceiling's cost,
#: law_b 1.5 times, mpc 1.25 times, the model 1.1 times (seeds 14 and 15 break these patterns, so
#: that a statistic taken over the wrong seeds shows).
CONTROLLERS = {
    "passive": ("baseline", [-100.0, -50.0, -80.0, -70.0, -5.0, -500.0]),
    "law_a": ("baseline", [-60.0, -30.0, -48.0, -42.0, -1.0, -1.0]),
    "law_b": ("baseline", [-30.0, -15.0, -24.0, -21.0, -400.0, -400.0]),
    "mpc": ("reference", [-25.0, -12.5, -20.0, -17.5, -2.0, -2.0]),
    "model": ("shipped model", [-22.0, -11.0, -17.6, -15.4, -300.0, -3.0]),
}
CEILING_RETURNS = [-20.0, -10.0, -16.0, -14.0]


def synthetic_reference(ids: tuple[str, ...] = ("idA", "idB")) -> dict[str, Any]:
    """Reference scores in :func:`agents.evaluation.scoring.load_reference`'s layout, with the
    entries the scores and the table read."""
    per_id = {
        env_id: {
            "seeds": list(SEEDS),
            "best_baseline": "law_b",
            "controllers": {
                name: {"kind": kind, "returns": list(returns), "terminated": [False] * len(SEEDS)}
                for name, (kind, returns) in CONTROLLERS.items()
            },
        }
        for env_id in ids
    }
    return {
        "format": FORMAT,
        "version": FORMAT_VERSION,
        "commit": "abc1234",
        "zero": "passive",
        "reference": "mpc",
        "confidence": 0.95,
        "score_bootstrap": {"reps": 2000, "seed": 10},
        "aggregate_bootstrap": {"reps": 500, "random_state": 10},
        "env_kwargs": {},
        "per_id": per_id,
    }


def ceiling_run(seeds: list[int] | None = None, returns: list[float] | None = None) -> SimpleNamespace:
    """A ceiling run as the table reads one (what agents.evaluation.ceiling.CeilingRun has)."""
    return SimpleNamespace(
        seeds=np.asarray(CEILING_SEEDS if seeds is None else seeds, dtype=np.int64),
        returns=np.asarray(CEILING_RETURNS if returns is None else returns, dtype=np.float64),
        seconds_per_step=0.078,
        machine="a test machine",
    )


# ---------------------------------------------------------------------------------------- the score


def test_a_score_reports_the_ceiling_on_the_ceiling_s_seeds() -> None:
    reference = synthetic_reference()
    returns = CONTROLLERS["law_a"][1]
    plain = score_returns(returns, "idA", SEEDS, name="law_a", reference=reference)
    score = score_returns(returns, "idA", SEEDS, name="law_a", reference=reference, ceiling={"idA": ceiling_run()})
    # law_a costs 3 times the ceiling on each ceiling seed: an excess cost of 2 on each, 200 %.
    assert score.ceiling_seeds == tuple(CEILING_SEEDS)
    assert score.ceiling_excess is not None
    assert (score.ceiling_excess.mean, score.ceiling_excess.low, score.ceiling_excess.high) == pytest.approx(
        (2.0, 2.0, 2.0), abs=1e-12
    )
    # Normalised with 100 = the ceiling, on its seeds: law_a gains 40, 20, 32, 28 over passive
    # (mean 30), the ceiling 80, 40, 64, 56 (mean 60): 100 * 30 / 60 = 50, on every resample.
    assert score.ceiling_score == pytest.approx(50.0, abs=1e-12)
    assert (score.ceiling_score_low, score.ceiling_score_high) == pytest.approx((50.0, 50.0), abs=1e-12)
    assert "excess cost over the ceiling: +200.0 % [+200.0, +200.0]" in score.summary()
    assert "(0 = passive, 100 = the ceiling): 50.0 [50.0, 50.0]" in score.summary()
    # Every other field is what it is without the ceiling.
    before = {field.name: getattr(plain, field.name) for field in dataclasses.fields(plain)}
    after = {field.name: getattr(score, field.name) for field in dataclasses.fields(score)}
    for name, value in before.items():
        if not name.startswith("ceiling"):
            assert np.array_equal(value, after[name]) if isinstance(value, np.ndarray) else value == after[name], name
    assert plain.ceiling_excess is None and plain.ceiling_score is None
    assert "ceiling" not in plain.summary()


def test_a_score_on_some_of_the_ceiling_s_seeds_uses_those() -> None:
    reference = synthetic_reference()
    values = [CONTROLLERS["model"][1][SEEDS.index(seed)] for seed in (15, 12, 10)]
    score = score_returns(values, "idA", [15, 12, 10], reference=reference, ceiling={"idA": ceiling_run()})
    # The ceiling's seeds among those scored, in the ceiling's order: 10, then 12.
    assert score.ceiling_seeds == (10, 12)
    assert score.ceiling_excess is not None and score.ceiling_excess.mean == pytest.approx(0.1, abs=1e-12)
    lone = score_returns(values[:2], "idA", [15, 12], reference=reference, ceiling={"idA": ceiling_run()})
    assert lone.ceiling_excess is None and lone.ceiling_note.startswith("not available: 1 of the ceiling's 4 seeds")
    elsewhere = score_returns(values, "idA", [15, 12, 10], reference=reference, ceiling={"idB": ceiling_run()})
    assert elsewhere.ceiling_excess is None and "no ceiling data for idA" in elsewhere.ceiling_note


def test_a_ceiling_on_seeds_the_reference_does_not_hold_is_refused() -> None:
    reference = synthetic_reference()
    foreign = ceiling_run(seeds=[10, 11, 99, 13])
    with pytest.raises(ReferenceDataError, match=r"hold seeds \[99\] that its reference scores do not"):
        score_returns(CONTROLLERS["law_a"][1], "idA", SEEDS, reference=reference, ceiling={"idA": foreign})


# ---------------------------------------------------------------------------------------- the table


def test_the_table_on_a_small_synthetic_pair() -> None:
    reference = synthetic_reference()
    table = ceiling_table(reference, {"idA": ceiling_run(), "idB": ceiling_run(), "idZ": ceiling_run()}, reps=300)
    assert [item.env_id for item in table.ids] == ["idA", "idB"]
    assert list(table.skipped) == ["idZ"]
    item = table.ids[0]
    assert item.seeds == tuple(CEILING_SEEDS) and item.seconds_per_step == 0.078
    rows = {row.controller: row for row in item.rows}
    assert list(rows) == [*CONTROLLERS, CEILING]
    # Excess costs per controller on the ceiling's seeds: passive 5x the ceiling (+400 %), law_a 3x,
    # law_b 1.5x, mpc 1.25x, the model 1.1x; each the same on every seed.
    expected = {"passive": 4.0, "law_a": 2.0, "law_b": 0.5, "mpc": 0.25, "model": 0.1, CEILING: 0.0}
    for name, fraction in expected.items():
        assert rows[name].excess.mean == pytest.approx(fraction, abs=1e-12), name
        assert rows[name].excess.half_width == pytest.approx(0.0, abs=1e-12), name
        # Normalised: the gain over passive (5 - k) / (5 - 1) of the ceiling's for a cost k times its own.
        assert rows[name].score == pytest.approx(100.0 * (4.0 - fraction) / 4.0, abs=1e-9), name
    # Mean returns on the ceiling's seeds: law_b (-30 - 15 - 24 - 21) / 4 = -22.5.
    assert rows["law_b"].mean_return == pytest.approx(-22.5, abs=1e-12)
    # The room left: the cheapest scripted law (not passive, not mpc nor the model) is law_b.
    assert (item.best_law, item.room_left.mean) == ("law_b", pytest.approx(0.5, abs=1e-12))
    aggregate = table.aggregate
    assert aggregate[BEST_LAW_ROW]["excess"]["iqm"] == pytest.approx(0.5, abs=1e-12)
    assert aggregate["model"]["excess"]["mean"] == pytest.approx(0.1, abs=1e-12)
    assert aggregate["model"]["score"]["mean"] == pytest.approx(100.0 * 3.9 / 4.0, abs=1e-9)
    assert (aggregate["model"]["excess"]["ids"], table.ids_total) == (2, 2)
    text = ceiling_markdown(table)
    assert "| idA | 4 (10..13) | -15.0 ± " in text
    assert "| 0.078 s (a test machine) | law_b | +50.0 % [+50.0, +50.0] |" in text
    assert "| **law_b** | -22.5 ± " in text
    # The gap to the best law closed: law_b's excess cost 0.5, mpc's 0.25 (half), the model's 0.1
    # (4/5), law_a's 2.0 (1 - 2.0 / 0.5 = -300 %), the ceiling's all of it.
    closed = {"law_b": 0.0, "mpc": 0.5, "model": 0.8, "law_a": -3.0, CEILING: 1.0}
    for name, fraction in closed.items():
        assert rows[name].gap is not None and rows[name].gap.fraction == pytest.approx(fraction, abs=1e-12), name
    assert "| gap to law_b closed |" in text and "| 97.5 [97.5, 97.5] | +80 % [+80, +80] |" in text
    assert "| model | 2/2 | +10.0 % [+10.0, +10.0] | +10.0 % [+10.0, +10.0] | 97.5 [97.5, 97.5] |" in text
    assert "Not tabled: idZ: the reference scores hold no returns for it" in text


def test_the_table_refuses_a_ceiling_it_cannot_pair() -> None:
    reference = synthetic_reference()
    with pytest.raises(ReferenceDataError, match=r"idB hold seeds \[16, 17\] that its reference scores do not"):
        ceiling_table(reference, {"idA": ceiling_run(), "idB": ceiling_run(seeds=[10, 11, 16, 17])}, reps=100)
    with pytest.raises(ReferenceDataError, match="idA, passive against the ceiling: .*must be above 0"):
        ceiling_table(reference, {"idA": ceiling_run(returns=[-20.0, 0.0, -16.0, -14.0])}, reps=100)
    with pytest.raises(ReferenceDataError, match="one return per seed"):
        ceiling_table(reference, {"idA": ceiling_run(returns=[-20.0, -10.0])}, reps=100)
    with pytest.raises(ReferenceDataError, match="hold none of the reference's ids"):
        ceiling_table(reference, {"idZ": ceiling_run()}, reps=100)


def test_ceilings_of_different_seed_counts_aggregate_over_the_seeds_every_id_holds() -> None:
    """Every id is tabled on all of its ceiling's seeds; the aggregate keeps each id's lowest seeds,
    as many as the fewest, so it equals the aggregate of ceilings cut to those seeds."""
    reference = synthetic_reference()
    short = ceiling_run([10, 11, 12], [-20.0, -10.0, -16.0])
    table = ceiling_table(reference, {"idA": ceiling_run(), "idB": short}, reps=200)
    assert [len(item.seeds) for item in table.ids] == [4, 3]
    assert "each id's first 3 ceiling seeds" in table.aggregate_note and "[3, 4]" in table.aggregate_note
    assert f"({table.aggregate_note}.)" in ceiling_markdown(table)
    cut = ceiling_run()
    cut_table = ceiling_table(
        reference, {"idA": ceiling_run(cut.seeds[:3].tolist(), cut.returns[:3].tolist()), "idB": short}, reps=200
    )
    assert table.aggregate and table.aggregate == cut_table.aggregate
    assert table.aggregate["model"]["excess"]["episodes"] == 3  # per id


# ---------------------------------------------------------------------------------------- the command


def _write_files(tmp_path: Path, ceiling_returns: list[float] | None = None) -> tuple[Path, Path]:
    reference = tmp_path / "reference.json"
    reference.write_text(json.dumps(synthetic_reference()), encoding="utf-8")
    entry = {
        "controller": "mpc",
        "settings": dataclasses.asdict(MPCSettings()),
        "env_kwargs": {},
        "seeds": CEILING_SEEDS,
        "returns": CEILING_RETURNS if ceiling_returns is None else ceiling_returns,
        "seconds_per_step": 0.078,
        "wall_seconds": 10.0,
        "seed_noise": {"seeds": [10], "planner_seeds": [0, 1], "returns": [[-20.0], [-20.5]], "std": 0.35},
        "commit": "abc1234",
        "date": "2026-12-02T07:30:00Z",
        "machine": "a test machine",
        "command": "python -m agents.ceiling compute",
    }
    ceiling = tmp_path / "ceiling.json"
    data = {"format": CEILING_FORMAT, "format_version": CEILING_FORMAT_VERSION, "ids": {"idA": entry}}
    ceiling.write_text(json.dumps(data), encoding="utf-8")
    return reference, ceiling


def test_the_command_prints_the_table_from_the_files(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    reference, ceiling = _write_files(tmp_path)
    options = ["--ceiling-file", str(ceiling), "--reference-file", str(reference), "--bootstrap-reps", "200"]
    result = main(["--ceiling", *options])
    printed = capsys.readouterr().out
    assert printed == result["ceiling_markdown"]
    assert "| idA | 4 (10..13) |" in printed and "| **law_b** |" in printed
    assert "200 replications" in printed
    assert sorted(path.name for path in tmp_path.iterdir()) == ["ceiling.json", "reference.json"]  # wrote nothing


def test_the_command_s_ceiling_options_go_together(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    reference, ceiling = _write_files(tmp_path)
    for argv, message in [
        (["--ceiling", "--commit", "abc1234"], "writes nothing: drop --commit"),
        (["--ceiling", "--force"], "writes nothing: drop --force"),
        (["--ceiling-file", str(ceiling)], "--ceiling-file go with --ceiling"),
        ([], "required: benchmark_json, --commit (or pass --ceiling)"),
        ([str(reference)], "required: --commit"),
    ]:
        with pytest.raises(SystemExit) as exit_:
            main(argv)
        assert exit_.value.code == 2 and message in capsys.readouterr().err, argv


def test_the_command_names_the_file_of_bad_ceiling_data(tmp_path: Path) -> None:
    reference, ceiling = _write_files(tmp_path, ceiling_returns=[-20.0, -10.0, 1.0, -14.0])
    with pytest.raises(ReferenceDataError, match=r"must be above 0.*--ceiling-file.*--reference-file"):
        main(["--ceiling", "--ceiling-file", str(ceiling), "--reference-file", str(reference)])
    # A missing file (the shipped one, before it is computed) is named with the option that picks it.
    with pytest.raises(FileNotFoundError, match=r"no ceiling at .*none.json.*--ceiling-file"):
        ceiling_report(str(tmp_path / "none.json"), str(reference))


def test_the_shipped_table_aggregates_each_track_apart() -> None:
    """The hard ids' larger room must not enter the standard track's aggregate: one heading and
    aggregate per track, each id under its own track's heading."""
    from agents.evaluation.ceiling import load_ceiling
    from tether_gym.registration import HARD_TRACK

    text = main(["--ceiling", "--bootstrap-reps", "100"])["ceiling_markdown"]
    standard, heading, hard = text.partition("## Against the reference ceiling: the hard track")
    assert standard.startswith("## Against the reference ceiling: the standard track")
    # A track with no id in the ceiling file has no section (the hard track is empty at present).
    assert bool(heading) == any(env_id in HARD_TRACK for env_id in load_ceiling())
    for env_id in load_ceiling():
        inside, outside = (hard, standard) if env_id in HARD_TRACK else (standard, hard)
        assert f"| {env_id} |" in inside and f"| {env_id} |" not in outside, env_id
