"""The viewer's server: a page on 127.0.0.1, and for the live view, episodes stepped as it plays.

:class:`LiveSession` steps one episode per controller in lockstep, on a thread, never more than
:data:`LEAD_SECONDS` of simulated time ahead of the frame the page has asked for: the page's
clock (its play, pause and speed controls) paces the simulation, and a paused page stops it.
:class:`ViewerServer` answers

* ``GET /``: the page (with the episodes inside it, for recordings; without, for the live view);
* ``GET /api/meta``: the live episodes' metadata;
* ``GET /api/frames?from=K&want=W``: the frames from K on, and the page's clock at frame W;
* ``POST /api/next``: start the next episode (the next seed) of every controller.

It uses only the standard library's ``http.server``: one user on a loopback address needs no
more, and an SSH tunnel (``ssh -L 8765:127.0.0.1:8765 host``) brings it from a training machine.
"""

from __future__ import annotations

import errno
import http.server
import json
import threading
import time
import urllib.parse
from collections.abc import Callable, Sequence
from typing import Any

from .page import (
    LIVE_EXAGGERATION,
    episode_meta,
    frames_chunk,
    page_html,
    recordings_config,
    suggested_exaggeration,
    title_of,
)
from .recording import EpisodeRecording, EpisodeStepper

__all__ = ["LEAD_SECONDS", "LiveSession", "ViewerError", "ViewerServer"]

#: How far (simulated seconds, at the page's speed) the live simulation runs ahead of the page.
LEAD_SECONDS = 2.0


class ViewerError(RuntimeError):
    """The viewer cannot start (a port in use, a bad address); the message says what to change."""


class LiveSession:
    """Episodes of one or more controllers on the same seed, stepped in lockstep on a thread.

    Args:
        make_steppers: builds one :class:`~tether_gym.viewer.recording.EpisodeStepper` per
            controller for a seed.
        seed: the first episode's seed; each :meth:`next_episode` adds one.
    """

    def __init__(self, make_steppers: Callable[[int], list[EpisodeStepper]], seed: int) -> None:
        self._make_steppers = make_steppers
        self._condition = threading.Condition()
        self._wanted = 0
        self._closed = False
        self.error: str | None = None
        self.seed = seed
        self.steppers = make_steppers(seed)
        self._started = time.perf_counter()
        self._stepped_seconds = 0.0
        self._thread = threading.Thread(target=self._run, name="tether-gym-live-view", daemon=True)
        self._thread.start()

    @property
    def count(self) -> int:
        """Frames every controller has (the lockstep's common count)."""
        return min(stepper.count for stepper in self.steppers)

    @property
    def done(self) -> bool:
        return all(stepper.done for stepper in self.steppers)

    def _run(self) -> None:
        while True:
            with self._condition:
                lead = max(1, round(LEAD_SECONDS / self.steppers[0].meta["control_interval"]))
                while not self._closed and (self.done or self.count > self._wanted + lead):
                    self._condition.wait()
                if self._closed:
                    return
                steppers = self.steppers
            began = time.perf_counter()
            try:
                for stepper in steppers:
                    stepper.step()
            except Exception as error:  # shown on the page and by the command, then the thread ends
                self.error = f"{type(error).__name__}: {error}"
                return
            with self._condition:
                self._stepped_seconds += time.perf_counter() - began
                self._condition.notify_all()

    def steps_per_second(self) -> float:
        """Control steps simulated per second of stepping (all controllers together), so far."""
        steps = self.count - 1
        return steps / self._stepped_seconds if self._stepped_seconds > 0 and steps > 0 else 0.0

    def meta(self) -> dict[str, Any]:
        return {"mode": "live", "episodes": [{"meta": episode_meta(s.meta)} for s in self.steppers]}

    def frames(self, start: int, wanted: int) -> dict[str, Any]:
        """The frames from ``start`` on (as many as every controller has), after noting that the
        page's clock has reached frame ``wanted``."""
        with self._condition:
            self._wanted = max(self._wanted, wanted)
            self._condition.notify_all()
            stop = self.count
            steppers = self.steppers
            chunks = []
            for stepper in steppers:
                arrays = {name: values[start:stop] for name, values in stepper.frames.items()}
                done = stepper.done and stop == stepper.count
                chunks.append(frames_chunk(arrays, 0, max(stop - start, 0), done, stepper.meta))
        reply: dict[str, Any] = {"episodes": chunks, "steps_per_second": self.steps_per_second()}
        if self.error:
            reply["error"] = self.error
        return reply

    def next_episode(self) -> None:
        """Start every controller's next episode, on the next seed."""
        steppers = self._make_steppers(self.seed + 1)
        with self._condition:
            self.seed += 1
            self.steppers = steppers
            self._wanted = 0
            self._stepped_seconds = 0.0
            self._condition.notify_all()

    def wait_until_done(self, timeout: float | None = None) -> bool:
        """Block until every episode has ended (True) or ``timeout`` seconds pass (False)."""
        end = None if timeout is None else time.perf_counter() + timeout
        with self._condition:
            while not self.done and self.error is None:
                left = None if end is None else end - time.perf_counter()
                if left is not None and left <= 0:
                    return False
                self._condition.wait(left)
        return self.done

    def close(self) -> None:
        with self._condition:
            self._closed = True
            self._condition.notify_all()
        self._thread.join(timeout=5)


