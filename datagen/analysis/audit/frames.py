"""The frames the audit's report draws: chosen from the dataset's frame order and labelled
with the dataset's own labelling context, so that the report only draws."""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np

from datagen.core.label_boxes import FrameLabels
from datagen.dataset.reader import DatasetMeta, DatasetView

__all__ = ["frames_to_draw"]


def frames_to_draw(dataset: DatasetMeta, n: int) -> Iterator[tuple[DatasetView, int, FrameLabels]]:
    """``(view, row, labels)`` of ``n`` frames spread evenly over the dataset's frame order;
    a source's shards are read, and labelled, only where a chosen frame lies."""
    count = len(dataset.frames())
    if not count or not n:
        return
    chosen = np.unique(np.linspace(0, count - 1, min(n, count)).round().astype(np.int64))
    labelled: tuple[DatasetView, FrameLabels] | None = None
    for view, rows in dataset.walk(chosen, checked=False):
        if labelled is None or labelled[0] is not view:
            labelled = (view, view.recompute())
        for row in rows.tolist():
            yield view, int(row), labelled[1]
