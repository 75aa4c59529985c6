"""MkDocs hook: the site's generated pages.

* One page per registered id, ``envs/<id>.md``, in the sections of a Gymnasium env page. Every
  word comes from the code: the class docstring of :class:`tether_gym.envs.TetherClusterEnv`
  (what all ids share), the id's :class:`tether_gym.registration.EnvDoc` (its description and
  version history), its preset's docstring and signature in :mod:`tether_gym.presets`, and the
  registered spec and a freshly made env (spaces, episode length, control interval, thrust,
  initial conditions, the cluster's magnitudes). A page therefore cannot disagree with the code.
* On each of them, the id's animation, drawn by ``scripts/figures.py``.
* The table of ids on ``environments.md``, in place of the marker ``<!-- env-ids-table ... -->``,
  and what the hard track is with its ids, in place of ``<!-- hard-track-table ... -->``; each
  hard id's page says it is on that track.
* The home page: ``README.md``, with its ``docs/`` links made relative to the site, in place of
  the placeholder ``docs/index.md``.

``tests/docs/test_docs.py`` imports this file too (``ids_table_rows``). Anything the hook expects
from the code and does not find (a docstring section, a setting, an id without its ``EnvDoc``)
raises an error that says what to update, so the strict build fails instead of printing a
wrong page.
"""

from __future__ import annotations

import dataclasses
import functools
import importlib.util
import inspect
import math
import re
import sys
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

import tether_gym
from tether_gym.analysis import tether_mode_errors
from tether_gym.envs import TetherClusterEnv
from tether_gym.envs._task_kernels import ON_OFF_THRESHOLD
from tether_gym.envs.contract import TETHER_FEATURE_MEANINGS, TETHER_FEATURES
from tether_gym.presets import PRESETS
from tether_gym.registration import ENV_DOCS, ENV_IDS, HARD_TRACK, HARD_TRACK_MIN_EXCESS_COST, track_of

ROOT = Path(__file__).resolve().parents[2]
ENV_PAGE_DIR = "envs"
IDS_TABLE_MARKER = re.compile(r"<!-- env-ids-table\b.*?-->")
HARD_TRACK_MARKER = re.compile(r"<!-- hard-track-table\b.*?-->")
#: Where the site explains the tracks, from an env page (``envs/<id>.md``).
HARD_TRACK_LINK = "../environments.md#the-hard-track"
NAV_SECTION = "Environments"
#: Where the env pages' embedded viewer exports go in the site, and the held-out seed they show.
VIEWER_DIR = "viewer"
VIEWER_SEED = 10_000

#: The task settings a page reports, by their ``gym.make`` keyword names.
REPORTED_SETTINGS = (
    "control_interval",
    "max_thrust",
    "thrust_limit",
    "thrust_mode",
    "initial_displacement",
    "initial_velocity",
    "observed_satellites",
    "observe_tensions",
    "thrusters",
    "thrust_delay",
    "observe_commands",
)

#: Sections of the class docstring that get this id's own lines in front of the shared text.
ID_SPECIFIC_SECTIONS = ("Description", "Action Space", "Observation Space", "Episode End", "Arguments")


class DocsBuildError(RuntimeError):
    """The code no longer offers what a generated page needs; the message says what to update."""


# ----------------------------------------------------------------------------------------------
# Reading the code


def number(value: float) -> str:
    """A magnitude as the pages print it: 4 significant digits, no trailing zeros."""
    value = float(value)
    if math.isinf(value):
        return "inf" if value > 0 else "-inf"
    if value == 0 or 1e-4 <= abs(value) < 1e7:
        return np.format_float_positional(value, precision=4, unique=True, fractional=False, trim="-")
    return f"{value:.4g}"


def values(array: Any, unit: str = "") -> str:
    """The distinct values of a per-node or per-cable array: one value, a few, or a range."""
    distinct = np.unique(np.asarray(array, dtype=float))
    suffix = f" {unit}" if unit else ""
    if distinct.size <= 3:
        return ", ".join(number(v) for v in distinct) + suffix
    return f"{number(distinct.min())} to {number(distinct.max())}{suffix}"


