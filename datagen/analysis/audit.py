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
import heapq
import itertools
import math
import os
import re
import stat
from collections import Counter
from collections.abc import Iterator
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Final

import numpy as np
from numpy.typing import NDArray

from datagen.analysis.exact import (
    OrderedSum,
    Spill,
    median,
    median_positions,
    order_statistics,
    percentile,
    percentile_positions,
)
from datagen.core.camera import Intrinsics
from datagen.core.keypoints import KEYPOINT_RANGE, keypoint_flags, mirror_name
from datagen.core.labels import Exclusion, FrameLabels
from datagen.core.training import ASSIGNABLE_SIDE_PX
from datagen.dataset.layout import MANIFEST_NAME
from datagen.dataset.reader import DatasetIndex, DatasetMeta, DatasetSource, DatasetView, image_size
from datagen.dataset.yolo import YOLO_DECIMALS, parse_line
from datagen.files import is_temporary
from datagen.pipeline.executors import map_in_order
from datagen.pipeline.progress import NullProgress

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
#: A label box side within this of the edge margin lies on it (label lines carry ~1e-7 px).
_ON_MARGIN_PX: Final = 1e-3
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
    #: (-score, frame order, sequence, text) of every failure; ``row`` (a row of the view
    #: the check ran on) is turned into the frame order by :meth:`ranked`.
    _scored: list[tuple[float, int, int, str]] = field(default_factory=list, repr=False)
    _seq: int = field(default=0, repr=False)

    @property
    def pass_share(self) -> float | None:
        return (self.checked - self.failures) / self.checked if self.checked else None

    @property
    def passed(self) -> bool:
        if self.min_pass_share is None:
            return self.failures == 0
        return self.checked == 0 or self.pass_share >= self.min_pass_share

    def fail(self, where: str, what: str, score: float = math.inf, row: int | None = None,
             seq: int | None = None) -> None:
        """Count a failure; ``row``: the row of the view it is about (offenders of equal
        score are listed in frame order, then in the order they failed, or of ``seq``)."""
        self.failures += 1
        self._scored.append((-score, 0 if row is None else int(row), self._seq if seq is None else seq,
                             f"{where}: {what}"))
        self._seq += 1

    def ranked(self, rank: NDArray[np.int64]) -> Check:
        """The offenders' rows as positions in the dataset's frame order (``rank[row]``),
        the worst :data:`MAX_OFFENDERS` kept."""
        self._scored = heapq.nsmallest(MAX_OFFENDERS, ((s, int(rank[r]), q, t) for s, r, q, t in self._scored))
        return self

    def merge(self, other: Check) -> Check:
        """Add the counts and offenders of the same check run on other frames."""
        self.checked += other.checked
        self.failures += other.failures
        if other.worst is not None:
            self.worst = other.worst if self.worst is None else max(self.worst, other.worst)
        self._scored = heapq.nsmallest(MAX_OFFENDERS, self._scored + other._scored)
        return self

    def finish(self) -> Check:
        self._scored.sort()
        self.offenders = [text for *_, text in self._scored[:MAX_OFFENDERS]]
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
            check.fail(f"{view.manifest_file[b]} frame {view.frame_id[b]}", f"no {kind} named", row=b)
            continue
        rows, problem = _read_label_file(view.root / rel)
        if problem:
            check.fail(rel, problem, row=b)
            continue
        yield b, rel, rows


# --- the audit -----------------------------------------------------------------------------
@dataclass
class _Part:
    """The audit of some of a dataset's frames (one shard's, or a whole view's): its
    per-frame checks, offenders ranked in the dataset's frame order, and the compact values
    the statistics need (:func:`_statistics_part`, :func:`_learnable_part`)."""

    checks: list[Check]
    stats: dict
    lines: dict | None  # label lines (_learnable_part), None without detection labels
    pose_learnable: NDArray[np.bool_] | None  # per pose instance, None without pose labels


def _audit_part(view: DatasetView, rank: NDArray[np.int64]) -> _Part:
    """Every per-frame check of ``view``'s rows; ``rank``: each row's position in the
    dataset's frame order."""
    labels = view.recompute()
    objects = view.recompute_objects()
    checks = [_check_manifest(view, labels), _check_objects(view, objects)]
    lines = pose = None
    if view.label_format != "pose":
        line_checks, parsed = _check_label_files(view, labels)
        checks += line_checks
        lines = _learnable_part(view, parsed)
    if view.pose_yaml is not None:
        pose_checks, instances = _check_pose_files(view, labels, objects)
        checks += pose_checks
        pose = _pose_learnable_part(view, instances)
    return _Part([c.ranked(rank) for c in checks], _statistics_part(view, labels, rank), lines, pose)


def _audit_shard(source: DatasetSource, name: str, rank: NDArray[np.int64]) -> _Part:
    return _audit_part(source.read_shard(name), rank)


def _parts(source: DatasetSource, index: DatasetIndex, workers: int, progress) -> Iterator[_Part]:
    """The audit of each shard, in manifest order, in ``workers`` processes (each reads and
    checks whole shards; only the compact results come back)."""
    names = list(source.manifests)
    tasks = [(source, name, index.rank[name]) for name in names]
    for name, part in zip(names, map_in_order(_audit_shard, tasks, workers), strict=True):
        progress.advance(len(index.rank[name]))
        yield part


