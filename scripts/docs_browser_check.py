"""Open the built documentation site in a real browser and fail on what a reader would see broken.

``bash scripts/docs_browser_check.sh`` runs this after the site is built (CI does, after
``scripts/docs.sh``). It serves ``outputs/site`` with Python's ``http.server`` on 127.0.0.1 (as a
reader serving the site locally would), opens every page of the site in
headless Chromium (Debian's ``/usr/bin/chromium``, driven by Playwright), and fails when a page

* logs an error to the browser's console, or throws an uncaught exception;
* requests anything that fails or answers 4xx/5xx (a missing image, stylesheet or script);
* shows an image that did not decode (``naturalWidth == 0``);
* is wider than the window (a wide table or image escapes the content column);
* (the home page) finds nothing for a search of "tetrahedron": the search index loads.

It writes a full-page screenshot of the home page, of one env page and of a few others into
``--out`` (default ``outputs/site_screenshots``), to look at.
"""

from __future__ import annotations

import argparse
import functools
import http.server
import sys
import tempfile
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from tether_gym.viewer.browser import HEADLESS_CHROMIUM_FLAGS, READY

ROOT = Path(__file__).resolve().parents[1]

#: Chromium's flags for a quiet, isolated, headless run (tether_gym.viewer.browser): no sandbox,
#: QUIC, first-run UI, background traffic, component updates or sync, shared memory in /tmp
#: rather than /dev/shm (a container's is often too small for a renderer), and WebGL on
#: SwiftShader, for the env pages' embedded viewer. Playwright adds ``--headless`` and the
#: ``--user-data-dir`` (a fresh temporary one) itself.
CHROMIUM_FLAGS = HEADLESS_CHROMIUM_FLAGS
#: Pages screenshotted, relative to the site root (the env page is the default id's).
SCREENSHOTS = {
    "index.html": "index.png",
    "envs/TetherTetrahedron-v0.html": "env_TetherTetrahedron-v0.png",
    "agents.html": "agents.png",
    "benchmark.html": "benchmark.png",
    "tutorial.html": "tutorial.png",
    "api/tether_gym.html": "api_tether_gym.png",
    "viewer/TetherTetrahedron-v0.html": "viewer_TetherTetrahedron-v0.png",
}
#: JavaScript: how far the page reaches past the window's width, px (a wide table or image that
#: escapes the content column makes the whole page scroll sideways).
OVERFLOW = "document.documentElement.scrollWidth - document.documentElement.clientWidth"
#: JavaScript: the images of the page that did not load or decode.
BROKEN_IMAGES = "Array.from(document.images).filter(i => !i.complete || i.naturalWidth === 0).map(i => i.src)"


class _QuietHandler(http.server.SimpleHTTPRequestHandler):
    """Serves the site without a log line per request (failures are reported by the browser)."""

    def log_message(self, format: str, *args: Any) -> None:  # noqa: A002 - the base class's name
        pass


@contextmanager
def serve(site: Path) -> Iterator[str]:
    """Serve ``site`` on 127.0.0.1 at a free port; yields the base URL."""
    handler = functools.partial(_QuietHandler, directory=str(site))
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        yield f"http://127.0.0.1:{server.server_address[1]}/"
    finally:
        server.shutdown()
        server.server_close()


def site_pages(site: Path) -> list[str]:
    """Every page of the site, relative to its root (the 404 page aside: it is served for a miss)."""
    if not (site / "index.html").is_file():
        raise SystemExit(f"{site / 'index.html'} is missing: build the site first (bash scripts/docs.sh)")
    pages = sorted(path.relative_to(site).as_posix() for path in site.rglob("*.html"))
    return [page for page in pages if page != "404.html"]


def check_site(site: Path, out: Path, chromium: str) -> list[str]:
    """Open every page; return the problems found (empty when the site is fine)."""
    from playwright.sync_api import sync_playwright

    problems: list[str] = []
    out.mkdir(parents=True, exist_ok=True)
    pages = site_pages(site)
    missing = [page for page in SCREENSHOTS if page not in pages]
    if missing:
        problems.append(f"pages to screenshot are not in the site: {missing} (update SCREENSHOTS)")
    with serve(site) as base, sync_playwright() as playwright, tempfile.TemporaryDirectory() as profile:
        context = playwright.chromium.launch_persistent_context(
            profile,
            executable_path=chromium,
            headless=True,
            args=list(CHROMIUM_FLAGS),
            viewport={"width": 1280, "height": 900},
        )
        try:
            for page_path in pages:
                problems += check_page(context, base, page_path, out)
        finally:
            context.close()
    return problems


