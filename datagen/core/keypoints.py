"""Feature centres as keypoints: YOLO pose instances, their visibility flags and ``flip_idx``.

A pose instance is one *object* (its class is the object's index in
``FeatureTable.objects``), with:

- **its box**: the box of the object's projected mesh, full-object and not clipped. It is
  computed from the vertices of the mesh's convex hull (:func:`object_table`): a
  perspective projection maps the hull onto the hull of its projected vertices, so their
  min/max is exactly the box of the whole projected mesh (through a lens distortion, the box
  of the distorted hull vertices). The box then follows the feature boxes' rules
  (:mod:`datagen.core.label_boxes`, uncorrected: its centre is the box's own), widened to
  ``labels.min_box_px`` at the training size, and the object is excluded when a hull vertex is
  behind the camera or the box fails the edge rule (``off_frame``, ``edge_margin``). With
  ``labels.truncated_objects: clip`` such an object is kept when part of it is in view: its
  box is then the box of the part of the hull in front of the camera (cut at
  :data:`CLIP_DEPTH_M`), clipped to the image (a truncated instance, as COCO boxes are). A
  camera mounted on the receiver never sees the whole receiver, so only ``clip`` gives the
  receiver's keypoints (the probe) a pose instance there;
- **its keypoints**: the true centre projections of every feature of the object, in
  class-id order, in the slots ``0 .. n_o - 1`` of ``K`` (the largest feature count of the
  objects; shorter objects are padded with ``0 0 0``);
- **a flag per keypoint** (:func:`keypoint_flags`): 2 where the feature is labeled and its
  centre is visible (or the frame was not rendered, so nothing is known to hide it), 1 where
  it is labeled but the centre is hidden (the ray casts of a rendered frame), 0 where the
  feature is excluded by the rules of the detection labels (behind the camera, off the
  frame, at the edge, occluded or too small): written ``0 0 0``.

``flip_idx`` (:func:`flip_index`) maps each slot to the slot of its mirror image under a
horizontal flip. A feature's mirror is found by name (``left`` and ``right`` swapped as whole
words) and confirmed by geometry: the two centres are reflections of each other in the
object's symmetry plane (``y = y0`` in the body frame, ``y0`` fitted to the named pairs). A
feature without a side in its name mirrors to the feature at its reflected centre: itself
when it lies on the plane, its geometric twin otherwise (the ribs of a drogue). One
``flip_idx`` serves every class, so it exists only when every object agrees on every slot;
otherwise :class:`PoseLayout` carries the reason and the pose recipe keeps ``fliplr`` off.
"""

from __future__ import annotations

import dataclasses
import re
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Final, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from datagen.core.camera import Intrinsics, RollingShutter, project_xyz
from datagen.core.features import FeatureTable
from datagen.core.label_boxes import Exclusion, FrameLabels, compute_labels

__all__ = [
    "CLIP_DEPTH_M",
    "FLAG_HIDDEN",
    "FLAG_OFF",
    "FLAG_VISIBLE",
    "KEYPOINT_RANGE",
    "PoseLayout",
    "TruncatedObjects",
    "flip_index",
    "keypoint_flags",
    "mirror_name",
    "object_boxes",
    "object_table",
    "pose_rows",
]

#: Ultralytics' keypoint visibility flags: not labeled, labeled but hidden, labeled and visible.
FLAG_OFF: Final = 0
FLAG_HIDDEN: Final = 1
FLAG_VISIBLE: Final = 2
#: Ultralytics drops an image as corrupt when a normalized keypoint lies outside this range.
KEYPOINT_RANGE: Final = (-0.01, 1.01)
#: Two centres mirror each other when they agree within this share of the object's size.
_MIRROR_TOLERANCE: Final = 1e-3

#: Where ``labels.truncated_objects: clip`` cuts an object's hull in front of the camera, metres.
CLIP_DEPTH_M: Final = 1e-3
#: What happens to an object whose full box is not inside the image's margins.
TruncatedObjects = Literal["exclude", "clip"]

_SIDE: Final = re.compile(r"(?<![a-z0-9])(left|right)(?![a-z0-9])")


def mirror_name(name: str) -> str | None:
    """``name`` with ``left`` and ``right`` swapped as whole words, or None when it names no side."""
    if not _SIDE.search(name):
        return None
    return _SIDE.sub(lambda m: "right" if m.group(1) == "left" else "left", name)


