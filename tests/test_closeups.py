"""The gallery's close-ups: windows chosen on what a frame shows, and bad input refused."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np

from datagen.render.world import SURFACES
from datagen.report.gallery import _windows


def test_the_close_up_windows_sit_on_the_cloud_edges_and_on_the_sea() -> None:
    surface = np.full((540, 1024), SURFACES.index("sky"), dtype=np.uint8)
    surface[300:, :] = SURFACES.index("sea")  # sea along the bottom
    surface[300:, 700:] = SURFACES.index("cloud")  # a cloud over the sea's right side, its edge at x = 700
    rng = np.random.default_rng(0)
    ragged = rng.random((240, 60)) < 0.5
    surface[300:, 670:730][ragged] = SURFACES.index("cloud")
    windows = _windows(surface, (320, 180))
    x, y = windows["clouds"]
    assert x <= 670 and x + 320 >= 730 and y + 180 > 300
    x, y = windows["sea"]
    assert y >= 270 and x + 320 <= 700


def test_gallery_refuses_a_missing_before_folder_in_one_line(tmp_path: Path) -> None:
    out = subprocess.run([sys.executable, "-m", "datagen", "gallery", "--out", str(tmp_path / "g.jpg"),
                          "--closeups", str(tmp_path / "c.jpg"), "--before", str(tmp_path / "nowhere")],
                         capture_output=True, text=True)
    assert out.returncode != 0
    lines = out.stderr.strip().splitlines()
    assert len(lines) == 1 and "--before" in lines[0] and "nowhere" in lines[0]
    assert not (tmp_path / "g.jpg").exists() and not (tmp_path / "c.jpg").exists()
