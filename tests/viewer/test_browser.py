"""The viewer in a real browser: an exported file and the live view, each drawn, without console
errors, and moved by the time slider; the live view keeps up with real time on the default id."""

from __future__ import annotations

import re
import time
from pathlib import Path

import numpy as np
import pytest

from tests.viewer.browser import browser_page, drawn_fraction, scene_pixels, wait_ready
from tests.viewer.test_recording import SineThrust
from tether_gym.view import make_steppers_for
from tether_gym.viewer import LiveSession, ViewerServer, export_html, load_recording, save_recording
from tether_gym.viewer.recording import record_episode

ENV_ID = "TetherTetrahedron-v0"


def move_slider_to_end(page: object) -> None:
    """What a user does: focus the time slider and press End (the browser fires its input event)."""
    slider = page.locator("#time-slider")  # type: ignore[attr-defined]
    slider.focus()
    page.keyboard.press("End")  # type: ignore[attr-defined]


def test_an_exported_episode_draws_offline_and_its_slider_moves_the_scene(tmp_path: Path) -> None:
    recordings = [
        load_recording(save_recording(record_episode(ENV_ID, 3, SineThrust, "sine"), tmp_path / "a.npz")),
        record_episode("TetherCoarseBeadedTetrahedron-v0", 3, SineThrust, "sine (beaded)", {"max_episode_steps": 300}),
    ]
    # A cable that breaks half-way (as a fault would break it): drawn as broken from then on.
    recordings[0].broken[150:, 2] = True
    recordings[0].slack[150:, 2] = True
    page_file = export_html(recordings, tmp_path / "episode.html")
    html = page_file.read_text()
    loaded = re.findall(r'(?:src|href)="(?!data:)([^"]*)"', html)
    assert loaded == [], f"an export loads nothing from elsewhere; it loads {loaded}"
    with browser_page() as (page, errors):
        page.goto(page_file.as_uri())
        wait_ready(page)
        assert page.evaluate("tetherViewer.frames()") == 301
        page.evaluate("tetherViewer.setFrame(0)")
        start = scene_pixels(page)
        assert drawn_fraction(start) > 0.005, "the scene is blank"
        move_slider_to_end(page)
        assert page.evaluate("tetherViewer.frame()") == 300
        end = scene_pixels(page)
        changed = np.any(start != end, axis=2).mean()
        assert changed > 0.001, f"the slider did not move the scene ({changed:.5f} of the pixels changed)"
        # The page holds the recorded positions to the bit (float64 over the wire).
        for k in (0, 150, 300):
            shown = np.array(page.evaluate(f"tetherViewer.recordedPositions(0, {k})"))
            np.testing.assert_array_equal(shown, recordings[0].positions[k].reshape(-1))
        assert "ended (time limit)" in page.inner_text("#status")
        assert "broken 1" in page.inner_text("#status")
        page.evaluate("tetherViewer.setFrame(149)")
        assert "broken 0" in page.inner_text("#status")
        assert "free space" in page.inner_text("#frame-name")
        assert "tether bead" in page.inner_text("#legend-roles")
        page.locator("#scene").screenshot(path=str(tmp_path / "export.png"))
    assert errors == []


def test_the_live_view_draws_keeps_up_with_real_time_and_reports_its_frame_rate() -> None:
    session = LiveSession(make_steppers_for(ENV_ID, ["tension_aware"], {}), seed=5)
    server = ViewerServer(port=0, session=session)
    server.start()
    try:
        with browser_page() as (page, errors):
            page.goto(server.url)
            wait_ready(page)
            began_frame, began = page.evaluate("tetherViewer.frame()"), time.perf_counter()
            time.sleep(4.0)
            shown_frame, wall = page.evaluate("tetherViewer.frame()"), time.perf_counter() - began
            fps = page.evaluate("tetherViewer.fps()")
            simulated = (shown_frame - began_frame) * 0.1
            print(f"live view: {simulated:.2f} s shown in {wall:.2f} s of wall time, {fps} frames/s drawn")
            assert simulated >= 0.85 * wall, f"the view fell behind real time: {simulated:.2f} s in {wall:.2f} s"
            assert fps >= 5, f"the view draws only {fps} frames per second"
            assert "x real time" in page.inner_text("#rate")
            assert drawn_fraction(scene_pixels(page)) > 0.005, "the live scene is blank"
            page.keyboard.press(" ")  # pause
            page.evaluate("tetherViewer.setFrame(0)")
            before = scene_pixels(page)
            move_slider_to_end(page)
            assert page.evaluate("tetherViewer.frame()") > 30
            assert np.any(before != scene_pixels(page), axis=2).mean() > 0.001, "the slider did not move the scene"
        assert errors == []
        # Paced by the page: the simulation ran at most LEAD_SECONDS ahead of it, not to the end.
        assert session.count < 300
    finally:
        server.stop()


def test_the_live_view_serves_the_next_episode_on_the_next_seed() -> None:
    import json
    import urllib.request

    session = LiveSession(make_steppers_for(ENV_ID, ["passive"], {}), seed=2)
    server = ViewerServer(port=0, session=session)
    server.start()
    try:
        request = urllib.request.Request(server.url + "api/next", method="POST")
        with urllib.request.urlopen(request, timeout=10) as reply:
            assert json.load(reply) == {"seed": 3}
        with urllib.request.urlopen(server.url + "api/meta", timeout=10) as reply:
            assert json.load(reply)["episodes"][0]["meta"]["seed"] == 3
        with urllib.request.urlopen(server.url + "api/frames?from=0&want=5", timeout=10) as reply:
            frames = json.load(reply)
        assert frames["episodes"][0]["count"] >= 1
        with pytest.raises(urllib.error.HTTPError, match="404"):
            urllib.request.urlopen(server.url + "nothing", timeout=10)
    finally:
        server.stop()
