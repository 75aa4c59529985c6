"""Griffe extension for the API reference: the docstrings as mkdocstrings' Google parser reads them.

The project's docstrings cross-reference with Sphinx roles (``:class:`~tether_gym.Cluster```,
``:func:`make_cluster```), which Markdown would print as they are. mkdocstrings loads this file
(mkdocs.yml, ``extensions``) and each role becomes inline code of its target, shortened as
Sphinx shortens ``~`` targets; a reST literal-block marker ``::`` at a line's end becomes ``:``
(the indented block after it is a code block in Markdown too).

Some ``Args:`` sections describe parameters that share a meaning on one entry,
``preset, preset_kwargs, cluster, **task: as for ...`` (the entry's names may wrap onto a second
line). The Google style that griffe parses wants one name per entry, and reports the group as
an unknown parameter (a warning, which fails the strict build), so each name gets its own copy
of the entry here. The docstrings themselves stay as the code's readers and ``help()`` see them.
"""

from __future__ import annotations

import re
from typing import Any

import griffe

ROLE = re.compile(r":(?:py:)?\w+:`(~?)([^`]+)`")
LITERAL_MARKER = re.compile(r"(?<=\S)::$", flags=re.MULTILINE)


SECTION = re.compile(r"^(\s*)(?:Args|Arguments|Parameters|Attributes|Other Parameters):\s*$")
NAME = r"\*{0,2}\w+"
GROUP = re.compile(rf"^(\s*)({NAME}(?:,\s*{NAME})+):(\s.*|)$")
WRAPPED_GROUP = re.compile(rf"^(\s*)({NAME}(?:,\s*{NAME})*,)\s*$")


def split_grouped_parameters(text: str) -> str:
    """``text`` with every ``a, b: meaning`` entry of an ``Args:``-like section as one entry per name."""
    lines = text.splitlines()
    out: list[str] = []
    section_indent: int | None = None
    i = 0
    while i < len(lines):
        line = lines[i]
        header = SECTION.match(line)
        if header:
            section_indent = len(header.group(1))
            out.append(line)
            i += 1
            continue
        indent = len(line) - len(line.lstrip())
        if section_indent is not None and line.strip() and indent <= section_indent:
            section_indent = None
        wrapped = WRAPPED_GROUP.match(line) if section_indent is not None else None
        if wrapped and i + 1 < len(lines):
            line = wrapped.group(1) + wrapped.group(2) + " " + lines[i + 1].strip()
            i += 1
        group = GROUP.match(line) if section_indent is not None else None
        if not group:
            out.append(line)
            i += 1
            continue
        entry_indent = len(group.group(1))
        continuation = []
        i += 1
        while i < len(lines) and lines[i].strip() and len(lines[i]) - len(lines[i].lstrip()) > entry_indent:
            continuation.append(lines[i])
            i += 1
        for name in re.split(r",\s*", group.group(2)):
            out.append(f"{group.group(1)}{name}:{group.group(3)}")
            out.extend(continuation)
    return "\n".join(out)


def roles_to_code(text: str) -> str:
    """``text`` with every ``:role:`target``` as ```target``` (``~a.b.c`` as ```c```)."""

    def code(match: re.Match[str]) -> str:
        target = match.group(2)
        return f"`{target.rsplit('.', 1)[-1]}`" if match.group(1) else f"`{target}`"

    return LITERAL_MARKER.sub(":", ROLE.sub(code, text))


class SphinxRoles(griffe.Extension):
    """Rewrite the roles of every docstring as it is loaded."""

    def on_instance(self, *, obj: griffe.Object, **kwargs: Any) -> None:
        if obj.docstring is not None:
            obj.docstring.value = split_grouped_parameters(roles_to_code(obj.docstring.value))
