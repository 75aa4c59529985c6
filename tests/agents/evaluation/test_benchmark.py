"""The benchmark (``python -m agents.benchmark``, ``agents.evaluation.benchmark``): smoke runs of
the command on two ids with a few scripted controllers, a missing reference, and refusals
before any rollout. Its statistics are checked by hand in ``test_stats.py``.
"""

from __future__ import annotations

import csv
import dataclasses
import json
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pytest

import agents.evaluation.benchmark
from agents.benchmark import main
from agents.common.files import OutputError, OutputExistsError
from agents.evaluation.benchmark import BEST_BASELINE_ROW, PLOT_FILES, TABLE_FILES, BenchmarkConfig, benchmark
from agents.evaluation.report import json_ready
from agents.evaluation.rollout import rollout
from agents.policies import make_controller


def _without_mpc(monkeypatch: pytest.MonkeyPatch) -> None:
    """Make ``mpc`` unknown, as it is until the reference controller lands (and stays so for
    these tests after it has: they check how a missing controller is reported)."""

    def make(spec: str, env: Any, trust_pickle: bool = False, allow_other_id: bool = False) -> Any:
        if spec == "mpc":
            raise ValueError("unknown controller 'mpc' (test: as if it did not exist)")
        return make_controller(spec, env, trust_pickle=trust_pickle, allow_other_id=allow_other_id)

    monkeypatch.setattr(agents.evaluation.benchmark, "make_controller", make)


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
    results = main(
        [*arguments, "--controllers", "velocity_feedback", "tension_aware", "mpc", "--save-episodes", "10001"]
    )
    from tether_gym.viewer import load_recording

    for env_id in SMOKE_IDS:  # the episodes saved for the viewer: every controller run, on the seed asked for
        saved = sorted(path.name for path in (out / "episodes" / env_id).iterdir())
        assert saved == [f"{name}_seed10001.npz" for name in ("passive", "tension_aware", "velocity_feedback")]
        recording = load_recording(out / "episodes" / env_id / "tension_aware_seed10001.npz")
        assert (recording.meta["env_id"], recording.meta["seed"], recording.steps) == (env_id, 10001, 300)
    for name in TABLE_FILES:
        assert (out / name).stat().st_size > 0
    for name in PLOT_FILES:
        assert (out / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    report = (out / "benchmark.md").read_text()
    data = json.loads((out / "benchmark.json").read_text())
    assert data == json.loads(json.dumps(json_ready(results)))
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
    # The episodes are the comparison's: agents.evaluation.rollout.rollout on the same seeds gives the same returns.
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
    assert set(aggregate) == {"passive", "velocity_feedback", "tension_aware", BEST_BASELINE_ROW}
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
        BenchmarkConfig(
            env_ids=[SMOKE_IDS[1]],
            controllers=["passive", "velocity_feedback"],
            episodes=3,
            out=tmp_path,
            bootstrap_reps=200,
        )
    )
    entry = results["per_id"][SMOKE_IDS[1]]
    assert entry["score"] == "not available: mpc did not run on this id"
    assert all(item["normalised_score"] is None for item in entry["controllers"].values())
    assert results["aggregate"] == {}
    report = (tmp_path / "benchmark.md").read_text()
    assert "Not available: the normalised score needs mpc" in report
    assert "| TetherTriangle-v0 | n/a | n/a |" in report
    assert (tmp_path / "aggregate.png").stat().st_size > 0  # a figure that says why it is empty


def test_the_config_keeps_checked_values_and_is_frozen() -> None:
    config = BenchmarkConfig(env_ids=[SMOKE_IDS[0]], controllers=["lqr"], episodes=np.int64(3), bootstrap_reps=100)
    assert (config.env_ids, config.controllers, config.episodes) == ((SMOKE_IDS[0],), ("lqr",), 3)
    assert type(config.episodes) is int
    with pytest.raises(dataclasses.FrozenInstanceError):
        config.seed = 0  # type: ignore[misc]
    for settings, message in [
        ({"env_ids": ["Nope-v0"]}, r"env_ids \(--envs\): unknown \['Nope-v0'\]"),
        ({"controllers": ["lqr", "lqr"]}, r"controllers lists \['lqr'\] more than once"),
        ({"episodes": 1}, "episodes must be an integer in 2..100000; got 1"),
        ({"bootstrap_reps": 99}, "bootstrap_reps must be an integer >= 100; got 99"),
    ]:
        with pytest.raises(ValueError, match=message):
            BenchmarkConfig(**settings)  # type: ignore[arg-type]


def test_bad_output_or_controller_is_refused_before_any_rollout(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    def no_rollout(*args: Any, **kwargs: Any) -> None:
        raise AssertionError("a rollout ran before the arguments were checked")

    monkeypatch.setattr(agents.evaluation.benchmark, "rollout", no_rollout)
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
    with pytest.raises(ValueError, match="unknown controllers \\['pasive'\\] \\(did you mean 'passive'\\?\\)"):
        main(["--envs", SMOKE_IDS[0], "--controllers", "pasive", "--out", str(tmp_path / "new")])
    # A misspelt reference would run nothing and leave every score "not available": refused, with the closest name.
    with pytest.raises(ValueError, match="--reference 'mcp' is no controller .*\\(did you mean 'mpc'\\?\\)"):
        main(["--envs", SMOKE_IDS[0], "--reference", "mcp", "--out", str(tmp_path / "new")])
    with pytest.raises(ValueError, match="--reference '.' is no controller"):  # a directory, but no policy
        main(["--envs", SMOKE_IDS[0], "--reference", ".", "--out", str(tmp_path / "new")])
    with pytest.raises(ValueError, match="reference"):
        BenchmarkConfig(env_ids=[SMOKE_IDS[0]], reference="passive", out=tmp_path / "new")
    with pytest.raises(SystemExit):  # argparse: --episodes must be at least 2
        main(["--episodes", "1", "--out", str(tmp_path / "new")])
