"""How Ultralytics' YOLO trainer sees a label, written down once (no Ultralytics import).

A label teaches a detector only if it survives the trainer's own transforms, the
detection head can assign it to an anchor, and that assignment gives it a target
that is not zero. Ultralytics 8.4 with the recipe of
:func:`datagen.pipeline.training_yaml.hyp_yaml` (mosaic, scale, translate, rotation, shear and
perspective all off) does this to a ``W x H`` image at ``imgsz``:

1. **resize** (``BaseDataset.load_image``): the long side becomes ``imgsz``,
   ``r = imgsz / max(W, H)``, each side ``min(ceil(side * r), imgsz)``; a box
   scales by ``w_t / W`` along x and ``h_t / H`` along y;
2. **centre on the square input** (``RandomPerspective`` with
   ``size=(imgsz, imgsz)``): the resized image is shifted by
   ``((imgsz - w_t) / 2, (imgsz - h_t) / 2)``;
3. **drop small boxes** (``RandomPerspective.box_candidates``): a box survives
   only if both sides exceed 2 px there, its aspect ratio stays under 100 (and
   its area ratio to the pre-transform box exceeds 0.1, which an identity
   transform always satisfies);
4. **anchors** (``make_anchors``, ``TaskAlignedAssigner.select_candidates_in_gts``):
   the head's anchor centres lie at ``(i + 0.5) * s`` for strides ``s`` of 8, 16
   and 32 over the square input; a box can be assigned a positive only where
   an anchor centre lies strictly inside it;
5. **targets** (``TaskAlignedAssigner``, ``utils/tal.py``): each positive's
   classification target, which also weighs its box loss, is ``score^0.5 * CIoU^6``
   against the head's current prediction, divided by the box's best such value plus
   1e-9 and scaled by its best CIoU. An untrained DFL head predicts boxes about 15
   strides wide (120 px at stride 8), so a box a few pixels wide gets targets near
   1e-9: it teaches "background" only, and with it the whole detector. Measured on
   rendered wingcam55 frames with an untrained ``yolo11n.yaml``
   (``bench/bench_train.py --sweep``): the median box's best target is about 1e-10 at
   8 px, 2e-6 at 16 px, 0.03 at 32 px and 0.2 at 48 px. Trained from scratch to
   memorize 24 frames, 8 px labels never gave a detection while 32 and 48 px labels
   were found to sub-pixel centres (README, "Does it train?").
   :data:`ASSIGNABLE_SIDE_PX` is the threshold.

A label is *learnable* when it passes 3, contains an anchor centre of 4, and both
its sides are at least :data:`ASSIGNABLE_SIDE_PX` at the training size (5).
(Ultralytics 8.4.190's assigner also widens boxes under 16 px to 16 px when it
picks candidate anchors; this module keeps the stricter rule that the box itself
contains an anchor, so that learnability does not hang on that detail.)

The smallest side a label box may have at the training size
(``labels.min_box_px``) converts to original pixels per axis with
:meth:`TrainView.min_label_size_px`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Final

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "ANCHOR_STRIDES",
    "ASSIGNABLE_SIDE_PX",
    "MATCH_PX",
    "MAX_ASPECT_RATIO",
    "MIN_TRAIN_SIDE_PX",
    "SIDE_TOLERANCE_PX",
    "TRAIN_BATCH",
    "TrainView",
]

#: Strides of the YOLO detection head's three levels (P3, P4, P5).
ANCHOR_STRIDES: Final[tuple[int, ...]] = (8, 16, 32)
#: Ultralytics drops a box whose width or height at the training size is not above this (``wh_thr``).
MIN_TRAIN_SIDE_PX: Final[float] = 2.0
#: ... or whose aspect ratio is not below this (``ar_thr``).
MAX_ASPECT_RATIO: Final[float] = 100.0
#: The training recipe's batch, and its nominal batch (``nbs``): one optimizer step per batch.
TRAIN_BATCH: Final[int] = 16
#: A detection finds a feature when its centre lies within this distance of the projection of
#: the feature's true centre (px at the dataset's resolution; ``datagen evaluate --match-px``).
MATCH_PX: Final[float] = 3.0
#: The shortest side (px at the training size) for which the untrained head's task-aligned
#: assigner gives a box a usable target (rule 5 of the module docstring).
ASSIGNABLE_SIDE_PX: Final[float] = 32.0
#: A box side counts as ASSIGNABLE_SIDE_PX long down to this much less (px at the training
#: size): a label line's rounding (well under 1e-4 px at 2048 px across) must not make a box
#: grown to exactly the side unassignable.
SIDE_TOLERANCE_PX: Final[float] = 1e-3
#: An anchor centre counts as inside a box when it is further than this from every side (the assigner's eps).
_ANCHOR_EPS: Final[float] = 1e-9


@dataclass(frozen=True)
class TrainView:
    """A ``width`` x ``height`` image as Ultralytics' trainer feeds it at ``imgsz``."""

    width: int
    height: int
    imgsz: int

    def __post_init__(self) -> None:
        if self.width <= 0 or self.height <= 0 or self.imgsz <= 0:
            raise ValueError(f"sizes must be positive, got {self.width}x{self.height} at imgsz {self.imgsz}")

    @property
    def resized(self) -> tuple[int, int]:
        """``(w_t, h_t)``: the image after the long side is resized to ``imgsz``."""
        r = self.imgsz / max(self.width, self.height)
        if r == 1:
            return self.width, self.height
        return min(math.ceil(self.width * r), self.imgsz), min(math.ceil(self.height * r), self.imgsz)

    @property
    def scale(self) -> tuple[float, float]:
        """``(sx, sy)``: training pixels per original pixel along x and y."""
        w_t, h_t = self.resized
        return w_t / self.width, h_t / self.height

    @property
    def offset(self) -> tuple[float, float]:
        """Where the resized image's top-left corner lies on the square training input."""
        w_t, h_t = self.resized
        return (self.imgsz - w_t) / 2.0, (self.imgsz - h_t) / 2.0

    def min_label_size_px(self, min_box_px: float) -> tuple[float, float]:
        """The smallest label box ``(width, height)`` in original pixels whose sides are
        ``min_box_px`` at the training size."""
        sx, sy = self.scale
        return min_box_px / sx, min_box_px / sy

    def to_train(self, xyxy: ArrayLike) -> NDArray[np.float64]:
        """``(..., 4)`` boxes in original continuous pixels to training-input pixels."""
        box = np.asarray(xyxy, dtype=np.float64)
        (sx, sy), (ox, oy) = self.scale, self.offset
        return box * np.array([sx, sy, sx, sy]) + np.array([ox, oy, ox, oy])

    def survives(self, xyxy: ArrayLike) -> NDArray[np.bool_]:
        """``(...)`` whether Ultralytics keeps each box (original pixels): both sides above
        :data:`MIN_TRAIN_SIDE_PX` and an aspect ratio below :data:`MAX_ASPECT_RATIO` at the training size."""
        t = self.to_train(xyxy)
        w, h = t[..., 2] - t[..., 0], t[..., 3] - t[..., 1]
        with np.errstate(invalid="ignore", divide="ignore"):
            aspect = np.maximum(w / (h + 1e-16), h / (w + 1e-16))
            return (w > MIN_TRAIN_SIDE_PX) & (h > MIN_TRAIN_SIDE_PX) & (aspect < MAX_ASPECT_RATIO)

    def has_anchor(self, xyxy: ArrayLike) -> NDArray[np.bool_]:
        """``(...)`` whether an anchor centre of some stride lies strictly inside each box
        (original pixels)."""
        t = self.to_train(xyxy)
        found = np.zeros(t.shape[:-1], dtype=bool)
        for s in ANCHOR_STRIDES:
            cells = self.imgsz // s
            inside = np.ones(t.shape[:-1], dtype=bool)
            for lo, hi in ((t[..., 0], t[..., 2]), (t[..., 1], t[..., 3])):
                with np.errstate(invalid="ignore"):
                    # The first anchor centre (i + 0.5) * s strictly right of lo + eps.
                    i = np.clip(np.floor((lo + _ANCHOR_EPS) / s - 0.5) + 1.0, 0, cells - 1)
                    centre = (i + 0.5) * s
                    inside &= (centre - lo > _ANCHOR_EPS) & (hi - centre > _ANCHOR_EPS)
            found |= inside
        return found

    def reaches_loss(self, xyxy: ArrayLike) -> NDArray[np.bool_]:
        """``(...)`` :meth:`survives` and :meth:`has_anchor`: the box gets positive anchors."""
        return self.survives(xyxy) & self.has_anchor(xyxy)

    def short_sides(self, xyxy: ArrayLike) -> NDArray[np.bool_]:
        """``(..., 2)`` whether the box's width, its height, is under :data:`ASSIGNABLE_SIDE_PX`
        at the training size (original pixels in); NaN boxes have no short side."""
        t = self.to_train(xyxy)
        with np.errstate(invalid="ignore"):
            # A box grown to exactly the side comes back short by its label line's rounding.
            return (t[..., 2:] - t[..., :2]) < ASSIGNABLE_SIDE_PX - SIDE_TOLERANCE_PX

    def assignable(self, xyxy: ArrayLike) -> NDArray[np.bool_]:
        """``(...)`` both sides at least :data:`ASSIGNABLE_SIDE_PX` at the training size (original
        pixels in): the untrained head's assigner gives the box a target that is not ~0."""
        t = self.to_train(xyxy)
        with np.errstate(invalid="ignore"):
            return np.all(np.isfinite(t), axis=-1) & ~np.any(self.short_sides(xyxy), axis=-1)

    def learnable(self, xyxy: ArrayLike) -> NDArray[np.bool_]:
        """``(...)`` :meth:`reaches_loss` and :meth:`assignable`: the box can teach the detector."""
        return self.reaches_loss(xyxy) & self.assignable(xyxy)
