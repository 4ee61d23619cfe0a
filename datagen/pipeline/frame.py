"""One frame through the pipeline: state, look and labels (pure numpy), then, when
rendering, the image and the feature visibility.

::

    frame index -> approach state (poses) + look (sky, sun, materials)      [datagen.scene]
                -> labels: true centres, tight, corrected and label boxes   [datagen.core.labels]
                -> render (Mitsuba) -> linear RGB (+ depth, ids)            [datagen.render]
                -> feature visibility (ray casts) -> occlusion rule

Everything a frame is depends on (scene, frame index) alone.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from datagen.core.conventions import frame_rng, render_seed
from datagen.core.labels import FrameLabels, compute_labels
from datagen.scene.approach import FrameState, FrameStates
from datagen.scene.look import FrameLook, draw_look
from datagen.scene.resolved import Scene

__all__ = ["FrameDraws", "draw_frame", "frame_labels"]


@dataclass(frozen=True, eq=False)
class FrameDraws:
    """What a frame is before anything is rendered: its index, seeds, state and look."""

    index: int
    seed: int
    render_seed: int
    state: FrameState
    look: FrameLook


def draw_frame(scene: Scene, states: FrameStates, i: int) -> FrameDraws:
    """Frame ``i``'s state (from ``states``, the scene's approach chains), look and
    Mitsuba sampler seed, all from the scene's root seed."""
    seed = scene.config.dataset.seed
    return FrameDraws(i, seed, render_seed(seed, i), states(i), draw_look(scene.config, frame_rng(seed, i)))


def frame_labels(scene: Scene, state: FrameState) -> FrameLabels:
    """Every feature's labels in a frame's camera (before the occlusion rule)."""
    features = scene.features
    cam_from_objects = np.stack([state.cam_from_world @ state.world_from(o) for o in features.objects])
    return compute_labels(features, cam_from_objects, scene.intrinsics, **scene.label_options)
