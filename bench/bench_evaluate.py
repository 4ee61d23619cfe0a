"""Labels-only builds and ``datagen evaluate`` (issue 8).

    python bench/bench_evaluate.py [--config scenes/wingcam55.yaml] [--build-frames 100000]
                                   [--eval-frames 16000] [--workers 2]

1. ``datagen build --no-render`` of ``--build-frames`` frames (a subprocess, as a user
   runs it): wall time and frames/s.
2. ``evaluate`` on one core (this process pinned to CPU 0) over a labels-only build
   of ``--eval-frames`` frames with 1 px of noise: frames/s, two PnP solves each
   (target: at least 500 frames/s with 80 features per frame).
3. The noise table of the README: PtD error at contact (< 0.5 m) and at 20, 50 and
   120 m (+-2.5 m) for 0, 0.5, 1 and 2.5 px of noise.
"""

from __future__ import annotations

import argparse
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def build(config: str, out: Path, frames: int, workers: int) -> float:
    start = time.perf_counter()
    subprocess.run([sys.executable, "-m", "datagen", "build", "--config", config, "--out", str(out), "--frames",
                    str(frames), "--no-render", "--workers", str(workers), "--shard-size", "2000"],
                   check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    return time.perf_counter() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--config", default="scenes/wingcam55.yaml")
    parser.add_argument("--build-frames", type=int, default=100_000)
    parser.add_argument("--eval-frames", type=int, default=16_000)
    parser.add_argument("--workers", type=int, default=2)
    args = parser.parse_args()
    print(f"machine: {platform.machine()}, {os.cpu_count()} CPUs, Python {platform.python_version()}; {args.config}")
    with tempfile.TemporaryDirectory() as tmp:
        if args.build_frames:
            wall = build(args.config, Path(tmp) / "big", args.build_frames, args.workers)
            print(f"datagen build --no-render --workers {args.workers}: {args.build_frames} frames in {wall:.1f} s "
                  f"= {args.build_frames / wall:.0f} frames/s")
        wall = build(args.config, Path(tmp) / "eval", args.eval_frames, args.workers)
        print(f"(evaluation dataset: {args.eval_frames} frames built in {wall:.1f} s)")
        os.sched_setaffinity(0, {0})
        from datagen.analysis.evaluate import evaluate, summarize
        from datagen.dataset.reader import load_dataset

        view = load_dataset(Path(tmp) / "eval")
        start = time.perf_counter()
        evaluate(view, noise_px=1.0, run=9)
        elapsed = time.perf_counter() - start
        print(f"evaluate, one core, {len(view.features)} features per frame, 1 px noise: {len(view) / elapsed:.0f} "
              f"frames/s ({1e3 * elapsed / len(view):.2f} ms per frame)")
        print("noise table (mean PtD error +- 2 sigma, successes):")
        print("| noise | contact (< 0.5 m) | 20 m | 50 m | 120 m | reliability |")
        for run, radius in enumerate((0.0, 0.5, 1.0, 2.5)):
            s = summarize(evaluate(view, noise_px=radius, run=run))

            def cell(at) -> str:  # an ErrorStats
                if at.mean_m is None or at.std_m is None:
                    return "-"
                return f"{100 * at.mean_m:.2f} cm +- {200 * at.std_m:.2f} (n={at.successes})"

            print(f"| {radius:g} px | {cell(s.at['contact'])} | {cell(s.at['20m'])} | {cell(s.at['50m'])} | "
                  f"{cell(s.at['120m'])} | {100 * (s.overall.reliability or 0.0):.1f}% |")


if __name__ == "__main__":
    main()
