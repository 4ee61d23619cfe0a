"""Reading untrusted input files (YAML configs, JSON feature files) with bounded resources.

A config or feature file may be hostile or broken: an alias bomb ("billion
laughs"), recursive aliases, thousands of nesting levels, integers with thousands
of digits, duplicate keys, NaN. Each is refused with one :class:`~datagen.core.errors.Problem`
before any structure is built from it, so that reading never hangs, never runs out
of memory and never ends in a traceback:

- YAML is first read as an event stream (PyYAML's parser is iterative), counting
  the nodes every alias would expand to, the nesting depth and the length of
  plain numbers; only a stream within :data:`LIMITS` is composed into data.
- JSON is scanned for its nesting depth before it is parsed, and parsed with
  duplicate keys, non-finite constants and overlong integers refused.
"""

from __future__ import annotations

import json
import math
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Final

import yaml

from datagen.core.errors import ConfigError, Problem
from datagen.paths import Unreadable, read_bytes

__all__ = ["LIMITS", "InputLimits", "parse_json", "parse_yaml", "read_json", "read_text"]


@dataclass(frozen=True)
class InputLimits:
    """Upper bounds on what an input file may hold."""

    max_bytes: int = 64 * 2**20
    """Largest input file read, bytes."""

    max_depth: int = 64
    """Deepest nesting of mappings and lists."""

    max_nodes: int = 100_000
    """Most values (scalars, mappings and lists) of a YAML file after every alias is expanded."""

    max_number_chars: int = 40
    """Longest integer, characters (a 64-bit integer has 20)."""


LIMITS: Final = InputLimits()

_INTEGER = re.compile(r"[-+]?(0|[1-9][0-9_]*|0o?[0-7_]+|0x[0-9a-fA-F_]+|0b[01_]+)")


def read_text(path: Path, what: str, limits: InputLimits = LIMITS, *, max_bytes: int | None = None) -> str:
    """The UTF-8 text of ``path`` (at most ``max_bytes``, or ``limits.max_bytes``); one
    :class:`ConfigError` line for any reason it cannot be read (:func:`datagen.paths.read_bytes`)."""
    path = Path(path)
    limit = limits.max_bytes if max_bytes is None else max_bytes
    try:
        data = read_bytes(path, f"a {what}", limit)
    except Unreadable as exc:
        raise ConfigError([Problem(path, "", exc.problem)]) from None
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise ConfigError([Problem(path, "", f"not UTF-8 text ({exc.reason} at byte {exc.start})")]) from None


def read_json(path: Path, what: str, max_bytes: int, limits: InputLimits = LIMITS) -> Any:
    """The JSON data of ``path`` read with both bounds: its size (``max_bytes``) and what
    :func:`parse_json` refuses (one :class:`ConfigError` line)."""
    return parse_json(read_text(path, what, limits, max_bytes=max_bytes), path, limits)


# --- YAML --------------------------------------------------------------------------------------
def parse_yaml(text: str, path: Path, limits: InputLimits = LIMITS) -> Any:
    """The data of one YAML document, checked against ``limits`` before it is built.

    Raises:
        ConfigError: one problem naming the file and line (syntax, more than one
            document, recursive alias, too deep, too many values, a number too long).
    """
    path = Path(path)

    def fail(message: str, mark=None) -> ConfigError:
        return ConfigError([Problem(path, "", message, line=mark.line + 1 if mark is not None else None)])

    try:
        _check_events(yaml.parse(text, Loader=yaml.SafeLoader), limits, fail)
        return yaml.load(text, Loader=yaml.SafeLoader)
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        what = " ".join(x for x in (exc.context, exc.problem) if x)
        raise fail(f"invalid YAML: {what}", mark) from None
    except yaml.reader.ReaderError as exc:
        raise fail(f"invalid YAML: {exc.reason} at character {exc.position}") from None
    except yaml.YAMLError as exc:
        raise fail(f"invalid YAML: {' '.join(str(exc).split())}") from None
    except (ValueError, RecursionError) as exc:  # e.g. a timestamp or float the constructor cannot make
        raise fail(f"invalid YAML value: {' '.join(str(exc).split()) or type(exc).__name__}") from None


