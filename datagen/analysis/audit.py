"""``datagen audit``: prove a dataset's labels are what they claim, and measure the
parallax that corrected boxes remove.

Every check recomputes from the manifests and ``features.parquet`` alone
(:meth:`datagen.dataset.reader.DatasetView.recompute`) and names its worst offenders by
file. The statistics show how far the *tight* box centre (the perceived centre)
lies from the projection of the true 3D centre, as a function of distance,
feature size and view obliqueness (paper Fig. 8).
"""

from __future__ import annotations

import contextlib
import math
import os
import stat
from collections import Counter
from collections.abc import Iterator
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Final

import numpy as np
from numpy.typing import NDArray

from datagen.core.keypoints import KEYPOINT_RANGE, keypoint_flags, mirror_name
from datagen.core.labels import Exclusion, FrameLabels
from datagen.dataset.layout import MANIFEST_NAME
from datagen.dataset.reader import DatasetView, image_size
from datagen.dataset.yolo import YOLO_DECIMALS, parse_line
from datagen.files import is_temporary

__all__ = [
    "DRIFT_LIMIT_PX",
    "AuditResult",
    "Check",
    "audit",
    "feature_normals",
    "obliqueness_deg",
    "tight_centre_drift_px",
]

#: The corrected-box centre of a label line may lie this far from the true centre projection.
DRIFT_LIMIT_PX: Final = 1e-3
#: Manifest boxes and centres must match the recomputation this closely.
MANIFEST_TOLERANCE_PX: Final = 1e-6
#: A label line's values may differ from the manifest box by the rounding of
#: :data:`datagen.core.labels.YOLO_DECIMALS` decimals (normalized units).
LINE_TOLERANCE: Final = 0.5 * 10.0 ** -YOLO_DECIMALS + 1e-12
#: A pose keypoint may differ from its true centre projection by this much (normalized units).
POSE_TOLERANCE: Final = 1e-6
#: Offenders listed per check (the worst first).
MAX_OFFENDERS: Final = 20
#: PnP needs at least this many labeled features of an object in a frame.
PNP_MIN_FEATURES: Final = 3
#: The ``learnable`` check fails when a smaller share of label lines can teach the detector.
MIN_LEARNABLE_SHARE: Final = 0.95
#: Files Ultralytics writes into a dataset it trains on: label caches beside the label
#: folders (``labels/train/00000.cache``, and ``.cache.npy`` while it writes one) and
#: ``.npy`` image caches beside the images (``cache=disk``). They are not orphans.
ULTRALYTICS_SUFFIXES: Final = (".cache", ".cache.npy", ".npy")


@dataclass
class Check:
    """One audit check: what it verifies, over how many items, and who failed it."""

    name: str
    description: str
    checked: int = 0
    failures: int = 0
    worst: float | None = None  # the largest error, where the check measures one
    offenders: list[str] = field(default_factory=list)  # "file: what", worst first
    applicable: bool = True
    #: None: any failure fails the check; else the check passes while at least this share passes.
    min_pass_share: float | None = None
    _scored: list[tuple[float, str]] = field(default_factory=list, repr=False)

    @property
    def pass_share(self) -> float | None:
        return (self.checked - self.failures) / self.checked if self.checked else None

    @property
    def passed(self) -> bool:
        if self.min_pass_share is None:
            return self.failures == 0
        return self.checked == 0 or self.pass_share >= self.min_pass_share

    def fail(self, where: str, what: str, score: float = math.inf) -> None:
        self.failures += 1
        self._scored.append((score, f"{where}: {what}"))

    def finish(self) -> Check:
        self._scored.sort(key=lambda s: -s[0])
        self.offenders = [text for _, text in self._scored[:MAX_OFFENDERS]]
        self._scored = []
        return self

    def as_dict(self) -> dict:
        out = {k: v for k, v in asdict(self).items() if not k.startswith("_")}
        out["passed"] = self.passed
        out["pass_share"] = self.pass_share
        return out


@dataclass
class AuditResult:
    root: Path
    name: str
    frames: int
    checks: list[Check]
    stats: dict
    labels: FrameLabels  # the recomputation the checks ran against (reused by the report's overlays)

    @property
    def passed(self) -> bool:
        return all(c.passed for c in self.checks)


# --- geometry of the statistics (pure functions) ---------------------------------------
def tight_centre_drift_px(tight_xyxy: NDArray[np.float64], center_px: NDArray[np.float64]) -> NDArray[np.float64]:
    """``(...)`` distance in pixels between the tight box's centre (the perceived centre)
    and the projection of the true 3D centre."""
    tight_centre = 0.5 * (tight_xyxy[..., :2] + tight_xyxy[..., 2:])
    return np.hypot(*np.moveaxis(tight_centre - center_px, -1, 0))


def feature_normals(points_model: NDArray[np.float64], n_points: NDArray[np.int64]) -> NDArray[np.float64]:
    """``(F, 3)`` unit normal of each feature's point set: the direction of least spread
    (the ring of a surface feature lies in the surface's tangent plane)."""
    normals = np.empty((len(points_model), 3))
    for i, (pts, n) in enumerate(zip(points_model, n_points, strict=True)):
        p = pts[:n] - pts[:n].mean(axis=0)
        normals[i] = np.linalg.svd(p, full_matrices=True)[2][-1]
    return normals


