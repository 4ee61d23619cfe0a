"""Peak memory and time of every reading command on a dataset folder and on hostile copies of it.

    python bench/bench_hostile.py [--frames 40] [--out /tmp/bench-hostile]

Builds a labels-only wingcam55 dataset of ``--frames`` frames and a rendered 128x68 one of
8 frames with EXR (as a user does, in subprocesses), then runs ``audit``, ``evaluate``,
``preview`` and ``export`` on each untouched and on copies carrying the bombs the readers
bound (``datagen/dataset/limits.py``): a 2 GiB sparse label file, a 256 MiB sparse
prediction file, a manifest of 100,000 copies of one row, a ``distance_m`` of 1e8, an EXR
declaring 16000x16000. For each run: exit status, wall seconds and the command's own peak
resident memory (``VmHWM``, read every 20 ms), and the largest peak of the hostile runs
beside that of the untouched dataset: the bad-input page's ceilings.
"""

from __future__ import annotations

import argparse
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

TINY = ("name: tiny\ncamera: {mount: wingcam, hfov_deg: 55.0, width: 128, height: 68}\n"
        "render: {spp: 1, max_depth: 2}\nlabels: {edge_margin_px: 2.0}\napproach: {frames_per_approach: 4}\n"
        "dataset: {frames: 8, shard_size: 3, min_shards: 1, seed: 7}\n")


def run(*args: str, cwd: Path | None = None) -> tuple[int, float, float]:
    """``datagen ARGS``: exit status, wall seconds, peak resident MiB of the command itself."""
    start, peak = time.perf_counter(), 0.0
    proc = subprocess.Popen([sys.executable, "-m", "datagen", *args], cwd=cwd, stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL)
    while proc.poll() is None:
        try:
            found = re.search(r"^VmHWM:\s+(\d+) kB", Path(f"/proc/{proc.pid}/status").read_text(), re.MULTILINE)
            peak = max(peak, int(found.group(1)) / 1024 if found else 0.0)
        except OSError:
            pass
        time.sleep(0.02)
    return proc.returncode, time.perf_counter() - start, peak


def set_distance(root: Path, value: float) -> None:
    import pyarrow as pa
    import pyarrow.parquet as pq

    path = sorted((root / "manifests").glob("train-*.parquet"))[0]
    table = pq.read_table(path)
    values = table.column("distance_m").to_pylist()
    values[0] = value
    index = table.schema.get_field_index("distance_m")
    pq.write_table(table.set_column(index, table.schema.field(index), pa.array(values))
                   .replace_schema_metadata(table.schema.metadata), path)


def duplicate_rows(root: Path) -> None:
    import pyarrow as pa
    import pyarrow.parquet as pq

    path = sorted((root / "manifests").glob("train-*.parquet"))[0]
    table = pq.read_table(path)
    pq.write_table(pa.concat_tables([table.slice(0, 1)] * 100_000).replace_schema_metadata(table.schema.metadata),
                   path, compression="zstd")


def sparse(path: Path, size: int) -> None:
    with path.open("wb") as f:
        f.truncate(size)


def huge_exr(root: Path) -> Path:
    """An EXR of the dataset whose header declares 16000x16000 (its data window patched: a
    decoder that trusts it allocates 5 GB before it finds the pixels missing)."""
    import struct

    exr = next((root / "exr").rglob("*.exr"))
    data = bytearray(exr.read_bytes())
    for name in (b"dataWindow", b"displayWindow"):
        at = data.index(name + b"\x00box2i\x00") + len(name) + len(b"\x00box2i\x00") + 4
        data[at:at + 16] = struct.pack("<4i", 0, 0, 15999, 15999)
    exr.write_bytes(bytes(data))
    return exr


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=40)
    parser.add_argument("--out", type=Path, default=None)
    args = parser.parse_args()
    work = args.out or Path(tempfile.mkdtemp(prefix="bench-hostile-"))
    work.mkdir(parents=True, exist_ok=True)
    (work / "tiny.yaml").write_text(TINY)
    bases = {"labels-only": work / "labels", "rendered": work / "rendered"}
    if not bases["labels-only"].exists():
        run("build", "--config", "wingcam55", "--frames", str(args.frames), "--no-render", "--out",
            str(bases["labels-only"]))
    if not bases["rendered"].exists():
        run("build", "--config", str(work / "tiny.yaml"), "--out", str(bases["rendered"]), "--exr")

    def prediction_bomb(ds: Path) -> None:
        folder = ds.parent / "pred"
        folder.mkdir(exist_ok=True)
        sparse(folder / f"{Path((ds / 'val.txt').read_text().split()[0]).stem}.txt", 256 * 2**20)

    tampers = {"untouched": None,
               "2 GiB sparse label file": lambda ds: sparse(next((ds / "labels").rglob("*.txt")), 2 * 2**30),
               "100,000 copies of a manifest row": duplicate_rows,
               "distance_m 1e8": lambda ds: set_distance(ds, 1e8)}
    readers = {"audit": ["audit"], "evaluate": ["evaluate", "--noise-px", "0,1"], "preview": ["preview"],
               "export": ["export", "--format", "coco", "--out", "{x}"]}
    runs = [(base, case, tamper, command, argv) for base in bases for case, tamper in tampers.items()
            for command, argv in readers.items() if not (command == "export" and base == "labels-only")]
    runs += [("rendered", "256 MiB sparse prediction file", prediction_bomb, "evaluate",
              ["evaluate", "--predictions", "{pred}"]),
             ("rendered", "EXR declaring 16000x16000", huge_exr, "export",
              ["export", "--format", "bop", "--out", "{x}"])]
    peaks: dict[str, dict[str, float]] = {}
    print(f"machine: {os.cpu_count()} cores; {work}")
    print(f"{'dataset':12} {'case':34} {'command':9} {'exit':>4} {'s':>6} {'peak MiB':>9}")
    for n, (base, case, tamper, command, argv) in enumerate(runs):
        copy = work / "runs" / str(n)
        shutil.rmtree(copy, ignore_errors=True)
        shutil.copytree(bases[base], copy / "ds", symlinks=True)
        if tamper is not None:
            tamper(copy / "ds")
        argv = [a.format(x=copy / "x", pred=copy / "pred") for a in argv]
        code, wall, peak = run(argv[0], str(copy / "ds"), *argv[1:])
        peaks.setdefault(f"{base} {command}", {})[case] = peak
        print(f"{base:12} {case:34} {command:9} {code:>4} {wall:6.1f} {peak:9.0f}")
        shutil.rmtree(copy, ignore_errors=True)
    print("\nthe largest peak of the hostile runs beside the untouched dataset's:")
    for key, by_case in peaks.items():
        hostile = max((v for c, v in by_case.items() if c != "untouched"), default=0.0)
        print(f"  {key:22} untouched {by_case.get('untouched', 0):6.0f} MiB, hostile at most {hostile:6.0f} MiB")


if __name__ == "__main__":
    main()
