"""The shard writer: renders and labels whole shards in one process and writes their
files, a shard's manifest last.

A shard is done exactly when its manifest exists. Every file goes through
:mod:`datagen.atomic`, so an interrupted build leaves only complete files
and hidden temporaries, which the next run removes before it finishes the
missing shards. Frames whose image an interrupted run already wrote are not
rendered again (their labels and rows are recomputed, which is cheap).
"""

from __future__ import annotations

import contextlib
import math
import os
import platform
import time
from collections import Counter, deque
from collections.abc import Callable, Iterator
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from datagen.atomic import write_exr, write_image, write_text
from datagen.core.box_content import blank_boxes
from datagen.core.keypoints import pose_rows
from datagen.core.label_boxes import FrameLabels
from datagen.dataset.columns import FeatureColumns, feature_records, object_records, write_manifest
from datagen.dataset.layout import Layout, ShardJob
from datagen.dataset.yolo import pose_lines, yolo_lines
from datagen.pipeline.frame import (
    TRAINING_IMAGE_STAGE,
    FrameDraws,
    draw_frame,
    frame_labels,
    shard_labels,
    training_image,
)
from datagen.pipeline.manifest_row import FrameFiles, FrameRender, FrameRun, manifest_row
from datagen.pipeline.progress import ShardSummary
from datagen.render.timing import StageClock
from datagen.scene.approach import FrameStates
from datagen.scene.resolved import Scene

if TYPE_CHECKING:
    from datagen.render.renderer import FrameRenderer

__all__ = ["MAX_GROUP_SHARDS", "MAX_PENDING_WRITES", "FrameRecord", "FramesDone", "ShardWriter", "shard_groups",
           "timed_frame"]

#: Told the number of frames just done (a worker's messages to the build's progress).
FramesDone = Callable[[int], None]

def _rss_mib() -> float:
    """Resident set size of this process now, MiB (Linux; NaN elsewhere)."""
    try:
        with open("/proc/self/statm") as f:
            return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20
    except OSError:
        return math.nan


#: Frames whose images may still be in the writer thread while the next one renders.
MAX_PENDING_WRITES = 1

#: The most shards :func:`shard_groups` puts in one task.
MAX_GROUP_SHARDS = 8


