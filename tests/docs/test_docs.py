"""The README stays short and its links hold; the generated env pages and the README's table of
ids agree with the registry. (The site's strict build, ``scripts/docs.sh``, checks every page's
links and anchors; these tests need no MkDocs.)"""

from __future__ import annotations

import re
from pathlib import Path
from types import ModuleType

import pytest

from tests.helpers import load_file
from tether_gym.registration import ENV_DOCS, ENV_IDS, HARD_TRACK, HARD_TRACK_MIN_EXCESS_COST

ROOT = Path(__file__).resolve().parents[2]
README = ROOT / "README.md"
#: The README is the pitch, the set-up and install, the snippets a newcomer runs first (simulator,
#: envs, SB3 training, a shipped model, scoring a policy), the ids, the headline results and links;
#: everything else belongs on a page under docs/.
MAX_README_LINES = 225
LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)\)")


def load_hook() -> ModuleType:
    """docs/hooks/env_pages.py, the site's page generator, imported as a module."""
    return load_file("tether_docs_env_pages", "docs/hooks/env_pages.py")


def slug(heading: str) -> str:
    """The anchor MkDocs (and GitHub) give a heading: lower case, punctuation dropped, spaces to '-'."""
    text = re.sub(r"[`*]", "", heading).strip().lower()
    text = re.sub(r"[^\w\s-]", "", text)
    return re.sub(r"[\s]+", "-", text)


def anchors(markdown: Path) -> set[str]:
    return {slug(match) for match in re.findall(r"^#+ +(.+?)\s*$", markdown.read_text(encoding="utf-8"), re.MULTILINE)}


def test_readme_is_short() -> None:
    lines = README.read_text(encoding="utf-8").splitlines()
    assert len(lines) <= MAX_README_LINES, (
        f"README.md has {len(lines)} lines (at most {MAX_README_LINES}): move the detail to a page under docs/ "
        f"and link it"
    )


def test_readme_links_point_at_existing_files_and_headings() -> None:
    text = README.read_text(encoding="utf-8")
    links = [target for target in LINK.findall(text) if "://" not in target]
    assert any(target.startswith("docs/") for target in links), "the README links no docs page"
    for target in links:
        path, _, anchor = target.partition("#")
        file = ROOT / path if path else README
        assert file.is_file(), f"README.md links {target!r}, but {path} does not exist"
        # The site's home page is the README with docs/ stripped, so every link must stay inside docs/.
        assert path.startswith("docs/"), f"README.md links {target!r} outside docs/: the site cannot follow it"
        if anchor and file.suffix == ".md":
            assert anchor in anchors(file), f"README.md links {target!r}, but {path} has no heading with that anchor"


def test_readme_keeps_the_two_set_up_commands_and_ci_runs_them() -> None:
    text = README.read_text(encoding="utf-8")
    assert re.search(r"^bash scripts/main\.sh +# main job", text, re.MULTILINE)
    assert re.search(r"^bash scripts/test\.sh +# the test suite", text, re.MULTILINE)
    ci = (ROOT / ".ci" / "run").read_text(encoding="utf-8").splitlines()
    assert "bash scripts/test.sh" in ci and "bash scripts/docs.sh" in ci
    assert ci.index("bash scripts/docs.sh") > ci.index("bash scripts/test.sh"), "CI builds the docs after the tests"


def test_slug_matches_the_headings_linked_from_the_docs() -> None:
    assert slug("The paper's traps") == "the-papers-traps"
    assert slug("The model-predictive reference (`mpc`)") == "the-model-predictive-reference-mpc"
    assert slug("Disturbances, faults and difficulty") == "disturbances-faults-and-difficulty"