def obliqueness_deg(cam_from_model: NDArray[np.float64], normal_model: NDArray[np.float64],
                    center_model: NDArray[np.float64]) -> NDArray[np.float64]:
    """Angle between a feature's normal and the line of sight to its centre, degrees:
    0 when the camera looks straight at the feature, 90 when it is seen edge-on.

    Args:
        cam_from_model: ``(..., F, 4, 4)``.
        normal_model, center_model: ``(F, 3)`` in the feature's object frame.
    """
    rot = cam_from_model[..., :3, :3]
    n_cam = np.einsum("...ij,...j->...i", rot, normal_model)
    c_cam = np.einsum("...ij,...j->...i", rot, center_model) + cam_from_model[..., :3, 3]
    cos = np.abs(np.sum(n_cam * c_cam, axis=-1)) / np.maximum(np.linalg.norm(c_cam, axis=-1), 1e-12)
    return np.degrees(np.arccos(np.clip(cos, 0.0, 1.0)))


def _binned(values: NDArray, keys: NDArray, edges: NDArray) -> list[dict]:
    """Count, mean, median, p95 and max of ``values`` per bin of ``keys``."""
    out = []
    for lo, hi in zip(edges[:-1], edges[1:], strict=True):
        v = values[(keys >= lo) & (keys < hi)]
        out.append({"lo": float(lo), "hi": float(hi), "count": int(v.size),
                    **({"mean": float(v.mean()), "median": float(np.median(v)), "p95": float(np.percentile(v, 95)),
                        "max": float(v.max())} if v.size else {})})
    return out


# --- label files --------------------------------------------------------------------------
def _read_label_file(path: Path) -> tuple[list[str], str | None]:
    """The non-blank lines of a label file, or why there are none."""
    if path.exists() and not path.is_file():
        return [], "not a regular file"
    try:
        text = path.read_text()
    except FileNotFoundError:
        return [], "missing"
    except (OSError, UnicodeDecodeError) as exc:
        return [], f"unreadable ({exc})"
    return [line for line in text.splitlines() if line.strip()], None




def _label_files(view: DatasetView, paths: list[str | None], check: Check,
                 kind: str = "label file") -> Iterator[tuple[int, str, list[str]]]:
    """``(row, path, non-empty lines)`` of each frame's label file in ``paths``; a frame whose
    manifest names none, or whose file cannot be read, fails ``check`` instead."""
    for b, rel in enumerate(paths):
        if rel is None:
            check.fail(f"{view.manifest_file[b]} frame {view.frame_id[b]}", f"no {kind} named")
            continue
        rows, problem = _read_label_file(view.root / rel)
        if problem:
            check.fail(rel, problem)
            continue
        yield b, rel, rows


# --- the audit -----------------------------------------------------------------------------
def audit(view: DatasetView, *, min_learnable: float = MIN_LEARNABLE_SHARE) -> AuditResult:
    """Run every check and compute every statistic of a loaded dataset.

    ``min_learnable``: the share of label lines that must be learnable by Ultralytics'
    trainer at ``labels.train_imgsz`` (:mod:`datagen.core.training`)."""
    labels = view.recompute()
    objects = view.recompute_objects()
    checks = [_check_manifest(view, labels), _check_objects(view, objects)]
    stats = _statistics(view, labels)
    if view.label_format != "pose":
        line_checks, lines = _check_label_files(view, labels)
        learnable, stats["learnable"] = _check_learnable(view, lines, min_learnable)
        checks += [*line_checks, learnable, _check_names(view)]
    if view.pose_yaml is not None:
        pose_checks, instances = _check_pose_files(view, labels, objects)
        checks += [*pose_checks, _check_pose_names(view)]
        stats["learnable_pose"] = _pose_learnable(view, instances)
    checks += [_check_files(view), _check_images(view)]
    stats["appearance"] = appearance(view.appearance)
    return AuditResult(view.root, str(view.doc.get("name", view.root.name)), len(view), [c.finish() for c in checks],
                       stats, labels)


def _check_manifest(view: DatasetView, labels) -> Check:
    check = Check("manifest_boxes", "manifest centres, tight, corrected and label boxes and exclusions equal a "
                  f"recomputation from the poses and features.parquet (to {MANIFEST_TOLERANCE_PX:g} px)")
    expected_k = np.array([view.intrinsics.width, view.intrinsics.height, view.intrinsics.fx, view.intrinsics.fy,
                           view.intrinsics.cx, view.intrinsics.cy])
    worst = 0.0
    labeled = labels.labeled  # a whole-dataset array: computed once
    for b in range(len(view)):
        where = f"{view.manifest_file[b]} frame {view.frame_id[b]}"
        check.checked += 1
        if not np.allclose(view.row_intrinsics[b], expected_k, rtol=0, atol=1e-9):
            check.fail(where, f"intrinsics {view.row_intrinsics[b].tolist()} differ from dataset.json's")
            continue
        if not np.array_equal(view.class_id[b], view.features.class_id):
            check.fail(where, "feature records are not one per class in class-id order")
            continue
        errors = []
        for name in ("center_px", "tight_xyxy", "corrected_xyxy", "label_xyxy"):
            stored, fresh = getattr(view, name)[b], getattr(labels, name)[b]
            if name == "label_xyxy":  # stored only for labeled features
                fresh = np.where(labeled[b][:, None], fresh, np.nan)
            both_nan = np.isnan(stored) & np.isnan(fresh)
            err = np.where(both_nan, 0.0, np.abs(stored - fresh))
            err = np.where(np.isnan(err), np.inf, err).max(axis=-1)
            errors.append(err)
        err = np.max(errors, axis=0)
        worst = max(worst, float(err[np.isfinite(err)].max(initial=0.0)))
        reasons = np.array([Exclusion(int(e)).reason for e in labels.exclusion[b]], dtype=object)
        bad = np.flatnonzero((err > MANIFEST_TOLERANCE_PX) | (reasons != view.exclusion[b])
                             | (view.labeled[b] != labeled[b]))
        for f in bad[:3]:
            what = (f"class {f}: stored exclusion {view.exclusion[b][f]!r}, recomputed {reasons[f]!r}"
                    if reasons[f] != view.exclusion[b][f] else f"class {f}: box or centre off by {err[f]:.3g} px")
            check.fail(where, what, float(err[f]))
    check.worst = worst
    return check