def audit(dataset: DatasetView | DatasetSource, *, min_learnable: float = MIN_LEARNABLE_SHARE, workers: int = 1,
          progress=None, index: DatasetIndex | None = None) -> AuditResult:
    """Run every check and compute every statistic of a dataset.

    ``dataset``: a loaded view (all in memory), or an opened source, which is read and
    checked shard by shard (in ``workers`` processes), keeping only counts, the worst
    offenders and the compact values the statistics need: the same report either way.
    ``min_learnable``: the share of label lines that must be learnable by Ultralytics'
    trainer at ``labels.train_imgsz`` (:mod:`datagen.core.training`).
    ``progress``: an object with ``start(total, done)``, ``advance(n)`` and ``close()``
    (:class:`datagen.pipeline.progress.BuildProgress`). ``index``: the source's, where the
    caller has read it."""
    progress = progress or NullProgress()
    if isinstance(dataset, DatasetView):
        index = dataset
        progress.start(len(dataset), 0)
        parts: Iterator[_Part] = iter([_audit_part(dataset, np.arange(len(dataset)))])
        progress.advance(len(dataset))
    else:
        index = index or dataset.index()
        progress.start(len(index), 0)
        parts = _parts(dataset, index, workers, progress)
    merged: dict[str, Check] = {}
    with Spill() as spill:  # the per-feature and per-line values, on disk until the statistics
        totals = _Totals(len(dataset.features))
        pose = np.zeros(2, dtype=np.int64)  # pose instances, learnable ones
        for part in parts:
            for c in part.checks:
                merged[c.name] = merged[c.name].merge(c) if c.name in merged else c
            totals.add(spill, part.stats)
            if part.lines is not None:
                spill.add("lines", None, **part.lines)
            if part.pose_learnable is not None:
                pose += (part.pose_learnable.size, part.pose_learnable.sum())
            del part
        progress.close()
        stats = _statistics(dataset, spill, totals)
        checks = [merged["manifest_boxes"], merged["manifest_objects"]]
        if dataset.label_format != "pose":
            learnable, stats["learnable"] = _check_learnable(dataset, spill, stats["_top_m"], min_learnable)
            checks += [merged[n] for n in ("label_lines", "centre_drift", "edge_margin_and_front",
                                           "ultralytics_rules")]
            checks += [learnable, _check_names(dataset)]
        if dataset.pose_yaml is not None:
            checks += [merged[n] for n in ("pose_lines", "keypoint_flags", "ultralytics_pose_rules")]
            checks += [_check_pose_names(dataset)]
            stats["learnable_pose"] = _pose_learnable(dataset, pose)
        stats["appearance"] = _appearance_finish(spill, totals.appearance)
    checks += [_check_files(index), _check_images(index, dataset.intrinsics)]
    del stats["_top_m"]
    return AuditResult(dataset.root, str(dataset.doc.get("name", dataset.root.name)), len(index),
                       [c.finish() for c in checks], stats)


#: Exclusion code -> the reason a manifest records (None: labeled).
_REASONS: Final = np.array([None if e is Exclusion.NONE else Exclusion(e).reason for e in range(max(Exclusion) + 1)],
                           dtype=object)


def _check_manifest(view: DatasetView, labels: FrameLabels) -> Check:
    check = Check("manifest_boxes", "manifest centres, tight, corrected and label boxes and exclusions equal a "
                  f"recomputation from the poses and features.parquet (to {MANIFEST_TOLERANCE_PX:g} px)")
    k = view.intrinsics
    expected_k = np.array([k.width, k.height, k.fx, k.fy, k.cx, k.cy])
    check.checked = len(view)
    k_ok = np.isclose(view.row_intrinsics, expected_k, rtol=0, atol=1e-9).all(axis=1)
    class_ok = (view.class_id == view.features.class_id).all(axis=1)
    fresh_label = np.where(labels.labeled[..., None], labels.label_xyxy, np.nan)  # stored only for labeled features
    err = np.max([_nan_error(view.center_px, labels.center_px), _nan_error(view.tight_xyxy, labels.tight_xyxy),
                  _nan_error(view.corrected_xyxy, labels.corrected_xyxy), _nan_error(view.label_xyxy, fresh_label)],
                 axis=0)
    good = k_ok & class_ok
    checked = err[good]
    check.worst = float(checked[np.isfinite(checked)].max(initial=0.0))
    reasons = _REASONS[labels.exclusion.astype(np.int64)]
    bad = good[:, None] & ((err > MANIFEST_TOLERANCE_PX) | (reasons != view.exclusion)
                           | (view.labeled != labels.labeled))
    for b in np.flatnonzero(~good | bad.any(axis=1)):
        where = f"{view.manifest_file[b]} frame {view.frame_id[b]}"
        if not k_ok[b]:
            check.fail(where, f"intrinsics {view.row_intrinsics[b].tolist()} differ from dataset.json's", row=b)
        elif not class_ok[b]:
            check.fail(where, "feature records are not one per class in class-id order", row=b)
        for f in np.flatnonzero(bad[b])[:3]:
            what = (f"class {f}: stored exclusion {view.exclusion[b][f]!r}, recomputed {reasons[b, f]!r}"
                    if reasons[b, f] != view.exclusion[b][f] else f"class {f}: box or centre off by {err[b, f]:.3g} px")
            check.fail(where, what, float(err[b, f]), row=b)
    return check


#: A line of plain decimals separated by blanks: such lines are parsed in bulk (:func:`_parse_lines`).
_PLAIN_LINE: Final = re.compile(r"[ \t]*-?[0-9]+(?:\.[0-9]+)?(?:[ \t]+-?[0-9]+(?:\.[0-9]+)?)*[ \t]*")