class _Handler(http.server.BaseHTTPRequestHandler):
    server: ViewerServer

    def log_message(self, format: str, *args: Any) -> None:  # noqa: A002 - the base class's name
        pass  # the page reports what goes wrong; a line per poll would drown the terminal

    def _send(self, body: bytes, content_type: str, status: int = 200) -> None:
        self.send_response(status)
        self.send_header("Content-Type", content_type)
        self.send_header("Content-Length", str(len(body)))
        self.send_header("Cache-Control", "no-store")
        self.end_headers()
        self.wfile.write(body)

    def _json(self, value: Any, status: int = 200) -> None:
        self._send(json.dumps(value, allow_nan=False).encode(), "application/json", status)

    def do_GET(self) -> None:  # noqa: N802 - http.server's name
        url = urllib.parse.urlsplit(self.path)
        session = self.server.session
        if url.path in ("/", "/index.html"):
            self._send(self.server.page.encode("utf-8"), "text/html; charset=utf-8")
        elif url.path == "/api/meta" and session is not None:
            self._json(session.meta())
        elif url.path == "/api/frames" and session is not None:
            query = urllib.parse.parse_qs(url.query)
            try:
                start = int(query.get("from", ["0"])[0])
                wanted = int(query.get("want", ["0"])[0])
            except ValueError:
                self._json({"error": "from and want must be integers"}, 400)
                return
            self._json(session.frames(max(start, 0), wanted))
        elif url.path == "/favicon.ico":
            self._send(b"", "image/x-icon", 204)
        else:
            self._json({"error": f"no such page: {url.path}"}, 404)

    def do_POST(self) -> None:  # noqa: N802 - http.server's name
        if urllib.parse.urlsplit(self.path).path == "/api/next" and self.server.session is not None:
            self.server.session.next_episode()
            self._json({"seed": self.server.session.seed})
        else:
            self._json({"error": f"no such action: {self.path}"}, 404)


class ViewerServer(http.server.ThreadingHTTPServer):
    """Serves the viewer page for ``recordings`` (played back) or a live ``session``.

    Args:
        host: the address to listen on (127.0.0.1 by default: only this machine can connect).
        port: the port; 0 picks a free one (:attr:`url` says which).
        session: a :class:`LiveSession`, or None to serve ``recordings``.
        recordings: recorded episodes, shown side by side (ignored with a session).
        exaggeration: the page's initial displacement exaggeration (None: 100 live, and for
            recordings the one that keeps them in view, :func:`~tether_gym.viewer.page.suggested_exaggeration`).

    Raises:
        ViewerError: the port is in use, or the address cannot be bound.
    """

    daemon_threads = True

    def __init__(
        self,
        host: str = "127.0.0.1",
        port: int = 8765,
        session: LiveSession | None = None,
        recordings: Sequence[EpisodeRecording] = (),
        exaggeration: float | None = None,
    ) -> None:
        self.session = session
        if session is not None:
            first = session.steppers[0].meta
            names = " vs ".join(s.meta["controller"] for s in session.steppers)
            live = LIVE_EXAGGERATION if exaggeration is None else exaggeration
            config: dict[str, Any] = {"mode": "live", "exaggeration": live}
            self.page = page_html(config, f"tether-gym live: {first['env_id']}, {names}")
        elif recordings:
            shown = suggested_exaggeration(recordings) if exaggeration is None else exaggeration
            self.page = page_html(recordings_config(recordings, shown), title_of(recordings))
        else:
            raise ValueError("ViewerServer needs a live session or at least one recording")
        try:
            super().__init__((host, port), _Handler)
        except OSError as error:
            if error.errno == errno.EADDRINUSE:
                raise ViewerError(
                    f"port {port} on {host} is in use (another viewer?): pass --port with a free port, "
                    f"or --port 0 to take any free one"
                ) from None
            raise ViewerError(f"cannot listen on {host}:{port}: {error.strerror or error}") from None

    def handle_error(self, request: Any, client_address: Any) -> None:
        # A page closed or reloaded mid-reply is normal for a viewer; anything else is reported.
        import sys

        if not isinstance(sys.exc_info()[1], (BrokenPipeError, ConnectionResetError)):
            super().handle_error(request, client_address)

    @property
    def url(self) -> str:
        host, port = self.server_address[:2]
        name = host.decode() if isinstance(host, bytes) else host
        return f"http://{name}:{port}/"

    def start(self) -> threading.Thread:
        """Serve on a daemon thread; returns it (:meth:`shutdown` stops it)."""
        thread = threading.Thread(target=self.serve_forever, name="tether-gym-viewer", daemon=True)
        thread.start()
        return thread

    def stop(self) -> None:
        """Stop serving, close the socket and the live session."""
        self.shutdown()
        self.server_close()
        if self.session is not None:
            self.session.close()