def _check_label_files(view: DatasetView, labels) -> tuple[list[Check], NDArray[np.float64]]:
    """The per-line checks, and every well-formed line as a row ``(frame row, class, cx, cy, w, h)``."""
    k = view.intrinsics
    w, h, m = k.width, k.height, view.edge_margin_px
    nc = len(view.features)
    lines = Check("label_lines", "every label line equals its manifest box (class, centre, size; to the "
                  "file's rounding) and every labeled feature has exactly one line")
    drift = Check("centre_drift", f"label-file box centres lie within {DRIFT_LIMIT_PX:g} px of the projection "
                  "of the feature's true 3D centre (corrected datasets)", applicable=view.corrected)
    margin = Check("edge_margin_and_front", f"labeled boxes lie at least edge_margin_px ({m:g} px) inside every "
                   "border and no labeled feature has a point at or behind the camera plane")
    rules = Check("ultralytics_rules", "label files follow Ultralytics' rules: 5 columns, integer class < nc, "
                  "values in [0, 1], positive size, no duplicate rows")
    label_centre = labels.label_center_px
    box = labels.label_xyxy
    labeled_all = labels.labeled  # a whole-dataset array: computed once, not per line
    worst_drift = worst_line = 0.0
    parsed: list[tuple[float, ...]] = []
    for b, rel, rows in _label_files(view, view.label_path, lines):
        seen: Counter = Counter()
        per_class: Counter = Counter()
        for n, line in enumerate(rows, start=1):
            where = f"{rel}:{n}"
            rules.checked += 1
            lines.checked += 1
            values, problem = parse_line(line, nc)
            if problem:
                rules.fail(where, problem)
                continue
            tokens = line.split()
            if min(values[1:]) < 0 or max(values[1:]) > 1 or values[3] <= 0 or values[4] <= 0:
                rules.fail(where, f"values {tokens[1:]} outside [0, 1] or a size not positive")
            parsed.append((b, *values))
            key = tuple(tokens)
            seen[key] += 1
            if seen[key] == 2:
                rules.fail(where, "duplicate row")
            f = int(values[0])
            per_class[f] += 1
            if per_class[f] == 2:
                lines.fail(where, f"class {f} has more than one line")
            if not labeled_all[b, f]:
                reason = Exclusion(int(labels.exclusion[b, f])).reason
                lines.fail(where, f"class {f} has a line but the feature is excluded ({reason})")
                if labels.exclusion[b, f] == Exclusion.BEHIND_CAMERA:
                    margin.fail(where, f"class {f} is behind the camera")
            else:
                expected = np.array([label_centre[b, f, 0] / w, label_centre[b, f, 1] / h,
                                     (box[b, f, 2] - box[b, f, 0]) / w, (box[b, f, 3] - box[b, f, 1]) / h])
                err = np.abs(np.array(values[1:]) - expected)
                if np.all(np.isfinite(err)):
                    worst_line = max(worst_line, float((err * [w, h, w, h]).max()))
                if not np.all(err <= LINE_TOLERANCE):
                    lines.fail(where, f"class {f} differs from the manifest box by "
                               f"{(err * [w, h, w, h]).max():.3g} px", float((err * [w, h, w, h]).max()))
            cx, cy, bw, bh = (values[1] * w, values[2] * h, values[3] * w, values[4] * h)
            drift.checked += 1
            d = math.hypot(cx - labels.center_px[b, f, 0], cy - labels.center_px[b, f, 1])
            if np.isfinite(d):
                worst_drift = max(worst_drift, d)
            if view.corrected and not d <= DRIFT_LIMIT_PX:
                drift.fail(where, f"class {f} centre is {d:.3g} px from the true centre projection", d)
            margin.checked += 1
            x0, y0, x1, y1 = cx - bw / 2, cy - bh / 2, cx + bw / 2, cy + bh / 2
            inside = min(x0, y0, w - x1, h - y1)
            if inside < m - 1e-3:
                margin.fail(where, f"class {f} box is {inside:.2f} px from the border, margin {m:g} px", m - inside)
        labeled = set(np.flatnonzero(labeled_all[b]).tolist())
        for f in sorted(labeled - set(per_class)):
            lines.fail(rel, f"class {f} is labeled in the manifest but has no line")
    lines.worst, drift.worst = worst_line, worst_drift
    return [lines, drift, margin, rules], np.array(parsed, dtype=np.float64).reshape(-1, 6)


