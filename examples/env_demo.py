"""Three simple controllers on the default Gymnasium task, ``TetherTetrahedron-v0``.

The task (see :class:`tether_gym.envs.TetherClusterEnv`) is to damp the vibration of a
tetrahedron of four tethered satellites, with one 3-axis thruster per satellite.  Each episode
starts from random displacements and velocities and lasts 300 control steps of 0.1 s (30 s).
This script runs three baseline controllers over the same seeds (seed k for episode k):

* **zero thrust**: action 0 (only the bias thrust, which holds the nominal shape, acts); the
  vibration decays by the cables' structural damping alone;
* **random**: actions drawn uniformly from [-1, 1]^12 by a numpy Generator seeded with k;
* **velocity feedback**: each thruster pushes against its satellite's velocity relative to the
  centre of mass, ``action = clip(-gain * v_obs, -1, 1)`` with ``gain = 2``, where ``v_obs`` is
  the velocity part of the observation (in units of ``initial_velocity`` = 0.1 m/s), so the
  thrusters saturate at 1 N once a satellite moves at 0.05 m/s.

For each controller it prints the mean return, the vibration energy left after 10 s and 30 s as
a fraction of the initial one, the propellant used and the number of failed episodes (formation
lost, cable broken or numerics diverged).  It writes:

* ``env_energy.png``: vibration energy over time per controller (median over the seeds, with the
  min-max band shaded; log scale), in J and as a fraction of the initial energy;
* ``env_demo.gif``: one episode rendered with ``render_mode="rgb_array"``, zero thrust (left)
  and velocity feedback (right) side by side from the same initial state.  Blue cables are taut,
  orange dashed ones slack, red arrows are the agent's thrust.  The displacements are a few
  centimetres on 100 m cables, so the shape barely changes at this scale; what the animation
  shows is the cables going slack and taut and the thrust commands.

Run (about 25 s, most of it drawing the animation's 3-D frames)::

    .venv/bin/python examples/env_demo.py                  # files in outputs/
    .venv/bin/python examples/env_demo.py --docs           # also docs/img/env_demo.gif and env_energy.png
    .venv/bin/python examples/env_demo.py --seeds 20 --gif-steps 300
"""

from __future__ import annotations

import argparse
import dataclasses
import io
import multiprocessing
import os
import shutil
import time
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import gymnasium as gym
import matplotlib
import matplotlib.colors

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from PIL import Image, ImageDraw, ImageFont  # noqa: E402

import tether_gym  # noqa: E402  (registers the environment ids)
from tether_gym.envs.rendering import BROKEN_COLOUR, SLACK_COLOUR, TAUT_COLOUR, THRUST_COLOUR  # noqa: E402

DOCS_IMG = Path(__file__).resolve().parents[1] / "docs" / "img"
ENV_ID = tether_gym.DEFAULT_ENV_ID

#: Feedback gain of the velocity controller (action per unit of observed velocity).
FEEDBACK_GAIN = 2.0
#: GIF files larger than this are re-encoded with smaller frames.
MAX_GIF_BYTES = 3_000_000

#: Colours the renderer draws with (satellites; taut, slack and broken cables; thrust), kept exact in the GIF.
KEY_COLOURS = ("black", TAUT_COLOUR, SLACK_COLOUR, BROKEN_COLOUR, THRUST_COLOUR)

#: A controller maps an observation to an action in [-1, 1].
Controller = Callable[[np.ndarray], np.ndarray]

#: Display names and plot colours of the controllers, in table order.
CONTROLLERS = {
    "zero": ("zero thrust", "black"),
    "random": ("random", "tab:red"),
    "feedback": (f"velocity feedback (gain {FEEDBACK_GAIN:g})", "tab:blue"),
}
#: Line styles in the energy plot (zero thrust and random nearly coincide).
LINESTYLES = {"zero": "--", "random": "-", "feedback": "-"}


@dataclasses.dataclass
class Episode:
    """What one episode recorded.

    Attributes:
        energy: vibration energy (J) at reset and after each step; NaN after an early end.
        ret: sum of the rewards.
        propellant: thrust impulse used, N*s.
        end_reason: ``info["end_reason"]`` of the last step (``"running"`` if it was truncated).
        steps: number of steps taken.
    """

    energy: np.ndarray
    ret: float
    propellant: float
    end_reason: str
    steps: int

    @property
    def failed(self) -> bool:
        return self.end_reason != "running"


