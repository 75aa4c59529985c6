"""scripts/docs_browser_check.py finds what a reader would see broken, and passes a sound page.
It needs Chromium and Playwright (the docs extra); without them the test is skipped, and CI's
scripts/docs_browser_check.sh, which installs both, runs the check on the real site."""

from __future__ import annotations

import shutil
from pathlib import Path
from types import ModuleType

import pytest

from tests.helpers import load_file

ROOT = Path(__file__).resolve().parents[2]


def load_checker() -> ModuleType:
    return load_file("docs_browser_check", "scripts/docs_browser_check.py")


def test_the_check_reports_broken_images_404s_console_errors_and_a_missing_search(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    pytest.importorskip("playwright", reason="the docs extra (playwright) is not installed")
    chromium = shutil.which("chromium")
    if chromium is None:
        pytest.skip("no chromium (scripts/docs_browser_check.sh installs it)")
    from PIL import Image

    site = tmp_path / "site"
    site.mkdir()
    Image.new("RGB", (4, 3), "white").save(site / "good.png")
    (site / "bad.png").write_bytes(b"not a png")
    (site / "index.html").write_text(
        '<html><body><img src="missing.png"><img src="bad.png"><script>console.error("boom")</script>'
        '<div style="width: 5000px">a table too wide</div></body></html>',
        encoding="utf-8",
    )
    (site / "sub").mkdir()
    (site / "sub" / "ok.html").write_text('<html><body><img src="../good.png"></body></html>', encoding="utf-8")
    checker = load_checker()
    monkeypatch.setattr(checker, "SCREENSHOTS", {"sub/ok.html": "ok.png"})
    problems = checker.check_site(site, tmp_path / "shots", chromium)
    text = "\n".join(problems)
    assert "HTTP 404" in text and "missing.png" in text
    assert "image did not load or decode" in text and "bad.png" in text
    assert "console error: boom" in text
    assert "no search link" in text
    assert "px wider than the window" in text
    assert not [problem for problem in problems if problem.startswith("sub/ok.html")], problems
    assert (tmp_path / "shots" / "ok.png").stat().st_size > 0