def _check_learnable(view: DatasetView, lines: NDArray[np.float64], min_share: float) -> tuple[Check, dict]:
    """Which label lines Ultralytics' trainer keeps at ``labels.train_imgsz`` and can assign
    to an anchor (:mod:`datagen.core.training`); the check passes while at least ``min_share`` can."""
    rules = view.label_rules
    train = view.train_view
    check = Check("learnable", f"at least {100 * min_share:g}% of label lines survive Ultralytics' training "
                  f"transforms at imgsz {rules.train_imgsz} (both sides above 2 px) and hold an anchor centre "
                  "(strides 8/16/32)", min_pass_share=min_share)
    k = view.intrinsics
    b, cls = lines[:, 0].astype(np.int64), lines[:, 1].astype(np.int64)
    cx, cy, bw, bh = lines[:, 2] * k.width, lines[:, 3] * k.height, lines[:, 4] * k.width, lines[:, 5] * k.height
    xyxy = np.stack([cx - bw / 2, cy - bh / 2, cx + bw / 2, cy + bh / 2], axis=-1)
    survives, anchored = train.survives(xyxy), train.has_anchor(xyxy)
    ok = survives & anchored
    check.checked = int(ok.size)
    check.worst = None if not ok.size else float(1.0 - ok.mean())
    names = view.features.name
    by_class = {}
    for c in np.unique(cls):
        mine = ok[cls == c]
        by_class[names[c]] = {"lines": int(mine.size), "share": float(mine.mean())}
        if not mine.all():
            check.fail(f"class {c} {names[c]}", f"{mine.mean():.1%} of {mine.size} lines learnable",
                       float(1.0 - mine.mean()))
    check.failures = int((~ok).sum())  # offenders are the classes above; the count is of label lines

    def share(mask: NDArray[np.bool_]) -> dict:
        return {"lines": int(mask.sum()), "share": float(ok[mask].mean()) if mask.any() else None}

    distance = view.distance_m[b] if b.size else np.zeros(0)
    top = max(10.0, float(np.ceil(view.distance_m.max() / 10.0) * 10.0)) if len(view) else 10.0
    edges = np.arange(0.0, top + 10.0, 10.0)
    size = np.array(view.features.size, dtype=object)[cls] if cls.size else np.zeros(0, dtype=object)
    train_w = np.minimum(bw * train.scale[0], bh * train.scale[1])
    stats = {
        "train_imgsz": rules.train_imgsz,
        "min_box_px": rules.min_box_px,
        "small_boxes": rules.small_boxes,
        "threshold": min_share,
        "lines": int(ok.size),
        "share": float(ok.mean()) if ok.size else None,
        "share_survive_2px": float(survives.mean()) if ok.size else None,
        "share_with_anchor": float(anchored.mean()) if ok.size else None,
        "min_side_train_px": {"median": float(np.median(train_w)) if ok.size else None,
                              "min": float(train_w.min()) if ok.size else None},
        "by_distance_m": [{"lo": float(lo), "hi": float(hi), **share((distance >= lo) & (distance < hi))}
                          for lo, hi in zip(edges[:-1], edges[1:], strict=True)],
        "by_size": {(tag or "untagged"): share(size == tag) for tag in sorted(set(view.features.size))},
        "by_class": by_class,
        "worst_classes": [{"class": n, **v} for n, v in sorted(by_class.items(), key=lambda kv: kv[1]["share"])
                          if v["share"] < 1.0][:10],
    }
    return check, stats





def _nan_error(stored: NDArray[np.float64], fresh: NDArray[np.float64]) -> NDArray[np.float64]:
    """``(...)`` the largest absolute difference over the last axis; 0 where both are NaN (a
    missing value on both sides), inf where only one is."""
    both_nan = np.isnan(stored) & np.isnan(fresh)
    err = np.where(both_nan, 0.0, np.abs(stored - fresh))
    return np.where(np.isnan(err), np.inf, err).max(axis=-1)


def _check_objects(view: DatasetView, objects: FrameLabels) -> Check:
    """The manifests' pose boxes against a recomputation from the poses and objects.parquet."""
    check = Check("manifest_objects", "manifest object boxes (projected hull box, pose label box) and exclusions "
                  f"equal a recomputation from the poses and objects.parquet (to {MANIFEST_TOLERANCE_PX:g} px)")
    label = np.where(objects.labeled[..., None], objects.label_xyxy, np.nan)
    err = np.maximum(_nan_error(view.object_tight_xyxy, objects.tight_xyxy), _nan_error(view.object_label_xyxy, label))
    reasons = np.vectorize(lambda e: Exclusion(int(e)).reason, otypes=[object])(objects.exclusion)
    check.checked = int(err.size)
    check.worst = float(err[np.isfinite(err)].max(initial=0.0))
    for b, c in zip(*np.nonzero((err > MANIFEST_TOLERANCE_PX) | (reasons != view.object_exclusion)), strict=True):
        where = f"{view.manifest_file[b]} frame {view.frame_id[b]}"
        name = view.features.objects[c]
        if reasons[b, c] != view.object_exclusion[b, c]:
            check.fail(where, f"{name}: stored exclusion {view.object_exclusion[b, c]!r}, recomputed {reasons[b, c]!r}")
        else:
            check.fail(where, f"{name}: box off by {err[b, c]:.3g} px", float(err[b, c]))
    return check


