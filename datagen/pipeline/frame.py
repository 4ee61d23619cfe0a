"""One frame through the pipeline: state, look and labels (pure numpy), then, when
rendering, the image and the feature visibility.

::

    frame index -> approach state (poses) + look (sky, sun, materials)      [datagen.scene]
                -> labels: true centres, tight, corrected and label boxes   [datagen.core.label_boxes]
                -> render (Mitsuba) -> linear RGB (+ depth, ids)            [datagen.render]
                -> feature visibility (ray casts) -> occlusion rule

Everything a frame is depends on (scene, frame index) alone.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Final

import numpy as np

from datagen.core.camera import RollingShutter
from datagen.core.conventions import render_seed
from datagen.core.label_boxes import FrameLabels
from datagen.scene.approach import FrameState, FrameStates
from datagen.scene.look import FrameLook, frame_look
from datagen.scene.resolved import Scene

if TYPE_CHECKING:
    from datagen.render.renderer import RenderResult

__all__ = ["TRAINING_IMAGE_STAGE", "FrameDraws", "draw_frame", "frame_labels", "object_labels", "shard_labels",
           "training_image"]

#: The stage of a rendered frame that is :func:`training_image`.
TRAINING_IMAGE_STAGE: Final = "sRGB, JPEG or video round trip, statistics"


@dataclass(frozen=True, eq=False)
class FrameDraws:
    """What a frame is before anything is rendered: its index, seeds, state and look."""

    index: int
    seed: int
    render_seed: int
    state: FrameState
    look: FrameLook


def draw_frame(scene: Scene, states: FrameStates, i: int, approaches: dict | None = None) -> FrameDraws:
    """Frame ``i``'s state (from ``states``, the scene's approach chains), look and
    Mitsuba sampler seed, all from the scene's root seed (``approaches``: a dict keeping
    each approach chain's weather and liveries for its other frames)."""
    seed = scene.config.dataset.seed
    state = states(i)
    return FrameDraws(i, seed, render_seed(seed, i), state, frame_look(scene.config, state, approaches))


def _cameras(scene: Scene, draws: Sequence[FrameDraws]) -> tuple[np.ndarray, np.ndarray | None,
                                                                   RollingShutter | None]:
    """``(N, O, 4, 4)`` camera-from-object transforms of frames ``draws`` (``features.objects``
    order), their lenses ``(N, 5)`` (None when no frame has one) and their rolling shutters
    (None when no frame has one)."""
    cam_from_objects = np.stack([np.stack([d.state.cam_from_world @ d.state.world_from(o)
                                           for o in scene.features.objects]) for d in draws])
    readouts = [d.look.sensor_readout_s for d in draws]
    shutter = None
    if any(r is not None for r in readouts):
        shutter = RollingShutter(
            np.array([r or 0.0 for r in readouts]),
            np.stack([np.stack([d.state.cam_from_per_s(o) if r is not None else np.zeros((4, 4))
                                for o in scene.features.objects]) for d, r in zip(draws, readouts, strict=True)]))
    lenses = [d.look.sensor_distortion for d in draws]
    if all(lens is None for lens in lenses):
        return cam_from_objects, None, shutter
    return (cam_from_objects, np.array([(0.0,) * 5 if lens is None else lens for lens in lenses], dtype=np.float64),
            shutter)


def shard_labels(scene: Scene, draws: Sequence[FrameDraws]) -> tuple[FrameLabels, FrameLabels]:
    """The feature labels (before the occlusion rule) and the objects' pose boxes of frames
    ``draws``, batched over the frames (``.frame(b)`` is frame ``b``'s; the same numbers as
    one frame at a time: the label arithmetic is element by element). Each frame is seen
    through its look's lens distortion and rolling shutter where it has them."""
    cam_from_objects, distortion, shutter = _cameras(scene, draws)
    return (scene.labelling.label_features(cam_from_objects, distortion, shutter),
            scene.labelling.label_objects(cam_from_objects, distortion, shutter))


def frame_labels(scene: Scene, draws: FrameDraws) -> FrameLabels:
    """Every feature's labels in a frame's camera (before the occlusion rule), through the
    frame's lens distortion when its look has one."""
    return shard_labels(scene, [draws])[0].frame(0)


def object_labels(scene: Scene, draws: FrameDraws) -> FrameLabels:
    """Every labeled object's pose box in a frame's camera (:mod:`datagen.core.keypoints`):
    the box of its projected convex hull under the feature boxes' size and edge rules."""
    return shard_labels(scene, [draws])[1].frame(0)


def training_image(result: RenderResult, look: FrameLook) -> tuple[np.ndarray, dict]:
    """The 8-bit sRGB training image of a :class:`~datagen.render.renderer.RenderResult`
    (through the camera's tone curve and the sensor's JPEG or video round trip where the look has
    them) and what the render measured, the image statistics included
    (:data:`datagen.dataset.columns.MEASURED_COLUMNS`)."""
    from datagen.render.sensor import jpeg_round_trip, tone_of, video_round_trip
    from datagen.render.tonemap import image_statistics, to_srgb8

    srgb = result.srgb8 if result.srgb8 is not None else to_srgb8(result.rgb, tone_of(look))
    if look.sensor_jpeg_quality is not None:
        srgb = jpeg_round_trip(srgb, look.sensor_jpeg_quality)
    if look.sensor_video_crf is not None:
        srgb = video_round_trip(srgb, look.sensor_video_crf)
    return srgb, {**(result.measured or {}), **image_statistics(srgb, result.surface, object_ids=result.object_id)}
