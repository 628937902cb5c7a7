"""YAML documents that remember where each value came from.

hexatherm's YAML files (hexapod, balls, plan, session) are read into plain
Python values together with the line of every key and item, so that a
validation error can say ``hexapod.yaml:12: field 'legs.segments[1].cte': ...``.
Duplicate keys, which YAML would silently collapse, are errors.

Hostile documents are refused with a one-line :class:`~hexatherm.errors.InputError`
naming the file, the line and the field, before they are composed: files that are
not regular or larger than :data:`~hexatherm.io.files.MAX_YAML_BYTES`, nesting
deeper than :data:`MAX_DEPTH`, aliases that expand to more than
:data:`MAX_ALIAS_NODES` nodes ("billion laughs") or that refer to a node containing
them. The parser's events are scanned first (libyaml's when PyYAML has it; no
recursion, no expansion), then libyaml composes as before.

>>> YamlDoc.from_text("a: " + "[" * 1000 + "]" * 1000, "deep.yaml")
Traceback (most recent call last):
hexatherm.errors.InputError: deep.yaml:1: field 'a[0][0][0][0][0]...': nested deeper than 100 levels

>>> doc = YamlDoc.from_text("a: 1\\nb:\\n  - [1, 2]\\n  - x\\n", "demo.yaml")
>>> doc.data
{'a': 1, 'b': [[1, 2], 'x']}
>>> doc.line("b", 1)
4
>>> str(doc.error("not a vector", "b", 1))
"demo.yaml:4: field 'b[1]': not a vector"

Readers of long files in a fixed layout (the plan) may parse their lines
themselves, with :data:`PLAIN_NUMBER`, :func:`plain_numbers` and :func:`plain_tag`
giving the values that the loader would, and fall back to :class:`YamlDoc` for
anything else, so that errors stay those of :class:`YamlDoc`.

>>> plain_numbers(["1", "-2.5", "1e-3"]), plain_tag("yes"), plain_tag("S1")
([1.0, -2.5, 0.001], 'bool', 'str')
"""

from __future__ import annotations

import contextlib
import math
import os
import re
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from hexatherm.errors import InputError
from hexatherm.io.files import MAX_YAML_BYTES, read_bytes, refuse_utf16

Key = str | int


class _Loader(yaml.SafeLoader):
    """SafeLoader that also reads YAML 1.2 floats such as ``1e-5`` as numbers."""


#: the composer: libyaml's (C, about 3x faster on a long plan) when PyYAML has it
_Composer: type[Any] = _Loader
if getattr(yaml, "__with_libyaml__", False):

    class _CLoader(yaml.CSafeLoader):
        """libyaml's SafeLoader with the same resolvers (composes; never constructs)."""

    _Composer = _CLoader

_loaders: list[type[Any]] = [_Loader, _Composer]
for _loader in dict.fromkeys(_loaders):  # once each
    _loader.add_implicit_resolver(
        "tag:yaml.org,2002:float",
        re.compile(r"^[-+]?(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)[eE][-+]?[0-9]+$"),
        list("-+0123456789."),
    )


#: the composer's tag resolution, for :func:`plain_tag`
_resolver = _Composer("")

#: a plain scalar that the loader reads as a decimal int or float (no sign ``+``, no
#: ``_``, no leading zero, digits on both sides of a point): :func:`plain_numbers`
#: gives its value
PLAIN_NUMBER = r"-?(?:0|[1-9][0-9]*)(?:\.[0-9]+)?(?:[eE][-+]?[0-9]+)?"


def plain_numbers(texts: Iterable[str]) -> list[float] | None:
    """The values that :meth:`YamlDoc.number` reads from plain scalars.

    Parameters
    ----------
    texts : iterable of str
        Plain scalars that match :data:`PLAIN_NUMBER` (not checked).

    Returns
    -------
    list of float or None
        ``float(text)`` of each, or None when one is not finite or is ``-0`` (the
        int 0, read as ``0.0``, where ``float("-0")`` is ``-0.0``): left to :class:`YamlDoc`.
    """
    texts = list(texts)
    if "-0" in texts:
        return None
    values = list(map(float, texts))
    if not all(map(math.isfinite, values)):
        return None
    return values


def plain_tag(text: str) -> str:
    """The type the loader gives a plain (unquoted) scalar: ``str``, ``int``, ``bool``, ...

    Parameters
    ----------
    text : str
        The scalar as written, a single line without indicators (``#``, ``:``, ``,``...).

    Returns
    -------
    str
        The last part of its resolved tag, e.g. ``"str"`` for ``S1``, ``"bool"`` for ``on``.
    """
    return str(_resolver.resolve(yaml.ScalarNode, text, (True, False))).rpartition(":")[2]


