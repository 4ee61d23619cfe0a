"""The manifests against a recomputation: feature boxes, centres and exclusions, and the objects'
pose boxes."""

from __future__ import annotations

import numpy as np

from datagen.analysis.audit.check import (
    MANIFEST_TOLERANCE_PX,
    REASONS,
    Check,
    Finish,
    GroupPart,
    Recomputed,
    Section,
    nan_error,
)
from datagen.core.label_boxes import Exclusion, FrameLabels
from datagen.dataset.reader import DatasetMeta, DatasetView


def check_manifest(view: DatasetView, labels: FrameLabels) -> Check:
    check = Check("manifest_boxes", "manifest centres, tight, corrected and label boxes and exclusions equal a "
                  f"recomputation from the poses and features.parquet (to {MANIFEST_TOLERANCE_PX:g} px)")
    check.checked = len(view)
    k_ok = view.intrinsics_as_built
    class_ok = (view.class_id == view.features.class_id).all(axis=1)
    fresh_label = np.where(labels.labeled[..., None], labels.label_xyxy, np.nan)  # stored only for labeled features
    err = np.max([nan_error(view.center_px, labels.center_px), nan_error(view.tight_xyxy, labels.tight_xyxy),
                  nan_error(view.corrected_xyxy, labels.corrected_xyxy), nan_error(view.label_xyxy, fresh_label)],
                 axis=0)
    good = k_ok & class_ok
    checked = err[good]
    check.worst = float(checked[np.isfinite(checked)].max(initial=0.0))
    reasons = REASONS[labels.exclusion.astype(np.int64)]
    bad = good[:, None] & ((err > MANIFEST_TOLERANCE_PX) | (reasons != view.exclusion)
                           | (view.labeled != labels.labeled))
    for b in np.flatnonzero(~good | bad.any(axis=1)).tolist():
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


def check_objects(view: DatasetView, objects: FrameLabels) -> Check:
    """The manifests' pose boxes against a recomputation from the poses and objects.parquet."""
    check = Check("manifest_objects", "manifest object boxes (projected hull box, pose label box) and exclusions "
                  f"equal a recomputation from the poses and objects.parquet (to {MANIFEST_TOLERANCE_PX:g} px)")
    label = np.where(objects.labeled[..., None], objects.label_xyxy, np.nan)
    err = np.maximum(nan_error(view.object_tight_xyxy, objects.tight_xyxy), nan_error(view.object_label_xyxy, label))
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


class ManifestChecks:
    """The manifests' boxes, centres and exclusions against the recomputation."""

    stream = "manifest"

    def applies(self, meta: DatasetMeta) -> bool:
        return True

    def frames(self, view: DatasetView, found: Recomputed) -> GroupPart:
        return GroupPart([check_manifest(view, found.labels), check_objects(view, found.objects)])

    def finish(self, meta: DatasetMeta, done: Finish) -> tuple[list[Check], Section | None]:
        return [done.merged["manifest_boxes"], done.merged["manifest_objects"]], None
