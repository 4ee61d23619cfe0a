"""Frames rendered for looking at, not for datasets: ``datagen render`` and the gallery sheet.

Both render a frame as a build does (its whole look, world included, through the camera
model), so that what a user looks at is what a dataset holds."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Final

import numpy as np

from datagen.atomic import write_exr, write_image
from datagen.config import override_config
from datagen.config.schema import WORLD_RANDOMIZERS, world_off
from datagen.core.conventions import render_seed
from datagen.pipeline.frame import training_image
from datagen.render.renderer import Renderer
from datagen.scene.approach import FrameStates
from datagen.scene.look import frame_look
from datagen.scene.resolved import Scene

if TYPE_CHECKING:
    from datagen.config.schema import Config

__all__ = ["CLOSEUP_FRAMES", "GALLERY_FRAMES", "GALLERY_SCENES", "WORLD_FRAME", "render_frames", "tile_rows",
           "world_tiles", "write_closeups", "write_gallery"]

#: The shipped scenes of the gallery, a row each.
GALLERY_SCENES: Final = ("wingcam55", "podcam15", "dashcam75")


def render_frames(config: Config, frames, out: Path, *, spp: int | None = None, scale: float = 1.0,
                  exr: bool = False, seed: int | None = None) -> list[Path]:
    """Render frames of a config into ``out`` as ``{name}-{frame:06d}.png`` (and ``.exr``)."""
    if seed is not None:
        config = override_config(config, {"dataset.seed": seed})
    seed = config.dataset.seed
    cam = config.camera
    renderer = Renderer(Scene.resolve(config), spp=spp, width=max(1, round(cam.width * scale)),
                        height=max(1, round(cam.height * scale)))
    written = []
    states = FrameStates(config, seed)
    for i in frames:
        state = states(i)
        look = frame_look(config, state)
        result = renderer.render(state, look, render_seed(seed, i), geometry=exr or config.render.exr)
        stem = Path(out) / f"{config.name}-{i:06d}"
        ext = config.render.image_suffix
        srgb, _ = training_image(result, look)
        write_image(stem.with_suffix(ext), srgb[..., ::-1], jpeg_quality=config.render.jpeg_quality)
        written.append(stem.with_suffix(ext))
        if exr or config.render.exr:
            write_exr(stem.with_suffix(".exr"), result.rgb, result.depth, result.object_id)
            written.append(stem.with_suffix(".exr"))
    return written


#: Frames of the gallery: spread over each config's approach chains and distances.
GALLERY_FRAMES: Final = (0, 7, 21, 45)
#: The wingcam55 frame of the gallery's world rows: the same frame with each world randomizer
#: alone, every one off, every one on, and with lens distortion.
WORLD_FRAME: Final = 25


def world_tiles(config: Config) -> dict[str, dict]:
    """The world rows' tiles: caption -> config overrides of ``config``."""
    tiles = {"all world randomizers off": world_off()}
    for name in WORLD_RANDOMIZERS:
        others = world_off(*(n for n in WORLD_RANDOMIZERS if n != name))
        tiles[f"{name} only"] = {**others, "randomization.sky.backlit_fraction": 1.0} if name == "backlit sun" \
            else others
    tiles["all on, lens distortion"] = {"randomization.sensor.distortion": True}
    tiles["all on"] = {}
    return tiles


def _tile(config: Config, renderer: Renderer, i: int, tile, caption: str) -> np.ndarray:
    import cv2

    state = FrameStates(config, config.dataset.seed)(i)
    look = frame_look(config, state)
    srgb, _ = training_image(renderer.render(state, look, render_seed(config.dataset.seed, i)), look)
    return _caption(cv2.resize(srgb[..., ::-1], tile, interpolation=cv2.INTER_AREA), caption)


def write_gallery(configs, out: Path, *, spp: int | None = None, tile=(512, 270)) -> Path:
    """Render :data:`GALLERY_FRAMES` of each config at twice the tile size, scale them down
    and write one sheet (a row per config) with captions; then two rows of the world's
    randomizers on :data:`WORLD_FRAME` of the first config (:func:`world_tiles`)."""
    rows = []
    size = {"width": 2 * tile[0], "height": 2 * tile[1]}
    for config in configs:
        renderer = Renderer(Scene.resolve(config), spp=spp, **size)
        states = FrameStates(config, config.dataset.seed)
        rows.append(np.concatenate([_tile(config, renderer, i, tile, f"{config.name} #{i}  PtD "
                                          f"{states(i).distance_m:.1f} m") for i in GALLERY_FRAMES], axis=1))
    world = []
    for caption, overrides in world_tiles(configs[0]).items():
        config = override_config(configs[0], overrides)
        world.append(_tile(config, Renderer(Scene.resolve(config), spp=spp, **size), WORLD_FRAME, tile,
                           f"#{WORLD_FRAME}: {caption}"))
    rows += tile_rows(world, len(GALLERY_FRAMES))
    return write_image(out, np.concatenate(rows, axis=0), jpeg_quality=90)