def _parse_lines(rows: list[str], nc: int, columns: int) -> tuple[NDArray[np.float64], list[str | None]]:
    """``(values (N, columns), problems)`` of a file's non-blank lines: what
    :func:`datagen.dataset.yolo.parse_line` gives, in bulk where every token is a plain
    decimal and every line has ``columns`` of them (a line with a problem has NaN values)."""
    tokens = [line.split() for line in rows]
    if all(len(t) == columns for t in tokens) and all(_PLAIN_LINE.fullmatch(line) for line in rows):
        values = np.array(tokens, dtype=np.float64).reshape(len(rows), columns)
        cls = values[:, 0]
        ok = np.isfinite(values).all(axis=1) & (cls == np.floor(cls)) & (cls >= 0) & (cls < nc)
        if ok.all():
            return values, [None] * len(rows)
    values = np.full((len(rows), columns), np.nan)
    problems: list[str | None] = []
    for n, line in enumerate(rows):
        parsed, problem = parse_line(line, nc, columns=(columns,))
        problems.append(problem)
        if parsed is not None:
            values[n] = parsed
    return values, problems


def _check_label_files(view: DatasetView, labels: FrameLabels) -> tuple[list[Check], NDArray[np.float64]]:
    """The per-line checks, and every well-formed line as a row ``(frame row, class, cx, cy, w, h)``.

    Vectorized over the view's lines; the failures, their order (frame, line, then the
    order the rules are listed in below) and their scores are those of checking one line
    at a time."""
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
    # Every line of every readable file, in (frame, line) order.
    texts: list[str] = []
    frame_rows: list[int] = []
    numbers: list[int] = []
    files: dict[int, tuple[str, int, int]] = {}  # row -> (path, first line index, line count)
    values_parts, problems = [], []
    for b, rel, rows in _label_files(view, view.label_path, lines):
        files[b] = (rel, len(texts), len(rows))
        values, why = _parse_lines(rows, nc, 5)
        values_parts.append(values)
        problems += why
        texts += rows
        frame_rows += [b] * len(rows)
        numbers += range(1, len(rows) + 1)
    n_lines = len(texts)
    rules.checked = lines.checked = n_lines
    values = np.concatenate(values_parts) if values_parts else np.zeros((0, 5))
    row = np.asarray(frame_rows, dtype=np.int64)
    number = np.asarray(numbers, dtype=np.int64)

    def where(i: int) -> str:
        return f"{view.label_path[row[i]]}:{number[i]}"

    def seq(i: int, sub: int) -> int:  # a line's failures in the order the rules run
        return int(number[i]) * 8 + sub

    well = np.array([p is None for p in problems], dtype=bool)
    for i in np.flatnonzero(~well):
        rules.fail(where(i), problems[i], row=row[i], seq=seq(i, 0))
    idx = np.flatnonzero(well)
    v, b, f = values[idx], row[idx], values[idx, 0].astype(np.int64)
    outside = (v[:, 1:].min(axis=1) < 0) | (v[:, 1:].max(axis=1) > 1) | (v[:, 3] <= 0) | (v[:, 4] <= 0)
    for i in idx[outside]:
        rules.fail(where(i), f"values {texts[i].split()[1:]} outside [0, 1] or a size not positive", row=row[i],
                   seq=seq(i, 1))
    # Duplicate rows (same tokens) and second lines of a class, per file: flagged on the second occurrence.
    for b_file, (_rel, start, count) in files.items():
        mine = idx[np.searchsorted(idx, start):np.searchsorted(idx, start + count)]  # the file's well-formed lines
        keys = [tuple(texts[i].split()) for i in mine]
        classes = values[mine, 0].astype(np.int64)
        if len(set(keys)) < len(keys):
            seen: Counter = Counter()
            for i, key in zip(mine, keys, strict=True):
                seen[key] += 1
                if seen[key] == 2:
                    rules.fail(where(i), "duplicate row", row=b_file, seq=seq(i, 2))
        if len(set(classes.tolist())) < len(classes):
            per_class: Counter = Counter()
            for i, c in zip(mine, classes.tolist(), strict=True):
                per_class[c] += 1
                if per_class[c] == 2:
                    lines.fail(where(i), f"class {c} has more than one line", row=b_file, seq=seq(i, 0))
    labeled = labels.labeled[b, f]
    exclusion = labels.exclusion[b, f].astype(np.int64)
    for i, c, e in zip(idx[~labeled], f[~labeled], exclusion[~labeled], strict=True):
        lines.fail(where(i), f"class {c} has a line but the feature is excluded ({_REASONS[e]})", row=row[i],
                   seq=seq(i, 1))
        if e == Exclusion.BEHIND_CAMERA:
            margin.fail(where(i), f"class {c} is behind the camera", row=row[i], seq=seq(i, 0))
    centre, box = labels.label_center_px[b, f], labels.label_xyxy[b, f]
    expected = np.stack([centre[:, 0] / w, centre[:, 1] / h, (box[:, 2] - box[:, 0]) / w, (box[:, 3] - box[:, 1]) / h],
                        axis=-1)
    err = np.abs(v[:, 1:] - expected)
    err_px = (err * [w, h, w, h]).max(axis=1)
    finite = labeled & np.isfinite(err).all(axis=1)
    lines.worst = float(err_px[finite].max(initial=0.0))
    off = labeled & ~np.all(err <= LINE_TOLERANCE, axis=1)
    for i, c, e in zip(idx[off], f[off], err_px[off], strict=True):
        lines.fail(where(i), f"class {c} differs from the manifest box by {e:.3g} px", float(e), row=row[i],
                   seq=seq(i, 1))
    cx, cy, bw, bh = v[:, 1] * w, v[:, 2] * h, v[:, 3] * w, v[:, 4] * h
    drift.checked = margin.checked = len(idx)
    true_centre = labels.center_px[b, f]
    d = np.hypot(cx - true_centre[:, 0], cy - true_centre[:, 1])
    drift.worst = float(d[np.isfinite(d)].max(initial=0.0))
    if view.corrected:
        far = ~(d <= DRIFT_LIMIT_PX)
        for i, c, e in zip(idx[far], f[far], d[far], strict=True):
            drift.fail(where(i), f"class {c} centre is {e:.3g} px from the true centre projection", float(e),
                       row=row[i], seq=seq(i, 0))
    inside = np.min([cx - bw / 2, cy - bh / 2, w - (cx + bw / 2), h - (cy + bh / 2)], axis=0)
    near = inside < m - 1e-3
    for i, c, e in zip(idx[near], f[near], inside[near], strict=True):
        margin.fail(where(i), f"class {c} box is {e:.2f} px from the border, margin {m:g} px", float(m - e),
                    row=row[i], seq=seq(i, 1))
    # Labeled features without a line: after the file's lines.
    have = np.zeros(labels.labeled.shape, dtype=bool)
    have[b, f] = True
    for b_file, (rel, _, count) in files.items():
        for c in np.flatnonzero(labels.labeled[b_file] & ~have[b_file]):
            lines.fail(rel, f"class {c} is labeled in the manifest but has no line", row=b_file,
                       seq=(count + 1) * 8 + int(c))
    parsed = np.column_stack([b.astype(np.float64), v]) if len(idx) else np.zeros((0, 6))
    return [lines, drift, margin, rules], parsed


