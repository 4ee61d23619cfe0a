"""Write the world page's sheet of the objects and the camera (docs/objects-and-camera.jpg):
frames rendered as a build renders them, once per drogue canopy scheme (podcam15 close behind
the drogue), then the things in the way (a wet, dirty pod window; a cockpit windscreen's
reflection with another tanker ahead; its frame out of focus; another receiver behind the
drogue), then the camera's processing (white balance set for 5,300 K and for 8,000 K; the
strongest tone curve; an H.264 round trip at CRF 40, which needs the ``[video]`` extra). Each
tile forces one draw; the rest of the frame's draws are its own.

    .venv/bin/python scripts/objects_and_camera.py          # about 9 minutes on 2 cores
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "docs" / "objects-and-camera.jpg"
#: podcam15's frame for the canopies and the window: the drogue 3 m from the probe.
DROGUE_FRAME = 333


def tiles() -> list[tuple[str, int, str, dict]]:
    """``(scene, frame, caption, config overrides)`` of every tile, in the sheet's order."""
    from datagen.assets.drogues import CANOPIES

    out = [("podcam15", DROGUE_FRAME, f"canopy: {name}", {"randomization.drogue.canopies": {name: 1.0}})
           for name in CANOPIES]
    out += [
        ("podcam15", DROGUE_FRAME, "pod window: droplets and dirt",
         {"randomization.window.droplet_share": 1.0, "randomization.window.dirt": [0.5, 0.5]}),
        ("dashcam75", 179, "windscreen reflection, another tanker",
         {"randomization.window.reflection": [0.12, 0.12], "randomization.traffic.share": 1.0}),
        ("dashcam75", 45, "the windscreen's frame, out of focus", {}),
        ("podcam25", 147, "another receiver", {"randomization.traffic.share": 1.0}),
        ("wingcam55", 0, "white balance set for 5,300 K", {"randomization.sensor.white_balance_k": [5300.0, 5300.0]}),
        ("wingcam55", 0, "white balance set for 8,000 K", {"randomization.sensor.white_balance_k": [8000.0, 8000.0]}),
        ("wingcam55", 0, "tone: gamma 1.15, full shoulder",
         {"randomization.sensor.tone_gamma": [1.15, 1.15], "randomization.sensor.tone_shoulder": [1.0, 1.0]}),
        ("wingcam55", 0, "H.264 round trip at CRF 40",
         {"randomization.sensor.video_share": 1.0, "randomization.sensor.video_crf": [40, 40]}),
    ]
    return out


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=OUT)
    parser.add_argument("--tile", type=int, nargs=2, default=(512, 270))
    args = parser.parse_args()
    from datagen.atomic import write_image
    from datagen.config import load_config, override_config
    from datagen.render.renderer import Renderer
    from datagen.report.gallery import _tile, tile_rows
    from datagen.scene.resolved import Scene

    size = {"width": 2 * args.tile[0], "height": 2 * args.tile[1]}
    images = []
    for scene, frame, caption, overrides in tiles():
        config = override_config(load_config(scene), overrides)
        images.append(_tile(config, Renderer(Scene.resolve(config), **size), frame, tuple(args.tile),
                            f"{scene} #{frame}: {caption}"))
        print(caption, flush=True)
    print(f"wrote {write_image(args.out, np.concatenate(tile_rows(images, 3), axis=0), jpeg_quality=90)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