def _check_pose_files(view: DatasetView, labels: FrameLabels, objects: FrameLabels
                      ) -> tuple[list[Check], NDArray[np.float64]]:
    """The pose label files line by line, and every well-formed instance as a row
    ``(frame row, class, cx, cy, w, h)``."""
    layout = view.pose_layout
    k = view.intrinsics
    w, h, n_obj, kpts = k.width, k.height, len(layout.objects), layout.kpt_count
    lo, hi = KEYPOINT_RANGE
    lines = Check("pose_lines", "every pose line equals its manifest instance: class, object box (to the file's "
                  f"rounding), keypoints on the true centre projections (to {POSE_TOLERANCE:g} normalized), flags "
                  "equal the manifest's, 0 0 0 for flag 0 and padding; every labeled object has exactly one line")
    flags = Check("keypoint_flags", "manifest keypoint flags equal the rule: 0 excluded, 1 labeled with its centre "
                  "hidden, 2 labeled and visible (or not rendered)")
    rules = Check("ultralytics_pose_rules", f"pose files follow Ultralytics' rules: {layout.columns} columns "
                  f"(5 + 3 x {kpts}), integer class < {n_obj}, box values in [0, 1], positive size, keypoints in "
                  f"[{lo}, {hi}], flags 0, 1 or 2, no duplicate rows")
    expected_flags = keypoint_flags(labels.exclusion, view.center_visible)
    bad = np.nonzero(expected_flags != view.keypoint_flag)
    flags.checked = int(expected_flags.size)
    for b, f in zip(*bad, strict=True):
        flags.fail(f"{view.manifest_file[b]} frame {view.frame_id[b]}",
                   f"class {f}: stored flag {view.keypoint_flag[b, f]}, the rule gives {expected_flags[b, f]}")
    centre, box = objects.label_center_px, objects.label_xyxy
    slots = np.arange(kpts)
    parsed: list[tuple[float, ...]] = []
    worst = 0.0
    for b, rel, rows in _label_files(view, view.pose_label_path, lines, "pose label file"):
        seen: set = set()
        classes: Counter = Counter()
        for n, line in enumerate(rows, start=1):
            where = f"{rel}:{n}"
            rules.checked += 1
            lines.checked += 1
            values, problem = parse_line(line, n_obj, columns=(layout.columns,))
            if problem:
                rules.fail(where, problem)
                continue
            v = np.asarray(values)
            kp = v[5:].reshape(kpts, 3)
            if min(v[1:5]) < 0 or max(v[1:5]) > 1 or v[3] <= 0 or v[4] <= 0:
                rules.fail(where, f"box {line.split()[1:5]} outside [0, 1] or a size not positive")
            if kp[:, :2].min() < lo or kp[:, :2].max() > hi or not np.isin(kp[:, 2], (0, 1, 2)).all():
                rules.fail(where, f"a keypoint outside [{lo}, {hi}] or a flag not 0, 1 or 2")
            if line in seen:
                rules.fail(where, "duplicate row")
            seen.add(line)
            c = int(v[0])
            classes[c] += 1
            parsed.append((b, *v[:5]))
            if classes[c] == 2:
                lines.fail(where, f"class {c} ({layout.objects[c]}) has more than one line")
            if not objects.labeled[b, c]:
                reason = Exclusion(int(objects.exclusion[b, c])).reason
                lines.fail(where, f"class {c} ({layout.objects[c]}) has a line but the object is excluded ({reason})")
                continue
            want_box = np.array([centre[b, c, 0] / w, centre[b, c, 1] / h,
                                 (box[b, c, 2] - box[b, c, 0]) / w, (box[b, c, 3] - box[b, c, 1]) / h])
            members = layout.feature_at[c]
            real = members >= 0
            f = np.where(real, members, 0)
            want_flag = np.where(real, view.keypoint_flag[b, f], 0)
            want_xy = labels.center_px[b, f] / [w, h]
            want_xy = np.where((want_flag > 0)[:, None], want_xy, 0.0)
            box_err = np.abs(v[1:5] - want_box)
            kp_err = np.abs(kp[:, :2] - want_xy).max(axis=1)
            kp_err = np.where(np.isnan(kp_err), np.inf, kp_err)
            worst = max(worst, float(kp_err.max(initial=0.0)) * max(w, h))
            if not np.all(box_err <= LINE_TOLERANCE):
                lines.fail(where, f"class {c} box differs from the manifest's by {(box_err * [w, h, w, h]).max():.3g} px",
                           float((box_err * [w, h, w, h]).max()))
            wrong_flag = slots[kp[:, 2] != want_flag]
            if len(wrong_flag):
                s0 = int(wrong_flag[0])
                lines.fail(where, f"class {c} keypoint {s0}: flag {kp[s0, 2]:g}, the manifest says {want_flag[s0]}")
            off = slots[kp_err > POSE_TOLERANCE]
            if len(off):
                s0 = int(off[np.argmax(kp_err[off])])
                lines.fail(where, f"class {c} keypoint {s0} is {kp_err[s0] * max(w, h):.3g} px from its true centre "
                           "projection", float(kp_err[s0] * max(w, h)))
        for c in sorted(set(np.flatnonzero(objects.labeled[b]).tolist()) - set(classes)):
            lines.fail(rel, f"class {c} ({layout.objects[c]}) is labeled in the manifest but has no line")
    lines.worst = worst
    return [lines, flags, rules], np.array(parsed, dtype=np.float64).reshape(-1, 6)


