"""Datasets at the size people train on (issue 20): build, audit and evaluate of labels-only
datasets of growing size, each as a user runs it (a subprocess), with wall time, frames per
second and peak RSS (the largest resident set of any one process of the command, from
``getrusage`` in a wrapper process of its own).

    python bench/bench_scale.py [--sizes 10000,100000] [--config scenes/wingcam55.yaml]
                                [--workers 2] [--noise-px 0,1]

``--workers`` is given to all three commands.

Prints one Markdown table row per (size, command) and the ratio of the time per frame at
each size to that at the smallest (linear time: about 1).
"""

from __future__ import annotations

import argparse
import os
import platform
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

#: Runs a command and prints the largest resident set any process of it reached (KiB): a
#: fresh wrapper per command, so that one command's peak never hides another's.
_WRAPPER = ("import resource, subprocess, sys; done = subprocess.run(sys.argv[1:], stdout=subprocess.DEVNULL, "
            "stderr=subprocess.PIPE, text=True); sys.stderr.write(done.stderr[-500:]); "
            "print(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss, done.returncode)")


def run(args: list[str]) -> tuple[float, float, int]:
    """Wall seconds, peak RSS (MiB) of the largest process of the command, exit status."""
    start = time.perf_counter()
    done = subprocess.run([sys.executable, "-c", _WRAPPER, sys.executable, "-m", "datagen", *args],
                          capture_output=True, text=True, check=True)
    wall = time.perf_counter() - start
    peak_kib, code = (int(v) for v in done.stdout.split())
    if code not in (0, 1):  # audit exits 1 when a check fails: still a measurement
        raise SystemExit(f"{' '.join(args)}: exit {code}: {done.stderr.strip()}")
    return wall, peak_kib / 1024.0, code


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", default="10000,100000")
    parser.add_argument("--config", default="scenes/wingcam55.yaml")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--noise-px", default="0,1")
    args = parser.parse_args()
    sizes = [int(s) for s in args.sizes.split(",")]
    print(f"# {platform.node()}, {os.cpu_count()} cores, Python {platform.python_version()}; {args.config}, "
          f"--workers {args.workers}")
    print("| frames | command | wall s | frames/s | peak RSS MiB | s per 1,000 frames vs smallest |")
    print("|---|---|---|---|---|---|")
    per_frame: dict[str, float] = {}
    with tempfile.TemporaryDirectory() as tmp:
        for n in sorted(sizes):
            root = Path(tmp) / f"d{n}"
            commands = {
                "build --no-render": ["build", "--config", args.config, "--out", str(root), "--frames", str(n),
                                      "--no-render", "--workers", str(args.workers)],
                "audit": ["audit", str(root), "--overlays", "0", "--workers", str(args.workers)],
                f"evaluate --noise-px {args.noise_px}": ["evaluate", str(root), "--noise-px", args.noise_px,
                                                         "--workers", str(args.workers)],
            }
            for name, command in commands.items():
                wall, rss, _ = run(command)
                rate = n / wall
                ratio = ""
                key = name.split()[0]
                if key not in per_frame:
                    per_frame[key] = wall / n
                else:
                    ratio = f"{(wall / n) / per_frame[key]:.2f}x"
                print(f"| {n:,} | `datagen {name}` | {wall:.1f} | {rate:,.0f} | {rss:,.0f} | {ratio} |", flush=True)
            shutil.rmtree(root)


if __name__ == "__main__":
    main()
