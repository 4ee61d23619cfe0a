"""Declared versions are tested versions: with the lowest pyarrow pyproject.toml declares
(installed beside the venv's by scripts/install.sh), a labels-only build, its audit and a
read with pandas and polars work, and a manifest written by either pyarrow is read by the
other."""

from __future__ import annotations

import os
import runpy
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
FLOOR = runpy.run_path(str(ROOT / "scripts" / "declared_floor.py"))["floor"]("pyarrow")
FLOOR_PATH = ROOT / ".venv" / "floor" / f"pyarrow-{FLOOR}"


def run(code: str, *, floor: bool) -> str:
    """``code`` in a fresh interpreter, with the floor pyarrow first on the path or not."""
    env = dict(os.environ)
    if floor:
        env["PYTHONPATH"] = os.pathsep.join([str(FLOOR_PATH), env.get("PYTHONPATH", "")]).rstrip(os.pathsep)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=600, cwd=ROOT)
    assert out.returncode == 0, out.stderr[-3000:]
    return out.stdout


def build_and_audit(root: Path) -> str:
    return f"""
import pyarrow, sys
from datagen.config import load_config, override_config
from datagen.pipeline.run import build_dataset
from datagen.dataset.reader import open_dataset
from datagen.analysis.audit import audit
cfg = override_config(load_config("wingcam55"), {{"dataset.frames": 12, "dataset.shard_size": 4}})
build_dataset(cfg, {str(root)!r}, render=False)
result = audit(open_dataset({str(root)!r}))
assert result.passed, [c.name for c in result.checks if not c.passed]
print(pyarrow.__version__)
"""


def read_everywhere(root: Path) -> str:
    return f"""
import pandas, polars, pyarrow
from datagen.analysis.audit import audit
from datagen.dataset.reader import open_dataset
assert audit(open_dataset({str(root)!r})).passed
frame = pandas.read_parquet({str(root / "manifests")!r})
assert len(frame) == 12 and frame["sensor_distortion"].isna().all()
assert polars.read_parquet({str(root / "manifests" / "*.parquet")!r}).height == 12
print(pyarrow.__version__)
"""


def test_the_lowest_declared_pyarrow_is_installed_beside_the_venvs() -> None:
    assert (FLOOR_PATH / ".complete").is_file(), f"{FLOOR_PATH}: run scripts/install.sh"
    assert run("import pyarrow; print(pyarrow.__version__)", floor=True).strip() == FLOOR


def test_a_manifest_written_by_one_supported_pyarrow_is_read_by_the_other(tmp_path) -> None:
    low, new = tmp_path / "low", tmp_path / "new"
    assert run(build_and_audit(low), floor=True).strip() == FLOOR
    current = run(build_and_audit(new), floor=False).strip()
    assert current != FLOOR
    assert run(read_everywhere(low), floor=False).strip() == current
    assert run(read_everywhere(new), floor=True).strip() == FLOOR
    for rel in sorted(p.relative_to(low) for p in (low / "labels").rglob("*.txt")):
        assert (low / rel).read_bytes() == (new / rel).read_bytes(), rel