def read_text(path: str | os.PathLike[str]) -> str:
    """The text of a YAML file; InputError when it is missing, not a regular file, larger
    than :data:`~hexatherm.io.files.MAX_YAML_BYTES`, unreadable or not UTF-8."""
    path = os.fspath(path)
    data = read_bytes(path, limit=MAX_YAML_BYTES)
    refuse_utf16(data, path)
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise InputError(f"not UTF-8 text ({exc.reason} at byte {exc.start})", path=path) from None


#: The deepest nesting of mappings and sequences read (a bound well below Python's
#: recursion limit: deeper documents are refused before they are composed)
MAX_DEPTH = 100
#: The most nodes that aliases (``*name``) may add to a document when expanded (a
#: "billion laughs" document adds 10**9)
MAX_ALIAS_NODES = 100_000

_COLLECTION_START = (yaml.SequenceStartEvent, yaml.MappingStartEvent)
_COLLECTION_END = (yaml.SequenceEndEvent, yaml.MappingEndEvent)


class _Level:
    """A mapping or sequence being scanned: its place and what it holds so far."""

    __slots__ = ("mapping", "anchor", "key", "index", "expect_key", "size", "height")

    def __init__(self, mapping: bool, anchor: str | None) -> None:
        self.mapping = mapping
        self.anchor = anchor
        self.key: Key = "?"
        self.index = -1
        self.expect_key = True
        self.size = 1
        self.height = 1


def _keys(stack: list[_Level]) -> tuple[Key, ...]:
    return tuple(level.key if level.mapping else level.index for level in stack[1:])


def _scan(text: str, path: str) -> None:
    """Refuse a document nested deeper than :data:`MAX_DEPTH` or whose aliases expand to
    more than :data:`MAX_ALIAS_NODES` nodes, from the parser's events (no recursion, no
    expansion), before it is composed; the error names the file, line and field.

    PyYAML >= 6.0.4 stops flow collections nested deeper than its own limit (1000) in
    the scanner, which looks ahead before it gives the first event of the nest: the text
    up to that point is then scanned again, so the error still names the field where
    the nest passed :data:`MAX_DEPTH`.
    """
    try:
        _scan_events(text, path)
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark
        if mark is None or "nesting depth" not in str(exc.problem):
            raise
        lines = text.splitlines(keepends=True)
        head = "".join(lines[: mark.line]) + lines[mark.line][: mark.column]
        with contextlib.suppress(yaml.YAMLError):
            _scan_events(head, path)
        raise InputError(
            f"nested deeper than {MAX_DEPTH} levels", path=path, line=mark.line + 1
        ) from None


def _scan_events(text: str, path: str) -> None:
    if "&" not in text and _shallow(text):
        return  # no anchors, so no aliases: only the depth mattered
    root = _Level(False, None)
    stack = [root]
    anchors: dict[str, tuple[int, int]] = {}
    added = 0
    scalar, alias, ends = yaml.ScalarEvent, yaml.AliasEvent, _COLLECTION_END
    parent = root
    events: Iterable[Any] = yaml.parse(text, Loader=_Composer)
    for event in events:
        kind = event.__class__
        if kind is scalar:  # the bulk: keep it short
            if parent.mapping:
                if parent.expect_key:
                    parent.key = event.value
                parent.expect_key = not parent.expect_key
            else:
                parent.index += 1
            parent.size += 1
            if event.anchor is not None:
                anchors[event.anchor] = (1, 1)
            continue
        if kind in ends:
            done = stack.pop()
            if done.anchor is not None:
                anchors[done.anchor] = (done.size, done.height)
            parent = stack[-1]
            parent.size += done.size
            parent.height = max(parent.height, done.height + 1)
            continue
        if kind is not alias and kind not in _COLLECTION_START:
            continue  # stream and document events
        if parent.mapping:
            if parent.expect_key:
                parent.key = "?"
            parent.expect_key = not parent.expect_key
        else:
            parent.index += 1
        line = event.start_mark.line + 1
        if kind is alias:
            if any(level.anchor == event.anchor for level in stack):
                raise InputError(
                    f"alias *{event.anchor} refers to a node that contains it (endless)",
                    path=path,
                    line=line,
                    field=_short_field(_keys(stack)),
                )
            size, height = anchors.get(str(event.anchor), (1, 1))
            added += size
            if added > MAX_ALIAS_NODES:
                raise InputError(
                    f"YAML aliases expand to more than {MAX_ALIAS_NODES:,} nodes "
                    f"(at alias *{event.anchor}): refused (an alias bomb?)",
                    path=path,
                    line=line,
                    field=_short_field(_keys(stack)),
                )
            if len(stack) - 1 + height > MAX_DEPTH:
                raise InputError(
                    f"alias *{event.anchor} nests deeper than {MAX_DEPTH} levels",
                    path=path,
                    line=line,
                    field=_short_field(_keys(stack)),
                )
            parent.size += size
            parent.height = max(parent.height, height + 1)
            continue
        if len(stack) > MAX_DEPTH:
            raise InputError(
                f"nested deeper than {MAX_DEPTH} levels",
                path=path,
                line=line,
                field=_short_field(_keys(stack)),
            )
        parent = _Level(kind is yaml.MappingStartEvent, event.anchor)
        stack.append(parent)