def make_controller(name: str, env: gym.Env, seed: int) -> Controller:
    """The controller ``name`` for ``env``; ``seed`` seeds the random one."""
    base = env.unwrapped
    n = base.cluster.num_nodes
    size = env.action_space.shape[0]
    if name == "zero":
        return lambda obs: np.zeros(size)
    if name == "random":
        rng = np.random.default_rng(seed)
        return lambda obs: rng.uniform(-1.0, 1.0, size)
    if name == "feedback":
        # Observation layout: [displacements (3n), velocities relative to the centre of mass
        # (3n), cable elongations]; action 3 j + d is the thrust of satellite j along axis d.
        if size != 3 * n or env.observation_space.shape[0] < 6 * n:
            raise ValueError("velocity feedback needs a thruster and an observation on every satellite")
        velocity = slice(3 * n, 6 * n)
        return lambda obs: np.clip(-FEEDBACK_GAIN * obs[velocity], -1.0, 1.0)
    raise ValueError(f"unknown controller {name!r}; choose from {list(CONTROLLERS)}")


def run_episode(env: gym.Env, controller_name: str, seed: int) -> Episode:
    """One full episode of ``controller_name`` from ``env.reset(seed=seed)``."""
    max_steps = env.spec.max_episode_steps if env.spec is not None else 300
    energy = np.full(max_steps + 1, np.nan)
    obs, info = env.reset(seed=seed)
    controller = make_controller(controller_name, env, seed)
    energy[0] = info["vibration_energy"]
    total, steps = 0.0, 0
    terminated = truncated = False
    while not (terminated or truncated):
        obs, reward, terminated, truncated, info = env.step(controller(obs))
        steps += 1
        total += reward
        energy[steps] = info["vibration_energy"]
    return Episode(energy, total, info["propellant_used"], info["end_reason"], steps)


def run_all(seeds: int) -> tuple[dict[str, list[Episode]], float]:
    """Every controller over seeds 0 .. seeds-1, and the control interval (s)."""
    env = gym.make(ENV_ID)
    try:
        results = {name: [run_episode(env, name, seed) for seed in range(seeds)] for name in CONTROLLERS}
        return results, env.unwrapped.config.control_interval
    finally:
        env.close()


def energy_fraction(episodes: list[Episode], t: float, dt: float) -> np.ndarray:
    """E_vib(t) / E_vib(0) per episode (NaN for an episode that ended before t)."""
    k = int(round(t / dt))
    return np.array([e.energy[k] / e.energy[0] for e in episodes])


def print_table(results: dict[str, list[Episode]], dt: float) -> None:
    """One row per controller."""
    seeds = len(next(iter(results.values())))
    initial = np.array([e.energy[0] for e in next(iter(results.values()))])
    print(
        f"{ENV_ID}: {seeds} episodes per controller (seeds 0..{seeds - 1}), "
        f"initial vibration energy {initial.min():.3g} .. {initial.max():.3g} J"
    )
    print("E(t)/E(0): median over the seeds [min, max]")
    header = (
        f"{'controller':<28} {'mean return':>12} {'E(10 s)/E(0)':>24} {'E(30 s)/E(0)':>24} "
        f"{'propellant (N*s)':>17} {'failures':>9}"
    )
    print(header)
    print("-" * len(header))
    for name, episodes in results.items():
        cells = []
        for t in (10.0, 30.0):
            f = energy_fraction(episodes, t, dt)
            ok = f[np.isfinite(f)]
            cells.append(f"{np.median(ok):.3g} [{ok.min():.2g}, {ok.max():.2g}]" if ok.size else "n/a")
        returns = np.array([e.ret for e in episodes])
        propellant = np.mean([e.propellant for e in episodes])
        failures = [e for e in episodes if e.failed]
        print(
            f"{CONTROLLERS[name][0]:<28} {returns.mean():12.1f} {cells[0]:>24} {cells[1]:>24} "
            f"{propellant:17.1f} {len(failures):>4}/{len(episodes)}"
        )
        for e in failures:
            print(f"    failure: {e.end_reason} after {e.steps} steps")


