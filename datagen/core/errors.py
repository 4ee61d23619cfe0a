"""User-facing errors: one line per problem, naming the file, the key and what is wrong.

The CLI prints :class:`DatagenError` messages and exits non-zero; any other
exception is a bug in datagen, not bad input.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

__all__ = ["ConfigError", "DatagenError", "Problem", "shown"]


def shown(text: object) -> str:
    """``text`` as it may be printed: every character a terminal would act on instead of
    showing (escape sequences, carriage returns, newlines, bells, C1 controls, undecodable
    bytes of a file name, unassigned code points) written as a Python escape, so that a
    name taken from a dataset can neither draw over a report's lines nor add lines to it.
    Printable text, non-ASCII letters included, is unchanged."""
    text = str(text)
    if text.isprintable():
        return text
    return "".join(ch if ch.isprintable() else ascii(ch)[1:-1] for ch in text)


class DatagenError(Exception):
    """Bad input: printed to the user as is (escaped: :func:`shown`), without a traceback."""

    def lines(self) -> list[str]:
        return [shown(str(self))]


@dataclass(frozen=True)
class Problem:
    """One thing wrong with one input file."""

    file: Path
    key: str  # dotted key path, "" for the whole file
    message: str
    line: int | None = None  # 1-based line in the file, when known
    value: object = None
    has_value: bool = False

    def __str__(self) -> str:
        where = f"{self.file}:{self.line}" if self.line is not None else f"{self.file}"
        parts = [where]
        if self.key:
            parts.append(self.key)
        if self.has_value:
            parts.append(f"value {_short_repr(self.value)}")
        parts.append(self.message)
        return shown(re.sub(r"\s*\n\s*", " ", ": ".join(parts)))


class ConfigError(DatagenError):
    """One or more problems with a config (or asset) file."""

    def __init__(self, problems: Sequence[Problem]):
        self.problems = list(problems)
        super().__init__("\n".join(str(p) for p in self.problems))

    def lines(self) -> list[str]:
        return [str(p) for p in self.problems]


def _short_repr(value: object, limit: int = 60) -> str:
    text = repr(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."