def flip_index(names: list[str] | tuple[str, ...], centers: ArrayLike) -> tuple[NDArray[np.int64] | None, str | None]:
    """The mirror of each of one object's features (an involution on ``range(n)``), or
    ``(None, why)`` when one has none. ``centers``: ``(n, 3)`` body frame (y left)."""
    c = np.asarray(centers, dtype=np.float64).reshape(-1, 3)
    n = len(names)
    index = {name: i for i, name in enumerate(names)}
    named = {}
    for i, name in enumerate(names):
        twin = mirror_name(name)
        if twin is None:
            continue
        if twin not in index:
            return None, f"{name} has no {twin}"
        named[i] = index[twin]
    y0 = float(np.mean([(c[i, 1] + c[j, 1]) / 2 for i, j in named.items()])) if named else 0.0
    tol = _MIRROR_TOLERANCE * max(float(np.ptp(c, axis=0).max()) if n else 0.0, 1e-3)
    reflected = c * [1.0, -1.0, 1.0] + [0.0, 2.0 * y0, 0.0]
    out = np.empty(n, dtype=np.int64)
    for i in range(n):
        distance = np.linalg.norm(c - reflected[i], axis=1)
        if i in named:
            j = named[i]
            if distance[j] > tol:
                return None, (f"{names[i]} and {names[j]} are named a pair but are not mirror images "
                              f"({distance[j]:.3g} m apart after reflection in y = {y0:.3g} m)")
        else:
            j = int(np.argmin(distance))
            if distance[j] > tol or (j != i and j in named):
                return None, f"{names[i]} has no mirror image among the features (and no side in its name)"
        out[i] = j
    if not np.array_equal(out[out], np.arange(n)):
        return None, "the mirror pairs are not symmetric"
    return out, None


@dataclass(frozen=True, eq=False)
class PoseLayout:
    """Where each feature goes in a pose instance.

    Attributes:
        objects: the pose classes (``FeatureTable.objects``): class ``c`` is ``objects[c]``.
        slot: ``(F,)`` each feature's keypoint slot within its object's instance.
        feature_at: ``(O, K)`` the feature in each object's slot, -1 for padding.
        flip_idx: the one ``flip_idx`` of every class, or None (see ``flip_problem``).
        flip_problem: why there is no ``flip_idx``.
    """

    objects: tuple[str, ...]
    slot: NDArray[np.int64]
    feature_at: NDArray[np.int64]
    flip_idx: tuple[int, ...] | None
    flip_problem: str | None

    @property
    def kpt_count(self) -> int:
        """``K``: the largest feature count of the objects."""
        return self.feature_at.shape[1]

    @property
    def columns(self) -> int:
        """Columns of a pose label line: class, box, then ``x y v`` per keypoint."""
        return 5 + 3 * self.kpt_count

    @classmethod
    def from_features(cls, features: FeatureTable) -> PoseLayout:
        n_obj = len(features.objects)
        order = np.argsort(features.class_id, kind="stable")
        counts = np.bincount(features.object_index, minlength=n_obj)
        k = int(counts.max()) if len(features) else 0
        feature_at = np.full((n_obj, k), -1, dtype=np.int64)
        slot = np.zeros(len(features), dtype=np.int64)
        filled = np.zeros(n_obj, dtype=np.int64)
        for f in order:
            o = features.object_index[f]
            slot[f], feature_at[o, filled[o]] = filled[o], f
            filled[o] += 1
        flip = np.full(k, -1, dtype=np.int64)
        problem = None
        for o, name in enumerate(features.objects):
            members = feature_at[o, :counts[o]]
            local, why = flip_index([features.name[f] for f in members], features.center_model[members])
            if local is None:
                problem = f"{name}: {why}"
                break
            for s, t in enumerate(local):
                if flip[s] not in (-1, t):
                    a, b = features.name[members[s]], features.name[members[t]]
                    other = next(p for p in range(o) if counts[p] > s)
                    problem = (f"slot {s} mirrors to slot {t} on {name} ({a} -> {b}) but to slot {flip[s]} on "
                               f"{features.objects[other]}: no single flip_idx fits every class")
                    break
                flip[s] = t
            if problem:
                break
        if problem is None:
            flip[flip < 0] = np.flatnonzero(flip < 0)  # slots no object fills map to themselves
        flip_idx = None if problem else tuple(int(t) for t in flip)
        for a in (slot, feature_at):
            a.setflags(write=False)
        return cls(tuple(features.objects), slot, feature_at, flip_idx, problem)

    def names(self, features: FeatureTable) -> list[list[str]]:
        """Each object's keypoint names (its features' names), in slot order, without padding."""
        return [[features.name[f] for f in row if f >= 0] for row in self.feature_at]


def keypoint_flags(exclusion: ArrayLike, center_visible: ArrayLike | None = None) -> NDArray[np.int8]:
    """``(..., F)`` Ultralytics visibility flags from the features' exclusion codes and (for a
    rendered frame) whether each centre is visible: 0 excluded, 1 hidden, 2 visible or not known."""
    labeled = np.asarray(exclusion) == 0
    flags = np.where(labeled, FLAG_VISIBLE, FLAG_OFF).astype(np.int8)
    if center_visible is not None:
        visible = np.asarray(center_visible, dtype=np.float64)
        flags[labeled & (visible == 0)] = FLAG_HIDDEN  # NaN (unknown) stays visible
    return flags


def object_table(objects: tuple[str, ...], hulls: Mapping[str, NDArray[np.float64]]) -> FeatureTable:
    """The objects' convex-hull vertices as a :class:`FeatureTable` (one 'feature' per object,
    in the order of ``objects``), so that :func:`datagen.core.label_boxes.compute_labels` with
    ``corrected=False`` gives each object's box, size rule and exclusion."""
    return FeatureTable.from_point_sets([hulls[o] for o in objects], objects=list(objects),
                                        names=list(objects), sizes=["object"] * len(objects))