def _learnable_part(view: DatasetView, lines: NDArray[np.float64]) -> dict[str, NDArray]:
    """Per well-formed label line (rows ``(frame row, class, cx, cy, w, h)``): its class and
    frame distance, whether Ultralytics' trainer keeps it at ``labels.train_imgsz``, whether
    it holds an anchor centre and whether it is large enough for the untrained head's
    assigner (:mod:`datagen.core.training`), and its shorter side there."""
    train = view.train_view
    k = view.intrinsics
    b, cls = lines[:, 0].astype(np.int64), lines[:, 1].astype(np.int64)
    cx, cy, bw, bh = lines[:, 2] * k.width, lines[:, 3] * k.height, lines[:, 4] * k.width, lines[:, 5] * k.height
    xyxy = np.stack([cx - bw / 2, cy - bh / 2, cx + bw / 2, cy + bh / 2], axis=-1)
    # A box short of the assigner's size because it reached the edge margin (labels grow only
    # that far: datagen.core.labels) is as large as its feature's line can be.
    m = view.label_rules.edge_margin_px
    on = np.isclose(xyxy, [m, m, k.width - m, k.height - m], rtol=0.0, atol=_ON_MARGIN_PX)
    short = train.short_sides(xyxy)
    border = short.any(axis=1) & ~(short & ~(on[:, :2] | on[:, 2:])).any(axis=1)  # every short side on it
    return {"cls": cls.astype(np.int16), "distance": view.distance_m[b], "survives": train.survives(xyxy),
            "anchored": train.has_anchor(xyxy), "assignable": ~short.any(axis=1), "border": border,
            "train_w": np.minimum(bw * train.scale[0], bh * train.scale[1])}


def _check_learnable(meta: DatasetMeta, spill: Spill, top: float, min_share: float) -> tuple[Check, dict]:
    """Which label lines Ultralytics' trainer keeps at ``labels.train_imgsz``, can assign to an
    anchor and gives a target at the start of training (:func:`_learnable_part` of every
    shard, in ``spill``'s stream ``lines``); the check passes while at least ``min_share``
    can. ``top``: the upper end of the distance bins."""
    rules = meta.label_rules
    check = Check("learnable", f"at least {100 * min_share:g}% of label lines survive Ultralytics' training "
                  f"transforms at imgsz {rules.train_imgsz} (both sides above 2 px), hold an anchor centre "
                  f"(strides 8/16/32) and have both sides of at least {ASSIGNABLE_SIDE_PX:g} px there (smaller "
                  "boxes get no target from the untrained head's assigner) unless a short side reached the "
                  "edge margin", min_pass_share=min_share)
    names = meta.features.name
    edges = np.arange(0.0, top + 10.0, 10.0)
    # per class and per distance bin: lines, learnable ones; and the lines' survivors, anchored ones
    per_class = np.zeros((len(names), 2), dtype=np.int64)
    per_bin = np.zeros((len(edges) - 1, 2), dtype=np.int64)
    survived = anchored_ = assignable = border = 0
    low = math.inf
    for part in spill.parts("lines", "cls", "distance", "survives", "anchored", "assignable", "border", "train_w"):
        ok = part["survives"] & part["anchored"] & (part["assignable"] | part["border"])
        cls = part["cls"].astype(np.int64)
        per_class += np.stack([np.bincount(cls, minlength=len(names)),
                               np.bincount(cls, weights=ok, minlength=len(names)).astype(np.int64)], axis=1)
        k = _bin_of(part["distance"], edges)
        inside = k >= 0
        per_bin += np.stack([np.bincount(k[inside], minlength=len(edges) - 1),
                             np.bincount(k[inside], weights=ok[inside], minlength=len(edges) - 1).astype(np.int64)],
                            axis=1)
        survived += int(part["survives"].sum())
        anchored_ += int(part["anchored"].sum())
        assignable += int(part["assignable"].sum())
        border += int(part["border"].sum())
        low = min(low, float(part["train_w"].min()))
    lines, good = (int(v) for v in per_class.sum(axis=0))
    check.checked = lines
    check.worst = None if not lines else float(1.0 - good / lines)
    by_class = {}
    for c in np.flatnonzero(per_class[:, 0]):
        n, ok_n = (int(v) for v in per_class[c])
        by_class[names[c]] = {"lines": n, "share": ok_n / n}
        if ok_n < n:
            check.fail(f"class {c} {names[c]}", f"{ok_n / n:.1%} of {n} lines learnable", float(1.0 - ok_n / n))
    check.failures = lines - good  # offenders are the classes above; the count is of label lines

    def share(counts: NDArray[np.int64]) -> dict:
        n, ok_n = (int(v) for v in counts)
        return {"lines": n, "share": ok_n / n if n else None}

    sizes = np.array(meta.features.size, dtype=object)
    stats = {
        "train_imgsz": rules.train_imgsz,
        "min_box_px": rules.min_box_px,
        "small_boxes": rules.small_boxes,
        "threshold": min_share,
        "lines": lines,
        "share": good / lines if lines else None,
        "share_survive_2px": survived / lines if lines else None,
        "share_with_anchor": anchored_ / lines if lines else None,
        "share_assignable": assignable / lines if lines else None,
        "share_at_edge_margin": border / lines if lines else None,
        "assignable_side_px": ASSIGNABLE_SIDE_PX,
        "min_side_train_px": {"median": _median_of(spill, "lines", "train_w") if lines else None,
                              "min": low if lines else None},
        "by_distance_m": [{"lo": float(lo), "hi": float(hi), **share(per_bin[k])}
                          for k, (lo, hi) in enumerate(itertools.pairwise(edges))],
        "by_size": {(tag or "untagged"): share(per_class[sizes == tag].sum(axis=0))
                    for tag in sorted(set(meta.features.size))},
        "by_class": by_class,
        "worst_classes": [{"class": n, **v} for n, v in sorted(by_class.items(), key=lambda kv: kv[1]["share"])
                          if v["share"] < 1.0][:10],
    }
    return check, stats


