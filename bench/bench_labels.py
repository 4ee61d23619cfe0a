"""Label throughput: frames per second for 80 features of 16 points each, on one core.

    python bench/bench_labels.py [--seconds 3] [--batch 256]

Reports two figures:
  * per-frame: one ``compute_labels`` call (+ YOLO lines) per frame, as a
    renderer-driven build uses it;
  * batched: ``--batch`` frames per call (labels-only builds, audits).
Pinned to one CPU with ``os.sched_setaffinity`` and single-threaded BLAS.
"""

from __future__ import annotations

import argparse
import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import platform  # noqa: E402 (the thread variables are set before numpy loads)
import time  # noqa: E402

import numpy as np  # noqa: E402

from datagen import FeatureTable, Intrinsics, compute_labels, make_transform, rotation_from_ypr, yolo_lines  # noqa: E402


def scene(n_frames: int, seed: int = 0):
    rng = np.random.default_rng(seed)
    sets = [rng.uniform(-0.5, 0.5, size=(16, 3)) + rng.uniform(-6, 6, size=3) for _ in range(80)]
    table = FeatureTable.from_point_sets(sets, objects=["receiver"] * 40 + ["tanker"] * 40)
    ypr = rng.uniform(-0.3, 0.3, size=(n_frames, 2, 3))
    rot = rotation_from_ypr(ypr[..., 0], ypr[..., 1], ypr[..., 2])
    trans = np.stack([rng.uniform(-5, 5, (n_frames, 2)), rng.uniform(-3, 3, (n_frames, 2)),
                      rng.uniform(10, 120, (n_frames, 2))], axis=-1)
    return table, make_transform(rot, trans)


def rate(fn, n_frames: int, seconds: float) -> float:
    fn()  # warm up
    done, start = 0, time.perf_counter()
    while (elapsed := time.perf_counter() - start) < seconds:
        fn()
        done += n_frames
    return done / elapsed


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=3.0)
    parser.add_argument("--batch", type=int, default=256)
    args = parser.parse_args()
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})
    k = Intrinsics.from_hfov_deg(2048, 1080, 55.0)
    table, poses = scene(args.batch)

    i = 0

    def per_frame() -> None:
        nonlocal i
        labels = compute_labels(table, poses[i % args.batch], k)
        yolo_lines(labels, table.class_id, k.width, k.height)
        i += 1

    def labels_only() -> None:
        nonlocal i
        compute_labels(table, poses[i % args.batch], k)
        i += 1

    def batched() -> None:
        compute_labels(table, poses, k)

    labeled = compute_labels(table, poses, k).labeled.mean()
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, 1 core used; "
          f"numpy {np.__version__}; 80 features x 16 points; {labeled:.0%} labeled")
    print(f"per-frame compute_labels:              {rate(labels_only, 1, args.seconds):10.0f} frames/s")
    print(f"per-frame compute_labels + yolo_lines: {rate(per_frame, 1, args.seconds):10.0f} frames/s")
    print(f"batched ({args.batch} frames/call):             {rate(batched, args.batch, args.seconds):10.0f} frames/s")


if __name__ == "__main__":
    main()
