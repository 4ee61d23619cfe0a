"""Frames per hour of ``datagen build`` for each shipped scene at its defaults (issue 32).

    python bench/bench_fph.py [--scenes wingcam55 podcam15 ...] [--frames 48] [--workers 2]

Each scene is built as a user builds it (a subprocess: ``datagen build --config NAME
--frames N --workers W`` of the scene's config with ``approach.min_approaches`` and
``dataset.min_shards`` 1, as a full build takes its frames; shards of
``frames_per_approach`` frames so that every worker has work), after a warm-up build of
the same frames: Dr.Jit compiles its kernels once per machine and keeps them on disk
(after a process's first frame no frame compiles one: ``tests/test_render.py``), so the
timed build pays no compile; ``--workers auto`` is accepted as the build takes it;
``--traced`` turns ``render.frozen`` off.
Prints a markdown table: the estimate the build printed in its first line, the measured
frames/h of the build's own summary, its split of a rendered frame (``other``: the host
work outside ``mi.render`` and the denoiser) and the kernels its workers compiled after
their first frame (0 once warm).
"""

from __future__ import annotations

import argparse
import os
import platform
import re
import subprocess
import sys
import tempfile
from pathlib import Path

import yaml

from datagen.config.load import load_config, shipped_scenes


def full_build_config(name: str, folder: Path, traced: bool = False) -> Path:
    """The scene's config as a full build runs it however few frames the bench builds: chains
    of frames_per_approach frames and shards of the bench's size (approach.min_approaches and
    dataset.min_shards 1; a small build spreads its frames over more approaches, whose
    simulation costs more a frame). ``traced``: ``render.frozen`` off."""
    data = load_config(name).model_dump(mode="json")
    data["approach"]["min_approaches"] = 1
    data["dataset"]["min_shards"] = 1
    if traced:
        data["render"]["frozen"] = False
    path = folder / f"{name}.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def build(name: str, out: Path, frames: int, workers: int, shard: int) -> str:
    done = subprocess.run([sys.executable, "-m", "datagen", "build", "--config", name, "--out", str(out),
                           "--frames", str(frames), "--workers", str(workers), "--shard-size", str(shard)],
                          capture_output=True, text=True, check=True)
    return done.stdout + done.stderr


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", nargs="+", default=list(shipped_scenes()))
    parser.add_argument("--frames", type=int, default=48)
    parser.add_argument("--workers", default="2", help="a count, or auto (datagen.pipeline.estimate.auto_workers)")
    parser.add_argument("--traced", action="store_true", help="render.frozen off: the path tracing traced each frame")
    args = parser.parse_args()
    print(f"machine: {platform.machine()}, {os.cpu_count()} CPUs, Python {platform.python_version()}; "
          f"{args.frames} frames per scene, --workers {args.workers}{', traced' if args.traced else ''}")
    print("\n| scene | setting | estimate frames/h | measured frames/h | per rendered frame | kernels compiled after "
          "each worker's first frame |")
    print("|---|---|---|---|---|---|")
    for name in args.scenes:
        count = int(args.workers) if args.workers != "auto" else os.cpu_count() or 1  # shards enough for any count
        shard = max(1, min(load_config(name).approach.frames_per_approach, args.frames // max(1, count)))
        with tempfile.TemporaryDirectory() as tmp:
            config = str(full_build_config(name, Path(tmp), args.traced))
            build(config, Path(tmp) / "warm", args.frames, args.workers, shard)
            text = build(config, Path(tmp) / "ds", args.frames, args.workers, shard)
        estimate = re.search(r"estimate [0-9.]+ s a frame = ([0-9,]+) frames/h on \d+ cores \(([^)]*)\)", text)
        measured = re.search(r"this run: .* = ([0-9,]+) frames/h", text)
        split = re.search(r"per rendered frame: (.*)\n", text)
        compiled = re.search(r"kernels compiled after each worker's first frame: (\d+)", text)
        print(f"| {name} | {estimate.group(2)} | {estimate.group(1)} | {measured.group(1)} | {split.group(1)} | "
              f"{compiled.group(1)} |", flush=True)


if __name__ == "__main__":
    main()
