"""The detection label files line by line, and whether their boxes can teach a detector
(Ultralytics' trainer at ``labels.train_imgsz``: :mod:`datagen.core.training`)."""

from __future__ import annotations

import functools
import itertools
import math
import re
from collections import Counter
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Final

import numpy as np
from numpy.typing import NDArray

from datagen.analysis.audit.check import (
    DRIFT_LIMIT_PX,
    LINE_TOLERANCE,
    REASONS,
    Check,
    Finish,
    GroupPart,
    Recomputed,
    Section,
    label_files,
)
from datagen.analysis.audit.statistics import bin_of
from datagen.analysis.audit.summary import Learnability, LearnableBin, LearnableShare
from datagen.analysis.exact import Spill, median, median_positions, order_statistics
from datagen.core.label_boxes import Exclusion, FrameLabels
from datagen.core.training import ASSIGNABLE_SIDE_PX
from datagen.dataset.reader import DatasetMeta, DatasetView
from datagen.dataset.yolo import parse_line

#: A label box side within this of the edge margin lies on it (label lines carry ~1e-7 px).
_ON_MARGIN_PX: Final = 1e-3


#: The ``learnable`` check fails when a smaller share of label lines can teach the detector.
MIN_LEARNABLE_SHARE: Final = 0.95


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


@dataclass
class _LabelLines:
    """Every line of every readable label file of a view, in (frame, line) order: its text,
    frame row and line number, its values (NaN where it is not well formed) and problem,
    and per file (by frame row) its path, first line and line count."""

    view: DatasetView
    texts: list[str]
    row: NDArray[np.int64]
    number: NDArray[np.int64]
    values: NDArray[np.float64]
    problems: list[str | None]
    files: dict[int, tuple[str, int, int]]

    @classmethod
    def read(cls, view: DatasetView, lines: Check) -> _LabelLines:
        """The view's label files, read and parsed (an unreadable file fails ``lines``)."""
        texts: list[str] = []
        frame_rows: list[int] = []
        numbers: list[int] = []
        files: dict[int, tuple[str, int, int]] = {}
        values_parts, problems = [], []
        for b, rel, rows in label_files(view, view.label_path, lines):
            files[b] = (rel, len(texts), len(rows))
            values, why = _parse_lines(rows, len(view.features), 5)
            values_parts.append(values)
            problems += why
            texts += rows
            frame_rows += [b] * len(rows)
            numbers += range(1, len(rows) + 1)
        values = np.concatenate(values_parts) if values_parts else np.zeros((0, 5))
        return cls(view, texts, np.asarray(frame_rows, dtype=np.int64), np.asarray(numbers, dtype=np.int64), values,
                   problems, files)

    def where(self, i: int) -> str:
        """Line ``i``'s file and line number."""
        return f"{self.view.label_path[self.row[i]]}:{self.number[i]}"

    def seq(self, i: int, sub: int) -> int:
        """Line ``i``'s ``sub``-th failure, in the order the rules run on one line."""
        return int(self.number[i]) * 8 + sub

    @functools.cached_property
    def well(self) -> NDArray[np.int64]:
        """The indices of the well-formed lines."""
        return np.flatnonzero(np.array([p is None for p in self.problems], dtype=bool))

    def well_per_file(self) -> Iterator[tuple[int, NDArray[np.int64]]]:
        """Per file: its frame row and the indices of its well-formed lines."""
        idx = self.well
        for b_file, (_rel, start, count) in self.files.items():
            yield b_file, idx[np.searchsorted(idx, start):np.searchsorted(idx, start + count)]


def check_label_files(view: DatasetView, labels: FrameLabels) -> tuple[list[Check], NDArray[np.float64]]:
    """The per-line checks, and every well-formed line as a row ``(frame row, class, cx, cy, w, h)``.

    Vectorized over the view's lines; the failures, their order (frame, line, then the
    order the rules are listed in below) and their scores are those of checking one line
    at a time."""
    m = view.edge_margin_px
    lines = Check("label_lines", "every label line equals its manifest box (class, centre, size; to the "
                  "file's rounding) and every labeled feature has exactly one line")
    drift = Check("centre_drift", f"label-file box centres lie within {DRIFT_LIMIT_PX:g} px of the projection "
                  "of the feature's true 3D centre (corrected datasets)", applicable=view.corrected)
    margin = Check("edge_margin_and_front", f"labeled boxes lie at least edge_margin_px ({m:g} px) inside every "
                   "border and no labeled feature has a point at or behind the camera plane")
    rules = Check("ultralytics_rules", "label files follow Ultralytics' rules: 5 columns, integer class < nc, "
                  "values in [0, 1], positive size, no duplicate rows")
    read = _LabelLines.read(view, lines)
    rules.checked = lines.checked = len(read.texts)
    drift.checked = margin.checked = len(read.well)
    _ultralytics_rules(read, rules)
    _label_lines(read, labels, lines)
    _centre_drift(read, labels, drift)
    _edge_margin_and_front(read, labels, margin)
    idx = read.well
    parsed = np.column_stack([read.row[idx].astype(np.float64), read.values[idx]]) if len(idx) else np.zeros((0, 6))
    return [lines, drift, margin, rules], parsed


