"""Approach simulation throughput: frame states per second, on one core.

    python bench/bench_approach.py [--config scenes/wingcam55.yaml] [--chains 20]

Each chain of ``frames_per_approach`` frames is simulated once from its start
(for 'distance' sampling: from the range's far end down to the nearest stratum),
as a worker does when it regenerates a shard's frames.
"""

from __future__ import annotations

import argparse
import os
import platform
import time

from datagen.config import load_config
from datagen.scene.approach import frame_states


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--config", default="scenes/wingcam55.yaml")
    parser.add_argument("--chains", type=int, default=20)
    args = parser.parse_args()
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})
    config = load_config(args.config)
    k = config.approach.frames_per_approach
    start = time.perf_counter()
    frame_states(config, range(args.chains * k))
    elapsed = time.perf_counter() - start
    print(f"machine: {platform.machine()}, {os.cpu_count()} CPUs, 1 core used")
    print(f"{args.config}: {args.chains} chains x {k} frames in {elapsed:.2f} s: "
          f"{args.chains * k / elapsed:.0f} frame states/s ({elapsed / args.chains * 1e3:.0f} ms per chain)")


if __name__ == "__main__":
    main()
