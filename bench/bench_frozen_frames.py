"""The renderer's own frozen frames against its traced frames, on any variant: the image and
the geometry pass's depth, object ids and surfaces, bit for bit, and the recordings made.

    python bench/bench_frozen_frames.py [--scenes wingcam55 podcam15 dashcam75]
        [--frames 0 1 5 13 29 40 57 70] [--size 96x51] [--variant llvm_ad_rgb]

Each scene renders its frames (every world randomizer and the camera model on, 1 spp, the
denoiser off, one thread) in a child process twice: as a build renders them
(:class:`~datagen.render.renderer.Renderer` with ``render.frozen`` on, the default: the path
tracing and the geometry pass's ray cast recorded once and replayed) and traced every
frame (``render.frozen: false``). The frames span approaches (7 frames each at the
defaults), so that a value a recording baked in shows as a difference. Prints a Markdown
table per scene: the frames whose four arrays are the same bytes, the first that is not,
the recordings of the render and of the cast, and the mean seconds a frame after the
first, frozen and traced. ``bench/bench_freeze.py`` asks the narrower question per world
randomizer with a ``dr.freeze`` of its own.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import platform
import subprocess
import sys
import time


def child(scene_name: str, frames: list[int], size: str, variant: str, frozen: bool) -> dict:
    """Per frame, the digests of the image, depth, ids and surfaces; the recordings; seconds."""
    import numpy as np

    from datagen.config import load_config, override_config
    from datagen.pipeline.frame import draw_frame
    from datagen.render.renderer import Renderer
    from datagen.render.runtime import set_threads, use_variant
    from datagen.scene.approach import FrameStates
    from datagen.scene.resolved import Scene

    use_variant(variant)
    set_threads(1)
    width, height = (int(v) for v in size.split("x"))
    config = override_config(load_config(scene_name), {
        "camera.width": width, "camera.height": height, "render.spp": 1, "render.denoise": "off",
        "render.variant": variant, "render.frozen": frozen})
    scene = Scene.resolve(config)
    states, renderer = FrameStates(config), Renderer(scene)
    digests, seconds = [], []
    for i in frames:
        draws = draw_frame(scene, states, i)
        start = time.perf_counter()
        out = renderer.render(draws.state, draws.look, draws.render_seed, geometry=True)
        seconds.append(time.perf_counter() - start)
        digests.append([hashlib.sha256(np.ascontiguousarray(a).tobytes()).hexdigest()
                        for a in (out.rgb, out.depth, out.object_id, out.surface)])
    return {"digests": digests, "recordings": [renderer.recordings, renderer.cast_recordings],
            "seconds": sum(seconds[1:]) / max(len(seconds) - 1, 1)}


def run(scene_name: str, frames: list[int], size: str, variant: str, frozen: bool) -> dict:
    job = json.dumps([scene_name, frames, size, variant, frozen])
    done = subprocess.run([sys.executable, __file__, "--child", job], capture_output=True, text=True, timeout=1800,
                          check=False)
    if done.returncode != 0:
        raise SystemExit(f"{scene_name} ({'frozen' if frozen else 'traced'}): {done.stderr.strip()[-2000:]}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", nargs="+", default=["wingcam55", "podcam15", "dashcam75"])
    parser.add_argument("--frames", type=int, nargs="+", default=[0, 1, 5, 13, 29, 40, 57, 70])
    parser.add_argument("--size", default="96x51")
    parser.add_argument("--variant", default="llvm_ad_rgb")
    parser.add_argument("--child", default=None, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child is not None:
        print(json.dumps(child(*json.loads(args.child))))
        return
    print(f"machine: {platform.machine()}, variant {args.variant}, {args.size}, 1 spp, frames {args.frames}\n")
    print("| scene | frames the same bytes (image, depth, ids, surfaces) | first differing | "
          "recordings (render, cast) | s a frame frozen | traced |")
    print("|---|---|---|---|---|---|")
    for name in args.scenes:
        frozen = run(name, args.frames, args.size, args.variant, True)
        traced = run(name, args.frames, args.size, args.variant, False)
        same = [a == b for a, b in zip(frozen["digests"], traced["digests"], strict=True)]
        first = next((f"#{i}" for i, s in zip(args.frames, same, strict=True) if not s), "none")
        print(f"| {name} | {sum(same)} of {len(same)} | {first} | {tuple(frozen['recordings'])} | "
              f"{frozen['seconds']:.3f} | {traced['seconds']:.3f} |", flush=True)


if __name__ == "__main__":
    main()