def _check_events(events, limits: InputLimits, fail) -> None:
    """Walk the event stream once: nesting depth, the expanded size of every anchor,
    recursive aliases and overlong integers."""
    sizes: dict[str, int] = {}  # anchor -> values it expands to
    stack: list[list] = []  # open collections: [anchor, values so far]
    documents = 0
    for event in events:
        if isinstance(event, yaml.DocumentStartEvent):
            documents += 1
            if documents > 1:
                raise fail("invalid YAML: expected one document, found more", event.start_mark)
            continue
        if isinstance(event, (yaml.MappingStartEvent, yaml.SequenceStartEvent)):
            if len(stack) >= limits.max_depth:
                raise fail(f"nested deeper than {limits.max_depth} levels", event.start_mark)
            stack.append([event.anchor, 1])
            continue
        if isinstance(event, (yaml.MappingEndEvent, yaml.SequenceEndEvent)):
            anchor, added = stack.pop()
            if anchor is not None:
                sizes[anchor] = added
        elif isinstance(event, yaml.ScalarEvent):
            value = event.value
            if event.style is None and len(value) > limits.max_number_chars and _INTEGER.fullmatch(value):
                raise fail(f"a number of {len(value)} characters (at most {limits.max_number_chars})",
                           event.start_mark)
            if event.anchor is not None:
                sizes[event.anchor] = 1
            added = 1
        elif isinstance(event, yaml.AliasEvent):
            if event.anchor not in sizes:
                open_anchors = {a for a, _ in stack}
                why = "refers to a value that contains it" if event.anchor in open_anchors else "is not defined"
                raise fail(f"alias *{event.anchor} {why}", event.start_mark)
            added = sizes[event.anchor]
        else:
            continue
        if stack:
            stack[-1][1] += added
        if added > limits.max_nodes or (stack and stack[-1][1] > limits.max_nodes):
            raise fail(f"expands to more than {limits.max_nodes:,} values (aliases included)", event.start_mark)


# --- JSON --------------------------------------------------------------------------------------
class _Duplicate(ValueError):
    pass


def parse_json(text: str, path: Path, limits: InputLimits = LIMITS) -> Any:
    """JSON data with the same bounds: nesting depth, integer length, no duplicate keys,
    no ``NaN`` or ``Infinity``.

    Raises:
        ConfigError: one problem naming the file (and the line where known).
    """
    path = Path(path)

    def fail(message: str, line: int | None = None) -> ConfigError:
        return ConfigError([Problem(path, "", message, line=line)])

    depth = _json_depth(text, limits.max_depth)
    if depth > limits.max_depth:
        raise fail(f"nested deeper than {limits.max_depth} levels")

    def pairs(items: list[tuple[str, Any]]) -> dict:
        out: dict = {}
        for key, value in items:
            if key in out:
                raise _Duplicate(f"duplicate key {key!r}")
            out[key] = value
        return out

    def integer(token: str) -> int:
        digits = token.lstrip("-")
        if len(digits) > limits.max_number_chars:
            raise _Duplicate(f"a number of {len(token)} characters (at most {limits.max_number_chars})")
        return int(token)

    def constant(name: str) -> float:
        raise _Duplicate(f"{name} is not a finite number")

    def real(token: str) -> float:
        value = float(token)
        if not math.isfinite(value):
            raise _Duplicate(f"{token[:20]}{'...' if len(token) > 20 else ''} is not a finite number")
        return value

    try:
        return json.loads(text, object_pairs_hook=pairs, parse_int=integer, parse_constant=constant,
                          parse_float=real)
    except json.JSONDecodeError as exc:
        raise fail(f"invalid JSON: {exc.msg} (column {exc.colno})", exc.lineno) from None
    except _Duplicate as exc:
        raise fail(str(exc)) from None
    except (ValueError, RecursionError) as exc:
        raise fail(f"invalid JSON: {' '.join(str(exc).split()) or type(exc).__name__}") from None


def _json_depth(text: str, stop: int) -> int:
    """The deepest nesting of ``[`` and ``{`` outside strings (stops counting past ``stop``)."""
    depth = deepest = 0
    in_string = escaped = False
    for ch in text:
        if in_string:
            if escaped:
                escaped = False
            elif ch == "\\":
                escaped = True
            elif ch == '"':
                in_string = False
        elif ch == '"':
            in_string = True
        elif ch in "[{":
            depth += 1
            if depth > deepest:
                deepest = depth
                if deepest > stop:
                    return deepest
        elif ch in "]}":
            depth -= 1
    return deepest