def _ultralytics_rules(read: _LabelLines, rules: Check) -> None:
    """Lines that are not 5 numbers with an integer class under nc, values outside [0, 1] or
    a size not positive, and a file's duplicate rows (on their second occurrence)."""
    for i, problem in enumerate(read.problems):
        if problem is not None:
            rules.fail(read.where(i), problem, row=read.row[i], seq=read.seq(i, 0))
    idx = read.well
    v = read.values[idx]
    outside = (v[:, 1:].min(axis=1) < 0) | (v[:, 1:].max(axis=1) > 1) | (v[:, 3] <= 0) | (v[:, 4] <= 0)
    for i in idx[outside]:
        rules.fail(read.where(i), f"values {read.texts[i].split()[1:]} outside [0, 1] or a size not positive",
                   row=read.row[i], seq=read.seq(i, 1))
    for b_file, mine in read.well_per_file():
        keys = [tuple(read.texts[i].split()) for i in mine]
        if len(set(keys)) < len(keys):
            seen: Counter = Counter()
            for i, key in zip(mine, keys, strict=True):
                seen[key] += 1
                if seen[key] == 2:
                    rules.fail(read.where(i), "duplicate row", row=b_file, seq=read.seq(i, 2))


def _label_lines(read: _LabelLines, labels: FrameLabels, lines: Check) -> None:
    """A file's second line of a class, a line of an excluded feature, a line that differs
    from its manifest box, and (after the file's lines) a labeled feature without a line."""
    view, idx = read.view, read.well
    w, h = view.intrinsics.width, view.intrinsics.height
    v, b, f = read.values[idx], read.row[idx], read.values[idx, 0].astype(np.int64)
    for b_file, mine in read.well_per_file():
        classes = read.values[mine, 0].astype(np.int64)
        if len(set(classes.tolist())) < len(classes):
            per_class: Counter = Counter()
            for i, c in zip(mine, classes.tolist(), strict=True):
                per_class[c] += 1
                if per_class[c] == 2:
                    lines.fail(read.where(i), f"class {c} has more than one line", row=b_file, seq=read.seq(i, 0))
    labeled = labels.labeled[b, f]
    exclusion = labels.exclusion[b, f].astype(np.int64)
    for i, c, e in zip(idx[~labeled], f[~labeled], exclusion[~labeled], strict=True):
        lines.fail(read.where(i), f"class {c} has a line but the feature is excluded ({REASONS[e]})",
                   row=read.row[i], seq=read.seq(i, 1))
    centre, box = labels.label_center_px[b, f], labels.label_xyxy[b, f]
    expected = np.stack([centre[:, 0] / w, centre[:, 1] / h, (box[:, 2] - box[:, 0]) / w, (box[:, 3] - box[:, 1]) / h],
                        axis=-1)
    err = np.abs(v[:, 1:] - expected)
    err_px = (err * [w, h, w, h]).max(axis=1)
    finite = labeled & np.isfinite(err).all(axis=1)
    lines.worst = float(err_px[finite].max(initial=0.0))
    off = labeled & ~np.all(err <= LINE_TOLERANCE, axis=1)
    for i, c, e in zip(idx[off], f[off], err_px[off], strict=True):
        lines.fail(read.where(i), f"class {c} differs from the manifest box by {e:.3g} px", float(e),
                   row=read.row[i], seq=read.seq(i, 1))
    have = np.zeros(labels.labeled.shape, dtype=bool)
    have[b, f] = True
    for b_file, (rel, _, count) in read.files.items():
        for c in np.flatnonzero(labels.labeled[b_file] & ~have[b_file]):
            lines.fail(rel, f"class {c} is labeled in the manifest but has no line", row=b_file,
                       seq=(count + 1) * 8 + int(c))


def _line_boxes(read: _LabelLines) -> tuple[NDArray[np.float64], ...]:
    """The well-formed lines' boxes in pixels: centre x and y, width and height."""
    k, v = read.view.intrinsics, read.values[read.well]
    return v[:, 1] * k.width, v[:, 2] * k.height, v[:, 3] * k.width, v[:, 4] * k.height


def _centre_drift(read: _LabelLines, labels: FrameLabels, drift: Check) -> None:
    """In a corrected dataset, a line whose centre lies farther than DRIFT_LIMIT_PX from the
    projection of its feature's true centre."""
    idx = read.well
    b, f = read.row[idx], read.values[idx, 0].astype(np.int64)
    cx, cy, _, _ = _line_boxes(read)
    true_centre = labels.center_px[b, f]
    d = np.hypot(cx - true_centre[:, 0], cy - true_centre[:, 1])
    drift.worst = float(d[np.isfinite(d)].max(initial=0.0))
    if read.view.corrected:
        far = ~(d <= DRIFT_LIMIT_PX)
        for i, c, e in zip(idx[far], f[far], d[far], strict=True):
            drift.fail(read.where(i), f"class {c} centre is {e:.3g} px from the true centre projection", float(e),
                       row=read.row[i], seq=read.seq(i, 0))


