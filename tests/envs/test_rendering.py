"""The env's frames: shape and type, what they show, that they depend on the state alone, and the
cached background that makes them fast."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import tether_gym as tg

pytest.importorskip("matplotlib")

from matplotlib.colors import to_rgb  # noqa: E402

from tether_gym.envs.rendering import (  # noqa: E402
    BROKEN_COLOUR,
    SLACK_COLOUR,
    TAUT_COLOUR,
    THRUST_COLOUR,
    ClusterRenderer,
    arrow_segments,
)

ENV_ID = "TetherTetrahedron-v0"


def pixels_of(frame: np.ndarray, colour: str, tolerance: int = 12) -> int:
    """Number of pixels within ``tolerance`` (per channel, 0-255) of a matplotlib colour."""
    target = np.round(255 * np.array(to_rgb(colour))).astype(int)
    return int(np.all(np.abs(frame.astype(int) - target) <= tolerance, axis=2).sum())


@pytest.fixture(scope="module")
def cluster() -> tg.Cluster:
    return tg.make_cluster("tetrahedron")


def test_env_frames_are_rgb_uint8_change_with_the_state_and_repeat_exactly() -> None:
    env = gym.make(ENV_ID, render_mode="rgb_array")
    env.reset(seed=0)
    first = env.render()
    assert isinstance(first, np.ndarray) and first.dtype == np.uint8
    assert first.ndim == 3 and first.shape[2] == 3 and first.shape[:2] == (480, 480)
    assert np.array_equal(env.render(), first)  # the same state, drawn again
    for _ in range(3):
        env.step(np.ones(12))
    moved = env.render()
    assert not np.array_equal(moved, first)
    assert np.array_equal(env.render(), moved)
    # A fresh env brought to the same state draws the same frame: nothing of the frames drawn
    # before (the cached background included) shows in it.
    other = gym.make(ENV_ID, render_mode="rgb_array")
    other.reset(seed=0)
    for _ in range(3):
        other.step(np.ones(12))
    assert np.array_equal(other.render(), moved)
    env.close()
    other.close()


def test_frames_show_taut_slack_and_broken_cables_and_thrust(cluster: tg.Cluster) -> None:
    renderer = ClusterRenderer(cluster, max_thrust=1.0, exaggeration=100.0)
    positions, m, n = cluster.positions, len(cluster.cables), cluster.num_nodes
    taut = renderer.draw(positions, np.zeros(m, bool), np.zeros((n, 3)), 0.0)
    slack = renderer.draw(positions, np.ones(m, bool), np.zeros((n, 3)), 0.0)
    assert pixels_of(taut, TAUT_COLOUR) > 300 and pixels_of(taut, SLACK_COLOUR) == 0
    assert pixels_of(slack, SLACK_COLOUR) > 100 and pixels_of(slack, TAUT_COLOUR) == 0
    assert pixels_of(taut, THRUST_COLOUR) == 0
    thrust = np.zeros((n, 3))
    thrust[0] = [1.0, 0.0, 0.0]
    pushed = renderer.draw(positions, np.zeros(m, bool), thrust, 0.0)
    assert pixels_of(pushed, THRUST_COLOUR) > 20
    # One cable broken (so slack too): drawn in the broken colour, not as a slack one.
    broken = np.zeros(m, bool)
    broken[0] = True
    cut = renderer.draw(positions, broken, np.zeros((n, 3)), 0.0, broken=broken)
    assert pixels_of(cut, SLACK_COLOUR) == 0
    assert pixels_of(cut, BROKEN_COLOUR) > pixels_of(taut, BROKEN_COLOUR) + 20
    assert not np.array_equal(cut, renderer.draw(positions, broken, np.zeros((n, 3)), 0.0))


def test_the_env_draws_the_cables_that_broke() -> None:
    # Satellite 0 pulled 0.2 % out from the centre: its three cables pass a 30 N breaking load.
    env = gym.make(ENV_ID, render_mode="rgb_array", preset_kwargs={"breaking_load": 30.0})
    cluster = env.unwrapped.cluster
    positions = cluster.positions.copy()
    centre = positions.mean(axis=0)
    positions[0] = centre + 1.002 * (positions[0] - centre)
    env.reset(seed=0, options={"positions": positions, "velocities": np.zeros_like(positions)})
    before = env.render()
    _, _, terminated, _, info = env.step(np.zeros(12))
    assert terminated and info["broken_cables"].sum() == 3
    after = env.render()
    assert pixels_of(after, BROKEN_COLOUR) > pixels_of(before, BROKEN_COLOUR) + 60
    env.close()


def test_the_axes_are_drawn_once_while_the_cluster_stays_in_view(
    cluster: tg.Cluster, monkeypatch: pytest.MonkeyPatch
) -> None:
    renderer = ClusterRenderer(cluster, max_thrust=1.0, exaggeration=100.0)
    full_draws = []
    draw = renderer.figure.canvas.draw
    monkeypatch.setattr(renderer.figure.canvas, "draw", lambda: full_draws.append(1) or draw())
    m, n = len(cluster.cables), cluster.num_nodes
    rng = np.random.default_rng(0)
    frames = [
        renderer.draw(cluster.positions + rng.normal(0, 0.01, (n, 3)), rng.random(m) < 0.5, np.zeros((n, 3)), k)
        for k in range(5)
    ]
    assert len(full_draws) == 1 and all(not np.array_equal(a, b) for a, b in zip(frames[:-1], frames[1:], strict=True))
    # Drifting a whole half width moves the view, which redraws the axes.
    renderer.draw(cluster.positions + renderer.half_width, np.zeros(m, bool), np.zeros((n, 3)), 5.0)
    assert len(full_draws) == 2


def test_arrows_are_quivers_segments(cluster: tg.Cluster) -> None:
    tails = np.array([[0.0, 0.0, 0.0], [1.0, 2.0, 3.0], [5.0, 5.0, 5.0]])
    vectors = np.array([[2.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
    segments = arrow_segments(tails, vectors)
    assert segments.shape == (6, 2, 3)  # the zero vector is not drawn
    import matplotlib.figure

    axes = matplotlib.figure.Figure().add_subplot(projection="3d")
    drawn = tails[[0, 2]], vectors[[0, 2]]
    quiver = axes.quiver(*drawn[0].T, *drawn[1].T)
    np.testing.assert_allclose(segments, np.asarray(quiver._segments3d), atol=1e-12)


def test_a_diverged_state_draws_without_failing(cluster: tg.Cluster) -> None:
    renderer = ClusterRenderer(cluster, max_thrust=1.0)
    m, n = len(cluster.cables), cluster.num_nodes
    good = renderer.draw(cluster.positions, np.zeros(m, bool), np.zeros((n, 3)), 0.0)
    positions = cluster.positions.copy()
    positions[1] = [np.inf, np.nan, 1.0]
    bad = renderer.draw(positions, np.ones(m, bool), np.zeros((n, 3)), 1.0)
    assert bad.shape == good.shape and not np.array_equal(bad, good)


def test_human_mode_runs_headless() -> None:
    import matplotlib

    matplotlib.use("Agg")  # no window, as on a machine without a display, even where there is one
    env = gym.make(ENV_ID, render_mode="human")
    env.reset(seed=0)
    env.step(np.ones(12))
    assert env.render() is None
    assert env.unwrapped._viewer.human
    env.close()
