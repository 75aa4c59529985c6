"""Every image the documentation shows is made by scripts/figures.py, and its generated blocks
are where the script writes them. These tests read the declarations; they run no figure (the
tutorial's own test runs the one cheap producer, examples/getting_started.py)."""

from __future__ import annotations

import re
from pathlib import Path
from types import ModuleType

import pytest

from tests.helpers import load_file
from tether_gym.registration import DEFAULT_ENV_ID, ENV_IDS

from .test_docs import load_hook

ROOT = Path(__file__).resolve().parents[2]
DOCS = ROOT / "docs"
IMG = DOCS / "img"
#: Markdown images and HTML <img> tags.
IMAGE = re.compile(r"!\[[^\]]*\]\(([^)\s]+)[^)]*\)|<img\b[^>]*\bsrc=[\"']([^\"']+)[\"']")


def load_figures() -> ModuleType:
    """scripts/figures.py as a module (the docs hook imports it under the same name)."""
    return load_file("docs_figures", "scripts/figures.py")


def images_in(markdown: str, page: Path) -> list[str]:
    """The local images ``markdown`` (at ``page``) shows, relative to docs/img; any other local
    image as its path relative to the root, so that the test reports it."""
    found = []
    for match in IMAGE.finditer(markdown):
        target = (match.group(1) or match.group(2)).split("#", 1)[0]
        if re.match(r"[a-z]+:", target):
            continue  # an address on the web: not this script's (the site keeps none, see mkdocs.yml)
        path = (page.parent / target).resolve()
        found.append(path.relative_to(IMG).as_posix() if path.is_relative_to(IMG) else str(path.relative_to(ROOT)))
    return found


def shown_images() -> dict[str, list[str]]:
    """Every page (README, docs/*.md, each generated env page) -> the images it shows."""
    pages = {"README.md": images_in((ROOT / "README.md").read_text(encoding="utf-8"), ROOT / "README.md")}
    for path in sorted(DOCS.rglob("*.md")):
        pages[str(path.relative_to(ROOT))] = images_in(path.read_text(encoding="utf-8"), path)
    hook = load_hook()
    for env_id in ENV_IDS:
        page = DOCS / hook.ENV_PAGE_DIR / f"{env_id}.md"  # where the site puts it
        pages[f"(generated) {page.relative_to(ROOT)}"] = images_in(hook.env_page(env_id), page)
    return pages


def test_every_image_shown_is_declared_by_the_figures_script() -> None:
    declared = load_figures().declared_images()
    undeclared = {page: [i for i in images if i not in declared] for page, images in shown_images().items()}
    undeclared = {page: images for page, images in undeclared.items() if images}
    assert not undeclared, (
        f"these pages show images that scripts/figures.py does not make: {undeclared}; add their producer to "
        f"FIGURES there (and run bash scripts/figures.sh)"
    )


def test_the_pages_show_images_at_all() -> None:
    """The scan finds the images (a regex that matched nothing would pass the test above)."""
    shown = shown_images()
    assert "benchmark_scores.png" in shown["README.md"]
    assert "compare_energy.png" in shown[str(Path("docs") / "agents.md")]
    for env_id in ENV_IDS:
        assert f"envs/{env_id}.gif" in shown[f"(generated) docs/envs/{env_id}.md"]


def test_every_declared_image_exists_and_every_file_in_docs_img_is_declared() -> None:
    declared = load_figures().declared_images()
    present = {path.relative_to(IMG).as_posix() for path in IMG.rglob("*") if path.is_file()}
    assert not declared - present, f"run bash scripts/figures.sh: these are declared but missing: {declared - present}"
    assert not present - declared, (
        f"docs/img holds files no entry of scripts/figures.py makes: {sorted(present - declared)}; declare their "
        f"producer in FIGURES, or delete them"
    )


def test_every_id_has_an_animation_declared() -> None:
    declared = load_figures().declared_images()
    assert {f"envs/{env_id}.gif" for env_id in ENV_IDS} <= declared


@pytest.mark.parametrize("entry", sorted(load_figures().FIGURES))
def test_generated_blocks_have_their_markers_once(entry: str) -> None:
    figures = load_figures()
    for page, key in figures.FIGURES[entry].blocks:
        text = (DOCS / page).read_text(encoding="utf-8")
        start, end = figures.block_markers(key)
        assert text.count(start) == 1 and text.count(end) == 1, f"docs/{page} needs the markers of {key!r} once"
        assert text.index(start) < text.index(end)


