"""The rolling shutter and the video link, without rendering: how far a rolling shutter moves
each scene's labels against a global shutter of the same poses (labels-only builds), that
the reader recomputes them, and the host time of the image skew and of the H.264 round trip
at the scene's image size.

    python bench/bench_shutter.py [--scenes wingcam55 podcam15] [--frames 40] [--readout 0.02 0.03]

Prints a markdown table: per scene, the labels, the shift's median, p95 and maximum (px),
the largest difference of the recomputed labels from the written ones, and the mean time of
:func:`datagen.render.sensor.rolling_shutter` and :func:`~datagen.render.sensor.video_round_trip`
(CRF 27) on a synthetic frame of the scene's size (10 runs each after one warm-up).
"""

from __future__ import annotations

import argparse
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np


def _timed(fn, runs: int = 10) -> float:
    fn()
    start = time.perf_counter()
    for _ in range(runs):
        fn()
    return (time.perf_counter() - start) / runs


def scene_row(scene: str, frames: int, readout: tuple[float, float], work: Path) -> str:
    from datagen.config import load_config, override_config
    from datagen.core.camera import Intrinsics
    from datagen.dataset.reader import load_dataset
    from datagen.pipeline.build import build_dataset
    from datagen.render.sensor import MOTION_STRIDE, rolling_shutter, video_round_trip

    config = override_config(load_config(scene), {"dataset": {"frames": frames, "min_shards": 1}, "randomization": {
        "sensor": {"rolling_shutter": True, "readout_s": list(readout)}}})
    out = work / scene
    build_dataset(config, out, render=False, workers=1)
    view = load_dataset(out)
    labeled = view.labeled
    still = view.labelling.label_features(view.cam_from_objects())
    shift = np.hypot(*(still.center_px[labeled] - view.center_px[labeled]).T)
    recomputed = float(np.abs(view.recompute().center_px[labeled] - view.center_px[labeled]).max())
    c = config.camera
    k = Intrinsics.from_hfov_deg(c.width, c.height, c.hfov_deg)
    rng = np.random.default_rng(0)
    margin = 8
    rgb = rng.random((c.height + 2 * margin, c.width + 2 * margin, 3), dtype=np.float32)
    velocity = rng.normal(0.0, 200.0, (-(-rgb.shape[0] // MOTION_STRIDE), -(-rgb.shape[1] // MOTION_STRIDE), 2))
    skew = _timed(lambda: rolling_shutter({"rgb": rgb}, velocity.astype(np.float32), MOTION_STRIDE, 0.025, k, margin))
    srgb = (rgb[margin:-margin, margin:-margin] * 255).astype(np.uint8)
    video = _timed(lambda: video_round_trip(srgb, 27))
    return (f"| {scene} | {c.width}x{c.height} | {int(labeled.sum())} | {np.median(shift):.2f} | "
            f"{np.percentile(shift, 95):.2f} | {shift.max():.2f} | {recomputed:.1e} | {skew * 1e3:.0f} ms | "
            f"{video * 1e3:.0f} ms |")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", nargs="+", default=["wingcam55", "podcam15"])
    parser.add_argument("--frames", type=int, default=40)
    parser.add_argument("--readout", nargs=2, type=float, default=[0.02, 0.03])
    args = parser.parse_args()
    print("| scene | image | labels | shift median px | p95 | max | recomputed, max px | skew | H.264 round trip |")
    print("|---|---|---|---|---|---|---|---|---|")
    work = Path(tempfile.mkdtemp(prefix="bench-shutter-"))
    try:
        for scene in args.scenes:
            print(scene_row(scene, args.frames, tuple(args.readout), work), flush=True)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