def pose_rows(objects: FrameLabels, keypoints_px: ArrayLike, flags: ArrayLike, layout: PoseLayout,
              width: int, height: int) -> NDArray[np.float64]:
    """One frame's pose lines as rows ``class cx cy w h (x y v) * K``, normalized by W and H:
    one per labeled object, in class order; keypoints of flag 0 and padding are ``0 0 0``."""
    if objects.exclusion.ndim != 1:
        raise ValueError(f"pose_rows takes one frame, got batch shape {objects.exclusion.shape[:-1]}")
    uv = np.asarray(keypoints_px, dtype=np.float64)
    flags = np.asarray(flags)
    keep = np.flatnonzero(objects.labeled)
    rows = np.zeros((len(keep), layout.columns))
    centre, box = objects.label_center_px, objects.label_xyxy
    for r, c in enumerate(keep):
        rows[r, :5] = (c, centre[c, 0] / width, centre[c, 1] / height,
                       (box[c, 2] - box[c, 0]) / width, (box[c, 3] - box[c, 1]) / height)
        members = layout.feature_at[c]
        real = members >= 0
        f = members[real]
        on = flags[f] > 0
        kp = np.zeros((len(members), 3))
        kp[np.flatnonzero(real)[on]] = np.column_stack([uv[f[on], 0] / width, uv[f[on], 1] / height, flags[f[on]]])
        rows[r, 5:] = kp.ravel()
    return rows


def object_boxes(table: FeatureTable, cam_from_objects: ArrayLike, intrinsics: Intrinsics, *, options: dict,
                 distortion: ArrayLike | None = None, truncated: TruncatedObjects = "exclude",
                 shutter: RollingShutter | None = None) -> FrameLabels:
    """Each object's pose box over any batch of frames (:func:`object_table` rows; ``options``:
    the keyword arguments of :func:`~datagen.core.label_boxes.compute_labels`, whose ``corrected``
    is ignored). ``truncated="clip"`` keeps an object cut by the image border or the camera
    plane with the box of its in-view part (module docstring; the part's box is of the frame's
    time, without the rolling ``shutter`` that moves every other box)."""
    cam_from_objects = np.asarray(cam_from_objects, dtype=np.float64)
    labels = compute_labels(table, cam_from_objects, intrinsics, **{**options, "corrected": False},
                            distortion=distortion, shutter=shutter)
    if truncated == "exclude":
        return labels
    if truncated != "clip":
        raise ValueError(f"truncated must be 'exclude' or 'clip', got {truncated!r}")
    cut = np.isin(labels.exclusion, (Exclusion.BEHIND_CAMERA, Exclusion.OFF_FRAME, Exclusion.EDGE_MARGIN))
    box = labels.tight_xyxy.copy()
    lens = None if distortion is None else np.asarray(distortion, dtype=np.float64)
    for index in zip(*np.nonzero(labels.exclusion == Exclusion.BEHIND_CAMERA), strict=True):
        frame_lens = None if lens is None else lens[index[:-1]]
        box[index] = _front_box(table.point_set(index[-1]), cam_from_objects[index], intrinsics, frame_lens)
    w, h = intrinsics.width, intrinsics.height
    with np.errstate(invalid="ignore"):
        clipped = np.clip(box, 0.0, [w, h, w, h])
        keep = cut & (clipped[..., 2] > clipped[..., 0]) & (clipped[..., 3] > clipped[..., 1])
    return dataclasses.replace(labels, label_xyxy=np.where(keep[..., None], clipped, labels.label_xyxy),
                               exclusion=np.where(keep, np.int8(Exclusion.NONE), labels.exclusion).astype(np.int8))


def _front_box(points_model: NDArray[np.float64], cam_from_model: NDArray[np.float64], intrinsics: Intrinsics,
               distortion: NDArray[np.float64] | None) -> NDArray[np.float64]:
    """The box of the projection of the hull of ``points_model`` cut at depth
    :data:`CLIP_DEPTH_M`: the vertices in front and, for every pair of a vertex in front and
    one behind, the point where their segment (inside the hull) crosses the cut; NaN when no
    vertex is in front."""
    p = points_model @ cam_from_model[:3, :3].T + cam_from_model[:3, 3]
    front = p[:, 2] >= CLIP_DEPTH_M
    if not front.any():
        return np.full(4, np.nan)
    a, b = p[front], p[~front]
    t = (CLIP_DEPTH_M - a[:, None, 2]) / (b[None, :, 2] - a[:, None, 2])
    crossing = a[:, None, :] + t[..., None] * (b[None, :, :] - a[:, None, :])
    pts = np.concatenate([a, crossing.reshape(-1, 3)])
    u, v = project_xyz(pts[:, 0], pts[:, 1], np.maximum(pts[:, 2], CLIP_DEPTH_M), intrinsics, distortion)
    return np.array([u.min(), v.min(), u.max(), v.max()])