def _median_of(spill: Spill, stream: str, column: str) -> float:
    """``np.median`` of a spilled column (no NaNs)."""
    n = spill.rows[stream]
    wanted = set(median_positions(n))

    def chunks():
        for part in spill.parts(stream, column):
            yield np.zeros(len(part[column]), dtype=np.int64), part[column]

    found = order_statistics(chunks, {0: wanted})
    return median(n, lambda k: found[(0, k)])


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
            check.fail(where, f"{name}: stored exclusion {view.object_exclusion[b, c]!r}, "
                              f"recomputed {reasons[b, c]!r}", row=b)
        else:
            check.fail(where, f"{name}: box off by {err[b, c]:.3g} px", float(err[b, c]), row=b)
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
                   f"class {f}: stored flag {view.keypoint_flag[b, f]}, the rule gives {expected_flags[b, f]}", row=b)
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
                rules.fail(where, problem, row=b)
                continue
            v = np.asarray(values)
            kp = v[5:].reshape(kpts, 3)
            if min(v[1:5]) < 0 or max(v[1:5]) > 1 or v[3] <= 0 or v[4] <= 0:
                rules.fail(where, f"box {line.split()[1:5]} outside [0, 1] or a size not positive", row=b)
            if kp[:, :2].min() < lo or kp[:, :2].max() > hi or not np.isin(kp[:, 2], (0, 1, 2)).all():
                rules.fail(where, f"a keypoint outside [{lo}, {hi}] or a flag not 0, 1 or 2", row=b)
            if line in seen:
                rules.fail(where, "duplicate row", row=b)
            seen.add(line)
            c = int(v[0])
            classes[c] += 1
            parsed.append((b, *v[:5]))
            if classes[c] == 2:
                lines.fail(where, f"class {c} ({layout.objects[c]}) has more than one line", row=b)
            if not objects.labeled[b, c]:
                reason = Exclusion(int(objects.exclusion[b, c])).reason
                lines.fail(where, f"class {c} ({layout.objects[c]}) has a line but the object is excluded "
                                  f"({reason})", row=b)
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
                worst = (box_err * [w, h, w, h]).max()
                lines.fail(where, f"class {c} box differs from the manifest's by {worst:.3g} px",
                           float((box_err * [w, h, w, h]).max()), row=b)
            wrong_flag = slots[kp[:, 2] != want_flag]
            if len(wrong_flag):
                s0 = int(wrong_flag[0])
                lines.fail(where, f"class {c} keypoint {s0}: flag {kp[s0, 2]:g}, "
                                  f"the manifest says {want_flag[s0]}", row=b)
            off = slots[kp_err > POSE_TOLERANCE]
            if len(off):
                s0 = int(off[np.argmax(kp_err[off])])
                lines.fail(where, f"class {c} keypoint {s0} is {kp_err[s0] * max(w, h):.3g} px from its true centre "
                           "projection", float(kp_err[s0] * max(w, h)), row=b)
        for c in sorted(set(np.flatnonzero(objects.labeled[b]).tolist()) - set(classes)):
            lines.fail(rel, f"class {c} ({layout.objects[c]}) is labeled in the manifest but has no line", row=b)
    lines.worst = worst
    return [lines, flags, rules], np.array(parsed, dtype=np.float64).reshape(-1, 6)


def _check_pose_names(view: DatasetMeta) -> Check:
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


def _pose_learnable_part(view: DatasetView, instances: NDArray[np.float64]) -> NDArray[np.bool_]:
    """Which pose instances (rows ``(frame row, class, cx, cy, w, h)``) Ultralytics' trainer
    keeps at ``labels.train_imgsz`` and can assign to an anchor, without mosaic (as for
    boxes: :mod:`datagen.core.training`; the pose assigner weighs anchors by keypoint OKS,
    not by box overlap, so the box size rule does not apply)."""
    k = view.intrinsics
    cx, cy = instances[:, 2] * k.width, instances[:, 3] * k.height
    bw, bh = instances[:, 4] * k.width, instances[:, 5] * k.height
    xyxy = np.stack([cx - bw / 2, cy - bh / 2, cx + bw / 2, cy + bh / 2], axis=-1)
    return view.train_view.reaches_loss(xyxy)