def plot_energy(results: dict[str, list[Episode]], dt: float, path: Path) -> None:
    """Vibration energy over time, absolute and relative to the initial energy."""
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2), sharex=True)
    for name, episodes in results.items():
        label, colour = CONTROLLERS[name]
        energy = np.array([e.energy for e in episodes])
        t = dt * np.arange(energy.shape[1])
        for ax, values in zip(axes, (energy, energy / energy[:, :1]), strict=True):
            # Episodes that failed are NaN after their end: the band covers the ones still running.
            with np.errstate(all="ignore"):
                median = np.nanmedian(values, axis=0)
                low, high = np.nanmin(values, axis=0), np.nanmax(values, axis=0)
            ax.fill_between(t, low, high, color=colour, alpha=0.15, linewidth=0)
            ax.plot(t, median, color=colour, linestyle=LINESTYLES[name], linewidth=1.8, label=label)
    axes[0].set_ylabel("vibration energy $E_{vib}$ (J)")
    axes[1].set_ylabel("$E_{vib}(t)\\,/\\,E_{vib}(0)$ (-)")
    for ax in axes:
        ax.set_yscale("log")
        ax.set_xlabel("time (s)")
        ax.set_xlim(0, t[-1])
        ax.grid(True, which="both", alpha=0.3)
    axes[0].legend(loc="lower left", fontsize=9)
    seeds = len(next(iter(results.values())))
    fig.suptitle(f"{ENV_ID}: vibration energy, median over {seeds} seeds (shaded: min to max)", fontsize=11)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


# ---------------------------------------------------------------------------------- animation
def _font(size: int) -> ImageFont.ImageFont:
    try:
        return ImageFont.load_default(size=size)
    except TypeError:  # Pillow < 10.1: fixed-size bitmap font
        return ImageFont.load_default()


def _labelled(image: Image.Image, title: str, subtitle: str) -> Image.Image:
    """A rendered frame with a two-line caption strip on top."""
    strip = 44
    canvas = Image.new("RGB", (image.width, image.height + strip), "white")
    canvas.paste(image, (0, strip))
    draw = ImageDraw.Draw(canvas)
    draw.text((10, 4), title, fill="black", font=_font(18))
    draw.text((10, 25), subtitle, fill=(60, 60, 60), font=_font(14))
    return canvas


def render_episode(name: str, seed: int, steps: int) -> tuple[list[np.ndarray], list[str]]:
    """Rendered frames (reset and ``steps`` steps) of one episode of ``name``, and their captions.

    An episode that ends early keeps showing its last frame.
    """
    env = gym.make(ENV_ID, render_mode="rgb_array")
    try:
        obs, info = env.reset(seed=seed)
        controller = make_controller(name, env, seed)
        picture = env.render()
        done = False
        pictures, captions = [], []
        for k in range(steps + 1):
            if k > 0 and not done:
                obs, _, terminated, truncated, info = env.step(controller(obs))
                picture = env.render()
                done = terminated or truncated
                if terminated:
                    print(f"  animation: {name} ended ({info['end_reason']}) at {info['time']:.1f} s")
            pictures.append(picture)
            captions.append(f"E_vib = {info['vibration_energy']:.3f} J   propellant {info['propellant_used']:.1f} N*s")
        return pictures, captions
    finally:
        env.close()


def render_frames(seed: int, steps: int, names: tuple[str, ...] = ("zero", "feedback")) -> list[Image.Image]:
    """Side-by-side frames of ``names`` run from the same initial state (reset and ``steps`` steps).

    Each episode renders in a process of its own, so the controllers' episodes draw in parallel.
    """
    workers = min(len(names), os.cpu_count() or 1)
    if workers > 1:
        with ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context("spawn")) as pool:
            episodes = list(pool.map(render_episode, names, [seed] * len(names), [steps] * len(names)))
    else:
        episodes = [render_episode(name, seed, steps) for name in names]
    panels = []
    for name, (pictures, captions) in zip(names, episodes, strict=True):
        cropped = crop_margins([Image.fromarray(picture) for picture in pictures])
        title = CONTROLLERS[name][0]
        panels.append([_labelled(picture, title, caption) for picture, caption in zip(cropped, captions, strict=True)])
    return side_by_side(panels)


def side_by_side(panels: list[list[Image.Image]]) -> list[Image.Image]:
    """Frame k of every panel (one list of frames per controller), placed left to right."""
    frames = []
    for row in zip(*panels, strict=True):
        frame = Image.new("RGB", (sum(p.width for p in row), max(p.height for p in row)), "white")
        x = 0
        for panel in row:
            frame.paste(panel, (x, 0))
            x += panel.width
        frames.append(frame)
    return frames


def crop_margins(frames: list[Image.Image], pad: int = 6) -> list[Image.Image]:
    """Crop the white margin that no frame draws on (the renderer's figure has wide ones)."""
    ink = np.zeros((frames[0].height, frames[0].width), dtype=bool)
    for frame in frames:
        ink |= np.asarray(frame).min(axis=2) < 250
    rows, cols = np.flatnonzero(ink.any(axis=1)), np.flatnonzero(ink.any(axis=0))
    box = (
        max(cols[0] - pad, 0),
        max(rows[0] - pad, 0),
        min(cols[-1] + pad + 1, frames[0].width),
        min(rows[-1] + pad + 1, frames[0].height),
    )
    return [frame.crop(box) for frame in frames]