def test_readme_table_of_ids_matches_the_registry() -> None:
    id_row = re.compile(
        r"\| `(Tether\w+-v\d+)`[^|]*\| `(\w+)`[^|]*\| (\d+) \| (\d+) \| (\d+) (?:steps of|×) ([\d.]+) s \|$"
    )
    table = {}
    for line in README.read_text(encoding="utf-8").splitlines():
        row = id_row.match(line)
        if row:
            env_id, preset, action, observation, steps, interval = row.groups()
            table[env_id] = (preset, int(action), int(observation), int(steps), float(interval))
    # A row with a cell past the episode column (a headline column pasted into the wrong table) fails to match.
    assert list(table) == list(ENV_IDS), "the README's table of ids must list every registered id, in order"
    for env_id, preset, action, observation, steps, interval in load_hook().ids_table_rows():
        assert table[env_id] == (preset, action, observation, steps, pytest.approx(interval)), env_id


def test_every_id_has_documentation() -> None:
    assert set(ENV_DOCS) == set(ENV_IDS)
    for env_id, doc in ENV_DOCS.items():
        assert doc.summary and doc.description and doc.version_history, env_id
        # Numbers the code knows are rendered from it; a typed one could go stale.
        assert not re.search(r"\d", doc.summary + doc.description), f"{env_id}: a number typed into its EnvDoc"


@pytest.mark.parametrize("env_id", list(ENV_IDS))
def test_generated_env_page_has_the_sections_of_a_gymnasium_env_page(env_id: str) -> None:
    page = load_hook().env_page(env_id)
    sections = re.findall(r"^## (.+)$", page, re.MULTILINE)
    for section in (
        "Description",
        "Action Space",
        "Observation Space",
        "Rewards",
        "Starting State",
        "Episode End",
        "Arguments",
        "Version History",
    ):
        assert section in sections, f"{env_id}: no {section!r} section"
    preset, steps, _ = ENV_IDS[env_id]
    assert f"preset `{preset}`" in page and f"{steps} steps" in page


def test_the_hard_track_is_registered_ids_in_the_registry_order() -> None:
    # Held in the registry's order, each once, and never every id (the standard track is the rest).
    assert list(HARD_TRACK) == [env_id for env_id in ENV_IDS if env_id in HARD_TRACK]
    assert len(set(HARD_TRACK)) == len(HARD_TRACK) and len(HARD_TRACK) < len(ENV_IDS)
    assert 0.0 < HARD_TRACK_MIN_EXCESS_COST < 1.0


@pytest.mark.parametrize("env_id", list(ENV_IDS))
def test_an_env_page_says_its_track_and_a_hard_page_what_the_track_means(env_id: str) -> None:
    hook = load_hook()
    page = hook.env_page(env_id)
    hard = env_id in HARD_TRACK
    assert f"| Track | [{'hard' if hard else 'standard'}]({hook.HARD_TRACK_LINK}) |" in page
    assert ("### On the hard track" in page) == hard
    threshold = f"at least {hook.number(100 * HARD_TRACK_MIN_EXCESS_COST)} % more than the reference ceiling"
    assert (threshold in page) == hard, env_id
    # The glance table says which satellites thrust where not all do, how late a delayed id acts,
    # and whether the thrusters are on/off valves.
    task = ENV_IDS[env_id][2]
    row = next(line for line in page.splitlines() if line.startswith("| Thrusters |"))
    thrusters, delay = task.get("thrusters"), task.get("thrust_delay", 0)
    assert ("on satellites " + ", ".join(map(str, thrusters or ())) + ";" in row) == (thrusters is not None), row
    assert (f"each command acting {delay} control interval" in row) == bool(delay), row
    on_off = task.get("thrust_mode") == "on_off"
    assert ("on/off: each axis fires at full thrust or not at all" in row) == on_off, row
    assert ("each axis on (|command| >= 0.5) or off" in page) == on_off, env_id


