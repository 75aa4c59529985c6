"""Headless Chromium for the viewer: the flags it needs to draw without a GPU, and a screenshot.

The project's browser checks (the viewer's tests, the documentation site's check) and its
figures drive Debian's ``/usr/bin/chromium`` through Playwright (the ``docs`` extra). Without a
GPU, WebGL runs on SwiftShader, Chromium's software renderer, which recent versions enable only
when asked: ``--enable-unsafe-swiftshader`` (unsafe only for untrusted pages, which these are not).
"""

from __future__ import annotations

import os
from pathlib import Path

from tether_gym._optional import require

__all__ = ["HEADLESS_CHROMIUM_FLAGS", "screenshot"]

#: Chromium's flags for a quiet, isolated headless run that draws WebGL in software: no sandbox
#: (containers), shared memory in /tmp rather than a container's small /dev/shm, no first-run
#: UI or background traffic, and ANGLE on SwiftShader.
HEADLESS_CHROMIUM_FLAGS = (
    "--no-sandbox",
    "--disable-dev-shm-usage",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--disable-quic",
    "--use-angle=swiftshader",
    "--enable-unsafe-swiftshader",
)

#: JavaScript: true once the viewer page has its episodes and has drawn them.
READY = "window.tetherViewer && window.tetherViewer.ready"


def screenshot(
    page_file: str | os.PathLike[str],
    png: str | os.PathLike[str],
    frame: int = 0,
    size: tuple[int, int] = (1200, 700),
    chromium: str = "/usr/bin/chromium",
) -> Path:
    """Open an exported viewer page in headless Chromium, show control step ``frame``, and save
    the window as a PNG (``size`` in CSS pixels). Returns the PNG's path."""
    sync_api = require("playwright.sync_api", "docs", "screenshots of the viewer")
    target = Path(png)
    with sync_api.sync_playwright() as playwright:
        browser = playwright.chromium.launch(
            executable_path=chromium, headless=True, args=list(HEADLESS_CHROMIUM_FLAGS)
        )
        try:
            page = browser.new_page(viewport={"width": size[0], "height": size[1]})
            page.goto(Path(page_file).resolve().as_uri())
            page.wait_for_function(READY, timeout=60_000)
            page.evaluate(f"tetherViewer.setFrame({int(frame)})")
            page.screenshot(path=str(target))
        finally:
            browser.close()
    return target