def shard_groups(jobs: list[ShardJob], workers: int, together: bool = True) -> list[list[ShardJob]]:
    """``jobs`` as tasks for ``workers`` workers, each task a list of shards that one worker
    runs with :meth:`ShardWriter.run_group`.

    With ``together``, the shards that share approach chains go in one task, so that a
    worker simulates each chain, and draws its weather, once instead of once per shard:
    with ``split_by: frame`` a val shard's frames are spread over the frames of several
    train shards, and both would simulate the same chains. The shards in order of their
    first frame are cut before each shard of the split that has fewer shards (the train
    shards that start in a val shard's frame range join it), and a task holds at most
    :data:`MAX_GROUP_SHARDS` shards and at most a ``2 * workers``-th of them. Without
    ``together`` (rendering, where the simulation is negligible and a shard takes
    minutes), or with one split, each shard is a task of its own. What a shard holds does
    not depend on its task."""
    ordered = sorted(jobs, key=lambda job: job.frames[0])
    counts = Counter(job.split for job in jobs)
    cap = min(MAX_GROUP_SHARDS, len(jobs) // (2 * max(1, workers)))
    if not together or len(counts) < 2 or cap < 2:
        return [[job] for job in ordered]
    rare = min(counts, key=lambda split: (counts[split], split))
    groups: list[list[ShardJob]] = [[]]
    for job in ordered:
        group = groups[-1]
        if len(group) == cap or (job.split == rare and any(other.split == rare for other in group)):
            groups.append(group := [])
        group.append(job)
    return groups


@dataclass(frozen=True)
class FrameRecord:
    """What writing one frame gives its shard (:meth:`ShardWriter.frame`): the manifest row,
    its feature records, its render (None: not rendered by this run) and its seconds, and
    for a rendered frame the label boxes that show nothing of their feature (``blank``,
    :func:`datagen.core.box_content.blank_boxes`) and the seconds per stage."""

    row: dict[str, object]
    features: FeatureColumns
    render: FrameRender | None
    frame_s: float
    blank: int = 0
    stages: dict[str, float] | None = None

    @property
    def rendered(self) -> bool:
        return self.render is not None


@dataclass
class _ShardTotals:
    """A shard's frames summed as they are written (:meth:`add`); ``compiled`` and
    ``recorded`` are the renderer's new kernels and recordings, which the writer adds."""

    classes: int
    rows: list[dict] = field(default_factory=list)
    labels: int = 0
    excluded: Counter[str] = field(default_factory=Counter)
    rendered: int = 0
    render_s: float = 0.0
    denoise_s: float = 0.0
    frame_s: float = 0.0
    blank: int = 0
    blank_frames: int = 0
    compiled: int = 0
    recorded: int = 0
    stages: Counter[str] = field(default_factory=Counter)  # seconds per stage of the rendered frames

    def __post_init__(self) -> None:
        self.per_class = np.zeros(self.classes, dtype=np.int64)  # label lines per class

    def add(self, record: FrameRecord) -> None:
        self.rows.append(record.row)
        self.labels += int(record.features.labeled.sum())
        self.per_class += record.features.labeled
        self.excluded.update(record.features.exclusion_counts())
        if record.render is not None:
            self.rendered += 1
            self.render_s += record.render.render_s
            self.denoise_s += record.render.denoise_s or 0.0
            self.frame_s += record.frame_s
            self.blank += record.blank
            self.blank_frames += record.blank > 0
            self.stages.update(record.stages or {})

    def summary(self, name: str, frames: int) -> ShardSummary:
        return ShardSummary(name, frames, self.labels, dict(self.excluded), self.rendered, self.render_s,
                            self.denoise_s, self.frame_s, stages=dict(self.stages), blank=self.blank,
                            blank_frames=self.blank_frames, compiled=self.compiled, recorded=self.recorded,
                            per_class=self.per_class.tolist())


class ShardWriter:
    """Renders and labels whole shards in one process: one scene, one feature table."""

    def __init__(self, scene: Scene, layout: Layout, *, render: bool = True) -> None:
        self.scene = scene
        self.states = FrameStates(scene.config)  # each approach chain simulated once per process
        self.layout = layout  # the build's (datagen.pipeline.plan.dataset_layout)
        self.renderer: FrameRenderer | None = None
        self._stop: Callable[[], bool] = lambda: False
        # Images are encoded and written by one background thread while the next frame
        # renders; at most MAX_PENDING_WRITES frames wait, so memory stays bounded.
        self._io = ThreadPoolExecutor(1, thread_name_prefix="datagen-write")
        self._writes: deque[Future] = deque()
        self._clock = StageClock()  # the frame being written
        self._census = None  # the kernels each rendered frame launches (datagen.render.runtime.KernelCensus)
        self._first_frame = True  # this process has rendered no frame yet
        self._recordings = 0  # the frozen render's and ray cast's recordings so far (datagen.render.frozen)
        if render:
            from datagen.render.renderer import Renderer  # Mitsuba only when rendering
            from datagen.render.runtime import KernelCensus

            self.renderer = Renderer(scene)
            self._census = KernelCensus()

    def run_group(self, jobs: list[ShardJob], progress: FramesDone | None = None,
                  stop: Callable[[], bool] | None = None) -> Iterator[ShardSummary]:
        """:meth:`run` each of ``jobs`` (a task of :func:`shard_groups`), yielding each
        shard's summary once its manifest is written; the approach chains of all of them
        are simulated together first, and each chain's weather and liveries drawn once."""
        self.states.prefetch([i for job in jobs for i in job.frames])
        approaches: dict = {}
        for job in jobs:
            yield self.run(job, progress, stop, approaches)

    def run(self, job: ShardJob, progress: FramesDone | None = None,
            stop: Callable[[], bool] | None = None, approaches: dict | None = None) -> ShardSummary:
        """Write every frame of ``job``, then its manifest; return its summary.

        ``stop`` is polled between frames and right after each render: when it
        turns true the shard is abandoned with :class:`KeyboardInterrupt` before
        anything of the current frame is written (a render cut short by Ctrl-C
        never becomes a training image). ``approaches``: a dict keeping each approach
        chain's weather and liveries for the next shards (:meth:`run_group`; by default,
        for this shard's frames only)."""
        start = time.perf_counter()
        self._stop = stop or (lambda: False)
        totals = _ShardTotals(len(self.scene.features))
        self.states.prefetch(job.frames)  # the shard's approach chains, simulated together
        approaches = {} if approaches is None else approaches  # each chain's weather and liveries, drawn once
        draws = [draw_frame(self.scene, self.states, i, approaches) for i in job.frames]
        labels_all, objects_all = shard_labels(self.scene, draws)  # every frame's labels at once
        recording = self._census.recording() if self._census is not None else contextlib.nullcontext()
        with recording:  # the kernels each frame launches
            for b, frame_draws in enumerate(draws):
                if self._stop():
                    raise KeyboardInterrupt
                record = self.frame(job, frame_draws, labels_all.frame(b), objects_all.frame(b))
                totals.add(record)
                if record.rendered:
                    assert self._census is not None and self.renderer is not None  # (a rendering writer's)
                    new = self._census.new_kernels()
                    totals.compiled += 0 if self._first_frame else new  # the first frame compiles (or loads) them all
                    recordings = self.renderer.recordings + self.renderer.cast_recordings
                    # the first frame records
                    totals.recorded += 0 if self._first_frame else recordings - self._recordings
                    self._recordings = recordings
                    self._first_frame = False
                if progress is not None:
                    progress(1)
        self._wait_for_writes(0)
        summary = totals.summary(job.name, len(job.frames))
        write_manifest(self.layout.manifest(job), totals.rows, summary.counts())
        summary.wall_s = time.perf_counter() - start
        return summary

    def frame(self, job: ShardJob, draws: FrameDraws, labels: FrameLabels, objects: FrameLabels) -> FrameRecord:
        """Render (when rendering) and write frame ``draws`` with its feature ``labels``
        (before the occlusion rule) and pose boxes ``objects``; return its manifest row and
        what else its shard sums (:class:`FrameRecord`)."""
        started = time.perf_counter()
        scene, layout = self.scene, self.layout
        k, features = scene.intrinsics, scene.features
        i = draws.index
        image_rel = exr_rel = None
        fraction = center_visible = None
        render = None
        blank = 0
        if self.renderer is not None:
            image_rel = layout.image_rel(job.split, job.shard, i)
            exr_rel = layout.exr_rel(job.split, job.shard, i) if scene.config.render.exr else None
            render, srgb = self._render(draws, layout.root / image_rel, layout.root / exr_rel if exr_rel else None)
            with self._clock.stage("feature visibility"):
                fraction, center_visible = self.renderer.feature_visibility(draws.state, features)
            labels = scene.labelling.occlude(labels, fraction)
            blank = int(np.count_nonzero(blank_boxes(srgb, labels.label_xyxy[labels.labeled])))
        records = feature_records(labels, features.class_id, fraction, center_visible)
        label_rel = layout.label_rel(job.split, job.shard, i)
        pose_rel = layout.pose_label_rel(job.split, job.shard, i)
        if label_rel is not None:
            lines = yolo_lines(labels, features.class_id, k.width, k.height)
            write_text(layout.root / label_rel, "".join(line + "\n" for line in lines))
        if pose_rel is not None:
            rows = pose_rows(objects, labels.center_px, records.keypoint_flag, scene.pose_layout, k.width, k.height)
            write_text(layout.root / pose_rel, "".join(line + "\n" for line in pose_lines(rows)))
        files = FrameFiles(i, job.split, job.shard, image_rel, label_rel, pose_rel, exr_rel)
        run = FrameRun(time.perf_counter() - started, f"{platform.node()}:{os.getpid()}", _rss_mib())
        row = manifest_row(files, k, draws, records, object_records(objects, features.objects), render, run)
        if render is None:
            return FrameRecord(row, records, None, run.frame_s)
        seconds = self._clock.seconds  # and "other": what the named stages leave of the frame's time
        return FrameRecord(row, records, render, run.frame_s, blank,
                           dict(seconds, other=run.frame_s - sum(seconds.values())))

    def _render(self, draws: FrameDraws, image: Path, exr: Path | None) -> tuple[FrameRender, np.ndarray]:
        """Render and write the frame's image (and EXR). Returns what its row records of the
        render (:class:`~datagen.pipeline.manifest_row.FrameRender`) and the 8-bit sRGB
        training image.
        A frame whose files an earlier, interrupted run left is rendered again: its
        measurements live only in the manifest that run did not write, and a shard holds
        few frames."""
        renderer = self.renderer
        assert renderer is not None  # (called where the writer renders)
        result = renderer.render(draws.state, draws.look, draws.render_seed, geometry=exr is not None)
        self._clock = StageClock()
        self._clock.seconds.update(result.stages or {})
        if self._stop():
            raise KeyboardInterrupt
        quality = self.scene.config.render.jpeg_quality
        with self._clock.stage(TRAINING_IMAGE_STAGE):
            srgb, measured = training_image(result, draws.look)

        def write() -> None:  # the image first: a frame is complete once its last file exists
            write_image(image, srgb[..., ::-1], jpeg_quality=quality)
            if exr is not None:
                write_exr(exr, result.rgb, result.depth, result.object_id)

        self._writes.append(self._io.submit(write))
        with self._clock.stage("waiting for image writes"):
            self._wait_for_writes(MAX_PENDING_WRITES)
        render = self.scene.config.render
        return FrameRender(render.spp, render.denoise, measured, result.render_s, result.denoise_s), srgb

    def _wait_for_writes(self, keep: int) -> None:
        """Wait until at most ``keep`` image writes are pending; re-raise their errors."""
        while len(self._writes) > keep:
            self._writes.popleft().result()


def timed_frame(scene: Scene, renderer: FrameRenderer, states: FrameStates, i: int, image: Path
                ) -> tuple[float, dict[str, float]]:
    """Frame ``i`` made as a build makes it (draws, labels, render, feature visibility, the
    training image), its image written to ``image`` (PNG, or JPEG by the suffix) in this
    thread; its wall seconds, whole and per stage (the render's stages included, ``other``
    what no stage names). For the benchmarks: :meth:`ShardWriter.frame` writes the image
    in a background thread instead."""
    clock = StageClock()
    start = time.perf_counter()
    with clock.stage("draws and labels"):
        draws = draw_frame(scene, states, i)
        frame_labels(scene, draws)
    result = renderer.render(draws.state, draws.look, draws.render_seed)
    for name, seconds in (result.stages or {}).items():
        clock.add(name, seconds)
    with clock.stage("feature visibility"):
        renderer.feature_visibility(draws.state, scene.features)
    with clock.stage(TRAINING_IMAGE_STAGE):
        srgb, _ = training_image(result, draws.look)
    with clock.stage("image encoding and writing"):
        write_image(image, srgb[..., ::-1], jpeg_quality=scene.config.render.jpeg_quality)
    whole = time.perf_counter() - start
    clock.add("other", whole - sum(clock.seconds.values()))
    return whole, clock.seconds
