"""How fast the viewer is, and RecordVideo's frames: ``python benchmarks/viewer_speed.py``.

What it measures, on the default id (or ``--env``):

* **the live simulation**: control steps per second that a live session steps, per controller,
  as a multiple of real time (1x = one control interval of simulated time per second of wall
  time: what the live view needs to keep up);
* **the live view in a browser**: headless Chromium (Debian's, through Playwright, WebGL on
  SwiftShader: a software renderer, so a lower bound on a desktop's GPU) plays the live episode
  at 1x for ``--seconds``; it reports the frames drawn per second and how far the shown
  simulation time kept up with the wall clock;
* **an export**: the seconds to record and write a whole episode, and the file's size;
* **RecordVideo**: the seconds Gymnasium's ``RecordVideo`` takes to record a whole episode
  through ``render_mode="rgb_array"`` (the matplotlib path), and the seconds per frame.

It prints the machine's CPU model with the numbers: figures from different machines differ.

Usage::

    python benchmarks/viewer_speed.py                       # about 40 s
    python benchmarks/viewer_speed.py --controllers lqr mpc --seconds 10
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import gymnasium as gym
import numpy as np

import tether_gym
from tether_gym.bench import cpu_model
from tether_gym.view import make_steppers_for, run_to_end
from tether_gym.viewer import LiveSession, ViewerServer, export_html
from tether_gym.viewer.browser import HEADLESS_CHROMIUM_FLAGS, READY


def simulation_rate(env_id: str, controller: str) -> tuple[float, float]:
    """Control steps per second of one episode stepped as the live view steps it, and the
    control interval (s)."""
    [stepper] = make_steppers_for(env_id, [controller], {})(0)
    stepper.step()  # the first step builds what the controller caches
    started = time.perf_counter()
    steps = 1
    while not stepper.step():
        steps += 1
    return (steps - 1) / (time.perf_counter() - started), stepper.meta["control_interval"]


def browser_rate(env_id: str, controller: str, seconds: float) -> tuple[float, float]:
    """Frames per second the live page draws, and simulated seconds shown per wall second."""
    from playwright.sync_api import sync_playwright

    session = LiveSession(make_steppers_for(env_id, [controller], {}), seed=0)
    server = ViewerServer(port=0, session=session)
    server.start()
    interval = session.steppers[0].meta["control_interval"]
    try:
        with sync_playwright() as playwright:
            browser = playwright.chromium.launch(
                executable_path="/usr/bin/chromium", headless=True, args=list(HEADLESS_CHROMIUM_FLAGS)
            )
            page = browser.new_page(viewport={"width": 1200, "height": 800})
            page.goto(server.url)
            page.wait_for_function(READY, timeout=60_000)
            time.sleep(1.0)
            frame0, wall0 = page.evaluate("tetherViewer.frame()"), time.perf_counter()
            frames_before = page.evaluate("performance.now()")
            page.evaluate("window.__frames = 0; (function count() { __frames++; requestAnimationFrame(count); })()")
            time.sleep(seconds)
            drawn, now = page.evaluate("[window.__frames, performance.now()]")
            frame1, wall1 = page.evaluate("tetherViewer.frame()"), time.perf_counter()
            browser.close()
    finally:
        server.stop()
    fps = drawn / ((now - frames_before) / 1000.0)
    return fps, (frame1 - frame0) * interval / (wall1 - wall0)


def record_video_seconds(env_id: str) -> tuple[float, int]:
    """Seconds RecordVideo takes over one whole episode of zero thrust, and its frame count."""
    with tempfile.TemporaryDirectory() as folder:
        env = gym.wrappers.RecordVideo(
            gym.make(env_id, render_mode="rgb_array"), folder, episode_trigger=lambda _: True, disable_logger=True
        )
        env.reset(seed=0)
        action = np.zeros(env.action_space.shape, np.float32)
        started = time.perf_counter()
        steps = 0
        while True:
            _, _, terminated, truncated, _ = env.step(action)
            steps += 1
            if terminated or truncated:
                break
        env.close()  # writes the video
        return time.perf_counter() - started, steps


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--env", default=tether_gym.DEFAULT_ENV_ID)
    parser.add_argument("--controllers", nargs="+", default=["passive", "local_tension_aware", "tension_aware"])
    parser.add_argument("--seconds", type=float, default=6.0, help="how long the browser plays (s)")
    parser.add_argument("--no-browser", action="store_true", help="skip the headless-Chromium measurement")
    args = parser.parse_args()
    print(f"{args.env}; CPU: {cpu_model()}; tether-gym {tether_gym.__version__}")
    print("\nlive simulation (one episode, stepped as the live view steps it):")
    for controller in args.controllers:
        rate, interval = simulation_rate(args.env, controller)
        print(f"  {controller:<22} {rate:8.0f} control steps/s = {rate * interval:6.1f}x real time")
    if not args.no_browser:
        fps, kept = browser_rate(args.env, args.controllers[-1], args.seconds)
        print(
            f"\nlive view in headless Chromium (SwiftShader, 1200 x 800, {args.controllers[-1]}, "
            f"{args.seconds:g} s at 1x):"
            f"\n  {fps:.1f} frames/s drawn; shown simulation time / wall time = {kept:.3f}"
        )
    with tempfile.TemporaryDirectory() as folder:
        started = time.perf_counter()
        recordings = run_to_end(make_steppers_for(args.env, args.controllers[-1:], {})(0))
        path = export_html(recordings, Path(folder) / "episode.html")
        seconds = time.perf_counter() - started
        print(f"\nexport: one episode recorded and written in {seconds:.2f} s, {path.stat().st_size / 1e6:.2f} MB")
    seconds, steps = record_video_seconds(args.env)
    print(
        f"\nRecordVideo (render_mode='rgb_array'), one {steps}-step episode: {seconds:.1f} s, "
        f"{1e3 * seconds / steps:.1f} ms per frame"
    )


if __name__ == "__main__":
    main()