def _pose_learnable(meta: DatasetMeta, counts: NDArray[np.int64]) -> dict:
    """The share of pose instances that are learnable (:func:`_pose_learnable_part`;
    ``counts``: instances, learnable ones)."""
    n, good = (int(v) for v in counts)
    return {"instances": n, "learnable": good, "share": good / n if n else None, "imgsz": meta.train_view.imgsz}


def _check_files(view: DatasetIndex | DatasetView) -> Check:
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
            what = (f"names {extra[0]!r}, which no manifest does" if extra
                    else "misses images or lists them out of order")
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


def _check_images(view: DatasetIndex | DatasetView, k: Intrinsics) -> Check:
    """Open every image a manifest names: its header states the dataset's size (``k``), and
    it decodes fully (a truncated file or one that is not an image fails). Missing files
    are the ``files`` check's."""
    import cv2

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


def _check_names(view: DatasetMeta) -> Check:
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
def _statistics_part(view: DatasetView, labels: FrameLabels, rank: NDArray[np.int64]) -> dict:
    """What the statistics need of ``view``'s rows: the drift, distance, obliqueness and class
    of each feature in view (with its frame's position ``rank`` in the dataset's frame
    order, so that the merged values keep the order a whole-dataset view has), and counts."""
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
    rows, cls = np.nonzero(inside)
    vis = view.visible_fraction[labels.labeled]
    cv = view.center_visible[labels.labeled]
    cv = cv[np.isfinite(cv)]
    return {
        "drift": drift[inside], "distance": view.distance_m[rows], "obliqueness": oblique[inside],
        "class": cls.astype(np.int16), "rank": rank[rows].astype(np.int32),
        "exclusions": np.bincount(labels.exclusion.ravel().astype(np.int64), minlength=max(Exclusion) + 1),
        "labeled_per_class": labels.labeled.sum(axis=0),
        "labeled_per_object": np.stack([labels.labeled[:, features.object_index == j].sum(axis=1)
                                        for j in range(len(features.objects))], axis=1).astype(np.int32),
        "visible_fraction": vis[np.isfinite(vis)],
        "centre_visible": (int(cv.size), int((cv == 1.0).sum())),
        "frame_distance": view.distance_m.copy(),
        "appearance": _appearance_part(view.appearance, rank),
    }


class _Totals:
    """What the statistics keep in memory of every :func:`_statistics_part`: counts; the
    per-feature, per-frame and per-draw values go to the spill."""

    def __init__(self, classes: int) -> None:
        self.exclusions = np.zeros(max(Exclusion) + 1, dtype=np.int64)
        self.per_class = np.zeros(classes, dtype=np.int64)
        self.visible = np.zeros(10, dtype=np.int64)  # histogram of labeled features' visible fractions
        self.visible_n = self.visible_full = self.cv_count = self.cv_ones = 0
        self.appearance: dict[str, dict] = {}  # column -> frames, and counts per value (names, flags)

    def add(self, spill: Spill, part: dict) -> None:
        spill.add("drift", part["rank"], drift=part["drift"], distance=part["distance"],
                  obliqueness=part["obliqueness"], cls=part["class"])
        spill.add("frames", None, distance=part["frame_distance"], labeled=part["labeled_per_object"])
        self.exclusions += part["exclusions"]
        self.per_class += part["labeled_per_class"]
        vis = part["visible_fraction"]
        self.visible += np.histogram(vis, bins=10, range=(0.0, 1.0))[0]
        self.visible_n += vis.size
        self.visible_full += int((vis >= 1.0).sum())
        self.cv_count += part["centre_visible"][0]
        self.cv_ones += part["centre_visible"][1]
        for name, column in part["appearance"].items():
            mine = self.appearance.setdefault(name, {"frames": 0})
            mine["frames"] += column["frames"]
            if "values" in column:
                mine["values"] = mine.get("values", Counter()) + column["values"]
            elif column["frames"]:
                spill.add(f"appearance.{name}", column["rank"], value=column["numbers"])


#: Drift groups (:func:`_drift_groups`): all features, then per distance bin, size tag and
#: obliqueness bin from these offsets.
_ALL, _BY_DISTANCE, _BY_SIZE, _BY_OBLIQUENESS = 0, 1, 100_000, 200_000
#: Bins of the drift by view obliqueness, degrees.
OBLIQUENESS_EDGES_DEG: Final = np.arange(0.0, 91.0, 15.0)


def _bin_of(values: NDArray[np.float64], edges: NDArray[np.float64]) -> NDArray[np.int64]:
    """The bin ``k`` with ``edges[k] <= value < edges[k + 1]`` of each value; -1 outside."""
    k = np.searchsorted(edges, values, side="right") - 1
    return np.where((k >= 0) & (k < len(edges) - 1), k, -1)


def _drift_groups(part: dict, distance_edges: NDArray, size_of_class: NDArray[np.int64]) -> list[NDArray[np.int64]]:
    """Each drift value's group in each grouping (-1: none): all, its distance bin, its
    feature's size tag, its obliqueness bin."""
    def offset(k: NDArray[np.int64], base: int) -> NDArray[np.int64]:
        return np.where(k >= 0, k + base, -1)

    return [np.full(len(part["drift"]), _ALL, dtype=np.int64),
            offset(_bin_of(part["distance"], distance_edges), _BY_DISTANCE),
            _size_group(part["cls"], size_of_class),
            offset(_bin_of(part["obliqueness"], OBLIQUENESS_EDGES_DEG), _BY_OBLIQUENESS)]


def _size_group(cls: NDArray, size_of_class: NDArray[np.int64]) -> NDArray[np.int64]:
    """Each drift value's size-tag group (:func:`_drift_groups`)."""
    return size_of_class[cls.astype(np.int64)] + _BY_SIZE


