"""Write the world page's sheet of cloud forms and ground types (docs/world-types.jpg): one
frame of wingcam55 rendered as a build renders it, once per deck form (over open sea) and once
per ground type (a thin cumulus deck), the rest of its draws its own.

    .venv/bin/python scripts/world_types.py          # about 3 minutes on 2 cores
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "docs" / "world-types.jpg"
#: The frame: the tanker ahead, the ground and the horizon below it.
FRAME = 0
SCENE = "wingcam55"


def tiles() -> dict[str, dict]:
    """Caption -> config overrides of the scene: each cloud form over the sea, then each ground
    type under a thin cumulus deck, in clear air (visibility 120-150 km)."""
    from datagen.assets.clouds import CLOUD_FORMS
    from datagen.assets.ground import GROUND_TYPES

    clear = {"randomization.haze.visibility_m": [120_000.0, 150_000.0]}
    out = {f"{form} deck over the sea": {**clear, "randomization.clouds.forms": {form: 1.0},
                                          "randomization.ground.shares": {"sea": 1.0}}
           for form in CLOUD_FORMS if form != "layer"}
    out |= {f"{kind}": {**clear, "randomization.clouds.forms": {"cumulus": 1.0},
                        "randomization.clouds.deck_coverage": [0.0, 0.15],
                        "randomization.clouds.layer_coverage": [0.0, 0.0],
                        "randomization.ground.shares": {kind: 1.0}} for kind in GROUND_TYPES}
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

    base = load_config(SCENE)
    size = {"width": 2 * args.tile[0], "height": 2 * args.tile[1]}
    images = []
    for caption, overrides in tiles().items():
        config = override_config(base, overrides)
        images.append(_tile(config, Renderer(Scene.resolve(config), **size), FRAME, tuple(args.tile),
                            f"{SCENE} #{FRAME}: {caption}"))
        print(caption, flush=True)
    print(f"wrote {write_image(args.out, np.concatenate(tile_rows(images, 3), axis=0), jpeg_quality=90)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
