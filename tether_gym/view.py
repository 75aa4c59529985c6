"""Watch episodes in a browser: ``tether-gym-view`` or ``python -m tether_gym.view``.

Live, one controller or two side by side on the same seed, served on 127.0.0.1::

    tether-gym-view --env TetherTetrahedron-v0 --controller lqr --seed 3
    tether-gym-view --env TetherTetrahedron-v0 --controller passive tension_aware

Recorded episodes (``.npz`` files from ``--save``, ``agents.compare --save-episodes`` or
``agents.benchmark --save-episodes``), played back on one time slider::

    tether-gym-view --recording runs/episodes/lqr_seed10000.npz runs/episodes/ppo_seed10000.npz

A self-contained HTML file that opens offline, instead of serving::

    tether-gym-view --env TetherTetrahedron-v0 --controller lqr --seed 0 --export episode.html

Controllers are named as in ``agents.compare``: a scripted law, ``mpc``, a model shipped for the
id, or the path of a policy directory. Stepping them needs the ``viewer`` extra; playing back or
exporting a recording needs nothing beyond the core package.
"""

from __future__ import annotations

import argparse
import importlib
import json
import sys
import time
import webbrowser
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from tether_gym._cli import program
from tether_gym._optional import needs_extra
from tether_gym.viewer.page import export_html
from tether_gym.viewer.recording import (
    EpisodeRecording,
    EpisodeStepper,
    RecordingError,
    load_recording,
    recording_file_name,
    save_recording,
)
from tether_gym.viewer.server import LiveSession, ViewerError, ViewerServer

__all__ = ["build_parser", "main"]

#: The refusals that end the command with ``<program>: error: <message>``, status 2.
ERRORS = (RecordingError, ViewerError, ValueError, OSError)


def build_parser() -> argparse.ArgumentParser:
    """The command line of the viewer."""
    parser = argparse.ArgumentParser(
        prog=program("tether_gym.view", "tether-gym-view"),
        description="Watch tether-gym episodes in a browser: live, recorded, or exported to one HTML file.",
    )
    source = parser.add_mutually_exclusive_group(required=True)
    source.add_argument("--env", metavar="ID", help="the env id to step live (with --controller)")
    source.add_argument("--recording", nargs="+", metavar="FILE", help="recorded episodes (.npz) to play back")
    parser.add_argument(
        "--controller", nargs="+", metavar="NAME", help="one controller, or several side by side (with --env)"
    )
    parser.add_argument("--seed", type=int, default=0, help="the episode's reset seed (default 0)")
    parser.add_argument("--env-kwargs", type=json.loads, default={}, metavar="JSON", help="gym.make_vec arguments")
    parser.add_argument("--export", metavar="FILE.html", help="write a self-contained HTML file instead of serving")
    parser.add_argument("--save", metavar="DIR", help="also save each episode run as DIR/<controller>_seed<S>.npz")
    parser.add_argument("--host", default="127.0.0.1", help="the address to serve on (default 127.0.0.1)")
    parser.add_argument("--port", type=int, default=8765, help="the port (default 8765; 0: any free port)")
    parser.add_argument("--no-browser", action="store_true", help="do not open a browser tab")
    parser.add_argument(
        "--exaggeration",
        type=float,
        help="initial displacement exaggeration (default: live 100; recorded, the largest that keeps them in view)",
    )
    return parser


def controller_factory(name: str) -> Callable[[Any], Any]:
    """A function that builds controller ``name`` for the env it is given (see the module)."""
    # Imported by name: the agents package is not part of the typed library.
    with needs_extra("viewer", "stepping named controllers in the viewer"):
        try:
            policies = importlib.import_module("tether_gym_agents.policies")
        except ModuleNotFoundError as error:
            if error.name != "tether_gym_agents":
                raise
            policies = importlib.import_module("agents.policies")  # a checkout on PYTHONPATH, not installed
    make_controller = policies.make_controller

    def make(env: Any) -> Any:
        return make_controller(name, env)

    return make


def check_env_id(env_id: str) -> None:
    """Raise ValueError naming the registered ids unless ``env_id`` is one of them."""
    from tether_gym.registration import ENV_IDS

    if env_id not in ENV_IDS:
        raise ValueError(f"unknown env id {env_id!r}: pass one of {sorted(ENV_IDS)}")


