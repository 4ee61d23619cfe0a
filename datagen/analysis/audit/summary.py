"""The audit's statistics as typed values, each with its JSON form (``to_json``: the
``stats`` of ``report.json``, key for key): the tight-box centre drift by distance, size and
obliqueness, labels per class, exclusions, visibility, PnP coverage, distance coverage, what
Ultralytics' trainer can learn of the label lines and pose instances, and the appearance
draws. :mod:`.statistics` and the check groups compute them; the report, its plots and the
command read their fields."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

__all__ = [
    "AppearanceColumn",
    "AuditStatistics",
    "DistanceCoverage",
    "DriftBin",
    "DriftStatistics",
    "DriftSummary",
    "Learnability",
    "LearnableBin",
    "LearnableShare",
    "PnPCoverage",
    "PoseLearnability",
    "Visibility",
]


@dataclass(frozen=True)
class DriftSummary:
    """The tight-box centre drift (px) of some features: how many, and their mean, median,
    95th percentile and maximum (None: no feature)."""

    count: int
    mean: float | None = None
    median: float | None = None
    p95: float | None = None
    max: float | None = None

    def to_json(self) -> dict[str, Any]:
        if not self.count:
            return {"count": 0}
        return {"count": self.count, "mean": self.mean, "median": self.median, "p95": self.p95, "max": self.max}


@dataclass(frozen=True)
class DriftBin:
    """The drift of the features whose distance (m) or obliqueness (degrees) lies in ``[lo, hi)``."""

    lo: float
    hi: float
    drift: DriftSummary

    def to_json(self) -> dict[str, Any]:
        return {"lo": self.lo, "hi": self.hi, **self.drift.to_json()}


@dataclass(frozen=True)
class DriftStatistics:
    """The tight-box centre drift from the true centre's projection: of every feature in view,
    by distance, by feature size and by view obliqueness (paper Fig. 8)."""

    overall: DriftSummary
    by_distance_m: tuple[DriftBin, ...]
    by_size: dict[str, DriftSummary]
    by_obliqueness_deg: tuple[DriftBin, ...]

    def to_json(self) -> dict[str, Any]:
        o = self.overall
        return {"features": o.count, "mean": o.mean, "median": o.median, "p95": o.p95, "max": o.max,
                "by_distance_m": [b.to_json() for b in self.by_distance_m],
                "by_size": {tag: s.to_json() for tag, s in self.by_size.items()},
                "by_obliqueness_deg": [b.to_json() for b in self.by_obliqueness_deg]}


@dataclass(frozen=True)
class Visibility:
    """The labeled features' visibility in rendered frames: how many, a 10-bin histogram of
    their visible fractions, and the shares fully visible and with their centre visible
    (None: nothing rendered)."""

    labeled_features_rendered: int
    visible_fraction_histogram: list[int]
    share_fully_visible: float | None
    share_centre_visible: float | None

    def to_json(self) -> dict[str, Any]:
        return dataclasses.asdict(self)


@dataclass(frozen=True)
class PnPCoverage:
    """An object's frames with fewer than three labeled features (no PnP), their share, and
    the median count of its labeled features in a frame."""

    frames_below_3: int
    share_below_3: float
    median_labeled: float

    def to_json(self) -> dict[str, Any]:
        return dataclasses.asdict(self)


@dataclass(frozen=True)
class DistanceCoverage:
    """Frames per 5 m distance bin (``edges_m``: the bins' edges)."""

    edges_m: list[float]
    frames: list[int]

    def to_json(self) -> dict[str, Any]:
        return dataclasses.asdict(self)


@dataclass(frozen=True)
class LearnableShare:
    """Label lines and the share of them Ultralytics' trainer can learn from (None: no line)."""

    lines: int
    share: float | None

    def to_json(self) -> dict[str, Any]:
        return {"lines": self.lines, "share": self.share}


@dataclass(frozen=True)
class LearnableBin:
    """The learnable share of the lines whose frame's distance (m) lies in ``[lo, hi)``."""

    lo: float
    hi: float
    lines: LearnableShare

    def to_json(self) -> dict[str, Any]:
        return {"lo": self.lo, "hi": self.hi, **self.lines.to_json()}


@dataclass(frozen=True)
class Learnability:
    """What Ultralytics' trainer can learn of the detection label lines at ``train_imgsz``
    (:mod:`datagen.core.training`): the shares that survive its transforms, hold an anchor
    centre, can be assigned, or reached the edge margin; the smallest sides at the training
    size; and the learnable share by distance, size and class (the ten worst classes)."""

    train_imgsz: int
    min_box_px: float
    small_boxes: str
    threshold: float
    lines: int
    share: float | None
    share_survive_2px: float | None
    share_with_anchor: float | None
    share_assignable: float | None
    share_at_edge_margin: float | None
    assignable_side_px: float
    min_side_train_median_px: float | None
    min_side_train_px: float | None
    by_distance_m: tuple[LearnableBin, ...]
    by_size: dict[str, LearnableShare]
    by_class: dict[str, LearnableShare]

    @property
    def worst_classes(self) -> list[tuple[str, LearnableShare]]:
        """The ten classes (at most) with the smallest learnable share under 1, worst first."""
        ranked = sorted(self.by_class.items(), key=lambda kv: kv[1].share if kv[1].share is not None else 1.0)
        return [(name, s) for name, s in ranked if s.share is not None and s.share < 1.0][:10]

    def to_json(self) -> dict[str, Any]:
        return {
            "train_imgsz": self.train_imgsz, "min_box_px": self.min_box_px, "small_boxes": self.small_boxes,
            "threshold": self.threshold, "lines": self.lines, "share": self.share,
            "share_survive_2px": self.share_survive_2px, "share_with_anchor": self.share_with_anchor,
            "share_assignable": self.share_assignable, "share_at_edge_margin": self.share_at_edge_margin,
            "assignable_side_px": self.assignable_side_px,
            "min_side_train_px": {"median": self.min_side_train_median_px, "min": self.min_side_train_px},
            "by_distance_m": [b.to_json() for b in self.by_distance_m],
            "by_size": {tag: s.to_json() for tag, s in self.by_size.items()},
            "by_class": {name: s.to_json() for name, s in self.by_class.items()},
            "worst_classes": [{"class": name, **s.to_json()} for name, s in self.worst_classes],
        }


@dataclass(frozen=True)
class PoseLearnability:
    """The pose instances (one per labeled object), those Ultralytics' trainer keeps at
    ``imgsz`` with an anchor centre, and their share (None: no instance)."""

    instances: int
    learnable: int
    share: float | None
    imgsz: int

    def to_json(self) -> dict[str, Any]:
        return dataclasses.asdict(self)


@dataclass(frozen=True)
class AppearanceColumn:
    """How many frames drew a manifest column of the appearance, and the draws: counts per
    value (names and flags) or the range, mean and a histogram over ``edges`` (numbers)."""

    frames: int
    values: dict[str, int] | None = None
    min: float | None = None
    max: float | None = None
    mean: float | None = None
    edges: list[float] | None = None
    histogram: list[int] | None = None

    def to_json(self) -> dict[str, Any]:
        return {"frames": self.frames, **{k: v for k, v in dataclasses.asdict(self).items()
                                          if k != "frames" and v is not None}}


@dataclass(frozen=True)
class AuditStatistics:
    """Every statistic of an audit (:func:`datagen.analysis.audit.audit`); ``learnable`` and
    ``learnable_pose`` where the dataset has detection and pose labels; ``appearance`` per
    dimension (:data:`datagen.dataset.columns.APPEARANCE`) and column."""

    drift: DriftStatistics
    labels_per_class: dict[str, int]
    exclusions: dict[str, int]
    visibility: Visibility
    pnp: dict[str, PnPCoverage]
    coverage: DistanceCoverage
    appearance: dict[str, dict[str, AppearanceColumn]]
    learnable: Learnability | None = None
    learnable_pose: PoseLearnability | None = None

    def to_json(self) -> dict[str, Any]:
        out: dict[str, Any] = {
            "tight_drift_px": self.drift.to_json(),
            "labels_per_class": self.labels_per_class,
            "exclusions": self.exclusions,
            "visibility": self.visibility.to_json(),
            "pnp_below_3_features": {obj: p.to_json() for obj, p in self.pnp.items()},
            "distance_coverage": self.coverage.to_json(),
        }
        if self.learnable is not None:
            out["learnable"] = self.learnable.to_json()
        if self.learnable_pose is not None:
            out["learnable_pose"] = self.learnable_pose.to_json()
        out["appearance"] = {dimension: {name: c.to_json() for name, c in columns.items()}
                             for dimension, columns in self.appearance.items()}
        return out
