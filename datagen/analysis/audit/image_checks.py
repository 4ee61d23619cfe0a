"""The images, each decoded once: every image a manifest names decodes to the dataset's size
(``images``), no frame shows nothing in all its label boxes (``image_content``), and nearly
every label box shows something (``label_content``): a label whose box is saturated, black
or flat in its frame's image teaches a detector nothing (:func:`datagen.core.box_content.blank_boxes`)."""

from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor
from typing import Final

import numpy as np

from datagen.analysis.audit.check import Check, Finish, GroupPart, Recomputed, Section
from datagen.analysis.audit.dataset_files import decode_image, quiet_stderr
from datagen.core.box_content import BLANK_REASONS, blank_boxes
from datagen.dataset.reader import DatasetMeta, DatasetView

#: The image_content check passes while at least this share of the label boxes shows something.
MIN_SHOWING_SHARE: Final = 0.99


def check_images(view: DatasetView) -> list[Check]:
    """The ``images`` and ``image_content`` checks of ``view``'s rows. Missing images and
    paths that lead outside the dataset are the ``files`` check's."""
    k = view.intrinsics
    images = Check("images", f"every image a manifest names decodes fully, {k.width}x{k.height} 8-bit colour as "
                   "dataset.json states")
    frames = Check("image_content", "every frame's image shows something inside at least one of its label boxes "
                   "(not saturated, black or flat)")
    content = Check("label_content", "the image shows something inside each label box (not saturated, black or "
                    f"flat) for at least {100 * MIN_SHOWING_SHARE:g}% of the boxes", min_pass_share=MIN_SHOWING_SHARE)
    paths = {b: rel for b, rel in enumerate(view.image_path) if rel and not view.folder.problem(rel)}
    rows = list(paths)

    def one(b: int) -> tuple[str | None, np.ndarray | None]:
        image, problem = decode_image(view.root / paths[b], view.limits)
        if image is None:
            return problem, None
        return None, blank_boxes(image, view.label_xyxy[b][view.labeled[b]])  # only the codes come back

    with quiet_stderr(), ThreadPoolExecutor(max(1, os.cpu_count() or 1)) as pool:  # OpenCV decodes without the GIL
        for b, (problem, codes) in zip(rows, pool.map(one, rows), strict=True):
            images.checked += 1
            if problem:
                images.fail(paths[b], problem, row=b)
            if codes is None:
                continue
            where = f"{view.manifest_file[b]} frame {view.frame_id[b]}"
            content.checked += len(codes)
            for c, code in zip(view.class_id[b][view.labeled[b]], codes, strict=True):
                if code:
                    content.fail(where, f"class {c}: the label box is {BLANK_REASONS[code]} in the image", row=b)
            if len(codes):
                frames.checked += 1
                if codes.all():
                    reasons = sorted({str(BLANK_REASONS[c]) for c in codes})
                    frames.fail(where, f"none of its {len(codes)} label boxes shows anything ({', '.join(reasons)})",
                                row=b)
    frames.applicable = content.applicable = bool(rows)
    return [images, frames, content]


class ImageChecks:
    """The images: decoded, and what they show where their labels are."""

    stream = "images"

    def applies(self, meta: DatasetMeta) -> bool:
        return True

    def frames(self, view: DatasetView, found: Recomputed) -> GroupPart:
        return GroupPart(check_images(view))

    def finish(self, meta: DatasetMeta, done: Finish) -> tuple[list[Check], Section | None]:
        return [done.merged["images"], done.merged["image_content"], done.merged["label_content"]], None