def _check_pose_names(view: DatasetView) -> Check:
    """The pose set's data.yaml: names, nc, kpt_shape and flip_idx."""
    layout = view.pose_layout
    where = "pose/data.yaml" if view.label_format == "both" else "data.yaml"
    doc = view.pose_yaml or {}
    check = Check("pose_names", "the pose data.yaml names the objects, its kpt_shape is [K, 3] (K the largest feature "
                  "count) and its flip_idx, an involution, swaps exactly the left/right pairs of feature names")
    check.checked = 4
    names = doc.get("names")
    names = dict(enumerate(names)) if isinstance(names, list) else names
    if names != dict(enumerate(layout.objects)) or doc.get("nc") != len(layout.objects):
        check.fail(where, f"names {names!r} or nc {doc.get('nc')!r}: expected the objects {list(layout.objects)}")
    if doc.get("kpt_shape") != [layout.kpt_count, 3]:
        check.fail(where, f"kpt_shape {doc.get('kpt_shape')!r}: expected [{layout.kpt_count}, 3]")
    flip = doc.get("flip_idx")
    if flip is not None:
        valid = (isinstance(flip, list) and len(flip) == layout.kpt_count
                 and all(isinstance(i, int) and 0 <= i < layout.kpt_count for i in flip))
        if not valid or any(flip[flip[i]] != i for i in range(len(flip))):
            check.fail(where, f"flip_idx {str(flip)[:60]}: not an involution on {layout.kpt_count} slots")
            return check
        for o, members in enumerate(layout.feature_at):
            for s, f in enumerate(members):
                if f < 0:
                    continue
                t = members[flip[s]]
                twin = mirror_name(view.features.name[f]) or view.features.name[f]
                if t < 0 or (mirror_name(view.features.name[f]) and view.features.name[t] != twin):
                    check.fail(where, f"flip_idx[{s}] = {flip[s]}: {layout.objects[o]} {view.features.name[f]} would "
                               f"become {view.features.name[t] if t >= 0 else 'padding'}")
    if (flip is None) != (layout.flip_idx is None) or (flip is not None and tuple(flip) != layout.flip_idx):
        check.fail(where, f"flip_idx {str(flip)[:60]}: the features give "
                   f"{list(layout.flip_idx) if layout.flip_idx else 'none'} ({layout.flip_problem or 'mirror pairs'})")
    return check


def _pose_learnable(view: DatasetView, instances: NDArray[np.float64]) -> dict:
    """The share of pose instances Ultralytics' trainer keeps at ``labels.train_imgsz`` and can
    assign to an anchor, without mosaic (as for boxes: :mod:`datagen.core.training`)."""
    k = view.intrinsics
    cx, cy = instances[:, 2] * k.width, instances[:, 3] * k.height
    bw, bh = instances[:, 4] * k.width, instances[:, 5] * k.height
    xyxy = np.stack([cx - bw / 2, cy - bh / 2, cx + bw / 2, cy + bh / 2], axis=-1)
    learnable = view.train_view.learnable(xyxy)
    return {"instances": len(instances), "learnable": int(learnable.sum()),
            "share": float(learnable.mean()) if len(instances) else None,
            "imgsz": view.train_view.imgsz}