def encode_gif(frames: list[Image.Image], scale: float, frame_ms: int) -> bytes:
    """GIF bytes of ``frames`` resized by ``scale`` (imageio if installed, else Pillow).

    All frames are mapped, without dithering, onto one palette built from a sample of them:
    consecutive frames then differ only where the picture changes, which keeps the GIF small.
    """
    size = (round(frames[0].width * scale), round(frames[0].height * scale))
    small = [f.resize(size, Image.BILINEAR) if scale != 1 else f for f in frames]
    sample = small[:: max(len(small) // 8, 1)]
    montage = Image.new("RGB", (size[0], size[1] * (len(sample) + 1)))
    for i, frame in enumerate(sample):
        montage.paste(frame, (0, i * size[1]))
    # Reserve the renderer's colours (thrust arrows are rare in the sample, but must stay red).
    width = size[0] // len(KEY_COLOURS)
    for i, colour in enumerate(KEY_COLOURS):
        box = (i * width, len(sample) * size[1], (i + 1) * width, montage.height)
        montage.paste(matplotlib.colors.to_hex(colour), box)
    palette = montage.quantize(colors=128, method=Image.Quantize.MEDIANCUT)
    paletted = [f.quantize(palette=palette, dither=Image.Dither.NONE) for f in small]
    buffer = io.BytesIO()
    try:
        import imageio.v3 as iio
    except ImportError:
        paletted[0].save(buffer, format="GIF", save_all=True, append_images=paletted[1:], duration=frame_ms, loop=0)
    else:
        rgb = np.stack([np.asarray(f.convert("RGB")) for f in paletted])
        iio.imwrite(buffer, rgb, extension=".gif", duration=frame_ms, loop=0)
    return buffer.getvalue()


def write_gif(frames: list[Image.Image], path: Path, frame_ms: int) -> float:
    """Write the GIF, shrinking the frames until it is under MAX_GIF_BYTES; returns the scale used."""
    scale = 1.0
    while True:
        data = encode_gif(frames, scale, frame_ms)
        if len(data) <= MAX_GIF_BYTES or scale < 0.3:
            path.write_bytes(data)
            return scale
        scale *= 0.85


# ---------------------------------------------------------------------------------- main
def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(
        description=__doc__.split("\n\n")[0], formatter_class=argparse.ArgumentDefaultsHelpFormatter
    )
    parser.add_argument("--out", type=Path, default=Path("outputs"), help="output directory")
    parser.add_argument(
        "--docs", action="store_true", help="also write docs/img/env_demo.gif and docs/img/env_energy.png"
    )
    parser.add_argument("--seeds", type=int, default=5, help="episodes per controller (seeds 0..N-1)")
    parser.add_argument("--gif-steps", type=int, default=150, help="control steps in the animation (0: none)")
    parser.add_argument("--gif-seed", type=int, default=1, help="seed of the animated episode")
    args = parser.parse_args(argv)
    if args.seeds < 1:
        parser.error("--seeds must be >= 1")
    start = time.perf_counter()

    results, dt = run_all(args.seeds)
    print_table(results, dt)

    args.out.mkdir(parents=True, exist_ok=True)
    written = [args.out / "env_energy.png"]
    plot_energy(results, dt, written[0])
    if args.gif_steps > 0:
        frames = render_frames(args.gif_seed, args.gif_steps)
        frame_ms = round(1000 * dt)  # real time: one frame per control step
        scale = write_gif(frames, args.out / "env_demo.gif", frame_ms)
        written.append(args.out / "env_demo.gif")
        print(
            f"animation: seed {args.gif_seed}, {len(frames)} frames of "
            f"{frames[0].width}x{frames[0].height} px, scaled by {scale:.2f}"
        )
    if args.docs:
        DOCS_IMG.mkdir(parents=True, exist_ok=True)
        for path in list(written):
            shutil.copyfile(path, DOCS_IMG / path.name)
            written.append(DOCS_IMG / path.name)
    for path in written:
        print(f"wrote {path}  ({path.stat().st_size / 1e6:.2f} MB)")
    print(f"done in {time.perf_counter() - start:.1f} s")


if __name__ == "__main__":
    main()
