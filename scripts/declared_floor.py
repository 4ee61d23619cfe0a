"""The lowest versions pyproject.toml declares, for the check that runs datagen with them.

``python scripts/declared_floor.py pyarrow`` prints the ``X`` of ``pyarrow>=X``;
``python scripts/declared_floor.py --constraints`` prints pip constraints that hold every
dependency (and the ``[tables]`` extra's pandas and polars) to its declared lowest minor
series (``NAME==X.*``; pins stay pins). scripts/install.sh makes ``.venv/floor`` with them
and tests/test_versions.py builds, audits and reads a dataset there."""

from __future__ import annotations

import re
import sys
import tomllib
from pathlib import Path

PYPROJECT = Path(__file__).resolve().parents[1] / "pyproject.toml"
#: The extra's packages the check reads manifests with.
READERS = ("pandas", "polars")
_SPEC = re.compile(r"([A-Za-z0-9_.-]+)\s*(>=|==)\s*([0-9][0-9.]*)(\s*,.*)?")


def _specs() -> list[tuple[str, str, str]]:
    project = tomllib.loads(PYPROJECT.read_text())["project"]
    specs = project["dependencies"] + [s for s in project["optional-dependencies"]["tables"]
                                       if s.startswith(READERS)]
    out = []
    for spec in specs:
        match = _SPEC.fullmatch(spec.strip())
        if match is None:
            raise SystemExit(f"{PYPROJECT}: {spec!r}: expected NAME>=VERSION or NAME==VERSION")
        out.append(match.groups()[:3])
    return out


def floor(name: str) -> str:
    """The ``X`` of ``NAME>=X`` (or ``NAME==X``) among the project's dependencies."""
    for package, _, version in _specs():
        if package.lower() == name.lower():
            return version
    raise SystemExit(f"{PYPROJECT}: no dependency {name}")


def constraints() -> str:
    """pip constraints: each ``NAME>=X`` held to X's lowest series (``>=2``: ``==2.0.*``,
    ``>=1.26``: ``==1.26.*``, ``>=16.1.0``: ``==16.1.0``), each pin as it is."""
    lines = []
    for package, op, version in _specs():
        parts = version.count(".") + 1
        series = version if op == "==" or parts >= 3 else f"{version}{'.0' if parts == 1 else ''}.*"
        lines.append(f"{package}=={series}")
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    print(constraints() if sys.argv[1:] == ["--constraints"] else floor(sys.argv[1]), end="" if
          sys.argv[1:] == ["--constraints"] else "\n")
