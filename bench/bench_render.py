"""Rendering cost per frame at the config's full resolution (2048x1080 by default).

    python bench/bench_render.py [--config scenes/wingcam55.yaml] [--spp 4 16 64] [--frames 3]
                                 [--variant auto] [--denoise off|oidn]

For each spp: seconds per frame in ``mi.render`` and in the denoiser; seconds per
frame for the whole frame (approach state, material draws, posing through
``mi.traverse``, render, denoise, geometry pass, feature visibility, 8-bit PNG
encoding); the share of frame time spent outside ``mi.render`` (and the
denoiser's part of it); and the process's peak RSS. The first
frame of each spp is a warm-up (kernel compilation) and is not counted.
"""

from __future__ import annotations

import argparse
import os
import platform
import resource
import tempfile
import time
from pathlib import Path

from datagen.config import load_config, override_config
from datagen.files import write_image
from datagen.pipeline.frame import draw_frame, frame_labels
from datagen.render.renderer import Renderer
from datagen.render.tonemap import to_srgb8
from datagen.scene.approach import FrameStates
from datagen.scene.resolved import Scene


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--config", default="scenes/wingcam55.yaml")
    parser.add_argument("--spp", type=int, nargs="+", default=[4, 16, 64])
    parser.add_argument("--frames", type=int, default=3, help="counted frames per spp")
    parser.add_argument("--variant", default=None)
    parser.add_argument("--denoise", default=None, choices=["off", "oidn"], help="override render.denoise")
    args = parser.parse_args()
    config = load_config(args.config)
    if args.denoise is not None:
        config = override_config(config, {"render.denoise": args.denoise})
    scene = Scene.resolve(config)
    print(f"machine: {platform.machine()}, {os.cpu_count()} CPUs; config {args.config}, "
          f"{config.camera.width}x{config.camera.height}")
    with tempfile.TemporaryDirectory() as tmp:
        for spp in args.spp:
            renderer = Renderer(scene, spp=spp, variant=args.variant)
            states = FrameStates(config)
            render_s = denoise_s = total_s = 0.0
            for n, i in enumerate(range(args.frames + 1)):
                start = time.perf_counter()  # the build's frame pipeline (datagen.pipeline.frame), timed whole
                draws = draw_frame(scene, states, i)
                frame_labels(scene, draws.state)
                result = renderer.render(draws.state, draws.look, draws.render_seed)
                renderer.feature_visibility(draws.state, scene.features)
                write_image(Path(tmp) / f"{i}.png", to_srgb8(result.rgb)[..., ::-1])
                elapsed = time.perf_counter() - start
                if n > 0:
                    render_s += result.render_s
                    denoise_s += result.denoise_s or 0.0
                    total_s += elapsed
            k = args.frames
            peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
            print(f"{renderer.variant} spp {spp:3d}, denoise {renderer.denoise}: mi.render {render_s / k:6.2f} s/frame, "
                  f"denoise {denoise_s / k:5.2f} s/frame, whole frame {total_s / k:6.2f} s/frame, outside mi.render "
                  f"{100 * (1 - render_s / total_s):4.1f}% (denoise {100 * denoise_s / total_s:4.1f}%), "
                  f"peak RSS {peak:,.0f} MiB")


if __name__ == "__main__":
    main()
