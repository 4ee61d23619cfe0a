"""Light through the cloud layers: Mitsuba's ``path`` against ``volpath`` (the renderer's
choice with clouds on, :attr:`datagen.render.world.World.integrator`), fireflies and cost.

    python bench/bench_integrator.py [--frames 0 5 21 14] [--width 2048] [--spp 4]
        [--firefly-width 512] [--firefly-spp 128]

For each integrator, in one process each (the integrator is part of the scene):
``mi.render`` seconds per wingcam55 frame at ``--width`` and ``--spp`` (every randomizer
on but the sensor model, no denoiser; the first frame warms the kernels and is not
counted), and the isolated hot pixels (:func:`datagen.analysis.image_quality.fireflies`)
of the same frames at ``--firefly-width`` and ``--firefly-spp``.
"""

from __future__ import annotations

import argparse
import json
import platform
import subprocess
import sys
import time

import numpy as np


def measure(integrator: str, args) -> dict:
    from datagen.analysis.image_quality import fireflies
    from datagen.config import load_config, override_config
    from datagen.pipeline.frame import draw_frame
    from datagen.render import world
    from datagen.render.renderer import Renderer
    from datagen.scene.approach import FrameStates
    from datagen.scene.resolved import Scene

    world.World.integrator = property(lambda self: integrator)
    out: dict = {"integrator": integrator}
    for key, width, spp in (("render_s", args.width, args.spp), ("fireflies", args.firefly_width, args.firefly_spp)):
        config = override_config(load_config("wingcam55"), {
            "render.denoise": "off", "randomization.sensor.enabled": False,
            "camera.width": width, "camera.height": width * 1080 // 2048})
        scene = Scene.resolve(config)
        renderer = Renderer(scene, spp=spp)
        states = FrameStates(config)
        values = []
        for k, frame in enumerate([args.frames[0], *args.frames] if key == "render_s" else args.frames):
            draws = draw_frame(scene, states, frame)
            start = time.perf_counter()
            rgb = renderer.render(draws.state, draws.look, draws.render_seed, geometry=False).rgb
            seconds = time.perf_counter() - start
            if key == "render_s" and k > 0:
                values.append(seconds)
            elif key == "fireflies":
                values.append(int(fireflies(rgb).sum()))
        out[key] = values
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, nargs="+", default=[0, 5, 21, 14])
    parser.add_argument("--width", type=int, default=2048)
    parser.add_argument("--spp", type=int, default=4)
    parser.add_argument("--firefly-width", type=int, default=512)
    parser.add_argument("--firefly-spp", type=int, default=128)
    parser.add_argument("--one", default=None, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.one:
        print(json.dumps(measure(args.one, args)))
        return
    print(f"wingcam55 frames {args.frames}; {platform.machine()}, Python {platform.python_version()}")
    for integrator in ("path", "volpath"):
        done = subprocess.run([sys.executable, __file__, "--one", integrator, *sys.argv[1:]], check=True,
                              capture_output=True, text=True)
        r = json.loads(done.stdout.strip().splitlines()[-1])
        print(f"{integrator:8s} mi.render {args.width} px {args.spp} spp: median {np.median(r['render_s']):.2f} s "
              f"({', '.join(f'{s:.2f}' for s in r['render_s'])}); fireflies at {args.firefly_width} px "
              f"{args.firefly_spp} spp: {r['fireflies']} px", flush=True)


if __name__ == "__main__":
    main()
