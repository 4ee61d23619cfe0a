"""The pose label files line by line, the keypoint flags, the pose data.yaml and the share of pose
instances the trainer can learn from."""

from __future__ import annotations

from collections import Counter

import numpy as np
from numpy.typing import NDArray

from datagen.analysis.audit.check import (
    LINE_TOLERANCE,
    POSE_TOLERANCE,
    Check,
    Finish,
    GroupPart,
    Recomputed,
    Section,
    label_files,
)
from datagen.analysis.audit.summary import PoseLearnability
from datagen.core.keypoints import KEYPOINT_RANGE, keypoint_flags, mirror_name
from datagen.core.label_boxes import Exclusion, FrameLabels
from datagen.dataset.reader import DatasetMeta, DatasetView
from datagen.dataset.yolo import parse_line


def check_pose_files(view: DatasetView, labels: FrameLabels, objects: FrameLabels
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
    for b, rel, rows in label_files(view, view.pose_label_path, lines, "pose label file"):
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


def check_pose_names(view: DatasetMeta) -> Check:
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


def pose_learnable_part(view: DatasetView, instances: NDArray[np.float64]) -> NDArray[np.bool_]:
    """Which pose instances (rows ``(frame row, class, cx, cy, w, h)``) Ultralytics' trainer
    keeps at ``labels.train_imgsz`` and can assign to an anchor, without mosaic (as for
    boxes: :mod:`datagen.core.training`; the pose assigner weighs anchors by keypoint OKS,
    not by box overlap, so the box size rule does not apply)."""
    k = view.intrinsics
    cx, cy = instances[:, 2] * k.width, instances[:, 3] * k.height
    bw, bh = instances[:, 4] * k.width, instances[:, 5] * k.height
    xyxy = np.stack([cx - bw / 2, cy - bh / 2, cx + bw / 2, cy + bh / 2], axis=-1)
    return view.train_view.reaches_loss(xyxy)


def pose_learnable(meta: DatasetMeta, counts: NDArray[np.int64]) -> PoseLearnability:
    """The share of pose instances that are learnable (:func:`pose_learnable_part`;
    ``counts``: instances, learnable ones)."""
    n, good = (int(v) for v in counts)
    return PoseLearnability(n, good, good / n if n else None, meta.train_view.imgsz)


class PoseChecks:
    """The pose label files, the keypoint flags, the pose data.yaml, and the share of pose
    instances the trainer can learn from."""

    stream = "pose"

    def applies(self, meta: DatasetMeta) -> bool:
        return meta.pose_yaml is not None

    def frames(self, view: DatasetView, found: Recomputed) -> GroupPart:
        checks, instances = check_pose_files(view, found.labels, found.objects)
        return GroupPart(checks, {"learnable": pose_learnable_part(view, instances)})

    def finish(self, meta: DatasetMeta, done: Finish) -> tuple[list[Check], Section | None]:
        counts = np.zeros(2, dtype=np.int64)  # pose instances, learnable ones
        for part in done.spill.parts(self.stream, "learnable"):
            counts += (part["learnable"].size, part["learnable"].sum())
        checks = [done.merged[n] for n in ("pose_lines", "keypoint_flags", "ultralytics_pose_rules")]
        return [*checks, check_pose_names(meta)], pose_learnable(meta, counts)