#: Drift values the report's scatter plot shows at most (every k-th in frame order).
SCATTER_POINTS: Final = 20000


def _drift_statistics(spill: Spill, distance_edges: NDArray, size_of_class: NDArray[np.int64]) -> dict:
    """Per drift group: count, mean, median, p95 and max, exactly as numpy gives them on the
    group's values in frame order, and what the plots need (quartiles and whiskers per size
    tag, every k-th feature's distance and drift): from the spilled ``drift`` stream."""
    columns = ("drift", "distance", "obliqueness", "cls")
    count: Counter = Counter()
    nans: Counter = Counter()
    top: dict[int, float] = {}
    for part in spill.parts("drift", *columns):
        d = part["drift"]
        for groups in _drift_groups(part, distance_edges, size_of_class):
            for g in np.unique(groups[groups >= 0]).tolist():
                mine = d[groups == g]
                count[g] += mine.size
                nans[g] += int(np.isnan(mine).sum())
                top[g] = float(np.maximum(top[g], mine.max())) if g in top else float(mine.max())
    sums = {g: OrderedSum(n) for g, n in count.items()}
    n_all = count[_ALL]
    pick = np.linspace(0, n_all - 1, min(n_all, SCATTER_POINTS)).astype(int) if n_all else np.zeros(0, dtype=int)
    scatter, seen = [], 0
    for part in spill.ordered("drift", *columns):
        d = part["drift"]
        for groups in _drift_groups(part, distance_edges, size_of_class):
            order = np.argsort(groups, kind="stable")
            present = np.unique(groups)
            bounds = np.searchsorted(groups[order], present)
            for g, piece in zip(present.tolist(), np.split(order, bounds[1:]), strict=True):
                if g >= 0:
                    sums[g].feed(d[piece])
        mine = pick[(pick >= seen) & (pick < seen + d.size)] - seen
        scatter.append(np.stack([part["distance"][mine], d[mine]], axis=1))
        seen += d.size
    quartiles = {g for g in count if _BY_SIZE <= g < _BY_OBLIQUENESS}
    wanted = {g: set(median_positions(n)) | set(percentile_positions(n, 95))
              | (set(percentile_positions(n, 25)) | set(percentile_positions(n, 75)) if g in quartiles else set())
              for g, n in count.items() if not nans[g]}

    def chunks():
        for part in spill.parts("drift", *columns):
            for groups in _drift_groups(part, distance_edges, size_of_class):
                yield groups, part["drift"]

    found = order_statistics(chunks, wanted)
    out = {}
    for g, n in count.items():
        def stat(k: int, g: int = g) -> float:
            return found[(g, k)]

        nan = bool(nans[g])
        out[g] = {"count": n, "mean": sums[g].mean(), "median": math.nan if nan else median(n, stat),
                  "p95": math.nan if nan else percentile(n, 95, stat), "max": top[g]}
        if g in quartiles and not nan:
            out[g]["box"] = {"q1": percentile(n, 25, stat), "med": out[g]["median"], "q3": percentile(n, 75, stat)}
    _whiskers(spill, out, size_of_class)
    return {"groups": out, "scatter": np.concatenate(scatter) if scatter else np.zeros((0, 2))}


def _whiskers(spill: Spill, groups: dict[int, dict], size_of_class: NDArray[np.int64]) -> None:
    """Matplotlib's box whiskers (the extreme values within 1.5 IQR of the quartiles) of the
    size groups' boxes."""
    boxes = {g: v["box"] for g, v in groups.items() if "box" in v}
    for box in boxes.values():
        iqr = box["q3"] - box["q1"]
        box["lo"], box["hi"] = box["q1"] - 1.5 * iqr, box["q3"] + 1.5 * iqr
        box["whislo"], box["whishi"] = math.inf, -math.inf
    for part in spill.parts("drift", "drift", "cls") if boxes else ():
        d = part["drift"]
        size_group = _size_group(part["cls"], size_of_class)
        for g, box in boxes.items():
            mine = d[size_group == g]
            low, high = mine[mine >= box["lo"]], mine[mine <= box["hi"]]
            if low.size:
                box["whislo"] = min(box["whislo"], float(low.min()))
            if high.size:
                box["whishi"] = max(box["whishi"], float(high.max()))
    for box in boxes.values():
        box["whislo"], box["whishi"] = min(box["whislo"], box["q1"]), max(box["whishi"], box["q3"])
        del box["lo"], box["hi"]