def _shallow(text: str) -> bool:
    """Whether the document nests no deeper than :data:`MAX_DEPTH` (events counted only)."""
    starts, ends = _COLLECTION_START, _COLLECTION_END
    depth = 0
    for event in yaml.parse(text, Loader=_Composer):
        kind = event.__class__
        if kind in starts:
            depth += 1
            if depth > MAX_DEPTH:
                return False
        elif kind in ends:
            depth -= 1
    return True


def _short_field(keys: Sequence[Key]) -> str | None:
    if not keys:
        return None
    return field_name(keys[:6]) + ("..." if len(keys) > 6 else "")


def field_name(keys: Sequence[Key]) -> str:
    """Dotted field name: ``("legs", "segments", 1, "cte")`` -> ``legs.segments[1].cte``."""
    out = ""
    for key in keys:
        out += f"[{key}]" if isinstance(key, int) else (f".{key}" if out else str(key))
    return out


@dataclass
class YamlDoc:
    """A parsed YAML mapping with the line of every value.

    Attributes
    ----------
    data : dict
        The document's top-level mapping.
    path : str
        The file (for messages).
    lines : dict
        ``tuple(keys) -> 1-based line`` for every mapping value and sequence item.
    scalars : dict
        ``tuple(keys) -> text`` of every scalar as written (``007``, which YAML reads as
        the number 7: a message can quote what the file says).
    """

    data: dict[str, Any]
    path: str
    lines: dict[tuple[Key, ...], int] = field(default_factory=dict)
    scalars: dict[tuple[Key, ...], str] = field(default_factory=dict)

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> YamlDoc:
        """Read a YAML file; InputError when it is missing, unreadable or not a mapping."""
        path = os.fspath(path)
        return cls.from_text(read_text(path), path)

    @classmethod
    def from_text(cls, text: str, path: str) -> YamlDoc:
        """Parse YAML text; InputError with the line on syntax errors."""
        try:
            _scan(text, path)
            node = yaml.compose(text, Loader=_Composer)
        except yaml.MarkedYAMLError as exc:
            mark = exc.problem_mark
            line = None if mark is None else mark.line + 1
            raise InputError(f"invalid YAML: {exc.problem}", path=path, line=line) from None
        except yaml.YAMLError as exc:
            raise InputError(f"invalid YAML: {exc}", path=path) from None
        if node is None or not isinstance(node, yaml.MappingNode):
            raise InputError(
                "expected a YAML mapping (key: value lines) at the top level",
                path=path,
                line=1 if node is None else node.start_mark.line + 1,
            )
        doc = cls(data={}, path=path)
        constructor = _Loader("")
        doc.data = doc._build(node, (), constructor)
        return doc

    def _build(self, node: yaml.Node, keys: tuple[Key, ...], constructor: Any) -> Any:
        self.lines[keys] = node.start_mark.line + 1
        if isinstance(node, yaml.MappingNode):
            out: dict[Any, Any] = {}
            for key_node, value_node in node.value:
                try:
                    key = constructor.construct_object(key_node, deep=True)
                except yaml.YAMLError as exc:
                    raise InputError(
                        f"invalid key: {exc}", path=self.path, line=key_node.start_mark.line + 1
                    ) from None
                if not isinstance(key, str | int | float | bool) or key is None:
                    raise InputError(
                        "keys must be plain names",
                        path=self.path,
                        line=key_node.start_mark.line + 1,
                    )
                key = str(key)
                if key in out:
                    raise InputError(
                        "duplicate key",
                        path=self.path,
                        line=key_node.start_mark.line + 1,
                        field=field_name(keys + (key,)),
                    )
                out[key] = self._build(value_node, keys + (key,), constructor)
            return out
        if isinstance(node, yaml.SequenceNode):
            return [
                self._build(item, keys + (i,), constructor) for i, item in enumerate(node.value)
            ]
        if isinstance(node, yaml.ScalarNode):
            self.scalars[keys] = str(node.value)
        try:
            return constructor.construct_object(node, deep=True)
        except (yaml.YAMLError, ValueError, TypeError) as exc:
            raise InputError(
                f"invalid value: {exc}",
                path=self.path,
                line=node.start_mark.line + 1,
                field=field_name(keys),
            ) from None

    # ---------------------------------------------------------------- access
    def line(self, *keys: Key) -> int | None:
        """Line of a value, or of its nearest ancestor that exists."""
        k = tuple(keys)
        while k not in self.lines and k:
            k = k[:-1]
        return self.lines.get(k)

    def error(self, message: str, *keys: Key) -> InputError:
        """An InputError located at the value ``keys``."""
        return InputError(
            message, path=self.path, line=self.line(*keys), field=field_name(keys) if keys else None
        )

    def get(self, *keys: Key, default: Any = ..., where: Any = None) -> Any:
        """The value at ``keys``; InputError if missing and no default is given."""
        node: Any = self.data
        for i, key in enumerate(keys):
            container_ok = (
                isinstance(node, dict) if isinstance(key, str) else isinstance(node, list)
            )
            if not container_ok:
                expected = "expected a mapping" if isinstance(key, str) else "expected a list"
                raise self.error(expected, *keys[:i])
            if (isinstance(key, str) and key not in node) or (
                isinstance(key, int) and key >= len(node)
            ):
                if default is not ...:
                    return default
                raise self.error("missing (required)", *keys)
            node = node[key]
        return node

    def check_keys(self, allowed: Sequence[str], *keys: Key) -> None:
        """Reject keys of the mapping at ``keys`` that the contract does not know."""
        mapping = self.get(*keys)
        if not isinstance(mapping, dict):
            raise self.error("expected a mapping", *keys)
        for key in mapping:
            if key not in allowed:
                raise self.error(f"unknown key; expected one of: {', '.join(allowed)}", *keys, key)

    @staticmethod
    def shown(value: Any) -> str:
        """``value`` as a message shows what the file holds: a mapping or a list in YAML's
        flow style (``{x: 1}``, not Python's ``{'x': 1}``), shortened past 60 characters.

        >>> YamlDoc.shown({"x": 1, "y": [1, "a"]}), YamlDoc.shown("a")
        ('{x: 1, y: [1, a]}', "'a'")
        """
        if not isinstance(value, dict | list):
            return repr(value)
        text = yaml.safe_dump(value, default_flow_style=True, width=10**6).strip()
        text = text.removesuffix("\n...").strip()
        return text if len(text) <= 60 else text[:57] + "..."

    def number(self, *keys: Key, default: Any = ..., positive: bool = False) -> float:
        """A finite number at ``keys``."""
        value = self.get(*keys, default=default)
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise self.error(f"expected a number, got {self.shown(value)}", *keys)
        value = float(value)
        if not math.isfinite(value):
            raise self.error(f"expected a finite number, got {value!r}", *keys)
        if positive and value <= 0:
            raise self.error(f"must be positive, got {value!r}", *keys)
        return value

    def vector(self, *keys: Key, size: int, default: Any = ...) -> list[float]:
        """A list of ``size`` finite numbers at ``keys``."""
        missing = object()
        value = self.get(*keys, default=missing if default is not ... else ...)
        if value is missing:
            return [float(v) for v in default]
        if not isinstance(value, list) or len(value) != size:
            raise self.error(f"expected a list of {size} numbers, got {self.shown(value)}", *keys)
        return [self.number(*keys, i) for i in range(size)]

    def string(self, *keys: Key, default: Any = ..., choices: Sequence[str] | None = None) -> str:
        """A string at ``keys``, optionally one of ``choices``."""
        value = self.get(*keys, default=default)
        if not isinstance(value, str):
            raise self.error(f"expected a text value, got {self.shown(value)}", *keys)
        if choices is not None and value not in choices:
            raise self.error(f"expected one of {', '.join(choices)}, got {value!r}", *keys)
        return value

    def check_format(self, expected: str) -> None:
        """The ``format:`` key must name this file's contract exactly."""
        value = self.get("format", default=None)
        if value is None:
            raise self.error(f"missing 'format: {expected}'", "format")
        if value != expected:
            raise self.error(f"expected format {expected!r}, got {value!r}", "format")

    def resolve(self, relative: str) -> Path:
        """A path written in this file, resolved relative to the file's folder."""
        return (Path(self.path).parent / relative).resolve()
