"""The package's annotations are checked: mypy, with the pydantic plugin and the settings
``pyproject.toml`` names (``[tool.mypy]``), finds no error in it."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from .support import ROOT


def test_mypy_finds_no_error_in_the_package(tmp_path: Path) -> None:
    out = subprocess.run([sys.executable, "-m", "mypy", "--cache-dir", str(tmp_path / "cache")],
                         capture_output=True, text=True, timeout=600, cwd=ROOT)
    assert out.returncode == 0, out.stdout[-6000:] + out.stderr[-2000:]
    assert "Success: no issues found" in out.stdout, out.stdout[-2000:]
