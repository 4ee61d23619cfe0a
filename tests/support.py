"""Helpers shared by the test modules (not tests themselves): a tiny config, the CLI
as a subprocess, and readers of a built dataset's files."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pyarrow.parquet as pq

from datagen.atomic import is_temporary
from datagen.config import load_config, override_config
from datagen.dataset.columns import RUN_COLUMNS

ROOT = Path(__file__).resolve().parents[1]

TINY = """\
name: tiny
camera: {mount: wingcam, hfov_deg: 55.0, width: 128, height: 68}
render: {spp: 1, max_depth: 3, exr: %(exr)s}
labels: {edge_margin_px: 2.0}
approach: {frames_per_approach: 4}
dataset: {frames: 8, shard_size: 3, min_shards: 1, seed: 7}
"""


def tiny_config(tmp: Path, *, exr: bool = False, **overrides):
    path = tmp / "tiny.yaml"
    path.write_text(TINY % {"exr": str(exr).lower()})
    config = load_config(path)
    return override_config(config, overrides) if overrides else config


def run_cli(*args: str, cwd: Path = ROOT, timeout: float = 300) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "datagen", *args], cwd=cwd, capture_output=True, text=True,
                          timeout=timeout)


def manifest_rows(root: Path) -> dict[int, dict]:
    rows = {}
    for path in sorted((root / "manifests").glob("*.parquet")):
        for row in pq.read_table(path).to_pylist():
            rows[row["frame_id"]] = row
    return rows


def comparable(root: Path) -> dict[int, str]:
    """Manifest rows without the timing columns, as canonical JSON (NaN-safe equality)."""
    return {i: json.dumps({k: v for k, v in row.items() if k not in RUN_COLUMNS}, sort_keys=True)
            for i, row in manifest_rows(root).items()}


def label_files(root: Path) -> dict[str, bytes]:
    return {str(p.relative_to(root)): p.read_bytes() for p in sorted((root / "labels").rglob("*.txt"))}


def image_files(root: Path) -> dict[str, bytes]:
    return {str(p.relative_to(root)): p.read_bytes() for tree in ("images", "exr")
            for p in sorted((root / tree).rglob("*")) if p.is_file()}


def temporaries(root: Path) -> list[Path]:
    return [p for p in root.rglob(".*") if is_temporary(p.name)]


def touch(folder: Path, i: int) -> int:
    """Make ``folder/i`` and return ``i`` (a task that shows when it started)."""
    (Path(folder) / str(i)).touch()
    return i
