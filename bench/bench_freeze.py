"""Can the frame's render be recorded once and replayed (``dr.freeze``)? Per world randomizer.

    python bench/bench_freeze.py [--config wingcam55] [--frames 0 1 2 3 7 14 21] [--size 64x34]
        [--variant llvm_ad_rgb]

For each setting (every world randomizer off; each one on alone; every one on), a child
process poses the scene as a build does (``Renderer.pose`` and the air, the frozen render's
settling included: :mod:`datagen.render.frozen`) for each frame, then renders it twice at
1 spp: ``mi.render`` traced, and through a ``dr.freeze`` of its own (the first frames record,
the later ones replay), both with the render seed as an opaque ``mi.UInt32`` so that the two
trace the same kernel. The frames span approaches (7 frames each at the defaults), so a
per-frame or per-approach value baked into a recording shows as a difference.

Prints a Markdown table per setting: frames bit-identical to the traced render, the largest
difference, the recordings made, and the mean seconds a frame traced and replayed (the
frames after the recordings). A setting whose recording fails (a Python plugin that uploads
data inside the render, say: ``enqueue_host_func ... cannot be recorded``) shows the error.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import time


def child(config_name: str, overrides: dict, frames: list[int], size: str, variant: str) -> None:
    """One setting in this process: a JSON line per frame."""
    import drjit as dr
    import mitsuba as mi
    import numpy as np

    from datagen.config import load_config, override_config
    from datagen.pipeline.frame import draw_frame
    from datagen.render.renderer import Renderer
    from datagen.render.runtime import set_threads, use_variant
    from datagen.scene.approach import FrameStates
    from datagen.scene.resolved import Scene

    use_variant(variant)
    set_threads(1)
    width, height = (int(v) for v in size.lower().split("x"))
    config = override_config(load_config(config_name), {"camera.width": width, "camera.height": height,
                                                        "render.spp": 1, "render.denoise": "off", **overrides})
    scene = Scene.resolve(config)
    states, renderer = FrameStates(config), Renderer(scene)

    def render(s, seed, textures=()):  # textures: their device values, the frozen render's inputs (Renderer.trace)
        return mi.render(s, seed=seed, spp=1)

    frozen = dr.freeze(render)
    for i in frames:
        draws = draw_frame(scene, states, i)
        renderer.pose(draws.state, draws.look)
        if renderer.aerial is not None:
            renderer._set_air(draws.state, draws.look)
        seed = dr.opaque(mi.UInt32, draws.render_seed)
        start = time.perf_counter()
        traced = np.array(render(renderer.scene, seed))
        traced_s = time.perf_counter() - start
        recordings = frozen.n_recordings
        start = time.perf_counter()
        textures = tuple(t.inputs() for t in renderer._textures())
        replayed = np.array(frozen(renderer.scene, seed, textures))
        frozen_s = time.perf_counter() - start
        print(json.dumps({"frame": i, "equal": bool(np.array_equal(traced, replayed)),
                          "diff": float(np.abs(traced - replayed).max()), "traced_s": traced_s,
                          "frozen_s": frozen_s, "recorded": frozen.n_recordings > recordings,
                          "recordings": frozen.n_recordings}), flush=True)


def settings() -> dict[str, dict]:
    from datagen.config.schema import WORLD_RANDOMIZERS, world_off

    out = {"every world randomizer off": world_off()}
    for name in WORLD_RANDOMIZERS:
        out[f"{name} only"] = world_off(*(n for n in WORLD_RANDOMIZERS if n != name))
    out["every one on"] = {}
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--config", default="wingcam55")
    parser.add_argument("--frames", type=int, nargs="+", default=[0, 1, 2, 3, 7, 14, 21])
    parser.add_argument("--size", default="64x34")
    parser.add_argument("--variant", default="llvm_ad_rgb")
    parser.add_argument("--child", default=None, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child is not None:
        child(args.config, json.loads(args.child), args.frames, args.size, args.variant)
        return
    print(f"machine: {platform.machine()}, {os.cpu_count()} CPUs; {args.config} at {args.size}, 1 spp, "
          f"{args.variant}, one thread; frames {' '.join(map(str, args.frames))}")
    print("| setting | frames identical | largest difference | recordings | traced s/frame | replayed s/frame |")
    print("|---|---|---|---|---|---|")
    for name, overrides in settings().items():
        done = subprocess.run([sys.executable, __file__, "--config", args.config, "--size", args.size,
                               "--variant", args.variant, "--frames", *map(str, args.frames),
                               "--child", json.dumps(overrides)], capture_output=True, text=True)
        rows = [json.loads(line) for line in done.stdout.splitlines() if line.startswith("{")]
        if done.returncode != 0 or len(rows) < len(args.frames):
            error = next((line.strip() for line in done.stderr.splitlines() if "what()" in line or "Error" in line),
                         f"exit {done.returncode}")
            print(f"| {name} | failed after {len(rows)} frames: {error} | | | | |", flush=True)
            continue
        replays = [r for r in rows if not r["recorded"]]
        traced = sum(r["traced_s"] for r in replays) / max(1, len(replays))
        replayed = sum(r["frozen_s"] for r in replays) / max(1, len(replays))
        print(f"| {name} | {sum(r['equal'] for r in rows)} of {len(rows)} | {max(r['diff'] for r in rows):.3g} "
              f"| {rows[-1]['recordings']} | {traced:.3f} | {replayed:.3f} |", flush=True)


if __name__ == "__main__":
    main()