def test_replace_block_writes_between_the_markers_and_refuses_a_page_without_them(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    figures = load_figures()
    monkeypatch.setattr(figures, "DOCS", tmp_path)
    start, end = figures.block_markers("k")
    (tmp_path / "page.md").write_text(f"before\n{start}\nold\n{end}\nafter\n", encoding="utf-8")
    figures.replace_block("page.md", "k", "new\ntable\n")
    assert (tmp_path / "page.md").read_text(encoding="utf-8") == f"before\n{start}\nnew\ntable\n{end}\nafter\n"
    (tmp_path / "bare.md").write_text("no markers\n", encoding="utf-8")
    with pytest.raises(SystemExit, match="has no block 'k'"):
        figures.replace_block("bare.md", "k", "new")


def test_the_comparison_tables_are_the_comparisons_output() -> None:
    """The tables in docs/agents.md keep the header agents.compare writes, with one row per
    baseline and shipped model of the id."""
    from agents.controllers.registry import BASELINES
    from agents.policies import shipped_models

    figures = load_figures()
    text = (DOCS / "agents.md").read_text(encoding="utf-8")
    for env_id in figures.COMPARISONS:
        start, end = figures.block_markers(f"compare {env_id}")
        block = text[text.index(start) + len(start) : text.index(end)]
        assert block.strip().startswith(f"{env_id}, 64 episodes per controller, seeds 10000..10063")
        rows = [line.split("|")[1].strip() for line in block.splitlines() if line.startswith("| ")][1:]
        assert rows == list(BASELINES) + list(shipped_models(env_id)), (
            f"the table of {env_id} in docs/agents.md is out of date: run bash scripts/figures.sh --only "
            f"compare_{env_id}"
        )


def test_the_benchmark_entry_redraws_the_plots_from_a_benchmark_json_and_copies_finished_ones(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A small real benchmark (one id, two baselines, 4 episodes, about 5 s) without plots: the
    entry draws both plots from its benchmark.json; with the benchmark's own plots there, it
    copies them; with neither, it says what the directory lacks."""
    import argparse

    from PIL import Image

    from agents.benchmark import main as benchmark_main

    figures = load_figures()
    run = tmp_path / "benchmark"
    benchmark_main(
        ["--envs", "TetherTriangle-v0", "--controllers", "lqr", "velocity_feedback", "--episodes", "4"]
        + ["--reference", "lqr", "--bootstrap-reps", "200", "--no-plots", "--out", str(run)]
    )
    img = tmp_path / "img"
    img.mkdir()
    monkeypatch.setattr(figures, "IMG", img)
    figures.make_benchmark(argparse.Namespace(benchmark_dir=str(run)))
    for name in ("benchmark_scores.png", "benchmark_paired.png"):
        with Image.open(img / name) as picture:
            assert picture.width > 100 and picture.height > 100
    (run / "normalised_scores.png").write_bytes(b"the benchmark's own plot")
    (run / "paired_differences.png").write_bytes(b"the benchmark's own paired plot")
    figures.make_benchmark(argparse.Namespace(benchmark_dir=str(run)))
    assert (img / "benchmark_scores.png").read_bytes() == b"the benchmark's own plot"
    assert (img / "benchmark_paired.png").read_bytes() == b"the benchmark's own paired plot"
    with pytest.raises(SystemExit, match="neither the benchmark's plots nor its benchmark.json"):
        figures.make_benchmark(argparse.Namespace(benchmark_dir=str(tmp_path / "img")))


def test_an_env_page_without_its_animation_fails_the_build_with_the_fix(monkeypatch: pytest.MonkeyPatch) -> None:
    hook = load_hook()
    figures = hook.figures_script()
    monkeypatch.setattr(figures, "env_animation", lambda env_id: f"envs/{env_id}-not-drawn.gif")
    with pytest.raises(hook.DocsBuildError, match="scripts/figures.sh --only env_animations"):
        hook.env_page(next(iter(ENV_IDS)))


def test_an_animation_shows_the_shipped_ars_or_else_the_law_its_ars_will_correct(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """An id that ships no ``ars`` yet (a new id) animates its ``residual_on`` law instead, and
    its page's caption says which controller is drawn."""
    import agents.policies
    from agents.controllers.registry import BASELINES
    from agents.policies import shipped_models
    from agents.training.ars import load_ars_settings

    figures, hook = load_figures(), load_hook()
    drawn = {env_id: figures.animated_controllers(env_id) for env_id in ENV_IDS}
    for env_id, (left, right) in drawn.items():
        assert left == "passive"
        if "ars" in shipped_models(env_id):
            assert right == "ars"
            assert "the shipped `ars` policy (right)" in hook.env_page(env_id)
        else:
            assert right == load_ars_settings(env_id).residual_on and right in BASELINES
            assert f"the scripted law `{right}`" in hook.env_page(env_id)
    # Both cases, whatever is shipped today: the default id with its models hidden.
    assert "ars" in shipped_models(DEFAULT_ENV_ID)
    monkeypatch.setattr(agents.policies, "shipped_models", lambda env_id: {})
    assert figures.animated_controllers(DEFAULT_ENV_ID) == ("passive", load_ars_settings(DEFAULT_ENV_ID).residual_on)
