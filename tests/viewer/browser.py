"""Headless Chromium for the viewer's tests: Debian's /usr/bin/chromium, driven by Playwright,
with the flags that let it draw WebGL without a GPU (tether_gym.viewer.browser)."""

from __future__ import annotations

import io
import shutil
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import numpy as np
import pytest

from tether_gym.viewer.browser import HEADLESS_CHROMIUM_FLAGS, READY

#: The scene's background colour (viewer/src/main.js, BACKGROUND), RGB.
BACKGROUND = (0xF6, 0xF7, 0xF9)


@contextmanager
def browser_page() -> Iterator[tuple[Any, list[str]]]:
    """A fresh page in headless Chromium and the list its console errors and uncaught exceptions
    go to; skips the test when Playwright (the docs extra) or Chromium is missing."""
    pytest.importorskip("playwright", reason="the docs extra (playwright) is not installed")
    chromium = shutil.which("chromium")
    if chromium is None:
        pytest.skip("no chromium (scripts/install_chromium.sh installs it; CI does)")
    from playwright.sync_api import sync_playwright

    errors: list[str] = []
    with sync_playwright() as playwright:
        browser = playwright.chromium.launch(
            executable_path=chromium, headless=True, args=list(HEADLESS_CHROMIUM_FLAGS)
        )
        try:
            page = browser.new_page(viewport={"width": 1200, "height": 800})
            page.on("console", lambda m: errors.append(f"console {m.type}: {m.text}") if m.type == "error" else None)
            page.on("pageerror", lambda error: errors.append(f"uncaught exception: {error}"))
            yield page, errors
        finally:
            browser.close()


def scene_pixels(page: Any) -> np.ndarray:
    """The 3-D canvas as drawn now, an (H, W, 3) uint8 array."""
    from PIL import Image

    png = page.locator("#scene").screenshot()
    return np.asarray(Image.open(io.BytesIO(png)).convert("RGB"))


def drawn_fraction(pixels: np.ndarray) -> float:
    """The fraction of the canvas's pixels that differ from its background."""
    return float(np.any(np.abs(pixels.astype(int) - np.array(BACKGROUND)) > 8, axis=2).mean())


def wait_ready(page: Any) -> None:
    page.wait_for_function(READY, timeout=30_000)
