"""Declared versions are tested versions: in ``.venv/floor`` (scripts/install.sh), every
dependency at the lowest series pyproject.toml declares (scripts/declared_floor.py), a
labels-only build, its audit and a read with pandas and polars work, and a manifest written
by either environment's pyarrow is read by the other's."""

from __future__ import annotations

import json
import os
import runpy
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DECLARED = runpy.run_path(str(ROOT / "scripts" / "declared_floor.py"))
FLOOR_PYTHON = ROOT / ".venv" / "floor" / "bin" / "python"


def run(code: str, *, floor: bool) -> str:
    """``code`` in a fresh interpreter of the floor environment, or of this one."""
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    python = str(FLOOR_PYTHON) if floor else sys.executable
    out = subprocess.run([python, "-c", code], capture_output=True, text=True, env=env, timeout=600, cwd=ROOT)
    assert out.returncode == 0, out.stderr[-3000:]
    return out.stdout


def build_and_audit(root: Path) -> str:
    return f"""
import pyarrow
from datagen.config import load_config, override_config
from datagen.pipeline.build import build_dataset
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


def test_the_floor_environment_holds_every_declared_lowest_series() -> None:
    assert FLOOR_PYTHON.is_file(), f"{FLOOR_PYTHON}: run scripts/install.sh"
    lines = DECLARED["constraints"]().split()
    names = [line.split("==")[0] for line in lines]
    installed = json.loads(run(f"import json, importlib.metadata as m\n"
                               f"print(json.dumps({{n: m.version(n) for n in {names!r}}}))", floor=True))
    for line in lines:
        name, series = line.split("==")
        assert installed[name] == series or (series.endswith(".*") and installed[name].startswith(series[:-1])), \
            (name, installed[name], series)
    assert installed["pyarrow"] == DECLARED["floor"]("pyarrow")


def test_a_manifest_written_by_one_supported_pyarrow_is_read_by_the_other(tmp_path) -> None:
    low, new = tmp_path / "low", tmp_path / "new"
    floor = run(build_and_audit(low), floor=True).strip()
    current = run(build_and_audit(new), floor=False).strip()
    assert floor == DECLARED["floor"]("pyarrow") != current
    assert run(read_everywhere(low), floor=False).strip() == current
    assert run(read_everywhere(new), floor=True).strip() == floor
    for rel in sorted(p.relative_to(low) for p in (low / "labels").rglob("*.txt")):
        assert (low / rel).read_bytes() == (new / rel).read_bytes(), rel


def test_the_command_line_works_with_the_lowest_declared_typer(tmp_path) -> None:
    cli = [str(FLOOR_PYTHON), "-m", "datagen"]
    scenes = subprocess.run([*cli, "scenes"], capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert scenes.returncode == 0 and "wingcam55" in scenes.stdout, scenes.stdout + scenes.stderr
    bad = subprocess.run([*cli, "evaluate", str(tmp_path), "--conf", "nan"], capture_output=True, text=True,
                         timeout=120, cwd=ROOT)
    assert bad.returncode == 2 and bad.stderr.count("\n") == 1 and "--conf" in bad.stderr, bad.stderr