def setting(env: gym.Env, name: str) -> Any:
    """The value of the ``gym.make`` keyword ``name`` in a made env: a field of its task
    configuration, looked up also inside grouped (nested dataclass) configurations."""
    config = getattr(env.unwrapped, "config", None)
    pending = [config]
    while pending:
        node = pending.pop(0)
        if dataclasses.is_dataclass(node):
            if name in {field.name for field in dataclasses.fields(node)}:
                return getattr(node, name)
            pending.extend(getattr(node, field.name) for field in dataclasses.fields(node))
    raise DocsBuildError(
        f"the env's configuration has no setting {name!r}: update REPORTED_SETTINGS and setting() in "
        f"docs/hooks/env_pages.py to the new names of the task configuration"
    )


def markdown_from_docstring(text: str) -> str:
    """Docstring text (reST roles, two-space list nesting) as Python-Markdown renders it."""
    text = re.sub(r":\w+:`~([\w.]+)`", lambda m: f"``{m.group(1).rsplit('.', 1)[-1]}``", text)
    text = re.sub(r":\w+:`([\w.]+)`", r"``\1``", text)
    text = re.sub(r"(?<=\w)\*(?=\w)", r"\\*", text)  # N*s is a unit, not emphasis
    lines: list[str] = []
    for line in text.splitlines():
        stripped = line.lstrip(" ")
        indent = len(line) - len(stripped)
        # Python-Markdown nests lists by 4 spaces and needs a blank line before a list.
        line = " " * (2 * indent) + stripped
        starts_list = stripped.startswith("- ")
        if starts_list and indent == 0 and lines and lines[-1].strip() and not _in_list(lines):
            lines.append("")
        lines.append(line)
    return "\n".join(lines).strip() + "\n"


def _in_list(lines: list[str]) -> bool:
    """Whether the paragraph that ``lines`` ends with is a list item (or its continuation)."""
    for line in reversed(lines):
        if not line.strip():
            return False
        if line.lstrip().startswith("- "):
            return True
    return False


def docstring_sections(cls: type) -> dict[str, str]:
    """The ``## Heading`` sections of a class docstring, in order, as Markdown."""
    doc = inspect.getdoc(cls) or ""
    parts = re.split(r"^## +(.+?)\s*$", doc, flags=re.MULTILINE)
    sections = {title: markdown_from_docstring(body) for title, body in zip(parts[1::2], parts[2::2], strict=True)}
    missing = [title for title in (*ID_SPECIFIC_SECTIONS, "Version History") if title not in sections]
    if missing:
        raise DocsBuildError(
            f"the docstring of {cls.__qualname__} has no section(s) {missing}; the env pages put each id's "
            f"own lines there: restore them or update ID_SPECIFIC_SECTIONS in docs/hooks/env_pages.py"
        )
    return sections


def preset_doc(preset: str) -> tuple[str, list[tuple[str, str, str]]]:
    """A preset's docstring before ``Args:``, and (name, default, meaning) for each parameter."""
    builder = PRESETS[preset]
    doc = inspect.getdoc(builder) or ""
    summary, _, args = doc.partition("\nArgs:\n")
    meanings: dict[str, str] = {}
    current = None
    for line in args.splitlines():
        match = re.match(r"\s{0,8}(\w+): (.*)", line)
        if match and match.group(1) in inspect.signature(builder).parameters:
            current = match.group(1)
            meanings[current] = match.group(2).strip()
        elif current and line.strip():
            meanings[current] += " " + line.strip()
    rows = []
    for name, parameter in inspect.signature(builder).parameters.items():
        if name not in meanings:
            raise DocsBuildError(f"preset {preset!r}: parameter {name!r} is not described under Args: in its docstring")
        rows.append((name, repr(parameter.default), meanings[name]))
    return markdown_from_docstring(summary), rows


@dataclasses.dataclass(frozen=True)
class EnvFacts:
    """What a page reports about one id, read from the registry and a made env."""

    env_id: str
    preset: str
    max_episode_steps: int
    registered: dict[str, Any]
    action_space: str
    observation_space: str
    action_size: int
    observation_size: int
    settings: dict[str, Any]
    render_modes: list[str]
    render_fps: int
    cluster: tether_gym.Cluster

    @property
    def thrusters(self) -> int:
        return self.action_size // 3

    @property
    def episode_seconds(self) -> float:
        return self.max_episode_steps * self.settings["control_interval"]