def _check_files(view: DatasetView) -> Check:
    check = Check("files", "every image, label and EXR a manifest names exists, no file in images/, labels/ "
                  "or exr/ is unnamed, no temporary file is left, and every planned shard is finished")
    root = view.root
    referenced = {p for paths in (view.image_path, view.label_path, view.pose_label_path, view.exr_path)
                  for p in paths if p}
    for rel in sorted(referenced):
        check.checked += 1
        if not (root / rel).is_file():
            check.fail(rel, "named in a manifest but missing")
    for tree in ("images", "labels", "exr", *(("pose/labels",) if view.label_format == "both" else ())):
        for dirpath, _, files in os.walk(root / tree):
            for name in files:
                rel = str((Path(dirpath) / name).relative_to(root))
                check.checked += 1
                if is_temporary(name):
                    check.fail(rel, "temporary file left by an interrupted writer")
                elif rel not in referenced and not name.endswith(ULTRALYTICS_SUFFIXES):
                    check.fail(rel, "orphan: no manifest names it")
    for name in sorted(os.listdir(root / "manifests")):
        if is_temporary(name):
            check.fail(f"manifests/{name}", "temporary file left by an interrupted writer")
        elif not MANIFEST_NAME.fullmatch(name):
            check.fail(f"manifests/{name}", "not a shard manifest ({split}-{shard:05d}.parquet): an orphan")
    rows = sorted(zip(view.frame_id.tolist(), view.split, view.image_path, strict=True))
    prefixes = ("", "pose/") if view.label_format == "both" else ("",)
    for split, prefix in ((s, p) for s in ("train", "val") for p in prefixes):  # what Ultralytics trains on
        want = [f"./{rel}" for _, s, rel in rows if s == split and rel]
        if not want:
            continue
        name = f"{prefix}{split}.txt"
        listed = root / name
        check.checked += 1
        try:
            have = listed.read_text().splitlines() if listed.is_file() else None
        except (OSError, UnicodeDecodeError):
            have = None
        if have is None:
            check.fail(name, f"missing or unreadable; it lists the {split} images for Ultralytics")
        elif have != want:
            extra = sorted(set(have) - set(want))[:1]
            what = f"names {extra[0]!r}, which no manifest does" if extra else "misses images or lists them out of order"
            check.fail(name, f"{what} ({len(have)} lines, {len(want)} {split} images)")
    ids, counts = np.unique(view.frame_id, return_counts=True)
    for frame in ids[counts > 1][:MAX_OFFENDERS]:
        rows = [view.manifest_file[b] for b in np.flatnonzero(view.frame_id == frame)]
        check.fail(rows[0], f"frame {frame} is in {len(rows)} manifest rows ({', '.join(sorted(set(rows)))}): a "
                   "manifest copied or renamed by hand")
    splits = view.doc.get("splits", {})
    for split, planned in (splits.items() if isinstance(splits, dict) else []):
        have = len({int(f) for f, s in zip(view.frame_id, view.split, strict=True) if s == split})
        want = planned.get("frames", have) if isinstance(planned, dict) else have
        check.checked += 1
        if have < want:
            check.fail("dataset.json", f"splits.{split}: {want} frames planned, {have} in the manifests "
                       "(an unfinished build: rerun it)")
        elif have > want:
            check.fail("dataset.json", f"splits.{split}: {want} frames planned, {have} in the manifests "
                       "(manifests from another build?)")
    return check


#: Bytes read to find an image's size in its header (a JPEG's frame header may follow its EXIF).
_HEADER_BYTES: Final = 65536


def _check_images(view: DatasetView) -> Check:
    """Open every image a manifest names: its header states the dataset's size, and it
    decodes fully (a truncated file or one that is not an image fails). Missing files
    are the ``files`` check's."""
    import cv2

    k = view.intrinsics
    check = Check("images", f"every image a manifest names decodes fully, {k.width}x{k.height} 8-bit colour as "
                  "dataset.json states")
    paths = [p for p in view.image_path if p]
    # A decoded frame is at most its raw size; a file far larger than that is not one.
    max_bytes = 4 * k.width * k.height * 3 + (1 << 20)

    def one(rel: str) -> str | None:
        path = view.root / rel
        try:
            info = path.stat()
            size = info.st_size
            if not stat.S_ISREG(info.st_mode):
                return "not a regular file"
            if size > max_bytes:
                return f"{size:,} bytes, more than a {k.width}x{k.height} image can take"
            data = path.read_bytes()
        except FileNotFoundError:
            return None
        except OSError as exc:
            return f"unreadable ({exc.strerror})"
        found = image_size(data[:_HEADER_BYTES])
        if found is None:
            return "not a PNG or JPEG image"
        if found != (k.width, k.height):
            return f"{found[0]}x{found[1]} px, dataset.json says {k.width}x{k.height}"
        image = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
        if image is None:
            return "does not decode (truncated or corrupt)"
        if image.dtype != np.uint8 or image.shape != (k.height, k.width, 3):
            return f"decodes to {image.dtype} {image.shape}, expected uint8 ({k.height}, {k.width}, 3)"
        return None

    from concurrent.futures import ThreadPoolExecutor

    with _quiet_stderr(), ThreadPoolExecutor(max(1, os.cpu_count() or 1)) as pool:  # OpenCV decodes without the GIL
        for rel, problem in zip(paths, pool.map(one, paths), strict=True):
            check.checked += 1
            if problem:
                check.fail(rel, problem)
    return check


@contextlib.contextmanager
def _quiet_stderr():
    """Silence what libpng prints to the process's stderr about a damaged file (the check
    names the file itself)."""
    try:
        saved = os.dup(2)
    except OSError:
        yield
        return
    try:
        with open(os.devnull, "wb") as null:
            os.dup2(null.fileno(), 2)
        yield
    finally:
        os.dup2(saved, 2)
        os.close(saved)


def _check_names(view: DatasetView) -> Check:
    check = Check("class_names", "data.yaml's nc and names match features.parquet class for class")
    names = view.data_yaml.get("names")
    expected = dict(zip(view.features.class_id.tolist(), view.features.name, strict=True))
    check.checked = len(expected)
    if isinstance(names, list):
        names = dict(enumerate(names))
    if not isinstance(names, dict):
        check.fail("data.yaml", f"names: expected a mapping of class ids, got {type(names).__name__}")
        return check
    for cid, name in expected.items():
        if names.get(cid) != name:
            check.fail("data.yaml", f"names.{cid}: {names.get(cid)!r}, features.parquet says {name!r}")
    for cid in sorted(set(names) - set(expected), key=str):
        check.fail("data.yaml", f"names.{cid}: {names[cid]!r} is not a class of features.parquet")
    if view.data_yaml.get("nc", len(expected)) != len(expected):
        check.fail("data.yaml", f"nc: {view.data_yaml.get('nc')}, features.parquet has {len(expected)} classes")
    return check


