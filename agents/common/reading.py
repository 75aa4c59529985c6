"""Strict reading of the data files a user gives the agents' commands (JSON and YAML): what a
file may cost and hold is bounded before it is parsed, and nothing in it is silently dropped.

* JSON (:func:`read_json`, and the hooks :mod:`agents.policies.codecs` parses policy files with):
  UTF-8, no NaN or Infinity literals, no number that overflows a float, no integer beyond 64
  bits, no key twice in an object, a bounded size and nesting depth (found before parsing, so a
  crafted file cannot make the parser recurse);
* YAML (:func:`read_yaml`: hyperparameters, settings, a run's ``config.yml``): safe (nothing
  evaluated), no key twice in a mapping, no alias inside its own anchor, a bounded expansion of
  aliases, a bounded size.

``json`` and PyYAML both keep the last of two entries with the same key without a word, so a
file could say two things about one entry and be read as the second: here it is refused.
"""

from __future__ import annotations

import functools
import json
import math
import os
import stat
from pathlib import Path
from typing import Any

from tether_gym._optional import needs_extra

__all__ = [
    "MAX_JSON_INTEGER",
    "read_bounded",
    "MAX_YAML_BYTES",
    "MAX_YAML_FLOW_DEPTH",
    "MAX_YAML_NODES",
    "decode_json",
    "json_depth",
    "json_hooks",
    "read_json",
    "read_yaml",
]


def read_bounded(file: Path, limit: int, error: type[Exception], fix: str) -> bytes:
    """The bytes of the regular file ``file``, or ``error`` naming it, the problem and ``fix``
    when it is not a regular file (a FIFO, which would block the read, a device such as
    /dev/zero, which never ends, a directory) or holds more than ``limit`` bytes. At most
    ``limit + 1`` bytes are read, whatever the file's size said a moment before: a file that grows
    (or is swapped) between a check and the read costs no more."""
    try:
        descriptor = os.open(file, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))
    except OSError as problem:
        raise error(f"{file} cannot be read ({problem.strerror}): {fix}") from problem
    if not stat.S_ISREG(os.fstat(descriptor).st_mode):
        os.close(descriptor)
        raise error(f"{file} is not a regular file (a FIFO, a device or a directory): {fix}")
    with os.fdopen(descriptor, "rb") as stream:
        data = stream.read(limit + 1)
    if len(data) > limit:
        raise error(f"{file} holds more than {limit:,} bytes, more than such a file can be: {fix}")
    return data


# ---------------------------------------------------------------------------------------------
# JSON
# ---------------------------------------------------------------------------------------------


def _reject_constant(name: str) -> None:
    raise ValueError(f"non-finite number {name} is not allowed here")


def _finite_float(text: str) -> float:
    value = float(text)
    if not math.isfinite(value):
        raise ValueError(f"number {text} overflows a float")
    return value


#: The largest integer magnitude a policy file may hold: 64-bit integers (counts, shapes), which a
#: float also holds without overflowing (an integer beyond a float's range raised OverflowError
#: wherever a number was read as a float).
MAX_JSON_INTEGER = 2**63 - 1


def _bounded_int(text: str) -> int:
    value = int(text)
    if abs(value) > MAX_JSON_INTEGER:
        raise ValueError(f"integer {text[:20]}{'...' if len(text) > 20 else ''} does not fit in 64 bits")
    return value


