"""How well a detector finds the features: its detections scored against the true centres.

The paper keeps, per image and class, the detection of highest confidence at or above
a threshold and uses its box centre as the feature's 2D point (3.3). This module scores
exactly those points (:class:`datagen.analysis.predictions.Predictions`) against the
projection of each feature's true 3D centre (``center_px`` of the manifests), per
feature of every frame of the scored split:

- **matched**: a labeled feature whose class was detected within ``match_px`` of its true centre;
- **mislocated**: a labeled feature whose class was detected further away;
- **missed**: a labeled feature whose class was not detected;
- **spurious**: a detection of a class the frame does not label (behind the camera, off
  the frame, in the edge margin, or not there at all).

For each detected labeled feature the centre error ``detection - true centre`` is kept
as a vector, and its component along the feature's *parallax direction*: the direction
from the true centre to the centre of its tight box (the perceived centre, paper
Fig. 8). A detector trained on corrected boxes should show no bias along it; one
trained on tight boxes should be pulled towards the perceived centre, by about the
offset the manifests record.
"""

from __future__ import annotations

import dataclasses
import itertools
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Final

import numpy as np
from numpy.typing import NDArray

from datagen.core.training import MATCH_PX
from datagen.dataset.reader import DatasetMeta, DatasetView

__all__ = ["DetectionScores", "DetectorBin", "DetectorCounts", "DetectorSummary", "score_detections",
           "summarize_detections"]

#: A parallax offset shorter than this (px) has no direction; such features have no signed error.
_MIN_PARALLAX_PX: Final = 1e-6


@dataclass(frozen=True)
class DetectionScores:
    """One row per (frame, class) that is labeled or detected, in frame then class order.

    Attributes:
        frame_id, class_id: ``(N,)`` the frame and the feature class.
        distance_m: ``(N,)`` the frame's probe-to-drogue distance.
        labeled, detected: ``(N,)`` the frame labels the feature; the detector reported its class.
        conf: ``(N,)`` the detection's confidence (NaN where not detected).
        error_uv: ``(N, 2)`` detection centre minus true centre, px (NaN where not detected).
        parallax_uv: ``(N, 2)`` tight-box centre minus true centre, px (NaN where the feature
            is behind the camera).
        match_px: the match radius.
        frames: frames scored; ``frames_without_file``: of those, frames with no prediction file.
        names: class names by class id.
    """

    frame_id: NDArray[np.int64]
    class_id: NDArray[np.int64]
    distance_m: NDArray[np.float64]
    labeled: NDArray[np.bool_]
    detected: NDArray[np.bool_]
    conf: NDArray[np.float64]
    error_uv: NDArray[np.float64]
    parallax_uv: NDArray[np.float64]
    match_px: float
    frames: int
    frames_without_file: int
    names: tuple[str, ...]

    @property
    def error_px(self) -> NDArray[np.float64]:
        return np.hypot(self.error_uv[:, 0], self.error_uv[:, 1])

    @property
    def matched(self) -> NDArray[np.bool_]:
        with np.errstate(invalid="ignore"):
            return self.labeled & self.detected & (self.error_px <= self.match_px)

    @property
    def mislocated(self) -> NDArray[np.bool_]:
        return self.labeled & self.detected & ~self.matched

    @property
    def missed(self) -> NDArray[np.bool_]:
        return self.labeled & ~self.detected

    @property
    def spurious(self) -> NDArray[np.bool_]:
        return self.detected & ~self.labeled

    @property
    def parallax_px(self) -> NDArray[np.float64]:
        return np.hypot(self.parallax_uv[:, 0], self.parallax_uv[:, 1])

    @property
    def along_parallax_px(self) -> NDArray[np.float64]:
        """``(N,)`` the centre error's component along the parallax direction (positive:
        towards the perceived centre); NaN where undetected or without a direction."""
        length = self.parallax_px
        with np.errstate(invalid="ignore", divide="ignore"):
            unit = self.parallax_uv / length[:, None]
            along = np.einsum("ij,ij->i", self.error_uv, unit)
        return np.where(length > _MIN_PARALLAX_PX, along, np.nan)


def _frame_rows(view: DatasetView, rows: NDArray[np.int64], predictions: Mapping) -> dict[str, NDArray]:
    """The (frame, class) rows of ``rows`` of ``view``."""
    n_features = len(view.features)
    stems = view.stems
    det = np.full((len(rows), n_features, 2), np.nan)
    conf = np.full((len(rows), n_features), np.nan)
    missing = 0
    for j, i in enumerate(rows.tolist()):
        found = predictions.get(stems[i])
        if found is None:
            missing += 1
            continue
        for cls, (u, v, c) in found.items():
            det[j, cls] = (u, v)
            conf[j, cls] = c
    labeled = view.labeled[rows]
    detected = np.isfinite(det[..., 0])
    centre = view.center_px[rows]
    tight = view.tight_xyxy[rows]
    parallax = 0.5 * (tight[..., :2] + tight[..., 2:]) - centre
    keep = labeled | detected
    b, f = np.nonzero(keep)
    return {"frame_id": view.frame_id[rows][b], "class_id": f.astype(np.int64),
            "distance_m": view.distance_m[rows][b], "labeled": labeled[b, f], "detected": detected[b, f],
            "conf": conf[b, f], "error_uv": (det - centre)[b, f], "parallax_uv": parallax[b, f],
            "missing": np.array([missing]), "frames": np.array([len(rows)])}


_NO_ROWS: Final = {"frame_id": np.zeros(0, np.int64), "class_id": np.zeros(0, np.int64),
                   "distance_m": np.zeros(0), "labeled": np.zeros(0, bool), "detected": np.zeros(0, bool),
                   "conf": np.zeros(0), "error_uv": np.zeros((0, 2)), "parallax_uv": np.zeros((0, 2)),
                   "missing": np.zeros(1, np.int64), "frames": np.zeros(1, np.int64)}