@functools.cache
def env_facts(env_id: str) -> EnvFacts:
    """Make the env of ``env_id`` once and read what its page reports."""
    spec = gym.spec(env_id)
    kwargs = dict(spec.kwargs)
    env = gym.make(env_id)
    try:
        facts = EnvFacts(
            env_id=env_id,
            preset=kwargs.pop("preset"),
            max_episode_steps=int(spec.max_episode_steps),
            registered=kwargs,
            action_space=str(env.action_space),
            observation_space=str(env.observation_space),
            action_size=int(env.action_space.shape[0]),
            observation_size=int(env.observation_space.shape[0]),
            settings={name: setting(env, name) for name in REPORTED_SETTINGS},
            render_modes=list(env.metadata["render_modes"]),
            render_fps=int(env.metadata["render_fps"]),
            cluster=env.unwrapped.cluster,
        )
    finally:
        env.close()
    return facts


# ----------------------------------------------------------------------------------------------
# Writing the pages


def env_doc(env_id: str) -> Any:
    if env_id not in ENV_DOCS:
        raise DocsBuildError(f"{env_id} has no entry in tether_gym.registration.ENV_DOCS: add its EnvDoc there")
    return ENV_DOCS[env_id]


def frame_text(cluster: tether_gym.Cluster) -> str:
    frame = cluster.frame
    if frame.kind == "hill":
        return f"Hill (Clohessy-Wiltshire) frame of a circular orbit, orbital rate {number(frame.rate)} rad/s"
    if frame.kind == "rotating":
        return f"rotating frame, spin rate {number(frame.rate)} rad/s about z"
    return "inertial (free space)"


def cluster_text(cluster: tether_gym.Cluster) -> str:
    text = f"{cluster.num_satellites} satellites, {cluster.num_cables} cables"
    if cluster.tethers:
        text += f" ({cluster.num_tethers} tethers with mass: {cluster.num_beads} beads)"
    return text


def discretisation_text(cluster: tether_gym.Cluster) -> str:
    """The section on a beaded id's discretisation error against the continuous line's closed
    forms (empty for a cluster without beads): one row per distinct tether."""
    errors = tether_mode_errors(cluster)
    if not errors:
        return ""
    rows: dict[tuple[str, ...], list[int]] = {}
    for e in errors:
        modes = ", ".join(
            f"{number(f)} Hz ({100 * err:+.2f} %)" for f, err in zip(e.transverse_hz, e.transverse_error, strict=True)
        )
        key = (
            str(e.segments),
            f"{number(e.length)} m",
            f"{number(e.line_density)} kg/m",
            f"{number(e.tension)} N",
            modes,
            f"{number(e.axial_hz)} Hz ({100 * e.axial_error:+.3f} %)",
        )
        rows.setdefault(key, []).append(e.tether)
    return (
        "\n### Discretisation error\n\n"
        "Each tether is a lumped-mass line, so its waves are those of its beads, not of the continuous line. "
        "The table gives, per tether, the continuous line's closed forms and the relative error of the "
        "beaded line's frequencies on them: the taut string's transverse modes 1-3 "
        "(`f_k = k / (2 L0) sqrt(N0 / mu)`, satellites held) and the first axial mode of a uniform bar "
        "between the two satellites' masses. Both errors fall as 1/N² with the segment count N; the time "
        "step adds a phase error far below them. Computed when the site was built by "
        "`tether_gym.analysis.tether_mode_errors`, from each tether taken alone between its two satellites; "
        '`preset_kwargs={"segments": ...}` trades them against cost.\n\n'
        + table(
            ("tethers", "segments N", "L0", "mu", "N0", "transverse modes 1-3 (error)", "axial mode 1 (error)"),
            [(", ".join(map(str, tethers)), *key) for key, tethers in rows.items()],
        )
    )


