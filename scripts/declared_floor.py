"""Print the lowest version pyproject.toml declares for a dependency (``NAME>=X``):
``python scripts/declared_floor.py pyarrow`` -> ``16.1.0``. scripts/install.sh installs
that version beside the venv's and tests/test_versions.py runs datagen with it."""

from __future__ import annotations

import re
import sys
import tomllib
from pathlib import Path

PYPROJECT = Path(__file__).resolve().parents[1] / "pyproject.toml"


def floor(name: str) -> str:
    """The ``X`` of ``NAME>=X`` among the project's dependencies."""
    dependencies = tomllib.loads(PYPROJECT.read_text())["project"]["dependencies"]
    for spec in dependencies:
        match = re.fullmatch(rf"{re.escape(name)}\s*>=\s*([0-9][0-9.]*)", spec.strip())
        if match:
            return match.group(1)
    raise SystemExit(f"{PYPROJECT}: no dependency {name}>=VERSION")


if __name__ == "__main__":
    print(floor(sys.argv[1]))
