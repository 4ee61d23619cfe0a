"""Rendering cost per frame at the config's full resolution (2048x1080 by default).

    python bench/bench_render.py [--config scenes/wingcam55.yaml] [--spp 4 16 64] [--frames 3]
                                 [--every 1] [--variant auto] [--denoise off|oidn] [--guides] [--traced]
    python bench/bench_render.py --randomizers [--frames 8]
    python bench/bench_render.py --size 64x34 --spp 1 --frames 16 --every 7 --threads 1   # the fixed per-frame cost

``--randomizers`` times the world's randomizers at the config's spp: every one off
(today's images), each one alone, and all on, one mode after another (a process holds
one scene at a time); it prints each mode's mean and median whole-frame time, its ratio
to all-off, and the process's peak RSS.

``--size WxH`` renders at another resolution (the same field of view): at 64x34 and 1 spp
the render's own work is negligible and what remains is the fixed per-frame cost (tracing
the kernel, posing, the camera model's fixed costs). ``--threads`` sizes Dr.Jit's thread pool
(one, with ``taskset -c 0``, for the one-core figures). ``--traced`` turns the frozen render
off (:mod:`datagen.render.frozen`; on by default): the path tracing traced again every frame.

``--cast K`` also times the geometry pass's ray cast alone, K times on the last frame's pose
(the frame's cast: half resolution, the target pass's grid, three extra rays): its median.

``--variant cuda_ad_rgb`` renders and denoises on the GPU where one is (nothing else
changes: the denoiser takes the render's Dr.Jit tensors on their device).

For each spp: seconds per frame in ``mi.render`` and in the denoiser; every other
stage's seconds (:class:`datagen.render.timing.StageClock`); seconds per
frame for the whole frame (approach state, material draws, posing through
``mi.traverse``, render, denoise, geometry pass, feature visibility, 8-bit PNG
encoding); the host work per frame (everything outside ``mi.render`` and the
denoiser) and its share of the frame; the kernels the counted frames compiled (launched,
and launched by no earlier frame: 0 once warm); and the process's peak RSS; and what
Dr.Jit launched a frame: kernels, memory copies (one of one value is a value read back to the
host, a wait for the device on a GPU, or a one-element gather made an asynchronous device copy:
:attr:`~datagen.render.runtime.KernelCensus.launched`) and fills (each opaque constant is one). The first
frame of each spp is a warm-up (kernel compilation) and is not counted.
"""

from __future__ import annotations

import argparse
import os
import platform
import resource
import tempfile
from pathlib import Path