def thrust_text(facts: EnvFacts) -> str:
    """The thrusters: how many, on which satellites where not all carry one, their limit, whether
    they are on/off valves, and their delay where there is one."""
    settings = facts.settings
    text = f"{facts.thrusters}"
    if settings["thrusters"] is not None:
        on = ", ".join(map(str, settings["thrusters"]))
        text += f" (on satellites {on}; the other {facts.cluster.num_satellites - facts.thrusters} passive)"
    text += f", up to {values(settings['max_thrust'], 'N')} each ({settings['thrust_limit']!s} limit)"
    if settings["thrust_mode"] == "on_off":
        interval = number(settings["control_interval"])
        text += (
            f"; on/off: each axis fires at full thrust or not at all for each {interval} s interval (a command "
            f"component of magnitude {number(ON_OFF_THRESHOLD)} or more fires it along its sign), so its minimum "
            f"impulse bit is the full thrust times {interval} s"
        )
    if settings["thrust_delay"]:
        delay = settings["thrust_delay"]
        text += f", each command acting {delay} control interval{'s' if delay > 1 else ''} after it is given"
    return text


def observation_rows(facts: EnvFacts) -> list[tuple[str, str, str]]:
    """(indices, observation, unit) of this id's observation, from the class docstring's layout
    with this id's satellite and cable counts; checked against the observation space's size."""
    settings = facts.settings
    observed = settings["observed_satellites"]
    cluster = facts.cluster
    satellites = cluster.num_satellites if observed is None else len(observed)
    # A tether with mass is observed as one block, not segment by segment: c counts plain cables.
    cables = cluster.num_cables - sum(spec.segments for spec in cluster.tethers)
    displacement = f"D = {number(settings['initial_displacement'])} m"
    blocks = [
        (
            3 * satellites,
            "displacement of each observed satellite from its nominal place (3 per satellite)",
            displacement,
        ),
        (
            3 * satellites,
            "velocity of each observed satellite relative to the centre of mass (3 per satellite)",
            f"V = {number(settings['initial_velocity'])} m/s",
        ),
        (cables, "cable elongation `L - L0`, one per cable", displacement),
    ]
    if settings["observe_tensions"]:
        blocks.append((cables, "cable tension / breaking load, one per cable", "1"))
    rows, start = [], 0
    for size, what, unit in blocks:
        rows.append((f"{start} .. {start + size - 1}", what, unit))
        start += size
    width = len(TETHER_FEATURES)
    for k, spec in enumerate(cluster.tethers):
        a, b = spec.ends
        for f, name in enumerate(TETHER_FEATURES):
            meaning, unit = TETHER_FEATURE_MEANINGS[name]
            rows.append(
                (
                    str(start + width * k + f),
                    f"tether {k} (satellites {a}-{b}, {spec.segments} segments), `{name}`: {meaning}",
                    displacement if unit == "D" else unit,
                )
            )
    start += width * cluster.num_tethers
    if settings["observe_commands"]:
        delay, size = settings["thrust_delay"], facts.action_size
        for age in range(delay):
            rows.append(
                (
                    f"{start} .. {start + size - 1}",
                    f"the command given {delay - age} control interval{'s' if delay - age > 1 else ''} ago, not "
                    f"acting yet ({'the next to act' if age == 0 else 'acts after the one above'})",
                    "1 (action units)",
                )
            )
            start += size
    if start != facts.observation_size:
        raise DocsBuildError(
            f"{facts.env_id}: the observation layout of TetherClusterEnv's docstring gives {start} entries, but "
            f"the observation space has {facts.observation_size}: update the docstring's layout and "
            f"observation_rows() in docs/hooks/env_pages.py"
        )
    return rows


def table(header: tuple[str, ...], rows: list[tuple[str, ...]]) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(cell.replace("|", "\\|") for cell in row) + " |" for row in rows]
    return "\n".join(lines) + "\n"


def hard_track_meaning() -> str:
    """One paragraph: what puts an id on the hard track (from the registry's threshold)."""
    return (
        "The **hard track** holds the ids where the best scripted law, its gains re-tuned for the id on "
        "tuning seeds, costs at least "
        f"{number(100 * HARD_TRACK_MIN_EXCESS_COST)} % more than the reference ceiling (the model-predictive "
        "planner at full strength) on the benchmark's held-out seeds: its excess cost "
        "`(-R[law]) / (-R[ceiling]) - 1`, averaged over the seeds, is at least "
        f"{number(HARD_TRACK_MIN_EXCESS_COST)}. There a learned controller has room to win over the laws; on "
        "the standard track the best law comes close to the ceiling.\n"
    )