def _statistics(meta: DatasetMeta, spill: Spill, totals: _Totals) -> dict:
    """The statistics of every shard's :func:`_statistics_part` (``totals`` and ``spill``),
    the same numbers numpy gives on the whole dataset's values in frame order."""
    features = meta.features
    frames = spill.rows["frames"]
    far = np.max([p["distance"].max() for p in spill.parts("frames", "distance")]) if frames else 0.0
    top = max(10.0, float(np.ceil(far / 10.0) * 10.0)) if frames else 10.0
    tags = sorted(set(features.size))
    size_of_class = np.array([tags.index(t) for t in features.size], dtype=np.int64)
    distance_edges = np.arange(0.0, top + 10.0, 10.0)
    drift = _drift_statistics(spill, distance_edges, size_of_class)
    groups = drift["groups"]

    def summary(g: int) -> dict:
        v = groups.get(g)
        return {"count": 0} if v is None else {"count": v["count"], "mean": v["mean"], "median": v["median"],
                                               "p95": v["p95"], "max": v["max"]}

    def binned(base: int, edges: NDArray) -> list[dict]:
        return [{"lo": float(lo), "hi": float(hi), **summary(base + k)}
                for k, (lo, hi) in enumerate(itertools.pairwise(edges))]

    coverage_edges = np.arange(0.0, top + 5.0, 5.0)
    coverage = np.zeros(len(coverage_edges) - 1, dtype=np.int64)
    # per object: how many frames have each count of labeled features (at most every feature)
    labeled = np.zeros((len(features.objects), len(features) + 1), dtype=np.int64)
    for part in spill.parts("frames", "distance", "labeled"):
        coverage += np.histogram(part["distance"], bins=coverage_edges)[0]
        for j, counts in enumerate(labeled):
            counts += np.bincount(part["labeled"][:, j], minlength=counts.size)
    pnp = {}
    for obj, counts in zip(features.objects, labeled, strict=True):
        cum = np.cumsum(counts)
        below = int(counts[:PNP_MIN_FEATURES].sum())
        pnp[obj] = {"frames_below_3": below, "share_below_3": below / frames if frames else 0.0,
                    "median_labeled": median(frames, lambda k, cum=cum: float(np.searchsorted(cum, k, side="right")))
                    if frames else 0.0}
    per_class, exclusions = totals.per_class, totals.exclusions
    whole = summary(_ALL)
    return {
        "tight_drift_px": {
            "features": whole["count"],
            "mean": whole.get("mean"),
            "median": whole.get("median"),
            "p95": whole.get("p95"),
            "max": whole.get("max"),
            "by_distance_m": binned(_BY_DISTANCE, distance_edges),
            "by_size": {(tag or "untagged"): summary(_BY_SIZE + i) for i, tag in enumerate(tags)},
            "by_obliqueness_deg": binned(_BY_OBLIQUENESS, OBLIQUENESS_EDGES_DEG),
        },
        "labels_per_class": {features.name[i]: int(per_class[i]) for i in range(len(features))},
        "exclusions": {r.reason or "labeled": int(exclusions[r]) for r in Exclusion},
        "visibility": {
            "labeled_features_rendered": totals.visible_n,
            "visible_fraction_histogram": totals.visible.tolist(),
            "share_fully_visible": totals.visible_full / totals.visible_n if totals.visible_n else None,
            # centre_visible is 1 or 0 where rendered: the mean is the share of ones
            "share_centre_visible": totals.cv_ones / totals.cv_count if totals.cv_count else None,
        },
        "pnp_below_3_features": pnp,
        "distance_coverage": {"edges_m": coverage_edges.tolist(), "frames": coverage.tolist()},
        "_top_m": top,
        "_plot": {"drift_scatter": drift["scatter"],
                  "drift_boxes": [((tag or "untagged"), groups[_BY_SIZE + i]["box"]) for i, tag in enumerate(tags)
                                  if "box" in groups.get(_BY_SIZE + i, {})]},
    }


#: Bins of the appearance section's histograms.
APPEARANCE_BINS: Final = 10


def _appearance_part(columns: dict[str, list], rank: NDArray[np.int64]) -> dict[str, dict]:
    """Per appearance column of some rows: how many drew it, and the draws (counts per value
    for names and flags; for numbers the values with their frames' ``rank``)."""
    out = {}
    for name, column in columns.items():
        rows = [i for i, v in enumerate(column) if v is not None]
        drawn = [column[i] for i in rows]
        if drawn and isinstance(drawn[0], (bool, str)):
            out[name] = {"frames": len(drawn), "values": Counter(str(v).lower() if isinstance(v, bool) else v
                                                                 for v in drawn)}
        else:
            out[name] = {"frames": len(drawn), "numbers": np.asarray(drawn, dtype=np.float64).reshape(-1),
                         "rank": rank[np.asarray(rows, dtype=np.int64)]}
    return out


def _appearance_finish(spill: Spill, columns: dict[str, dict]) -> dict:
    """The appearance section: per dimension (:data:`datagen.dataset.schema.APPEARANCE`) and
    column, how many frames drew it and the distribution of the draws (a histogram of
    :data:`APPEARANCE_BINS` bins for numbers, counts per value for names and flags). A
    column no frame drew (its randomizer off) has ``frames`` 0. ``columns``: the counts
    (:class:`_Totals`); the numbers are in ``spill``'s streams ``appearance.<column>``."""
    from datagen.dataset.schema import APPEARANCE

    out: dict[str, dict] = {}
    for dimension, names in APPEARANCE.items():
        section = {}
        for name in names:
            if name not in columns:
                continue
            entry: dict = {"frames": columns[name]["frames"]}
            if "values" in columns[name]:
                entry["values"] = dict(sorted(columns[name]["values"].items()))
            elif entry["frames"]:
                entry.update(_number_summary(spill, f"appearance.{name}"))
            section[name] = entry
        out[dimension] = section
    return out


def _number_summary(spill: Spill, stream: str) -> dict:
    """Min, max, mean (in frame order) and a histogram of a spilled stream's finite values."""
    n, lo, hi = 0, math.inf, -math.inf
    for part in spill.parts(stream, "value"):
        v = part["value"][np.isfinite(part["value"])]
        if v.size:
            n, lo, hi = n + v.size, min(lo, float(v.min())), max(hi, float(v.max()))
    if not n:
        return {}
    total = OrderedSum(n)
    for part in spill.ordered(stream, "value"):
        total.feed(part["value"][np.isfinite(part["value"])])
    counts = np.zeros(APPEARANCE_BINS, dtype=np.int64)
    for part in spill.parts(stream, "value"):
        v = part["value"][np.isfinite(part["value"])]
        counts_, edges = np.histogram(v, bins=APPEARANCE_BINS, range=(lo, hi if hi > lo else lo + 1.0))
        counts += counts_
    return {"min": lo, "max": hi, "mean": total.mean(), "edges": edges.tolist(), "histogram": counts.tolist()}
