"""The hard track qualifies: on every hard id the best scripted law, its gains re-tuned for the id,
costs at least HARD_TRACK_MIN_EXCESS_COST more than the reference ceiling, on the shipped
held-out seeds and in a fresh quick check."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

from agents.controllers.registry import BASELINES, make_baseline
from agents.evaluation.ceiling import load_ceiling
from agents.evaluation.ceiling_report import ceiling_table
from agents.evaluation.rollout import rollout
from agents.evaluation.scoring import load_reference
from agents.evaluation.stats import excess_cost
from tether_gym.registration import ENV_IDS, HARD_TRACK, HARD_TRACK_MIN_EXCESS_COST

#: Seeds of the quick check: the ceiling's first held-out seeds.
QUICK_SEEDS = 16


def test_the_hard_track_is_registered_with_its_ceiling_and_reference_scores() -> None:
    ceiling, reference = load_ceiling(), load_reference()
    assert HARD_TRACK, "the hard track has no id"
    for env_id in HARD_TRACK:
        assert env_id in ENV_IDS
        assert env_id in ceiling, f"{env_id} has no shipped ceiling: python -m agents.ceiling --envs {env_id}"
        assert env_id in reference["per_id"], f"{env_id} has no reference scores"


@pytest.mark.parametrize("env_id", HARD_TRACK)
def test_the_best_law_leaves_the_track_s_room_on_the_held_out_seeds(env_id: str) -> None:
    """From the shipped data: the lowest mean excess cost of any scripted law over the ceiling,
    on all of the ceiling's held-out seeds, is at least the track's threshold."""
    table = ceiling_table(load_reference(), {env_id: load_ceiling()[env_id]}, reps=100)
    (entry,) = table.ids
    assert entry.room_left.mean >= HARD_TRACK_MIN_EXCESS_COST, (
        f"{env_id}: the best law ({entry.best_law}) costs only {100 * entry.room_left.mean:.1f} % more than the "
        f"ceiling; the hard track needs {100 * HARD_TRACK_MIN_EXCESS_COST:.0f} %"
    )


@pytest.mark.slow
@pytest.mark.parametrize("env_id", HARD_TRACK)
def test_a_fresh_quick_check_qualifies_every_hard_id(env_id: str) -> None:
    """Every scripted law (with the id's gains from laws.yml) rerun on the ceiling's first seeds:
    the best of them still costs at least the threshold more than the shipped ceiling there."""
    run = load_ceiling()[env_id]
    seeds = run.seeds[:QUICK_SEEDS].tolist()
    ceiling_returns = run.returns_on(seeds)
    excess = {}
    for name in BASELINES:
        if name == "passive":
            continue
        envs = gym.make_vec(env_id, num_envs=1)
        record = rollout(make_baseline(name, envs), env_id, seeds)
        envs.close()
        excess[name] = excess_cost(np.nansum(record.rewards, axis=1), ceiling_returns).mean
    best = min(excess, key=excess.__getitem__)
    assert excess[best] >= HARD_TRACK_MIN_EXCESS_COST, (env_id, best, excess)
