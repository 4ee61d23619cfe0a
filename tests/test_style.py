"""The code passes the linter with the rules ``pyproject.toml`` names (``[tool.ruff.lint]``)."""

from __future__ import annotations

import subprocess
import sys

from .support import ROOT


def test_ruff_check_passes_with_the_configured_rules() -> None:
    out = subprocess.run([sys.executable, "-m", "ruff", "check", "--no-cache", "--output-format", "concise", "."],
                         capture_output=True, text=True, timeout=300, cwd=ROOT)
    assert out.returncode == 0, out.stdout[-4000:] + out.stderr[-2000:]
