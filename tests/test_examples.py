"""The examples a reader copies run as written: the doctests of the core geometry (camera,
projection, pixel conventions, transforms, labels) and the Python API page's code."""

from __future__ import annotations

import contextlib
import doctest
import importlib
import io
import re

import numpy as np
import pytest

from .support import ROOT

#: The modules whose docstrings carry examples, and how many examples each holds at least.
DOCTESTED = {"datagen.core.camera": 4, "datagen.core.conventions": 2, "datagen.core.transforms": 4,
             "datagen.core.label_boxes": 4}


@pytest.mark.parametrize("name", sorted(DOCTESTED))
def test_the_examples_in_the_core_geometrys_docstrings_give_what_they_show(name: str) -> None:
    result = doctest.testmod(importlib.import_module(name), optionflags=doctest.NORMALIZE_WHITESPACE)
    assert result.failed == 0
    assert result.attempted >= DOCTESTED[name]


def python_blocks(markdown: str) -> list[str]:
    """The fenced ``python`` code blocks of a Markdown page."""
    return re.findall(r"^```python\n(.*?)^```", markdown, re.DOTALL | re.MULTILINE)


def test_the_python_api_pages_example_runs_and_prints_yolo_lines_centred_on_the_true_centres() -> None:
    blocks = python_blocks((ROOT / "docs" / "reference" / "python-api.md").read_text())
    assert blocks
    namespace: dict = {}
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        for code in blocks:
            exec(compile(code, "python-api.md", "exec"), namespace)
    lines = out.getvalue().split()
    labels, k = namespace["labels"], namespace["k"]
    labeled = labels.labeled[0]
    assert labeled.any() and len(lines) == 5 * int(labeled.sum())
    centres = [(float(lines[i + 1]) * k.width, float(lines[i + 2]) * k.height) for i in range(0, len(lines), 5)]
    np.testing.assert_allclose(centres, labels.center_px[0][labeled], atol=1e-4)  # YOLO text: 6 decimals