def hard_track_table() -> str:
    """What the hard track is, and a table of its ids: what each is and what it registers
    beyond its preset's task (``environments.md``)."""
    rows = []
    for env_id in HARD_TRACK:
        facts = env_facts(env_id)
        registered = ", ".join(f"`{k}={v!r}`" for k, v in facts.registered.items()) or "none"
        rows.append(
            (f"[`{env_id}`]({ENV_PAGE_DIR}/{env_id}.md)", f"`{facts.preset}`", registered, env_doc(env_id).summary)
        )
    if not rows:
        return hard_track_meaning() + (
            "\n**No id qualifies at present**, so the track is empty. The candidates measured left less room "
            "once each law was designed for its task: thrusters on two of the tetrahedron's four satellites "
            "7.7 %, a chain with thrusters on its ends about 2 %, and "
            f"[`TetherDelayedTetrahedron-v0`]({ENV_PAGE_DIR}/TetherDelayedTetrahedron-v0.md) 13.8 % until the "
            "laws predicted the state their command meets over the delay, and 7.7 % after "
            "(`tether_gym.registration.HARD_TRACK` records them).\n"
        )
    return hard_track_meaning() + "\n" + table(("id", "cluster", "registered beyond the preset", "what it is"), rows)


def env_page(env_id: str) -> str:
    """The Markdown of ``envs/<env_id>.md``."""
    facts, doc, shared = env_facts(env_id), env_doc(env_id), docstring_sections(TetherClusterEnv)
    cluster, settings = facts.cluster, facts.settings
    interval = number(settings["control_interval"])
    preset_summary, preset_rows = preset_doc(facts.preset)
    glance = [
        ("Action Space", f"`{facts.action_space}`"),
        ("Observation Space", f"`{facts.observation_space}`"),
        ("Make", f'`gym.make("tether_gym:{env_id}")`'),
        ("Make a vector env", f'`gym.make_vec("tether_gym:{env_id}", num_envs=N)`'),
        ("Cluster", f"preset `{facts.preset}`: {cluster_text(cluster)}"),
        ("Frame", frame_text(cluster)),
        ("Control interval", f"{interval} s"),
        ("Episode", f"{facts.max_episode_steps} steps ({number(facts.episode_seconds)} s), then truncated"),
        ("Track", f"[{track_of(env_id)}]({HARD_TRACK_LINK})"),
        ("Thrusters", thrust_text(facts)),
        (
            "Initial conditions (std per component)",
            f"{number(settings['initial_displacement'])} m, {number(settings['initial_velocity'])} m/s",
        ),
        ("Render modes", ", ".join(facts.render_modes) + f" ({facts.render_fps} fps)"),
    ]
    magnitudes = [
        ("satellites", str(cluster.num_satellites)),
        *(
            [("tethers with mass", f"{cluster.num_tethers}, with {cluster.num_beads} beads in all")]
            if cluster.tethers
            else []
        ),
        ("cables", str(cluster.num_cables) + (" (tether segments included)" if cluster.tethers else "")),
        ("masses", values(cluster.masses, "kg")),
        ("cable lengths L0", values(cluster.L0, "m")),
        ("axial stiffness EA", values(cluster.EA, "N")),
        ("pretension N0", values(cluster.N0, "N")),
        ("breaking load", values(cluster.breaking_load, "N")),
        ("diagonal damping", values(cluster.damping, "N s/m")),
        ("cable (Kelvin-Voigt) damping", values(cluster.axial_damping, "N s/m")),
        ("frame", frame_text(cluster)),
    ]
    own: dict[str, str] = {
        "Description": (
            doc.description.strip()
            + ("\n\n### On the hard track\n\n" + hard_track_meaning() if env_id in HARD_TRACK else "")
            + "\n\n### The cluster\n\n"
            + preset_summary
            + "\n"
            + table(("quantity", "value"), magnitudes)
            + f'\n### The preset\'s parameters\n\n`gym.make("tether_gym:{env_id}", preset_kwargs={{...}})` overrides '
            f"them (defaults from `tether_gym.presets.{facts.preset}`):\n\n"
            + table(("parameter", "default", "meaning"), [(f"`{n}`", f"`{d}`", m) for n, d, m in preset_rows])
            + discretisation_text(cluster)
            + "\n### The task (every id)\n"
        ),
        "Action Space": (
            f"Here: `{facts.action_space}`: {facts.thrusters} thrusters, 3 axes each, "
            f"{values(settings['max_thrust'], 'N')} full scale, held for {interval} s"
            + (
                f", each axis on (|command| >= {number(ON_OFF_THRESHOLD)}) or off"
                if settings["thrust_mode"] == "on_off"
                else ""
            )
            + ".\n"
        ),
        "Observation Space": (
            f"Here: `{facts.observation_space}`:\n\n"
            + table(("index", "observation", "unit"), observation_rows(facts))
            + "\nIn general:\n"
        ),
        "Episode End": (
            f"Here: truncated after {facts.max_episode_steps} steps of {interval} s "
            f"({number(facts.episode_seconds)} s).\n"
        ),
        "Arguments": (
            "This id registers "
            + (
                "these task arguments beyond the defaults:\n\n"
                + table(("argument", "registered value"), [(f"`{k}`", f"`{v!r}`") for k, v in facts.registered.items()])
                if facts.registered
                else "no task arguments beyond the defaults.\n"
            )
            + "\nAny argument below can be passed to `gym.make` or `gym.make_vec`.\n"
        ),
    }
    page = [f"# {env_id}\n", doc.summary + "\n", table(("", ""), glance), animation(facts), viewer_embed(env_id)]
    for title, body in shared.items():
        page.append(f"## {title}\n")
        if title == "Version History":
            page.append("\n".join(f"- {entry}" for entry in doc.version_history) + "\n")
            continue
        if title in own:
            page.append(own[title])
        page.append(body)
    source = "`tether_gym/envs/cluster_env.py`, `tether_gym/registration.py` and `tether_gym/presets.py`"
    page.append(f"---\n\n*Generated from {source} when the site was built.*\n")
    return "\n".join(page)


