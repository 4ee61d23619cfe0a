"""Approach simulation throughput: frame states per second, on one core.

    python bench/bench_approach.py [--config scenes/wingcam55.yaml] [--chains 40]

Each chain of ``frames_per_approach`` frames is simulated once from its start
(for 'distance' sampling: from the range's far end down to the nearest stratum),
as a worker does when it regenerates a shard's frames: approach model 1 a chain at
a time, model 2 a chain at a time, and model 2's chains together as a shard writer
prefetches them (``FrameStates.prefetch``). Frame states are made for every frame.
"""

from __future__ import annotations

import argparse
import os
import platform
import time

from datagen.config import load_config, override_config
from datagen.scene.approach import FrameStates, frame_states


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--config", default="scenes/wingcam55.yaml")
    parser.add_argument("--chains", type=int, default=40)
    args = parser.parse_args()
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})
    print(f"machine: {platform.machine()}, {os.cpu_count()} CPUs, 1 core used")
    for model, together in ((1, False), (2, False), (2, True)):
        config = override_config(load_config(args.config), {"approach.model": model})
        k = config.approach.frames_per_approach
        frames = range(args.chains * k)
        start = time.perf_counter()
        if together:
            states = FrameStates(config)
            states.prefetch(frames)
            [states(i) for i in frames]
        else:
            frame_states(config, frames)
        elapsed = time.perf_counter() - start
        how = "chains together" if together else "a chain at a time"
        print(f"{args.config}, approach model {model}, {how}: {args.chains} chains x {k} frames in {elapsed:.2f} s: "
              f"{args.chains * k / elapsed:.0f} frame states/s ({elapsed / args.chains * 1e3:.1f} ms per chain)")


if __name__ == "__main__":
    main()
