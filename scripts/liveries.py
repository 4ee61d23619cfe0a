"""Write the world page's sheet of the aircraft's surfaces (docs/liveries.jpg): crops at full
resolution (no scaling: one image pixel is one sheet pixel) of frames rendered as a build
renders them, camera model on, each forcing one livery scheme: the tanker's rear fuselage and
engines seen from wingcam55's wing pod 30-40 m behind it (the seams, panel tones, soot) and
the receiver's spine and intakes seen from podcam15's pod on the tanker a few metres above
(panels, rivet rows, the markings). Each crop is centred on a point of its aircraft's pixels.

    .venv/bin/python scripts/liveries.py          # about 10 minutes on 2 cores
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "docs" / "liveries.jpg"
SCHEMES = ("grey_camouflage", "two_tone", "high_visibility", "bare_metal")
#: (scene, frame, the object the crop centres on, where in it: a share of its pixels' box).
VIEWS = (("wingcam55", 14, "tanker", (0.49, 0.69)), ("podcam15", 30, "receiver", (0.53, 0.45)))


def tiles() -> list[tuple[str, int, str, tuple[float, float], str, dict]]:
    """``(scene, frame, object, where, caption, config overrides)`` of every tile, in order."""
    out = []
    for scene, frame, obj, where in VIEWS:
        out += [(scene, frame, obj, where, scheme.replace("_", " "), {"randomization.livery.schemes": [scheme]})
                for scheme in SCHEMES]
    return out


def crop(image: np.ndarray, ids: np.ndarray, object_id: int, where: tuple[float, float],
         size: tuple[int, int]) -> np.ndarray:
    """A ``size`` (w, h) window of ``image`` centred at ``where`` within the box of ``object_id``'s pixels."""
    h, w = image.shape[:2]
    rows, cols = np.nonzero(ids == object_id)
    if len(rows):
        cx = cols.min() + where[0] * (cols.max() - cols.min())
        cy = rows.min() + where[1] * (rows.max() - rows.min())
    else:
        cx, cy = w / 2, h / 2
    x0 = int(np.clip(cx - size[0] / 2, 0, w - size[0]))
    y0 = int(np.clip(cy - size[1] / 2, 0, h - size[1]))
    return np.ascontiguousarray(image[y0:y0 + size[1], x0:x0 + size[0]])


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=OUT)
    parser.add_argument("--tile", type=int, nargs=2, default=(512, 270))
    args = parser.parse_args()
    from datagen.atomic import write_image
    from datagen.config import load_config, override_config
    from datagen.core.conventions import object_id, render_seed
    from datagen.pipeline.frame import training_image
    from datagen.render.renderer import Renderer
    from datagen.report.gallery import _caption, tile_rows
    from datagen.scene.approach import FrameStates
    from datagen.scene.look import frame_look
    from datagen.scene.resolved import Scene

    images = []
    for scene, frame, obj, where, caption, overrides in tiles():
        config = override_config(load_config(scene), overrides)
        state = FrameStates(config, config.dataset.seed)(frame)
        result = Renderer(Scene.resolve(config)).render(state, frame_look(config, state),
                                                        render_seed(config.dataset.seed, frame), geometry=True)
        srgb, _ = training_image(result, frame_look(config, state))
        tile = crop(srgb[..., ::-1], result.object_id, object_id(obj), where, tuple(args.tile))
        images.append(_caption(tile, f"{scene} #{frame}: {caption}"))
        print(f"{scene} #{frame}: {caption}", flush=True)
    print(f"wrote {write_image(args.out, np.concatenate(tile_rows(images, 4), axis=0), jpeg_quality=92)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