def tile_rows(tiles: list[np.ndarray], per_row: int) -> list[np.ndarray]:
    """Equal-sized ``tiles`` side by side, ``per_row`` to a row, the last row padded with black."""
    tiles = tiles + [np.zeros_like(tiles[0])] * (-len(tiles) % per_row)
    return [np.concatenate(tiles[j:j + per_row], axis=1) for j in range(0, len(tiles), per_row)]


#: The frames of the close-ups, one per camera type: where clouds, sea and cloud shadows
#: come closest (the frames the blocky clouds showed worst on).
CLOSEUP_FRAMES: Final = {"wingcam55": 0, "podcam15": 21, "dashcam75": 12}
#: A close-up's size at the frame's own resolution (pixels for pixels).
CLOSEUP: Final = (640, 360)


def _windows(surface: np.ndarray, size: tuple[int, int]) -> dict[str, tuple[int, int]]:
    """Top-left corners of the close-up windows of a frame from its surface map
    (:data:`datagen.render.world.SURFACES`): ``clouds``, the window with the most cloud
    edge (cloud pixels beside others), and ``sea``, the one with the most sea. Windows lie
    on a grid of half their size."""
    from datagen.render.world import SURFACES

    h, w = surface.shape
    cloud = surface == SURFACES.index("cloud")
    edge = cloud ^ np.roll(cloud, 1, 0) | cloud ^ np.roll(cloud, 1, 1)
    sea = surface == SURFACES.index("sea")
    best: dict[str, tuple[float, tuple[int, int]]] = {}
    for y in range(0, max(h - size[1], 0) + 1, size[1] // 2):
        for x in range(0, max(w - size[0], 0) + 1, size[0] // 2):
            box = (slice(y, y + size[1]), slice(x, x + size[0]))
            for name, score in (("clouds", edge[box].mean()), ("sea", sea[box].mean())):
                if score > best.get(name, (-1.0, (0, 0)))[0]:
                    best[name] = (float(score), (x, y))
    return {name: corner for name, (_, corner) in best.items()}


def write_closeups(out: Path, *, before: Path | None = None, spp: int | None = None) -> Path:
    """Close-ups of :data:`CLOSEUP_FRAMES` at full resolution: per camera type, the frame
    scaled down, its cloud edges and its sea (cloud shadows lie on both), pixel for pixel.
    ``before``: a folder of ``datagen render`` images of the same frames made by another
    datagen (``{name}-{frame:06d}.png``): its crops of the same windows go beside each."""
    import cv2

    from datagen.config import load_config

    rows = []
    for name, i in CLOSEUP_FRAMES.items():
        config = load_config(name)
        renderer = Renderer(Scene.resolve(config), spp=spp)
        state = FrameStates(config, config.dataset.seed)(i)
        look = frame_look(config, state)
        result = renderer.render(state, look, render_seed(config.dataset.seed, i), geometry=True)
        after = training_image(result, look)[0][..., ::-1]
        earlier = cv2.imread(str(Path(before) / f"{name}-{i:06d}.png")) if before is not None else None
        overview = cv2.resize(after, (CLOSEUP[0], round(CLOSEUP[0] * after.shape[0] / after.shape[1])),
                              interpolation=cv2.INTER_AREA)
        overview = np.pad(overview, ((0, max(CLOSEUP[1] - overview.shape[0], 0)), (0, 0), (0, 0)))[:CLOSEUP[1]]
        tiles = [_caption(overview, f"{name} #{i}")]
        assert result.surface is not None  # (rendered with its geometry pass)
        for what, (x, y) in _windows(result.surface, CLOSEUP).items():
            box = (slice(y, y + CLOSEUP[1]), slice(x, x + CLOSEUP[0]))
            if earlier is not None:
                tiles.append(_caption(earlier[box].copy(), f"{what}, before"))
            tiles.append(_caption(after[box].copy(), f"{what}{', now' if earlier is not None else ''}"))
        rows.append(np.concatenate(tiles, axis=1))
    width = max(r.shape[1] for r in rows)
    rows = [np.pad(r, ((0, 0), (0, width - r.shape[1]), (0, 0))) for r in rows]
    return write_image(out, np.concatenate(rows, axis=0), jpeg_quality=90)


def _caption(image: np.ndarray, caption: str) -> np.ndarray:
    from datagen.report.overlays import draw_text

    draw_text(image, caption, (8, 22), (255, 255, 255), 0.65)  # legible on sky, cloud and sea
    return image
