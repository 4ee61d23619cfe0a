"""The frames the audit's report draws: chosen from the dataset's frame order and labelled
with the dataset's own labelling context, so that the report only draws."""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np

from datagen.core.label_boxes import FrameLabels
from datagen.dataset.reader import DatasetIndex, DatasetSource, DatasetView

__all__ = ["frames_to_draw"]


def frames_to_draw(dataset: DatasetView | DatasetSource, n: int, index: DatasetIndex | None = None
                   ) -> Iterator[tuple[DatasetView, int, FrameLabels]]:
    """``(view, row, labels)`` of ``n`` frames spread evenly over the dataset's frame order;
    a source's shards are read, and labelled, only where a chosen frame lies."""
    if isinstance(dataset, DatasetView):
        if len(dataset) and n:
            labels = dataset.recompute()
            for b in np.linspace(0, len(dataset) - 1, min(n, len(dataset))).round().astype(int):
                yield dataset, int(b), labels
        return
    index = index or dataset.index()
    if not len(index) or not n:
        return
    shard = labels = None
    for b in np.linspace(0, len(index) - 1, min(n, len(index))).round().astype(int):
        name = index.manifest_file[b]
        if shard is None or shard.manifest_file[0] != name:
            shard = dataset.read_shard(name, checked=False)
            labels = shard.recompute()
        rows = np.flatnonzero(shard.frame_id == index.frame_id[b])
        yield shard, int(rows[0]), labels