def _unique_keys(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    """An object's entries as a dict, refusing a key given twice: ``json`` would keep the last one
    silently, so a file could say two things about the same entry and be read as one of them."""
    table: dict[str, Any] = {}
    for key, value in pairs:
        if key in table:
            raise ValueError(f"the key {key[:40]!r} appears twice in one object (each key once)")
        table[key] = value
    return table


def json_depth(data: bytes, limit: int) -> int:
    """The nesting depth of the JSON text ``data`` (brackets inside strings not counted), read up
    to the first point deeper than ``limit`` (then ``limit + 1``): found before parsing, so that a
    crafted file cannot make the parser recurse."""
    depth = deepest = 0
    in_string = escaped = False
    for byte in data:
        if in_string:
            if escaped:
                escaped = False
            elif byte == 0x5C:  # backslash
                escaped = True
            elif byte == 0x22:  # quote
                in_string = False
        elif byte == 0x22:
            in_string = True
        elif byte in (0x5B, 0x7B):  # [ {
            depth += 1
            if depth > limit:
                return depth
            deepest = max(deepest, depth)
        elif byte in (0x5D, 0x7D):  # ] }
            depth -= 1
    return deepest


def json_hooks() -> dict[str, Any]:
    """The keyword arguments of ``json.loads`` for strict JSON: non-finite numbers, integers
    beyond 64 bits and a key twice in one object raise ``ValueError``."""
    return {
        "parse_constant": _reject_constant,
        "parse_float": _finite_float,
        "parse_int": _bounded_int,
        "object_pairs_hook": _unique_keys,
    }


#: The deepest nesting :func:`read_json` reads.
MAX_READ_JSON_DEPTH = 64
#: The largest file :func:`read_json` reads, bytes.
MAX_READ_JSON_BYTES = 64 * 2**20


def decode_json(data: bytes, where: Path, error: type[Exception], fix: str, max_depth: int, why: str = "") -> Any:
    """The strict JSON data of the bytes ``data`` read from ``where``: nested at most ``max_depth``
    deep (checked before parsing, so that the parser cannot recurse) and parsed with
    :func:`json_hooks`; otherwise ``error`` naming ``where``, the problem (``why`` added to the
    depth's) and ``fix``."""
    if json_depth(data, max_depth) > max_depth:
        raise error(f"{where} nests lists or objects more than {max_depth} deep{why}: {fix}")
    try:
        return json.loads(data.decode("utf-8"), **json_hooks())
    except (UnicodeDecodeError, ValueError) as problem:
        raise error(f"{where} is not valid JSON ({problem}): {fix}") from problem


def read_json(file: Path, error: type[Exception], fix: str) -> Any:
    """The strict JSON data of ``file``, or ``error`` naming the file, the problem and ``fix``."""
    return decode_json(read_bounded(file, MAX_READ_JSON_BYTES, error, fix), file, error, fix, MAX_READ_JSON_DEPTH)


# ---------------------------------------------------------------------------------------------
# YAML
# ---------------------------------------------------------------------------------------------

#: The largest YAML file read (hyperparameters, settings, a run's config.yml): they are a few KB.
MAX_YAML_BYTES = 4 * 2**20


#: The most nodes a YAML file read may expand to, aliases followed (the project's own files, with
#: their ``<<: *default`` merges, expand to a few hundred).
MAX_YAML_NODES = 100_000
#: The deepest nesting of flow collections (``[ ]`` and ``{ }``) a YAML file may have. PyYAML's
#: scanner keeps a possible key per open flow level and checks them all at every token, so its
#: time grows as the square of the depth: 3 000 nested ``[`` took over a second to refuse. The
#: project's settings files nest two deep.
MAX_YAML_FLOW_DEPTH = 64


@functools.cache
def _strict_loader() -> Any:
    """The YAML loader of :func:`read_yaml` (PyYAML comes with the train extra: imported here, so
    that reading JSON needs nothing beyond the core)."""
    with needs_extra("train", "reading the settings files"):
        import yaml

    class _StrictLoader(yaml.SafeLoader):
        """``yaml.SafeLoader`` that refuses a key given twice in one mapping (PyYAML keeps the last
        one silently, so a file could say two things about one setting and be read as the second), an
        alias inside its own anchor (a structure that contains itself, which recursed without end
        wherever it was walked), and documents that expand beyond :data:`MAX_YAML_NODES` nodes with
        their aliases followed (a few lines of nested aliases expand to billions of entries)."""

        def get_single_node(self) -> Any:
            node = super().get_single_node()
            if node is not None:
                _expanded_size(node, {}, set())
            return node

        def construct_mapping(self, node: Any, deep: bool = False) -> Any:
            # A set, so that a mapping of many keys costs linear time (a list made 50 000 keys cost
            # a billion comparisons); an unhashable key is refused later by the constructor itself.
            seen: set[Any] = set()
            for key_node, _ in node.value:
                if key_node.tag == "tag:yaml.org,2002:merge":
                    continue  # '<<: *default' merges another mapping's entries, which may be overridden
                key = self.construct_object(key_node, deep=True)
                try:
                    repeated = key in seen
                except TypeError:
                    continue
                if repeated:
                    raise yaml.constructor.ConstructorError(
                        None,
                        None,
                        f"the key {str(key)[:40]!r} appears twice in one mapping (each key once)",
                        key_node.start_mark,
                    )
                seen.add(key)
            return super().construct_mapping(node, deep=deep)

    return _StrictLoader


def _expanded_size(node: Any, sizes: dict[int, int], open_nodes: set[int]) -> int:
    """The number of nodes ``node`` stands for with every alias followed (``sizes`` memoises the
    shared ones), or a ``ComposerError`` for a node inside itself or a size beyond the limit."""
    import yaml

    key = id(node)
    if key in sizes:
        return sizes[key]
    if key in open_nodes:
        raise yaml.composer.ComposerError(None, None, "an alias inside its own anchor", node.start_mark)
    open_nodes.add(key)
    size = 1
    if isinstance(node, yaml.SequenceNode):
        children = list(node.value)
    elif isinstance(node, yaml.MappingNode):
        children = [child for pair in node.value for child in pair]
    else:
        children = []
    for child in children:
        size += _expanded_size(child, sizes, open_nodes)
        if size > MAX_YAML_NODES:
            raise yaml.composer.ComposerError(
                None,
                None,
                f"the document expands to more than {MAX_YAML_NODES:,} entries with its aliases",
                node.start_mark,
            )
    open_nodes.discard(key)
    sizes[key] = size
    return size


def _flow_depth(data: bytes) -> int:
    """The deepest nesting of ``[``/``{`` over ``]``/``}`` in ``data``, counted over the whole
    text (quoted or not), in one vectorised pass: an upper bound on the flow depth the YAML
    scanner will see, for files without unmatched brackets in their strings."""
    import numpy as np

    codes = np.frombuffer(data, dtype=np.uint8)
    opens = (codes == ord("[")).astype(np.int64) + (codes == ord("{"))
    closes = (codes == ord("]")).astype(np.int64) + (codes == ord("}"))
    return int(np.cumsum(opens - closes).max(initial=0))


def read_yaml(file: Path, error: type[Exception] = ValueError) -> Any:
    """The data of the YAML ``file`` (nothing in it evaluated), read strictly: at most
    :data:`MAX_YAML_BYTES`, UTF-8, no key twice in a mapping, no alias inside its own anchor, at
    most :data:`MAX_YAML_NODES` entries with aliases followed, flow collections at most
    :data:`MAX_YAML_FLOW_DEPTH` deep, no nesting deeper than the parser's recursion allows. Raises
    ``error`` naming the file and the problem."""
    data = read_bounded(file, MAX_YAML_BYTES, error, "pass another file")
    depth = _flow_depth(data)
    if depth > MAX_YAML_FLOW_DEPTH:
        raise error(
            f"{file} nests [ ] or {{ }} {depth} deep (at most {MAX_YAML_FLOW_DEPTH}, brackets in quotes and "
            "comments counted too): it is not a settings file"
        )
    loader = _strict_loader()
    import yaml

    try:
        return yaml.load(data.decode("utf-8"), Loader=loader)  # noqa: S506 - a SafeLoader
    except UnicodeDecodeError as problem:
        raise error(f"{file} is not UTF-8 text ({problem})") from problem
    except yaml.YAMLError as problem:
        raise error(f"{file} is not valid YAML: {problem}") from problem
    except RecursionError:
        raise error(f"{file} nests lists or mappings too deep to read: it is not a settings file") from None
