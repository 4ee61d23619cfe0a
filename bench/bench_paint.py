"""What the aircraft's paint costs a frame: frames of the shipped scenes made as a build makes
them (every randomizer on, the camera model included), with the liveries on and off, timed
back to back in one process and one thread after warm-up renders that compile the kernels.

    python bench/bench_paint.py [--frames wingcam55:14 podcam15:22 dashcam75:12] [--scale 0.5] [--repeats 3]

Prints per frame the whole frame's seconds (median of ``--repeats``) with and without the
liveries, their ratio, and ``mi.render``'s share; then the mean ratio. Run it on two
checkouts (``PYTHONPATH=<checkout>``) to compare what two versions of the paint cost.
"""

from __future__ import annotations

import argparse
import os
import platform
import tempfile
from pathlib import Path

import numpy as np

from datagen.config import load_config, override_config
from datagen.pipeline.frame import draw_frame
from datagen.pipeline.writer import timed_frame
from datagen.render.renderer import Renderer
from datagen.render.runtime import set_threads, use_variant
from datagen.render.timing import PATH_TRACING
from datagen.scene.approach import FrameStates
from datagen.scene.resolved import Scene


def timed(config, frame: int, repeats: int, tmp: Path) -> tuple[float, float]:
    """Median seconds of ``frame`` whole and in ``mi.render``, after two untimed renders."""
    scene = Scene.resolve(config)
    renderer = Renderer(scene)
    warm = draw_frame(scene, FrameStates(config), frame)
    for _ in range(2):
        renderer.render(warm.state, warm.look, warm.render_seed)
    runs = [timed_frame(scene, renderer, FrameStates(config), frame, tmp / "frame.png") for _ in range(repeats)]
    return float(np.median([w for w, _ in runs])), float(np.median([c.get(PATH_TRACING, 0.0) for _, c in runs]))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", nargs="+", default=["wingcam55:14", "podcam15:22", "dashcam75:12"])
    parser.add_argument("--scale", type=float, default=0.5)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    use_variant("llvm_ad_rgb")
    set_threads(1)
    print(f"machine: {platform.machine()}, {os.cpu_count()} CPUs, one thread; scale {args.scale}")
    print("| frame | livery on s | livery off s | ratio | mi.render on / off s |")
    print("|---|---|---|---|---|")
    ratios = []
    with tempfile.TemporaryDirectory() as tmp:
        for item in args.frames:
            name, i = item.split(":")
            base = load_config(name)
            size = {"camera.width": round(base.camera.width * args.scale),
                    "camera.height": round(base.camera.height * args.scale)}
            on = timed(override_config(base, size), int(i), args.repeats, Path(tmp))
            off = timed(override_config(base, {**size, "randomization.livery.enabled": False}), int(i),
                        args.repeats, Path(tmp))
            ratios.append(on[0] / off[0])
            print(f"| {item} | {on[0]:.2f} | {off[0]:.2f} | {on[0] / off[0]:.2f} | {on[1]:.2f} / {off[1]:.2f} |",
                  flush=True)
    print(f"mean ratio {np.mean(ratios):.2f}")


if __name__ == "__main__":
    main()
