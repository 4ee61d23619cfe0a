"""The audit's driver: every per-frame check and the statistics' values, shard by shard (in
worker processes) or on a whole view, merged into one :class:`~datagen.analysis.audit.check.AuditResult`."""

from __future__ import annotations

import dataclasses
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Final

import numpy as np
from numpy.typing import NDArray

from datagen.analysis.audit.check import AuditResult, Check, CheckGroup, Finish, GroupPart, Recomputed, Section
from datagen.analysis.audit.dataset_files import check_files, check_recipe, check_texels
from datagen.analysis.audit.image_checks import ImageChecks
from datagen.analysis.audit.label_lines import MIN_LEARNABLE_SHARE, LabelLineChecks
from datagen.analysis.audit.manifest_checks import ManifestChecks
from datagen.analysis.audit.pose import PoseChecks
from datagen.analysis.audit.statistics import StatisticsPart, Totals, appearance_finish, statistics, statistics_part
from datagen.analysis.audit.summary import Learnability, PoseLearnability
from datagen.analysis.exact import Spill
from datagen.console import NullProgress, Progress
from datagen.dataset.reader import DatasetMeta, DatasetView, Shard
from datagen.parallel import map_in_order

#: The groups of per-frame checks, in report order (the dataset's files and images follow).
GROUPS: Final[tuple[CheckGroup, ...]] = (ManifestChecks(), LabelLineChecks(), PoseChecks(), ImageChecks())


@dataclass
class _Part:
    """The audit of some of a dataset's frames (one shard's, or a whole view's): each group's
    part, offenders ranked in the dataset's frame order, and the compact values the
    statistics need (:func:`statistics_part`)."""

    groups: list[GroupPart]  # of the groups that apply, in GROUPS order
    stats: StatisticsPart


def _audit_part(view: DatasetView, rank: NDArray[np.int64]) -> _Part:
    """Every per-frame check of ``view``'s rows; ``rank``: each row's position in the
    dataset's frame order."""
    found = Recomputed(view.recompute(), view.recompute_objects())
    parts = [group.frames(view, found) for group in GROUPS if group.applies(view)]
    for part in parts:
        part.checks = [c.ranked(rank) for c in part.checks]
    return _Part(parts, statistics_part(view, found.labels, rank))


def _audit_shard(dataset: DatasetMeta, shard: Shard) -> _Part:
    return _audit_part(dataset.read(shard, checked=False), shard.positions)


def _parts(dataset: DatasetMeta, workers: int, progress) -> Iterator[_Part]:
    """The one iterator the checks and statistics are fed from: each shard in manifest order
    (a loaded view is one), in ``workers`` processes (each reads and checks whole shards;
    only the compact results come back)."""
    shards = dataset.shards()
    for shard, part in zip(shards, map_in_order(_audit_shard, [(dataset, s) for s in shards], workers), strict=True):
        progress.advance(len(shard.positions))
        yield part


def audit(dataset: DatasetMeta, *, min_learnable: float = MIN_LEARNABLE_SHARE, workers: int = 1,
          progress: Progress | None = None) -> AuditResult:
    """Run every check and compute every statistic of a dataset.

    ``dataset``: a loaded view (all in memory), or an opened source, which is read and
    checked shard by shard (in ``workers`` processes), keeping only counts, the worst
    offenders and the compact values the statistics need: the same report either way.
    ``min_learnable``: the share of label lines that must be learnable by Ultralytics'
    trainer at ``labels.train_imgsz`` (:mod:`datagen.core.training`).
    ``progress``: an object with ``start(total, done)``, ``advance(n)`` and ``close()``
    (:class:`datagen.console.Progress`)."""
    progress = progress or NullProgress()
    index = dataset.frames()
    progress.start(len(index), 0)
    groups = [group for group in GROUPS if group.applies(dataset)]
    merged: dict[str, Check] = {}
    with Spill() as spill:  # the per-feature and per-line values, on disk until the statistics
        totals = Totals(len(dataset.features))
        for part in _parts(dataset, workers, progress):
            for group, found in zip(groups, part.groups, strict=True):
                for c in found.checks:
                    merged[c.name] = merged[c.name].merge(c) if c.name in merged else c
                if found.values is not None:
                    spill.add(group.stream, None, **found.values)
            totals.add(spill, part.stats)
            del part
        progress.close()
        found_stats = statistics(dataset, spill, totals)
        done = Finish(merged, spill, found_stats.top_m, min_learnable)
        checks: list[Check] = []
        sections: list[Section] = []
        for group in groups:
            group_checks, section = group.finish(dataset, done)
            checks += group_checks
            sections += [section] if section is not None else []
        stats = dataclasses.replace(
            found_stats.summary, appearance=appearance_finish(spill, totals.appearance),
            learnable=next((s for s in sections if isinstance(s, Learnability)), None),
            learnable_pose=next((s for s in sections if isinstance(s, PoseLearnability)), None))
    checks += [check_files(index), check_recipe(dataset), check_texels(index)]
    return AuditResult(dataset.root, str(dataset.doc.get("name", dataset.root.name)), len(index),
                       [c.finish() for c in checks], stats, found_stats.plot)