def make_steppers_for(
    env_id: str, controllers: Sequence[str], env_kwargs: dict[str, Any]
) -> Callable[[int], list[EpisodeStepper]]:
    """For a seed, one :class:`EpisodeStepper` per controller."""
    factories = [(name, controller_factory(name)) for name in controllers]

    def make(seed: int) -> list[EpisodeStepper]:
        return [EpisodeStepper(env_id, seed, factory, name, env_kwargs) for name, factory in factories]

    return make


def run_to_end(steppers: list[EpisodeStepper]) -> list[EpisodeRecording]:
    """Step every episode to its end; returns the recordings."""
    for stepper in steppers:
        while not stepper.step():
            pass
    return [stepper.recording() for stepper in steppers]


def save_all(recordings: Sequence[EpisodeRecording], folder: str) -> list[Path]:
    """Save each recording as ``folder/<controller>_seed<S>.npz``."""
    paths = []
    for recording in recordings:
        name = recording_file_name(str(recording.meta["controller"]), int(recording.meta["seed"]))
        paths.append(save_recording(recording, Path(folder) / name))
    return paths


def serve(server: ViewerServer, open_browser: bool, session: LiveSession | None) -> None:
    """Serve until Ctrl-C, saying where, and for a live session how fast it simulates."""
    server.start()
    port = server.server_address[1]
    print(f"serving the view at {server.url}  (Ctrl-C to stop)")
    print(f"  from another machine: ssh -N -L {port}:127.0.0.1:{port} <this host>, then open http://127.0.0.1:{port}/")
    if open_browser:
        webbrowser.open(server.url)
    reported: tuple[int, bool] | None = None
    try:
        while True:
            time.sleep(0.5)
            if session is None:
                continue
            if session.error:
                print(f"the live episode stopped: {session.error}", file=sys.stderr)
                return
            state = (session.seed, session.done)
            if session.done and state != reported:
                rate = session.steps_per_second()
                interval = session.steppers[0].meta["control_interval"]
                returns = ", ".join(f"{s.meta['controller']} {s.meta['return']:.2f}" for s in session.steppers)
                print(
                    f"seed {session.seed}: episode over ({returns}); simulated {rate:.0f} control steps/s, "
                    f"{rate * interval:.1f}x real time"
                )
                reported = state
    except KeyboardInterrupt:
        print()
    finally:
        server.stop()


def run(args: argparse.Namespace) -> None:
    if args.exaggeration is not None and not 0.0 < args.exaggeration <= 1e6:
        raise ValueError(f"--exaggeration must be a number in (0, 1e6]; got {args.exaggeration}")
    if args.recording:
        if args.controller:
            raise ValueError("--controller steps a live env: use it with --env, not with --recording")
        recordings = [load_recording(path) for path in args.recording]
        intervals = {recording.meta["control_interval"] for recording in recordings}
        if len(intervals) > 1:
            raise ValueError(
                f"the recordings have different control intervals {sorted(intervals)}: one time slider cannot "
                "serve them"
            )
        if args.export:
            print(f"wrote {export_html(recordings, args.export, args.exaggeration)}")
            return
        server = ViewerServer(args.host, args.port, recordings=recordings, exaggeration=args.exaggeration)
        serve(server, not args.no_browser, None)
        return
    check_env_id(args.env)
    if not args.controller:
        raise ValueError("--env needs --controller NAME (a scripted law such as lqr, mpc, a shipped model or a path)")
    if args.seed < 0:
        raise ValueError(f"--seed must be >= 0; got {args.seed}")
    make_steppers = make_steppers_for(args.env, args.controller, dict(args.env_kwargs))
    if args.export:
        started = time.perf_counter()
        recordings = run_to_end(make_steppers(args.seed))
        if args.save:
            for path in save_all(recordings, args.save):
                print(f"wrote {path}")
        written = export_html(recordings, args.export, args.exaggeration)
        print(f"wrote {written} ({time.perf_counter() - started:.1f} s)")
        return
    session = LiveSession(make_steppers, args.seed)
    server = ViewerServer(args.host, args.port, session=session, exaggeration=args.exaggeration)
    serve(server, not args.no_browser, session)
    if args.save:
        for path in save_all([stepper.recording() for stepper in session.steppers], args.save):
            print(f"wrote {path}")


def main(argv: list[str] | None = None) -> int:
    """Run the command line; returns the exit status (2 for a refused argument)."""
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        run(args)
    except ERRORS as error:
        parser.exit(2, f"{parser.prog}: error: {error}\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