@functools.cache
def figures_script() -> Any:
    """scripts/figures.py, the producer of the animations: the page says what it drew."""
    spec = importlib.util.spec_from_file_location("docs_figures", ROOT / "scripts" / "figures.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules["docs_figures"] = module  # its dataclasses look their module up there
    spec.loader.exec_module(module)
    return module


def animation(facts: EnvFacts) -> str:
    """The id's animation (written by ``bash scripts/figures.sh``) and its caption, in Markdown
    relative to its page."""
    figures = figures_script()
    path = f"img/{figures.env_animation(facts.env_id)}"
    if not (ROOT / "docs" / path).is_file():
        raise DocsBuildError(
            f"docs/{path} is missing: run `bash scripts/figures.sh --only env_animations`, which draws one "
            f"animation per registered id"
        )
    left, right = figures.animated_controllers(facts.env_id)
    learned = right == figures.ANIMATED_CONTROLLERS[1]
    # Before an id ships its learned controller, the animation shows the law it will correct.
    shown = (
        f"the shipped `{right}` policy (right)"
        if learned
        else f"the scripted law `{right}` (right: the id ships no `ars` policy yet, and its `ars` residual is "
        f"trained on `{right}`)"
    )
    interval = number(facts.settings["control_interval"])
    return (
        f"![{facts.env_id}: {left} and {right} from the same initial state](../{path})\n\n"
        f"*{left} (left) and {shown} from the same reset (seed "
        f"{figures.ANIMATION_SEED}), {figures.ANIMATION_STEPS} control steps of {interval} s, one frame each; "
        f"blue cables are taut, orange dashed ones slack, red arrows the thrust. Drawn by "
        f"`bash scripts/figures.sh`.*\n"
    )


def best_law(env_id: str) -> str:
    """The id's best scripted law on the benchmark's held-out seeds (the shipped reference scores)."""
    import json

    scores = json.loads((ROOT / "agents" / "reference" / "reference_scores.json").read_text(encoding="utf-8"))
    entry = scores["per_id"].get(env_id)
    if entry is None:
        raise DocsBuildError(f"{env_id} has no reference scores: run the benchmark on it (docs/benchmark.md)")
    return str(entry["best_baseline"])


@functools.cache
def viewer_export(env_id: str) -> str:
    """The self-contained viewer page of ``env_id``: its best scripted law on seed VIEWER_SEED,
    made as ``tether-gym-view --export`` makes it."""
    from agents.controllers.registry import make_baseline
    from tether_gym.viewer import record_episode
    from tether_gym.viewer.page import page_html, recordings_config, suggested_exaggeration, title_of

    law = best_law(env_id)
    recording = record_episode(env_id, VIEWER_SEED, lambda env: make_baseline(law, env), law)
    return page_html(recordings_config([recording], suggested_exaggeration([recording])), title_of([recording]))


def viewer_embed(env_id: str) -> str:
    """The env page's embedded viewer and its caption, in Markdown relative to the page."""
    law = best_law(env_id)
    path = f"../{VIEWER_DIR}/{env_id}.html"
    return (
        f'<iframe class="viewer" src="{path}" title="{env_id}: {law} on seed {VIEWER_SEED}" '
        'loading="lazy"></iframe>\n\n'
        f"*The viewer: the best scripted law on the benchmark's held-out seeds, `{law}`, on seed {VIEWER_SEED}. "
        f"Drag to orbit, scroll to zoom; play, step or slide through the episode; the exaggeration slider scales "
        f"the displacements. [Open it on its own page]({path}). Made when the site was built, as "
        f"`tether-gym-view --env {env_id} --controller {law} --seed {VIEWER_SEED} --export {env_id}.html` makes it "
        f"([the viewer](../viewer.md)).*\n"
    )


def ids_table_rows() -> list[tuple[str, str, int, int, int, float]]:
    """(id, preset, action size, observation size, episode steps, control interval in s) per id."""
    rows = []
    for env_id in ENV_IDS:
        facts = env_facts(env_id)
        rows.append(
            (
                env_id,
                facts.preset,
                facts.action_size,
                facts.observation_size,
                facts.max_episode_steps,
                float(facts.settings["control_interval"]),
            )
        )
    return rows


def ids_table() -> str:
    rows = []
    for env_id, preset, action, observation, steps, interval in ids_table_rows():
        rows.append(
            (
                f"[`{env_id}`]({ENV_PAGE_DIR}/{env_id}.md)",
                f"`{preset}`",
                str(action),
                str(observation),
                f"{steps} × {number(interval)} s",
                track_of(env_id),
                env_doc(env_id).summary,
            )
        )
    return table(("id", "cluster", "action", "observation", "episode", "track", "what it is"), rows)


def readme_for_site(readme: str) -> str:
    """The README with its ``docs/`` links and images made relative to the site's root."""
    return re.sub(r"\]\(docs/", "](", readme)


# ----------------------------------------------------------------------------------------------
# MkDocs events


def on_config(config: Any) -> Any:
    """Put one page per id under the navigation's Environments section."""
    for entry in config["nav"] or []:
        if isinstance(entry, dict) and NAV_SECTION in entry:
            pages = entry[NAV_SECTION]
            pages.extend({env_id: f"{ENV_PAGE_DIR}/{env_id}.md"} for env_id in ENV_IDS)
            return config
    raise DocsBuildError(f"mkdocs.yml's nav has no {NAV_SECTION!r} section for the generated env pages")


def on_files(files: Any, config: Any) -> Any:
    from mkdocs.structure.files import File

    for env_id in ENV_IDS:
        files.append(File.generated(config, f"{ENV_PAGE_DIR}/{env_id}.md", content=env_page(env_id)))
        files.append(File.generated(config, f"{VIEWER_DIR}/{env_id}.html", content=viewer_export(env_id)))
    return files


def on_page_markdown(markdown: str, page: Any, config: Any, files: Any) -> str:
    if page.file.src_uri == "index.md":
        return readme_for_site((ROOT / "README.md").read_text(encoding="utf-8"))
    markdown = IDS_TABLE_MARKER.sub(lambda _: ids_table(), markdown)
    return HARD_TRACK_MARKER.sub(lambda _: hard_track_table(), markdown)
