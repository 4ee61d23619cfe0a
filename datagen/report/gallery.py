"""Frames rendered for looking at, not for datasets: ``datagen render`` and the gallery sheet."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Final

import numpy as np

from datagen.core.conventions import frame_rng, render_seed
from datagen.files import write_exr, write_image
from datagen.render.renderer import Renderer
from datagen.render.tonemap import to_srgb8
from datagen.scene.approach import FrameStates
from datagen.scene.look import draw_look
from datagen.scene.resolved import Scene

if TYPE_CHECKING:
    from datagen.config.schema import Config

__all__ = ["GALLERY_FRAMES", "GALLERY_SCENES", "render_frames", "write_gallery"]

#: The shipped scenes of the gallery, a row each.
GALLERY_SCENES: Final = ("wingcam55", "podcam15", "dashcam75")

def render_frames(config: Config, frames, out: Path, *, spp: int | None = None, scale: float = 1.0,
                  exr: bool = False, seed: int | None = None) -> list[Path]:
    """Render frames of a config into ``out`` as ``{name}-{frame:06d}.png`` (and ``.exr``)."""
    seed = config.dataset.seed if seed is None else seed
    cam = config.camera
    renderer = Renderer(Scene.resolve(config), spp=spp, width=max(1, round(cam.width * scale)),
                        height=max(1, round(cam.height * scale)))
    written = []
    states = FrameStates(config, seed)
    for i in frames:
        state = states(i)
        result = renderer.render(state, draw_look(config, frame_rng(seed, i)), render_seed(seed, i),
                                 geometry=exr or config.render.exr)
        stem = Path(out) / f"{config.name}-{i:06d}"
        ext = config.render.image_suffix
        write_image(stem.with_suffix(ext), to_srgb8(result.rgb)[..., ::-1], jpeg_quality=config.render.jpeg_quality)
        written.append(stem.with_suffix(ext))
        if exr or config.render.exr:
            write_exr(stem.with_suffix(".exr"), result.rgb, result.depth, result.object_id)
            written.append(stem.with_suffix(".exr"))
    return written


#: Frames of the gallery: spread over each config's approach chains and distances.
GALLERY_FRAMES: Final = (0, 7, 21, 45)


def write_gallery(configs, out: Path, *, spp: int | None = None, tile=(512, 270)) -> Path:
    """Render :data:`GALLERY_FRAMES` of each config at twice the tile size, scale
    them down and write one sheet (a row per config) with captions."""
    import cv2

    rows = []
    for config in configs:
        seed = config.dataset.seed
        renderer = Renderer(Scene.resolve(config), spp=spp, width=2 * tile[0], height=2 * tile[1])
        tiles = []
        states = FrameStates(config, seed)
        for i in GALLERY_FRAMES:
            state = states(i)
            result = renderer.render(state, draw_look(config, frame_rng(seed, i)), render_seed(seed, i))
            image = cv2.resize(to_srgb8(result.rgb)[..., ::-1], tile, interpolation=cv2.INTER_AREA)
            caption = f"{config.name} #{i}  PtD {state.distance_m:.1f} m"
            cv2.putText(image, caption, (6, 18), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (255, 255, 255), 1, cv2.LINE_AA)
            tiles.append(image)
        rows.append(np.concatenate(tiles, axis=1))
    return write_image(out, np.concatenate(rows, axis=0), jpeg_quality=90)
