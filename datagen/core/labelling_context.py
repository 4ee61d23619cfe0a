"""The labelling context: everything that turns a frame's poses into its labels, built once
(from a config by :meth:`datagen.scene.resolved.Scene.resolve`, from a dataset's
``dataset.json`` by :class:`datagen.dataset.reader.DatasetMeta`), and the one call that
labels a batch of frames with it. The build writes what :meth:`LabellingContext.label_features`
and :meth:`~LabellingContext.label_objects` return and the audit recomputes with the same
calls, so that they agree by construction.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Mapping
from dataclasses import dataclass, fields
from typing import Any, Final, Literal, get_args

import numpy as np
from numpy.typing import ArrayLike, NDArray

from datagen.core.camera import Intrinsics, RollingShutter
from datagen.core.features import FeatureTable
from datagen.core.keypoints import PoseLayout, TruncatedObjects, object_boxes, object_table
from datagen.core.label_boxes import FrameLabels, SmallBoxes, compute_labels
from datagen.core.training import TrainView

__all__ = ["RULE_BOUNDS", "LabelFormat", "LabelRules", "Labelled", "LabellingContext"]

#: Which label files a dataset has: one box per feature, one pose instance per object, or both.
LabelFormat = Literal["detect", "pose", "both"]
_CHOICES: Final = {"small_boxes": SmallBoxes, "format": LabelFormat, "truncated_objects": TruncatedObjects}
#: Each numeric rule's inclusive bounds, stated once: the config's schema
#: (:class:`datagen.config.schema.LabelsConfig`) and a dataset's reader check them.
RULE_BOUNDS: Final[dict[str, tuple[float, float]]] = {
    "edge_margin_px": (0.0, 8192.0),
    "min_visible_fraction": (0.0, 1.0),
    "train_imgsz": (32, 8192),
    "min_box_px": (0.0, 512.0),
}


@dataclass(frozen=True)
class LabelRules:
    """A config's ``labels`` section as the labelling reads it (the keys and their meaning:
    :class:`datagen.config.schema.LabelsConfig`)."""

    corrected: bool
    edge_margin_px: float
    min_visible_fraction: float
    train_imgsz: int
    min_box_px: float
    small_boxes: SmallBoxes
    format: LabelFormat
    truncated_objects: TruncatedObjects

    @classmethod
    def from_mapping(cls, section: Mapping) -> LabelRules:
        """The rules of a ``labels`` mapping (a dataset's ``dataset.json``).

        Raises:
            ValueError: ``"<key>: <problem>"`` for the first key that is missing or of the
                wrong kind.
        """
        if not isinstance(section, Mapping):
            raise ValueError(f": expected a mapping, got {type(section).__name__}")
        values: dict[str, Any] = {}
        for f in fields(cls):
            if f.name not in section:
                raise ValueError(f"{f.name}: missing")
            v = section[f.name]
            if f.name in _CHOICES:
                ok = v in get_args(_CHOICES[f.name])
            elif f.type == "bool":
                ok = isinstance(v, bool)
            else:
                lo, hi = RULE_BOUNDS[f.name]
                kinds = int if f.type == "int" else int | float
                ok = isinstance(v, kinds) and not isinstance(v, bool) and math.isfinite(v) and lo <= v <= hi
            if not ok:
                raise ValueError(f"{f.name}: {v!r} is not a valid value")
            values[f.name] = float(v) if f.type == "float" else v
        return cls(**values)


@dataclass(frozen=True, eq=False)
class LabellingContext:
    """The features, the camera, the labeled objects' hulls and the rules: what labels a
    frame (frozen; pickles to worker processes)."""

    features: FeatureTable
    intrinsics: Intrinsics
    hulls: Mapping[str, NDArray[np.float64]]  # labeled object -> its mesh's convex-hull vertices (H, 3), body frame
    rules: LabelRules

    @functools.cached_property
    def train_view(self) -> TrainView:
        """How Ultralytics' trainer sees the images (``labels.train_imgsz``)."""
        return TrainView(self.intrinsics.width, self.intrinsics.height, self.rules.train_imgsz)

    @functools.cached_property
    def min_size_px(self) -> tuple[float, float]:
        """The smallest label box, original pixels per axis (``labels.min_box_px`` at the training size)."""
        return self.train_view.min_label_size_px(self.rules.min_box_px)

    @functools.cached_property
    def object_table(self) -> FeatureTable:
        """The labeled objects' hulls as a feature table (:func:`datagen.core.keypoints.object_table`)."""
        return object_table(self.features.objects, self.hulls)

    @functools.cached_property
    def pose_layout(self) -> PoseLayout:
        """Where each feature goes in a pose instance (:class:`datagen.core.keypoints.PoseLayout`)."""
        return PoseLayout.from_features(self.features)

    def _options(self) -> dict:
        r = self.rules
        return {"edge_margin_px": r.edge_margin_px, "corrected": r.corrected, "min_size_px": self.min_size_px,
                "small_boxes": r.small_boxes}

    def label_features(self, cam_from_objects: ArrayLike, distortion: ArrayLike | None = None,
                       shutter: RollingShutter | None = None) -> FrameLabels:
        """Every feature's labels (before the occlusion rule, :meth:`occlude`) in frames with
        camera-from-object transforms ``(*B, O, 4, 4)`` (``features.objects`` order), through
        each frame's lens distortion ``(*B, 5)`` and rolling shutter where given."""
        return compute_labels(self.features, cam_from_objects, self.intrinsics, **self._options(),
                              distortion=distortion, shutter=shutter)

    def label_objects(self, cam_from_objects: ArrayLike, distortion: ArrayLike | None = None,
                      shutter: RollingShutter | None = None) -> FrameLabels:
        """Every labeled object's pose box in the same frames (:func:`datagen.core.keypoints.object_boxes`)."""
        return object_boxes(self.object_table, cam_from_objects, self.intrinsics, options=self._options(),
                            distortion=distortion, truncated=self.rules.truncated_objects, shutter=shutter)

    def occlude(self, labels: FrameLabels, visible_fraction: ArrayLike | None) -> FrameLabels:
        """``labels`` under the occlusion rule (``labels.min_visible_fraction``): features whose
        visible share of points is below it are excluded as occluded. A NaN or None
        fraction (a frame that was not rendered) counts as fully visible."""
        threshold = self.rules.min_visible_fraction
        if visible_fraction is None or threshold <= 0:
            return labels
        fraction = np.asarray(visible_fraction, dtype=np.float64)
        return labels.with_visibility(np.where(np.isnan(fraction), 1.0, fraction), threshold)


class Labelled:
    """What a holder of a labelling context (``labelling``: a build's
    :class:`~datagen.scene.resolved.Scene`, a dataset's
    :class:`~datagen.dataset.reader.DatasetMeta`) reads from it by name."""

    labelling: LabellingContext

    @property
    def features(self) -> FeatureTable:
        """The feature table: every labeled feature's points and true centre, per object."""
        return self.labelling.features

    @property
    def intrinsics(self) -> Intrinsics:
        """The camera that labels (and renders) the frames."""
        return self.labelling.intrinsics

    @property
    def hulls(self) -> Mapping[str, NDArray[np.float64]]:
        """Each labeled object's convex hull vertices (its pose box)."""
        return self.labelling.hulls

    @property
    def label_rules(self) -> LabelRules:
        """The ``labels`` section of the config."""
        return self.labelling.rules

    @property
    def train_view(self) -> TrainView:
        """How Ultralytics' trainer sees the images (``labels.train_imgsz``)."""
        return self.labelling.train_view

    @property
    def object_table(self) -> FeatureTable:
        """The labeled objects' hulls as a feature table (:func:`datagen.core.keypoints.object_table`)."""
        return self.labelling.object_table

    @property
    def pose_layout(self) -> PoseLayout:
        """Where each feature goes in a pose instance (:class:`datagen.core.keypoints.PoseLayout`)."""
        return self.labelling.pose_layout
