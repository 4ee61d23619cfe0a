"""The image lists ``train.txt`` and ``val.txt`` of a finished dataset (and placeholder
images for labels-only builds that a dataloader must read)."""

from __future__ import annotations

from pathlib import Path

from datagen.atomic import link_or_copy, write_image, write_text
from datagen.dataset.layout import SPLITS, Layout, ShardJob

__all__ = [
    "write_image_lists",
    "write_placeholder_images",
]


def write_image_lists(layout: Layout, jobs: list[ShardJob]) -> list[Path]:
    """``train.txt`` and ``val.txt``: every image of each split in frame order, one
    ``./images/...`` path per line (Ultralytics resolves ``./`` against the list's
    folder, for training and for ``yolo predict source=``). Written when every shard
    is done, so that a list never names a missing image."""
    written = []
    roots = [layout.root] + ([layout.pose_root] if layout.pose_root != layout.root else [])
    for split in SPLITS:
        lines = [f"./{layout.image_rel(job.split, job.shard, i)}\n"
                 for job in jobs if job.split == split for i in job.frames]
        if lines:
            written += [write_text(root / layout.image_list(split).name, "".join(lines)) for root in roots]
    return written


def write_placeholder_images(layout: Layout, jobs: list[ShardJob], width: int, height: int) -> list[Path]:
    """One grey image at every frame's image path (the first written, the others hard links
    to it), then the image lists: a labels-only build that Ultralytics' dataloader reads
    (the labels do not depend on the pixels). For tests and benchmarks, not datasets."""
    import numpy as np

    first = None
    for job in jobs:
        for i in job.frames:
            path = layout.root / layout.image_rel(job.split, job.shard, i)
            if first is None:
                first = write_image(path, np.full((height, width, 3), 90, np.uint8))
            else:
                link_or_copy(first, path)
    return write_image_lists(layout, jobs)