def check_page(context: Any, base: str, page_path: str, out: Path) -> list[str]:
    """Load one page and return its problems; screenshot it if it is one of :data:`SCREENSHOTS`."""
    problems: list[str] = []
    page = context.new_page()
    page.on(
        "console",
        lambda message: (
            problems.append(f"{page_path}: console {message.type}: {message.text}") if message.type == "error" else None
        ),
    )
    page.on("pageerror", lambda error: problems.append(f"{page_path}: uncaught exception: {error}"))
    page.on(
        "requestfailed",
        lambda request: problems.append(f"{page_path}: request failed: {request.url} ({request.failure})"),
    )
    page.on(
        "response",
        lambda response: (
            problems.append(f"{page_path}: HTTP {response.status} for {response.url}")
            if response.status >= 400
            else None
        ),
    )
    try:
        response = page.goto(base + page_path, wait_until="load")
        if response is None or not response.ok:
            problems.append(f"{page_path}: the page itself did not load")
        # The env pages' viewers are lazy iframes: "load" does not wait for them, and closing the
        # page while one is still arriving aborts its request (net::ERR_ABORTED), a failure of
        # this check's timing and not of the site. Waiting for the network to go quiet lets them
        # finish, so their own errors are still seen.
        page.wait_for_load_state("networkidle")
        broken = page.evaluate(BROKEN_IMAGES)
        problems += [f"{page_path}: image did not load or decode: {source}" for source in broken]
        overflow = page.evaluate(OVERFLOW)
        if overflow > 1:
            problems.append(
                f"{page_path}: the page is {overflow} px wider than the window (a table or image overflows)"
            )
        if page_path == "index.html":
            problems += check_search(page)
        if page_path.startswith("viewer/"):
            problems += check_viewer(page, page_path)
        if page_path in SCREENSHOTS:
            path = out / SCREENSHOTS[page_path]
            page.screenshot(path=str(path), full_page=True)
            print(f"screenshot {path}")
    finally:
        page.close()
    return problems


def check_viewer(page: Any, page_path: str) -> list[str]:
    """An embedded viewer page (docs/hooks/env_pages.py): it starts, holds its episode and draws
    its scene (the canvas is not left at the background colour)."""
    try:
        page.wait_for_function(READY, timeout=60_000)
    except Exception as error:  # Playwright's TimeoutError: reported, not raised
        return [f"{page_path}: the viewer did not start ({type(error).__name__})"]
    drawn = page.evaluate(
        """() => {
            const canvas = document.getElementById("scene");
            const probe = document.createElement("canvas");
            probe.width = canvas.width; probe.height = canvas.height;
            const g = probe.getContext("2d");
            g.drawImage(canvas, 0, 0);
            const data = g.getImageData(0, 0, probe.width, probe.height).data;
            let differ = 0;
            for (let i = 0; i < data.length; i += 4) {
                const off = Math.abs(data[i] - 0xf6) + Math.abs(data[i + 1] - 0xf7) + Math.abs(data[i + 2] - 0xf9);
                if (off > 24) differ++;
            }
            return differ / (data.length / 4);
        }"""
    )
    return [] if drawn > 0.002 else [f"{page_path}: the viewer's scene is blank ({drawn:.4f} of it drawn)"]


def check_search(page: Any, attempts: int = 8) -> list[str]:
    """Open the theme's search dialog, search for "tetrahedron" and expect results.

    The theme builds its index in a web worker after the page loads, and a query typed before
    that finds nothing; so the query is typed again, up to ``attempts`` times, 2 s apart."""
    opener = page.locator("a[data-bs-target='#mkdocs_search_modal']")
    if opener.count() == 0:
        return ["index.html: no search link (the theme's search is missing)"]
    opener.first.click()
    box = page.locator("#mkdocs-search-query")
    box.wait_for(state="visible")
    for _ in range(attempts):
        box.fill("")
        # The theme searches on keyup, so type the query key by key.
        box.press_sequentially("tetrahedron")
        try:
            page.wait_for_selector("#mkdocs-search-results article", timeout=2_000)
        except Exception:  # Playwright's TimeoutError: no result yet
            continue
        page.keyboard.press("Escape")
        return []
    return ["index.html: a search for 'tetrahedron' found nothing (the search index did not load?)"]


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--site", type=Path, default=ROOT / "outputs" / "site", help="the built site")
    parser.add_argument("--out", type=Path, default=ROOT / "outputs" / "site_screenshots", help="screenshots")
    parser.add_argument("--chromium", default="/usr/bin/chromium", help="the Chromium executable")
    args = parser.parse_args(argv)
    if not Path(args.chromium).is_file():
        raise SystemExit(f"no Chromium at {args.chromium}: install it (apt-get install -y chromium) or pass --chromium")
    problems = check_site(args.site, args.out, args.chromium)
    for problem in problems:
        print(f"docs browser check: {problem}", file=sys.stderr)
    if problems:
        raise SystemExit(f"docs browser check: {len(problems)} problem(s) in {args.site}")
    print(f"docs browser check: every page of {args.site} loaded, with its images, and no console error")


if __name__ == "__main__":
    main()