# --- statistics ------------------------------------------------------------------------------
def _statistics(view: DatasetView, labels) -> dict:
    features = view.features
    k = view.intrinsics
    in_image = labels.exclusion != Exclusion.BEHIND_CAMERA
    tight = labels.tight_xyxy
    inside = in_image & (tight[..., 0] >= 0) & (tight[..., 1] >= 0) & (tight[..., 2] <= k.width) \
        & (tight[..., 3] <= k.height)
    drift = tight_centre_drift_px(tight, labels.center_px)
    cam_from_model = view.cam_from_objects()[:, features.object_index]
    oblique = obliqueness_deg(cam_from_model, feature_normals(features.points_model, features.n_points),
                              features.center_model)
    distance = np.broadcast_to(view.distance_m[:, None], drift.shape)
    d, dist, obl = drift[inside], distance[inside], oblique[inside]
    size = np.broadcast_to(np.array(features.size, dtype=object)[None, :], drift.shape)[inside]
    top = max(10.0, float(np.ceil(view.distance_m.max() / 10.0) * 10.0)) if len(view) else 10.0
    by_size = {}
    for tag in sorted(set(features.size)):
        v = d[size == tag]
        by_size[tag or "untagged"] = {"count": int(v.size), **({"mean": float(v.mean()), "median": float(np.median(v)),
                                                                 "p95": float(np.percentile(v, 95)),
                                                                 "max": float(v.max())} if v.size else {})}
    reasons = Counter(Exclusion(int(e)).reason or "labeled" for e in labels.exclusion.ravel())
    per_class = labels.labeled.sum(axis=0)
    pnp = {}
    for j, obj in enumerate(features.objects):
        count = labels.labeled[:, features.object_index == j].sum(axis=1)
        pnp[obj] = {"frames_below_3": int((count < PNP_MIN_FEATURES).sum()),
                    "share_below_3": float((count < PNP_MIN_FEATURES).mean()) if len(view) else 0.0,
                    "median_labeled": float(np.median(count)) if len(view) else 0.0}
    vis = view.visible_fraction[labels.labeled]
    vis = vis[np.isfinite(vis)]
    cv = view.center_visible[labels.labeled]
    cv = cv[np.isfinite(cv)]
    coverage_edges = np.arange(0.0, top + 5.0, 5.0)
    return {
        "tight_drift_px": {
            "features": int(d.size),
            "mean": float(d.mean()) if d.size else None,
            "median": float(np.median(d)) if d.size else None,
            "p95": float(np.percentile(d, 95)) if d.size else None,
            "max": float(d.max()) if d.size else None,
            "by_distance_m": _binned(d, dist, np.arange(0.0, top + 10.0, 10.0)),
            "by_size": by_size,
            "by_obliqueness_deg": _binned(d, obl, np.arange(0.0, 91.0, 15.0)),
        },
        "labels_per_class": {features.name[i]: int(per_class[i]) for i in range(len(features))},
        "exclusions": {r.reason or "labeled": int(reasons.get(r.reason or "labeled", 0)) for r in Exclusion},
        "visibility": {
            "labeled_features_rendered": int(vis.size),
            "visible_fraction_histogram": np.histogram(vis, bins=10, range=(0.0, 1.0))[0].tolist(),
            "share_fully_visible": float((vis >= 1.0).mean()) if vis.size else None,
            "share_centre_visible": float(cv.mean()) if cv.size else None,
        },
        "pnp_below_3_features": pnp,
        "distance_coverage": {"edges_m": coverage_edges.tolist(),
                              "frames": np.histogram(view.distance_m, bins=coverage_edges)[0].tolist()},
        "_arrays": {"drift": d, "distance": dist, "obliqueness": obl, "size": size,
                    "visible_fraction": vis},
    }












#: Bins of the appearance section's histograms.
APPEARANCE_BINS: Final = 10


def appearance(columns: dict[str, list]) -> dict:
    """The appearance section: per dimension (:data:`datagen.dataset.schema.APPEARANCE`) and
    column, how many frames drew it and the distribution of the draws (a histogram of
    :data:`APPEARANCE_BINS` bins for numbers, counts per value for names and flags). A
    column no frame drew (its randomizer off) has ``frames`` 0."""
    from datagen.dataset.schema import APPEARANCE

    out: dict[str, dict] = {}
    for dimension, names in APPEARANCE.items():
        section = {}
        for name in names:
            if name not in columns:
                continue
            drawn = [v for v in columns[name] if v is not None]
            entry: dict = {"frames": len(drawn)}
            if drawn and isinstance(drawn[0], (bool, str)):
                entry["values"] = dict(sorted(Counter(str(v).lower() if isinstance(v, bool) else v
                                                      for v in drawn).items()))
            elif drawn:
                values = np.asarray(drawn, dtype=np.float64)
                values = values[np.isfinite(values)]
                if values.size:
                    lo, hi = float(values.min()), float(values.max())
                    counts, edges = np.histogram(values, bins=APPEARANCE_BINS, range=(lo, hi if hi > lo else lo + 1.0))
                    entry.update(min=lo, max=hi, mean=float(values.mean()), edges=edges.tolist(),
                                 histogram=counts.tolist())
            section[name] = entry
        out[dimension] = section
    return out