def test_the_environments_page_explains_the_hard_track_and_lists_its_ids() -> None:
    hook = load_hook()
    source = (ROOT / "docs" / "environments.md").read_text(encoding="utf-8")
    assert len(hook.HARD_TRACK_MARKER.findall(source)) == 1 and len(hook.IDS_TABLE_MARKER.findall(source)) == 1
    heading, anchor = "## The hard track", hook.HARD_TRACK_LINK.partition("#")[2]
    assert source.index(heading) < hook.HARD_TRACK_MARKER.search(source).start() and slug(heading[3:]) == anchor

    class Page:
        class file:  # noqa: N801 (MkDocs' page.file)
            src_uri = "environments.md"

    rendered = hook.on_page_markdown(source, Page(), None, None)
    assert "<!--" not in rendered.split("## In short")[0], "a marker was left in the page"
    section = rendered.split(heading)[1].split("\n## ")[0]
    listed = re.findall(r"^\| \[`(Tether\w+-v\d+)`\]", section, re.MULTILINE)
    assert listed == list(HARD_TRACK)
    # An empty track says so, and why, rather than showing an empty table.
    assert ("No id qualifies at present" in section) == (not HARD_TRACK)
    ids_rows = re.findall(r"^\| \[`(Tether\w+-v\d+)`\].*\| (hard|standard) \|", rendered, re.MULTILINE)
    assert [(env_id, "hard" if env_id in HARD_TRACK else "standard") for env_id in ENV_IDS] == ids_rows


def test_page_generator_refuses_a_docstring_without_its_sections() -> None:
    hook = load_hook()

    class Undocumented:
        """## Description

        Something.
        """

    with pytest.raises(hook.DocsBuildError, match="no section"):
        hook.docstring_sections(Undocumented)


def test_docstring_lists_and_roles_become_markdown() -> None:
    hook = load_hook()
    text = "Terms:\n- a :class:`~tether_gym.envs.EnvArgumentError` (N*s)\n  - nested"
    assert hook.markdown_from_docstring(text) == "Terms:\n\n- a ``EnvArgumentError`` (N\\*s)\n    - nested\n"


def test_pages_write_lists_as_the_site_renders_them() -> None:
    """Python-Markdown (the site) needs a blank line before a list and nests by 4 spaces, where
    GitHub also accepts none and 2: a page written for GitHub alone renders as run-on text."""
    for page in [README, *sorted((ROOT / "docs").glob("*.md"))]:
        lines = page.read_text(encoding="utf-8").splitlines()
        fenced = False
        for number, line in enumerate(lines, 1):
            if line.lstrip().startswith("```"):
                fenced = not fenced
            item = re.match(r"^( *)[-*] ", line)
            if fenced or not item:
                continue
            previous = lines[number - 2] if number > 1 else ""
            indent = len(item.group(1))
            assert indent % 4 == 0, f"{page.name}:{number}: a list nested by {indent} spaces (use 4)"
            if indent == 0 and previous.strip():
                assert re.match(r"^ *[-*] ", previous) or previous.startswith(" "), (
                    f"{page.name}:{number}: a list right after a paragraph (leave a blank line before it)"
                )


@pytest.mark.parametrize(("env_id", "observe_tensions"), [("TetherChain-v0", False), ("TetherSpinningHub-v0", True)])
def test_the_observation_table_lists_the_tether_block_of_a_beaded_cluster(env_id: str, observe_tensions: bool) -> None:
    """With tethers that have mass, the page's table has a row for every entry of each tether's
    block, at the indices of ObservationLayout.tether, and covers the whole observation."""
    import dataclasses

    import gymnasium as gym

    from tether_gym.envs.contract import TETHER_FEATURES

    hook = load_hook()
    env = gym.make(env_id, preset_kwargs={"tether_mass": 1.0, "segments": 4}, observe_tensions=observe_tensions)
    layout = env.unwrapped.task.observation_layout
    facts = dataclasses.replace(
        hook.env_facts(env_id),
        observation_size=int(env.observation_space.shape[0]),
        settings={name: hook.setting(env, name) for name in hook.REPORTED_SETTINGS},
        cluster=env.unwrapped.cluster,
    )
    rows = hook.observation_rows(facts)
    tether_rows = [row for row in rows if row[1].startswith("tether ")]
    assert [int(row[0]) for row in tether_rows] == list(range(layout.tether.start, layout.tether.stop))
    for row, name in zip(tether_rows, TETHER_FEATURES * layout.tethers, strict=True):
        assert f"`{name}`" in row[1]
    last = rows[len(rows) - len(tether_rows) - 1][0]
    assert int(last.split("..")[-1]) == layout.tether.start - 1  # satellites and plain cables before it