from datagen.config import load_config, override_config
from datagen.config.schema import WORLD_RANDOMIZERS, world_off
from datagen.pipeline.writer import timed_frame
from datagen.render.renderer import Renderer
from datagen.render.runtime import KernelCensus
from datagen.render.timing import DENOISE, PATH_TRACING, rest_of_frame
from datagen.scene.approach import FrameStates
from datagen.scene.resolved import Scene


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--config", default="scenes/wingcam55.yaml")
    parser.add_argument("--spp", type=int, nargs="+", default=[4, 16, 64])
    parser.add_argument("--frames", type=int, default=3, help="counted frames per spp")
    parser.add_argument("--every", type=int, default=1, help="frames 0, K, 2K, ...: K > 1 spreads them over "
                        "approach chains (frame_per_approach frames each)")
    parser.add_argument("--variant", default=None)
    parser.add_argument("--denoise", default=None, choices=["off", "oidn"], help="override render.denoise")
    parser.add_argument("--guides", action="store_true", help="render.denoise_guides on: the denoiser's albedo "
                        "and normal guides")
    parser.add_argument("--randomizers", action="store_true", help="time each world randomizer and all of them")
    parser.add_argument("--size", default=None, help="WxH: render at this resolution instead of the config's")
    parser.add_argument("--threads", type=int, default=None, help="Dr.Jit threads (default: every core)")
    parser.add_argument("--cast", type=int, default=0, help="time the geometry pass's ray cast alone this many "
                        "times on the last frame's pose")
    parser.add_argument("--traced", action="store_true", help="render.frozen off: the path tracing traced again "
                        "every frame (datagen.render.frozen)")
    args = parser.parse_args()
    config = load_config(args.config)
    if args.size is not None:
        width, height = (int(v) for v in args.size.lower().split("x"))
        config = override_config(config, {"camera.width": width, "camera.height": height})
    if args.threads is not None:
        from datagen.render.runtime import set_threads

        set_threads(args.threads)
    if args.denoise is not None:
        config = override_config(config, {"render.denoise": args.denoise})
    if args.guides:
        config = override_config(config, {"render.denoise_guides": True})
    if args.traced:
        config = override_config(config, {"render.frozen": False})
    if args.randomizers:
        randomizers(config, args)
        return
    scene = Scene.resolve(config)
    print(f"machine: {platform.machine()}, {os.cpu_count()} CPUs; config {args.config}, "
          f"{config.camera.width}x{config.camera.height}")
    with tempfile.TemporaryDirectory() as tmp:
        for spp in args.spp:
            renderer = Renderer(scene, spp=spp, variant=args.variant)
            states = FrameStates(config)
            census = KernelCensus()
            stages: dict[str, float] = {}
            total_s = 0.0
            compiles = 0  # kernels launched by a counted frame that no frame before it launched
            launched: dict[str, int] = {}  # Dr.Jit's launches of the counted frames, by kind
            with census.recording():
                for n, i in enumerate(range(0, (args.frames + 1) * args.every, args.every)):
                    # The build's frame pipeline (datagen.pipeline.frame), timed whole and by stage.
                    elapsed, clock = timed_frame(scene, renderer, states, i, Path(tmp) / f"{i}.png")
                    new = census.new_kernels()
                    if n > 0:
                        compiles += new
                        for kind, count in census.launched.items():
                            launched[kind] = launched.get(kind, 0) + count
                        total_s += elapsed
                        for name, seconds in clock.items():
                            stages[name] = stages.get(name, 0.0) + seconds
            k = args.frames
            render_s, denoise_s = stages.get(PATH_TRACING, 0.0), stages.get(DENOISE, 0.0)
            peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
            print(f"{renderer.variant} spp {spp:3d}, denoise {renderer.denoise}: "
                  f"mi.render {render_s / k:6.3f} s/frame, "
                  f"denoise {denoise_s / k:5.2f} s/frame, whole frame {total_s / k:6.3f} s/frame, "
                  f"host work (outside mi.render and the denoiser) {(total_s - render_s - denoise_s) / k:5.3f} s/frame "
                  f"= {100 * (1 - (render_s + denoise_s) / total_s):4.1f}%, "
                  f"kernels compiled after warm-up {compiles}, render recordings {renderer.recordings}, "
                  f"ray-cast recordings {renderer.cast_recordings} ({renderer.refused_recordings} refused, "
                  f"those traced), peak RSS {peak:,.0f} MiB")
            print("    Dr.Jit a frame: " + ", ".join(f"{count / k:.0f} {kind}" for kind, count in launched.items()))
            rest = rest_of_frame(stages)
            print("    stages: " + ", ".join(f"{name} {t / k:.3f} s" for name, t in rest)
                  + f" ({sum(t for _, t in rest) / total_s:.0%} of the frame)")
            if args.cast:
                print(f"    the geometry pass's ray cast alone: {cast_seconds(renderer, args.cast):.4f} s "
                      f"(median of {args.cast})")


def cast_seconds(renderer: Renderer, times: int) -> float:
    """The median seconds of the frame's geometry pass cast (as :meth:`Renderer.render` makes
    it, on the pose the renderer holds), after one call not counted."""
    import time

    import numpy as np

    directions = np.tile(np.float32([0.0, 0.0, 1.0]), (3, 1))  # the sun's and two lights' rays
    seconds = []
    for n in range(times + 1):
        start = time.perf_counter()
        renderer.frame_cast(directions)
        if n > 0:
            seconds.append(time.perf_counter() - start)
    return float(np.median(seconds))


#: Every world randomizer's switch, off (today's images) and on.
def randomizers(config, args) -> None:
    """Whole-frame time with the world's randomizers off, each alone, and all on."""
    import numpy as np

    others = {name: world_off(*(n for n in WORLD_RANDOMIZERS if n != name)) for name in WORLD_RANDOMIZERS}
    modes = {"all off": world_off(), **others, "all on": {}}  # "on": as the config (shipped: all on)
    print(f"machine: {platform.machine()}, {os.cpu_count()} CPUs; config {args.config}, "
          f"{config.camera.width}x{config.camera.height}, spp {config.render.spp}, denoise {config.render.denoise}")
    times: dict[str, list[float]] = {name: [] for name in modes}
    with tempfile.TemporaryDirectory() as tmp:
        for name, switches in modes.items():  # one scene at a time (datagen.render.runtime.hold_scene)
            mode_config = override_config(config, switches)
            scene = Scene.resolve(mode_config)
            renderer, states = Renderer(scene), FrameStates(mode_config)
            for n in range(args.frames + 1):  # frame 0 warms the mode up (its scene, kernel compilation)
                # frame n * 7: spread over approach chains and distances
                elapsed, _ = timed_frame(scene, renderer, states, n * 7, Path(tmp) / "frame.png")
                if n > 0:
                    times[name].append(elapsed)
    base = float(np.mean(times["all off"]))
    for name, t in times.items():
        print(f"{name:12s} whole frame {np.mean(t):6.2f} s/frame (median {np.median(t):5.2f}), "
              f"{np.mean(t) / base:4.2f}x all off")
    print(f"peak RSS {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:,.0f} MiB")


if __name__ == "__main__":
    main()