def _edge_margin_and_front(read: _LabelLines, labels: FrameLabels, margin: Check) -> None:
    """A line of a feature behind the camera, and a line whose box lies closer than the edge
    margin to a border."""
    view, idx = read.view, read.well
    k, m = view.intrinsics, view.edge_margin_px
    b, f = read.row[idx], read.values[idx, 0].astype(np.int64)
    behind = labels.exclusion[b, f].astype(np.int64) == Exclusion.BEHIND_CAMERA
    for i, c in zip(idx[behind], f[behind], strict=True):
        margin.fail(read.where(i), f"class {c} is behind the camera", row=read.row[i], seq=read.seq(i, 0))
    cx, cy, bw, bh = _line_boxes(read)
    inside = np.min([cx - bw / 2, cy - bh / 2, k.width - (cx + bw / 2), k.height - (cy + bh / 2)], axis=0)
    near = inside < m - 1e-3
    for i, c, e in zip(idx[near], f[near], inside[near], strict=True):
        margin.fail(read.where(i), f"class {c} box is {e:.2f} px from the border, margin {m:g} px", float(m - e),
                    row=read.row[i], seq=read.seq(i, 1))


def learnable_part(view: DatasetView, lines: NDArray[np.float64]) -> dict[str, NDArray]:
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
    # that far: datagen.core.label_boxes) is as large as its feature's line can be.
    m = view.label_rules.edge_margin_px
    on = np.isclose(xyxy, [m, m, k.width - m, k.height - m], rtol=0.0, atol=_ON_MARGIN_PX)
    short = train.short_sides(xyxy)
    border = short.any(axis=1) & ~(short & ~(on[:, :2] | on[:, 2:])).any(axis=1)  # every short side on it
    return {"cls": cls.astype(np.int16), "distance": view.distance_m[b], "survives": train.survives(xyxy),
            "anchored": train.has_anchor(xyxy), "assignable": ~np.any(short, axis=1), "border": border,
            "train_w": np.minimum(bw * train.scale[0], bh * train.scale[1])}


def check_learnable(meta: DatasetMeta, spill: Spill, top: float, min_share: float) -> tuple[Check, Learnability]:
    """Which label lines Ultralytics' trainer keeps at ``labels.train_imgsz``, can assign to an
    anchor and gives a target at the start of training (:func:`learnable_part` of every
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
        k = bin_of(part["distance"], edges)
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
    by_class: dict[str, LearnableShare] = {}
    for c in np.flatnonzero(per_class[:, 0]):
        n, ok_n = (int(v) for v in per_class[c])
        by_class[names[c]] = LearnableShare(n, ok_n / n)
        if ok_n < n:
            check.fail(f"class {c} {names[c]}", f"{ok_n / n:.1%} of {n} lines learnable", float(1.0 - ok_n / n))
    check.failures = lines - good  # offenders are the classes above; the count is of label lines

    def share(counts: NDArray[np.int64]) -> LearnableShare:
        n, ok_n = (int(v) for v in counts)
        return LearnableShare(n, ok_n / n if n else None)

    sizes = np.array(meta.features.size, dtype=object)
    stats = Learnability(
        train_imgsz=rules.train_imgsz,
        min_box_px=rules.min_box_px,
        small_boxes=rules.small_boxes,
        threshold=min_share,
        lines=lines,
        share=good / lines if lines else None,
        share_survive_2px=survived / lines if lines else None,
        share_with_anchor=anchored_ / lines if lines else None,
        share_assignable=assignable / lines if lines else None,
        share_at_edge_margin=border / lines if lines else None,
        assignable_side_px=ASSIGNABLE_SIDE_PX,
        min_side_train_median_px=_median_of(spill, "lines", "train_w") if lines else None,
        min_side_train_px=low if lines else None,
        by_distance_m=tuple(LearnableBin(float(lo), float(hi), share(per_bin[k]))
                            for k, (lo, hi) in enumerate(itertools.pairwise(edges))),
        by_size={(tag or "untagged"): share(per_class[sizes == tag].sum(axis=0))
                 for tag in sorted(set(meta.features.size))},
        by_class=by_class,
    )
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


def check_names(view: DatasetMeta) -> Check:
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


class LabelLineChecks:
    """The detection label files, line by line, and whether their boxes can teach a detector."""

    stream = "lines"

    def applies(self, meta: DatasetMeta) -> bool:
        return meta.label_format != "pose"

    def frames(self, view: DatasetView, found: Recomputed) -> GroupPart:
        checks, parsed = check_label_files(view, found.labels)
        return GroupPart(checks, learnable_part(view, parsed))

    def finish(self, meta: DatasetMeta, done: Finish) -> tuple[list[Check], Section | None]:
        learnable, section = check_learnable(meta, done.spill, done.top_m, done.min_learnable)
        checks = [done.merged[n] for n in ("label_lines", "centre_drift", "edge_margin_and_front", "ultralytics_rules")]
        return [*checks, learnable, check_names(meta)], section