def score_detections(dataset: DatasetMeta, predictions: Mapping, *, split: str | None = None,
                     match_px: float = MATCH_PX) -> DetectionScores:
    """Score ``predictions`` (per image stem, per class ``(u_px, v_px, conf)``: the points PnP
    uses) on every frame of ``split`` (all frames when None); a frame without a prediction
    file has no detections. A source is read one shard at a time."""
    parts = [_frame_rows(view, rows, predictions) for view, rows in dataset.walk(split=split)]
    if not parts:
        parts = [_NO_ROWS]
    cat = {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}
    order = np.lexsort((cat["class_id"], cat["frame_id"]))
    return DetectionScores(
        frame_id=cat["frame_id"][order], class_id=cat["class_id"][order], distance_m=cat["distance_m"][order],
        labeled=cat["labeled"][order], detected=cat["detected"][order], conf=cat["conf"][order],
        error_uv=cat["error_uv"][order].reshape(-1, 2), parallax_uv=cat["parallax_uv"][order].reshape(-1, 2),
        match_px=float(match_px), frames=int(cat["frames"].sum()), frames_without_file=int(cat["missing"].sum()),
        names=tuple(dataset.features.name))


def _quantile(values: NDArray[np.float64], q: float) -> float | None:
    values = values[np.isfinite(values)]
    return float(np.percentile(values, q)) if values.size else None


@dataclass(frozen=True)
class DetectorCounts:
    """A detector's labeled features, those it found within the match radius (``matched``),
    further away (``mislocated``) or not at all (``missed``), its detections of no labeled
    feature (``spurious``), its recall (matched / labeled) and precision (matched /
    detections), the centre error's median and 95th percentile (px, every detected labeled
    feature), and the mean and spread of the error along the parallax direction beside the
    mean tight-box offset (None: nothing to measure)."""

    labeled: int
    matched: int
    mislocated: int
    missed: int
    spurious: int
    recall: float | None
    precision: float | None
    error_median_px: float | None
    error_p95_px: float | None
    along_parallax_mean_px: float | None
    along_parallax_std_px: float | None
    parallax_offset_mean_px: float | None

    def to_json(self) -> dict[str, Any]:
        return dataclasses.asdict(self)


@dataclass(frozen=True)
class DetectorBin:
    """The detector's counts over the features whose frame's distance (m) lies in ``[lo_m, hi_m)``."""

    lo_m: float
    hi_m: float
    counts: DetectorCounts

    def to_json(self) -> dict[str, Any]:
        return {"lo_m": self.lo_m, "hi_m": self.hi_m, **self.counts.to_json()}


@dataclass(frozen=True)
class DetectorSummary:
    """A detector scored against the true centres (:func:`summarize_detections`): the match
    radius, the frames scored and those without a prediction file, and its counts overall,
    per class and per distance bin; ``evaluation.json``'s ``detector`` is :meth:`to_json`."""

    match_px: float
    frames: int
    frames_without_file: int
    overall: DetectorCounts
    by_class: dict[str, DetectorCounts]
    by_distance: tuple[DetectorBin, ...]

    def to_json(self) -> dict[str, Any]:
        return {"match_px": self.match_px, "frames": self.frames, "frames_without_file": self.frames_without_file,
                "overall": self.overall.to_json(), "by_class": {k: v.to_json() for k, v in self.by_class.items()},
                "by_distance": [b.to_json() for b in self.by_distance]}


def _counts(s: DetectionScores, sel: NDArray[np.bool_]) -> DetectorCounts:
    """Counts, recall and centre-error statistics of the rows ``sel``."""
    labeled = int((s.labeled & sel).sum())
    matched = int((s.matched & sel).sum())
    detected_labeled = s.labeled & s.detected & sel
    error = s.error_px[detected_labeled]
    along = s.along_parallax_px[detected_labeled]
    along = along[np.isfinite(along)]
    offset = s.parallax_px[detected_labeled & np.isfinite(s.along_parallax_px)]
    detections = int((s.detected & sel).sum())
    return DetectorCounts(
        labeled=labeled,
        matched=matched,
        mislocated=int((s.mislocated & sel).sum()),
        missed=int((s.missed & sel).sum()),
        spurious=int((s.spurious & sel).sum()),
        recall=matched / labeled if labeled else None,
        precision=matched / detections if detections else None,
        error_median_px=_quantile(error, 50),
        error_p95_px=_quantile(error, 95),
        along_parallax_mean_px=float(along.mean()) if along.size else None,
        along_parallax_std_px=float(along.std()) if along.size else None,
        parallax_offset_mean_px=float(offset.mean()) if offset.size else None,
    )


def summarize_detections(s: DetectionScores, distance_edges: NDArray[np.float64]) -> DetectorSummary:
    """Overall, per class and per distance bin: matched, mislocated, missed and spurious
    counts, recall (matched / labeled), precision (matched / detections), the centre
    error's median and 95th percentile (px, every detected labeled feature), and the mean
    and spread of the error along the parallax direction beside the mean tight-box offset."""
    everything = np.ones(len(s.frame_id), dtype=bool)
    by_class = {s.names[c]: _counts(s, s.class_id == c) for c in range(len(s.names))}
    by_distance = tuple(DetectorBin(float(lo), float(hi), _counts(s, (s.distance_m >= lo) & (s.distance_m < hi)))
                        for lo, hi in itertools.pairwise(distance_edges))
    return DetectorSummary(s.match_px, s.frames, s.frames_without_file, _counts(s, everything), by_class, by_distance)
