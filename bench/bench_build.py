"""Throughput and memory of ``datagen build`` (issue 6).

    python bench/bench_build.py [--config scenes/wingcam55.yaml] [--frames 12] [--spp 16]
                                [--rss-frames 500] [--rss-spp 1] [--skip-rss]

1. Pure render: the same frames' ``mi.render`` time alone, in one process with
   every core (scene posed through ``mi.traverse``; nothing else is timed).
2. ``datagen build`` of those frames at the config's resolution, as a user runs
   it (a subprocess: start-up, scene loading, labels, visibility, PNG, manifests
   included), with 1 worker (both cores) and with 2 workers (one core each):
   wall time, frames/hour and the ratio to pure render (target: <= 1.10).
3. Memory: a ``--rss-frames`` build with 2 workers at ``--rss-spp``; every
   manifest row records its worker's RSS after the frame, so per worker: RSS
   after its 10th frame, after its last, and the slope over its second half
   (MiB per 100 frames). Flat means no growth with frames.

Dr.Jit caches compiled kernels in ``~/.drjit``; the sky scales take 25
combinations, each compiled once per machine and resolution. Run the benchmark
twice and take the second run: the first one on a machine pays those compiles
(in whichever step meets a combination first).
"""

from __future__ import annotations

import argparse
import os
import platform
import subprocess
import sys
import tempfile
import time
from collections import defaultdict
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq

from datagen.config import load_config, override_config
from datagen.pipeline.frame import draw_frame
from datagen.render.renderer import Renderer
from datagen.scene.approach import FrameStates
from datagen.scene.resolved import Scene


def pure_render_s(config, frames: int) -> float:
    import mitsuba as mi

    scene = Scene.resolve(config)
    renderer, states = Renderer(scene), FrameStates(config)
    total = 0.0
    for i in range(frames):
        draws = draw_frame(scene, states, i)
        renderer.pose(draws.state, draws.look)
        start = time.perf_counter()
        image = mi.render(renderer.scene, seed=draws.render_seed, spp=renderer.spp)
        np.array(image)  # make sure the kernel ran
        total += time.perf_counter() - start
    return total


def build(config_path: str, out: Path, frames: int, spp: int, workers: int, shard_size: int) -> float:
    args = [sys.executable, "-m", "datagen", "build", "--config", config_path, "--out", str(out),
            "--frames", str(frames), "--spp", str(spp), "--workers", str(workers),
            "--shard-size", str(shard_size)]
    start = time.perf_counter()
    subprocess.run(args, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    return time.perf_counter() - start


def rows(out: Path) -> list[dict]:
    return [r for p in sorted((out / "manifests").glob("*.parquet"))
            for r in pq.read_table(p, columns=["frame_id", "split", "shard", "worker", "worker_rss_mib",
                                                "render_s"]).to_pylist()]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--config", default="scenes/wingcam55.yaml")
    parser.add_argument("--frames", type=int, default=12)
    parser.add_argument("--spp", type=int, default=16)
    parser.add_argument("--rss-frames", type=int, default=500)
    parser.add_argument("--rss-spp", type=int, default=1)
    parser.add_argument("--skip-rss", action="store_true")
    args = parser.parse_args()
    config = override_config(load_config(args.config), {"render.spp": args.spp, "dataset.frames": args.frames})
    n = args.frames
    print(f"machine: {platform.machine()}, {os.cpu_count()} CPUs, {platform.python_version()}; "
          f"{args.config} at {config.camera.width}x{config.camera.height}, {args.spp} spp, {n} frames")
    pure = pure_render_s(config, n)
    print(f"pure mi.render: {pure:7.1f} s = {pure / n:5.2f} s/frame = {3600 * n / pure:6.0f} frames/h")
    with tempfile.TemporaryDirectory() as tmp:
        for workers in (1, 2):
            out = Path(tmp) / f"w{workers}"
            wall = build(args.config, out, n, args.spp, workers, max(1, n // 12))  # shards to balance 2 workers
            inside = sum(r["render_s"] or 0.0 for r in rows(out))
            print(f"datagen build --workers {workers}: {wall:7.1f} s = {3600 * n / wall:6.0f} frames/h, "
                  f"{wall / pure:4.2f}x pure render (mi.render inside the build: {inside:6.1f} s summed "
                  f"over workers)")
        if args.skip_rss:
            return
        out = Path(tmp) / "rss"
        m = args.rss_frames
        wall = build(args.config, out, m, args.rss_spp, 2, 50)
        per_worker = defaultdict(list)
        # A worker takes shards in submission order (train shards, then val) and renders a
        # shard's frames in frame order: this sort is each worker's own time order.
        for r in sorted(rows(out), key=lambda r: (r["split"] != "train", r["shard"], r["frame_id"])):
            per_worker[r["worker"]].append(r["worker_rss_mib"])
        print(f"memory: {m} frames at {args.rss_spp} spp, 2 workers, {wall:.0f} s")
        for worker, rss in per_worker.items():
            rss = np.array(rss)
            half = rss[len(rss) // 2:]
            slope = np.polyfit(np.arange(len(half)), half, 1)[0] * 100 if len(half) > 2 else float("nan")
            print(f"  worker {worker}: {len(rss)} frames, RSS after 10th {rss[min(9, len(rss) - 1)]:6.0f} MiB, "
                  f"after last {rss[-1]:6.0f} MiB, peak {rss.max():6.0f} MiB, "
                  f"second-half slope {slope:+5.1f} MiB/100 frames")


if __name__ == "__main__":
    main()
