"""The reference ceiling: computing it in chunks, its file, the check against a fresh run, and the
shipped data against a fresh planner."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

from agents import ceiling as command
from agents.common.cli import HELD_OUT_SEED
from agents.controllers.mpc import MPCSettings
from agents.evaluation.ceiling import (
    CEILING_FILE,
    CEILING_SETTINGS_FILE,
    CeilingDataError,
    ceiling_ids,
    check_ceiling,
    compute_ceiling,
    load_ceiling,
    load_ceiling_settings,
    write_ceiling,
)

ENV_ID = "TetherTetrahedron-v0"
#: A planner small enough that an episode takes about a second.
TINY = MPCSettings(samples=3, horizon=2, knots=1, noise=0.2, prior="velocity_feedback")
SEEDS = [HELD_OUT_SEED, HELD_OUT_SEED + 1, HELD_OUT_SEED + 2]


@pytest.fixture(scope="module")
def tiny_run():
    return compute_ceiling(ENV_ID, SEEDS, TINY, noise_seeds=2, chunk=3, commit="test", machine="test")


def test_a_chunk_s_episodes_do_not_depend_on_the_chunk(tiny_run) -> None:
    """One seed per rollout and all three in one give the same returns to the bit: a serial loop
    and parallel workers agree."""
    alone = compute_ceiling(ENV_ID, SEEDS, TINY, noise_seeds=2, chunk=1)
    np.testing.assert_array_equal(alone.returns, tiny_run.returns)
    np.testing.assert_array_equal(alone.seed_noise.returns, tiny_run.seed_noise.returns)
    assert tiny_run.seed_noise.returns[0].tolist() == tiny_run.returns[:2].tolist()


def test_the_seed_noise_is_the_spread_over_planner_seeds(tiny_run) -> None:
    noise = tiny_run.seed_noise
    assert noise.planner_seeds.tolist() == [0, 1, 2]
    assert noise.std == pytest.approx(np.sqrt(noise.returns.var(axis=0, ddof=1).mean()))
    # Another planner seed plans differently: a noise of zero would make the check's tolerance zero.
    assert noise.std > 0.0


def test_the_file_round_trips_and_merges(tmp_path: Path, tiny_run) -> None:
    file = tmp_path / "ceiling.json"
    write_ceiling([tiny_run], file)
    other = dataclasses.replace(tiny_run, env_id="TetherChain-v0")
    write_ceiling([other], file)
    loaded = load_ceiling(file)
    assert sorted(loaded) == ["TetherChain-v0", ENV_ID]
    np.testing.assert_array_equal(loaded[ENV_ID].returns, tiny_run.returns)
    assert loaded[ENV_ID].settings == dataclasses.asdict(TINY)
    np.testing.assert_array_equal(loaded[ENV_ID].returns_on([SEEDS[2], SEEDS[0]]), tiny_run.returns[[2, 0]])
    with pytest.raises(KeyError, match="no return for seed"):
        loaded[ENV_ID].returns_on([1])


def test_a_fresh_run_matches_and_a_changed_return_is_caught(tiny_run) -> None:
    assert check_ceiling(tiny_run, count=1).passed
    tampered = dataclasses.replace(
        tiny_run, returns=tiny_run.returns + np.array([0.0, 0.0, 10 * tiny_run.seed_noise.std])
    )
    result = check_ceiling(tampered, count=1)
    assert not result.passed and "DIFFERS" in result.summary()


@pytest.mark.parametrize(
    ("change", "message"),
    [
        (lambda data: data.update(format="other"), "is not a 'tether-gym-ceiling' file"),
        (lambda data: data["ids"][ENV_ID].update(returns=[1.0]), "one finite number per seed"),
        (lambda data: data["ids"][ENV_ID].update(seeds=[1, 1, 2]), "distinct"),
        (lambda data: data["ids"][ENV_ID]["settings"].update(samples=1), "planner settings are invalid"),
        (lambda data: data["ids"][ENV_ID].update(seconds_per_step=-1), "seconds_per_step"),
        (lambda data: data["ids"][ENV_ID].pop("seed_noise"), "seed_noise"),
    ],
)
def test_a_malformed_file_is_refused_with_the_fix(tmp_path: Path, tiny_run, change, message: str) -> None:
    file = tmp_path / "ceiling.json"
    write_ceiling([tiny_run], file)
    data = json.loads(file.read_text())
    change(data)
    file.write_text(json.dumps(data))
    with pytest.raises(CeilingDataError, match=message) as error:
        load_ceiling(file)
    assert "python -m agents.ceiling" in str(error.value)


def test_an_id_without_tuned_settings_has_no_ceiling() -> None:
    with pytest.raises(ValueError, match="no ceiling settings for 'TetherBeadedChain-v0'"):
        load_ceiling_settings("TetherBeadedChain-v0")


def test_bad_seeds_are_refused() -> None:
    with pytest.raises(ValueError, match="distinct"):
        compute_ceiling(ENV_ID, [1, 1], TINY)
    with pytest.raises(ValueError, match="non-negative"):
        compute_ceiling(ENV_ID, [-1], TINY)


def test_the_command_checks_its_arguments_before_any_work(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="--envs: no ceiling for"):
        command.main(["--envs", "TetherBeadedChain-v0", "--serial"])
    with pytest.raises(ValueError, match="--file"):
        command.main(["--show", "--file", str(tmp_path / "missing.json")])


def test_the_command_shows_the_shipped_table(capsys: pytest.CaptureFixture[str]) -> None:
    assert command.main(["--show"]) == 0
    table = capsys.readouterr().out
    for env_id in load_ceiling():
        assert f"| {env_id} |" in table


# --- the shipped ceiling ---------------------------------------------------------------------


def test_the_shipped_ceiling_was_computed_with_today_s_settings_on_held_out_seeds() -> None:
    shipped = load_ceiling(CEILING_FILE)
    assert set(shipped) <= set(ceiling_ids(CEILING_SETTINGS_FILE))
    for env_id, run in shipped.items():
        # A field added since a run was computed takes its default, which is the behaviour the run had.
        assert MPCSettings(**run.settings) == load_ceiling_settings(env_id), env_id
        assert run.seeds.tolist() == list(range(HELD_OUT_SEED, HELD_OUT_SEED + run.seeds.size)), env_id
        assert run.env_kwargs == {}, env_id
        assert run.command.startswith("python -m agents.ceiling --envs "), run.command  # pastes into a shell


@pytest.mark.slow
@pytest.mark.parametrize("env_id", sorted(load_ceiling(CEILING_FILE)) if CEILING_FILE.is_file() else [])
def test_the_shipped_returns_match_a_fresh_planner(env_id: str) -> None:
    """A fresh full-strength run on the last shipped seed is within 3 seed-noise standard
    deviations of the shipped return (the same bits on the machine that computed it)."""
    result = check_ceiling(load_ceiling(CEILING_FILE)[env_id], count=1)
    assert result.passed, result.summary()
