"""Corrected YOLO labels (paper 3.2, Figs 8-10), pure numpy, all features at once.

For each feature in each frame:

1. project its points and its true 3D centre (continuous pixels);
2. **tight box**: min/max of the projected points; its centre is the
   *perceived* centre, which parallax moves away from the true one;
3. **corrected box**: the two sides facing the true centre grow by
   ``2*dx`` and ``2*dy`` (``d = true - perceived``), so the box is centred on the
   true centre and contains the tight box. Equivalently the half-size per axis
   is ``max(true - lo, hi - true)``, which is how it is computed here (exact
   centre, no cancellation);
4. **exclusion**, in this order of precedence:

   - ``behind_camera``: a point or the centre is at or behind the camera plane;
   - ``off_frame``: the label box reaches outside ``[0, W] x [0, H]``;
   - ``edge_margin``: the label box lies inside the image but closer than
     ``edge_margin_px`` to a border. A side exactly at the margin is allowed;
   - ``too_small`` (only with ``small_boxes="exclude"``): a side of the box is
     shorter than ``min_size_px``.

The *label box* (the box written to the label file) starts as the corrected
box, or the tight box when ``corrected`` is false (the paper's uncorrected
ablation, model H). A detector can only learn boxes of a few pixels at its
training size (:mod:`datagen.core.training`), so with ``small_boxes="grow"`` a side
shorter than ``min_size_px`` is widened symmetrically about the box's centre
(the true centre when corrected) to exactly that size, or as far as the edge margin
allows where the centre is closer to a border: the centre does not move and the label
box contains the corrected (or tight) box. The exclusion rules apply to the label
box, so growing never excludes a feature. Only features with no exclusion become YOLO lines.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from enum import IntEnum
from typing import Final, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from datagen.core.camera import Intrinsics, RollingShutter, depth_in_front, project_rolling, project_xyz
from datagen.core.features import FeatureTable

__all__ = [
    "Exclusion",
    "FrameLabels",
    "SmallBoxes",
    "boxes_from_uv",
    "compute_labels",
]


class Exclusion(IntEnum):
    """Why a feature is not labeled in a frame (``NONE``: it is)."""

    NONE = 0
    BEHIND_CAMERA = 1
    OFF_FRAME = 2
    EDGE_MARGIN = 3
    OCCLUDED = 4  # only with labels.min_visible_fraction > 0 and a rendered frame
    TOO_SMALL = 5  # only with small_boxes="exclude"

    @property
    def reason(self) -> str | None:
        """The name recorded in manifests: ``None`` or e.g. ``"edge_margin"``."""
        return None if self is Exclusion.NONE else self.name.lower()

    @property
    def meaning(self) -> str:
        """What the reason says of a feature in a frame, in a phrase."""
        return _MEANINGS[self]


_MEANINGS: Final = {
    Exclusion.NONE: "labeled",
    Exclusion.BEHIND_CAMERA: "a point or the centre at or behind the camera plane",
    Exclusion.OFF_FRAME: "the label box reaches outside the image",
    Exclusion.EDGE_MARGIN: "the label box inside the image but closer than labels.edge_margin_px to a border",
    Exclusion.OCCLUDED: "fewer than labels.min_visible_fraction of its points visible in the rendered frame",
    Exclusion.TOO_SMALL: "a side of the label box under the size a detector can learn (labels.small_boxes: exclude)",
}


@dataclass(frozen=True, eq=False)
class FrameLabels:
    """Labels of ``F`` features over any leading batch shape ``B`` (frames).

    All boxes are ``xyxy`` in continuous pixels.

    Attributes:
        center_px: ``(*B, F, 2)`` projection of each feature's true 3D centre.
        tight_xyxy: ``(*B, F, 4)`` tight box of the projected points.
        corrected_xyxy: ``(*B, F, 4)`` box centred on ``center_px`` containing the tight box.
        label_xyxy: ``(*B, F, 4)`` the box written to the label file: the corrected (or
            tight) box, widened to the minimum size where ``small_boxes`` is ``"grow"``.
        exclusion: ``(*B, F)`` int8 :class:`Exclusion` codes.
        corrected: whether labels use the corrected box.
    """

    center_px: NDArray[np.float64]
    tight_xyxy: NDArray[np.float64]
    corrected_xyxy: NDArray[np.float64]
    label_xyxy: NDArray[np.float64]
    exclusion: NDArray[np.int8]
    corrected: bool

    @property
    def labeled(self) -> NDArray[np.bool_]:
        return self.exclusion == Exclusion.NONE

    @property
    def label_center_px(self) -> NDArray[np.float64]:
        """``(*B, F, 2)`` centre of the label box; exactly ``center_px`` when corrected."""
        if self.corrected:
            return self.center_px
        return 0.5 * (self.label_xyxy[..., :2] + self.label_xyxy[..., 2:])

    def with_visibility(self, visible_fraction: ArrayLike, min_visible_fraction: float) -> FrameLabels:
        """These labels with features whose visible share of points is below
        ``min_visible_fraction`` excluded as ``OCCLUDED`` (other exclusions kept).
        A threshold of 0 changes nothing: occluded features stay labeled."""
        fraction = np.asarray(visible_fraction, dtype=np.float64)
        if fraction.shape != self.exclusion.shape:
            raise ValueError(f"visible_fraction has shape {fraction.shape}, labels {self.exclusion.shape}")
        occluded = (self.exclusion == Exclusion.NONE) & (fraction < min_visible_fraction)
        exclusion = np.where(occluded, np.int8(Exclusion.OCCLUDED), self.exclusion).astype(np.int8)
        return dataclasses.replace(self, exclusion=exclusion)

    def frame(self, index: int | tuple[int, ...]) -> FrameLabels:
        """The labels of one frame of a batch."""
        return FrameLabels(
            center_px=self.center_px[index],
            tight_xyxy=self.tight_xyxy[index],
            corrected_xyxy=self.corrected_xyxy[index],
            label_xyxy=self.label_xyxy[index],
            exclusion=self.exclusion[index],
            corrected=self.corrected,
        )


#: What happens to a label box with a side under the minimum size: widened about its
#: centre, or the feature excluded as ``too_small``.
SmallBoxes = Literal["grow", "exclude"]


def boxes_from_uv(
    uv_points: ArrayLike,
    uv_center: ArrayLike,
    front: ArrayLike,
    *,
    width: int,
    height: int,
    edge_margin_px: float,
    corrected: bool = True,
    min_size_px: float | tuple[float, float] = 0.0,
    small_boxes: SmallBoxes = "grow",
) -> FrameLabels:
    """Boxes and exclusions from projected points.

    Args:
        uv_points: ``(*B, F, P, 2)`` projected feature points (padding allowed
            by repetition). Values for features not in front are ignored.
        uv_center: ``(*B, F, 2)`` projected true centres.
        front: ``(*B, F)`` whether every point and the centre lie in front
            of the camera plane.
        width, height: image size in pixels.
        edge_margin_px: minimum distance of the label box from every border.
        corrected: label with the corrected box (else the tight box).
        min_size_px: smallest label box side, pixels (one value, or width and height).
        small_boxes: ``"grow"`` a smaller box about its centre, or ``"exclude"`` the feature.

    One feature whose points span 100-110 px across and 100-120 px down, its true centre
    projected at (103, 105): the tight box is centred on (105, 110), the perceived centre;
    the corrected box on (103, 105), the true one, and it contains the tight box:

    >>> labels = boxes_from_uv([[[100, 100], [110, 100], [100, 120]]], [[103, 105]], [True],
    ...                        width=640, height=480, edge_margin_px=10)
    >>> labels.tight_xyxy.tolist(), labels.corrected_xyxy.tolist()
    ([[100.0, 100.0, 110.0, 120.0]], [[96.0, 90.0, 110.0, 120.0]])
    >>> labels.label_center_px.tolist(), Exclusion(int(labels.exclusion[0])).name
    ([[103.0, 105.0]], 'NONE')

    Moved left so that its corrected box starts 8 px from the border (inside the image but
    within the 10 px margin), and then past the border:

    >>> for left in (12, 0):
    ...     labels = boxes_from_uv([[[left, 100], [left + 10, 100], [left, 120]]], [[left + 3, 105]], [True],
    ...                            width=640, height=480, edge_margin_px=10)
    ...     print(labels.corrected_xyxy[0, 0], Exclusion(int(labels.exclusion[0])).name)
    8.0 EDGE_MARGIN
    -4.0 OFF_FRAME
    """
    uv_points = np.asarray(uv_points, dtype=np.float64)
    center = np.asarray(uv_center, dtype=np.float64)
    return _boxes(uv_points[..., 0], uv_points[..., 1], center, np.asarray(front, dtype=bool),
                  width=width, height=height, edge_margin_px=edge_margin_px, corrected=corrected,
                  min_size_px=min_size_px, small_boxes=small_boxes)


def _min_size(min_size_px: float | tuple[float, float]) -> NDArray[np.float64]:
    size = np.broadcast_to(np.asarray(min_size_px, dtype=np.float64), (2,)).copy()
    if not np.all(np.isfinite(size) & (size >= 0.0)):
        raise ValueError(f"min_size_px must be finite and not negative, got {min_size_px}")
    return size


def _boxes(
    u: NDArray[np.float64],
    v: NDArray[np.float64],
    center: NDArray[np.float64],
    front: NDArray[np.bool_],
    *,
    width: int,
    height: int,
    edge_margin_px: float,
    corrected: bool,
    min_size_px: float | tuple[float, float],
    small_boxes: SmallBoxes,
) -> FrameLabels:
    """:func:`boxes_from_uv` on point coordinates ``u``, ``v`` of shape ``(*B, F, P)``."""
    if small_boxes not in ("grow", "exclude"):
        raise ValueError(f"small_boxes must be 'grow' or 'exclude', got {small_boxes!r}")
    need = _min_size(min_size_px)
    lo = np.stack([u.min(axis=-1), v.min(axis=-1)], axis=-1)
    hi = np.stack([u.max(axis=-1), v.max(axis=-1)], axis=-1)
    tight = np.concatenate([lo, hi], axis=-1)
    half = np.maximum(center - lo, hi - center)
    # min/max guard the containment against rounding in center -/+ half; the
    # centre stays within a few ulps of the true centre.
    corrected_box = np.concatenate(
        [np.minimum(lo, center - half), np.maximum(hi, center + half)], axis=-1
    )
    box = corrected_box if corrected else tight
    with np.errstate(invalid="ignore"):
        small = (box[..., 2:] - box[..., :2]) < need  # (*B, F, 2); NaN boxes are never small
    m = float(edge_margin_px)
    if small_boxes == "grow" and small.any():
        centre = center if corrected else 0.5 * (lo + hi)
        # Grown no further than the edge margin allows: a feature near a border keeps its
        # line (with a smaller box) instead of becoming an unlabeled feature the detector
        # would learn as background. A box already past the margin is excluded below.
        far = np.array([width, height], dtype=np.float64) - m
        with np.errstate(invalid="ignore"):
            grow = np.maximum(np.minimum(need / 2, np.minimum(centre - m, far - centre)), 0.0)
            # The clamps only absorb rounding: a side grown to the margin lands on it exactly.
            grown = np.concatenate([np.minimum(box[..., :2], np.maximum(centre - grow, m)),
                                    np.maximum(box[..., 2:], np.minimum(centre + grow, far))], axis=-1)
        box = np.where(np.concatenate([small, small], axis=-1), grown, box)
    too_small = small.any(axis=-1) if small_boxes == "exclude" else np.zeros(front.shape, dtype=bool)

    x0, y0, x1, y1 = np.moveaxis(box, -1, 0)
    with np.errstate(invalid="ignore"):
        inside_image = (x0 >= 0.0) & (y0 >= 0.0) & (x1 <= width) & (y1 <= height)
        inside_margin = (x0 >= m) & (y0 >= m) & (x1 <= width - m) & (y1 <= height - m)
    exclusion = np.full(front.shape, Exclusion.NONE, dtype=np.int8)
    exclusion[too_small] = Exclusion.TOO_SMALL
    exclusion[~inside_margin] = Exclusion.EDGE_MARGIN
    exclusion[~inside_image] = Exclusion.OFF_FRAME
    exclusion[~front] = Exclusion.BEHIND_CAMERA
    return FrameLabels(
        center_px=center,
        tight_xyxy=tight,
        corrected_xyxy=corrected_box,
        label_xyxy=box,
        exclusion=exclusion,
        corrected=corrected,
    )


def compute_labels(
    features: FeatureTable,
    cam_from_objects: ArrayLike,
    intrinsics: Intrinsics,
    *,
    edge_margin_px: float = 10.0,
    corrected: bool = True,
    min_size_px: float | tuple[float, float] = 0.0,
    small_boxes: SmallBoxes = "grow",
    distortion: ArrayLike | None = None,
    shutter: RollingShutter | None = None,
) -> FrameLabels:
    """Labels for every feature of ``features`` in one or many frames.

    Args:
        features: the dataset's feature table (``F`` features, ``O`` objects).
        cam_from_objects: ``(*B, O, 4, 4)`` OpenCV-camera-from-object transforms,
            columns in the order of ``features.objects``.
        intrinsics: the camera (shared by all frames of the batch).
        edge_margin_px: minimum distance of a labeled box from every border.
        corrected: use corrected boxes (paper 3.2) rather than tight ones.
        min_size_px: smallest side of a label box in pixels, one value or ``(width,
            height)`` (:meth:`datagen.core.training.TrainView.min_label_size_px` converts
            ``labels.min_box_px`` at the training size); 0 keeps every box as it is.
        small_boxes: ``"grow"`` smaller label boxes about their centre, or
            ``"exclude"`` their features as ``too_small``.
        distortion: ``(*B, 5)`` OpenCV lens distortion per frame (``k1, k2, p1, p2, k3``),
            or None for the pinhole: points, centres and boxes are projected through it.
        shutter: the frames' rolling shutters (readouts ``(*B,)``, object rates ``(*B, O, 4,
            4)``), or None for a global one: each point is projected where it was when its
            row was exposed (:func:`~datagen.core.camera.project_rolling`).

    Returns:
        :class:`FrameLabels` with leading shape ``B``.
    """
    cam_from_objects = np.asarray(cam_from_objects, dtype=np.float64)
    n_obj = len(features.objects)
    if cam_from_objects.shape[-3:] != (n_obj, 4, 4):
        raise ValueError(
            f"cam_from_objects must have shape (..., {n_obj}, 4, 4) for objects "
            f"{features.objects}, got {cam_from_objects.shape}"
        )
    # Each feature's object transform, (*B, F, 3, 4), with a trailing axis for points.
    cam_from_model = cam_from_objects[..., features.object_index, :3, :, None]
    # Points then the centre as one extra point, one array per model axis: (F, P + 1).
    px, py, pz = features.points_and_center_by_axis
    x, y, z = (
        cam_from_model[..., i, 0, :] * px
        + cam_from_model[..., i, 1, :] * py
        + cam_from_model[..., i, 2, :] * pz
        + cam_from_model[..., i, 3, :]
        for i in range(3)
    )
    if distortion is not None:  # one row per frame, against (*B, F, P + 1) coordinates
        distortion = np.asarray(distortion, dtype=np.float64)[..., None, None, :]
    if shutter is not None and shutter.any:
        rate_model = shutter.cam_from_objects_per_s[..., features.object_index, :3, :, None]
        rate = tuple(rate_model[..., i, 0, :] * px + rate_model[..., i, 1, :] * py + rate_model[..., i, 2, :] * pz
                     + rate_model[..., i, 3, :] for i in range(3))
        u, v, z = project_rolling(x, y, z, rate, intrinsics, distortion, shutter.readout_s[..., None, None])
    else:
        u, v = project_xyz(x, y, z, intrinsics, distortion)
    center = np.stack([u[..., -1], v[..., -1]], axis=-1)
    return _boxes(
        u[..., :-1],
        v[..., :-1],
        center,
        np.all(depth_in_front(z), axis=-1),
        width=intrinsics.width,
        height=intrinsics.height,
        edge_margin_px=edge_margin_px,
        corrected=corrected,
        min_size_px=min_size_px,
        small_boxes=small_boxes,
    )
