"""The viewer's command line: exports, recordings, and clear refusals of bad arguments."""

from __future__ import annotations

import hashlib
import socket
from pathlib import Path

import numpy as np
import pytest

from tether_gym.view import main
from tether_gym.viewer import load_recording

ROOT = Path(__file__).resolve().parents[2]


def refusal(capsys: pytest.CaptureFixture[str], argv: list[str]) -> str:
    with pytest.raises(SystemExit) as stop:
        main(argv)
    assert stop.value.code == 2
    return capsys.readouterr().err


def test_export_and_save_write_a_page_and_recordings_that_play_back(tmp_path: Path) -> None:
    page = tmp_path / "episode.html"
    main(
        [
            "--env",
            "TetherTetrahedron-v0",
            "--controller",
            "lqr",
            "passive",
            "--seed",
            "4",
            "--env-kwargs",
            '{"max_episode_steps": 50}',
            "--export",
            str(page),
            "--save",
            str(tmp_path / "eps"),
        ]
    )
    html = page.read_text()
    assert html.startswith("<!DOCTYPE html>") and "lqr (seed 4) vs passive (seed 4)" in html
    lqr = load_recording(tmp_path / "eps" / "lqr_seed4.npz")
    passive = load_recording(tmp_path / "eps" / "passive_seed4.npz")
    assert lqr.steps == passive.steps == 50
    np.testing.assert_array_equal(lqr.positions[0], passive.positions[0])  # the same seed
    assert lqr.meta["return"] > passive.meta["return"]
    again = tmp_path / "again.html"
    main(
        [
            "--recording",
            str(tmp_path / "eps" / "lqr_seed4.npz"),
            str(tmp_path / "eps" / "passive_seed4.npz"),
            "--export",
            str(again),
        ]
    )
    assert again.read_text() == html


def test_bad_arguments_are_refused_by_name(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = str(tmp_path / "x.html")
    assert "unknown env id 'TetherNope-v0': pass one of" in refusal(
        capsys, ["--env", "TetherNope-v0", "--controller", "lqr", "--export", out]
    )
    assert "unknown controller 'nope'" in refusal(
        capsys, ["--env", "TetherTetrahedron-v0", "--controller", "nope", "--export", out]
    )
    assert "--env needs --controller" in refusal(capsys, ["--env", "TetherTetrahedron-v0", "--export", out])
    (tmp_path / "corrupt.npz").write_bytes(b"PK\x03\x04 truncated")
    assert "corrupt.npz is not" in refusal(capsys, ["--recording", str(tmp_path / "corrupt.npz"), "--export", out])
    np.savez(tmp_path / "foreign.npz", weights=np.ones(2))
    assert "not a tether-gym episode recording" in refusal(
        capsys, ["--recording", str(tmp_path / "foreign.npz"), "--export", out]
    )
    assert not Path(out).exists()


def test_a_port_in_use_is_refused_by_name(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        message = refusal(
            capsys, ["--env", "TetherTetrahedron-v0", "--controller", "passive", "--port", str(port), "--no-browser"]
        )
    assert f"port {port} on 127.0.0.1 is in use" in message and "--port 0" in message


def test_the_bundled_script_is_built_from_the_current_sources() -> None:
    """scripts/build_viewer.sh heads the bundle with its sources' digest: a change to
    viewer/src without a rebuild fails here."""
    digest = hashlib.sha256(
        (ROOT / "viewer" / "src" / "main.js").read_bytes() + (ROOT / "viewer" / "package-lock.json").read_bytes()
    ).hexdigest()
    bundle = (ROOT / "tether_gym" / "viewer" / "static" / "viewer.js").read_text()
    assert bundle.startswith(f"/* tether-gym viewer bundle, sources sha256 {digest} */"), (
        "tether_gym/viewer/static/viewer.js is older than viewer/src: run bash scripts/build_viewer.sh"
    )
