"""What a build did: shard summaries and the build report (its summary lines)."""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

from datagen.core.label_boxes import Exclusion
from datagen.dataset.layout import SPLITS, ShardJob
from datagen.render.timing import rest_of_frame

__all__ = ["BuildReport", "ShardSummary"]

@dataclass
class ShardSummary:
    """What one shard holds (deterministic counts) and what it cost (this run)."""

    name: str
    frames: int
    labels: int
    excluded: dict[str, int]
    rendered: int = 0  # frames rendered by this run (0 for a shard done earlier)
    render_s: float = 0.0  # seconds inside mi.render
    denoise_s: float = 0.0  # seconds in the denoiser
    frame_s: float = 0.0  # seconds of the rendered frames, whole (render, denoise and the rest)
    wall_s: float = 0.0
    stages: dict[str, float] = field(default_factory=dict)  # seconds per stage of the rendered frames
    blank: int = 0  # label boxes of the rendered frames that show nothing (datagen.core.box_content)
    blank_frames: int = 0  # rendered frames with such a box
    compiled: int = 0  # JIT kernels first launched by a rendered frame after its process's first
    recorded: int = 0  # recordings of the frozen render or ray cast made after its process's first frame
    per_class: list[int] | None = None  # label lines per class (None: a shard written before they were counted)

    def counts(self) -> dict:
        """The deterministic part, stored in the manifest's metadata."""
        return {"frames": self.frames, "labels": self.labels, "excluded": dict(sorted(self.excluded.items())),
                "per_class": self.per_class}

    @classmethod
    def from_counts(cls, name: str, counts: dict, frames: int) -> ShardSummary:
        """A finished shard's summary from :meth:`counts` as its manifest's metadata holds
        them (``frames``: the plan's, where the metadata has none)."""
        per_class = counts.get("per_class")
        return cls(name, int(counts.get("frames", frames)), int(counts.get("labels", 0)),
                   {str(k): int(v) for k, v in counts.get("excluded", {}).items()},
                   per_class=[int(n) for n in per_class] if per_class else None)


# --- the build ---------------------------------------------------------------------------
def _summed(name: str, doc: str) -> property:
    """A :class:`BuildReport` property: ShardSummary field ``name`` added up over the shards."""
    return property(lambda self: sum(getattr(s, name) for s in self.shards.values()), doc=f"The {doc}, all shards.")


@dataclass
class BuildReport:
    """What a build did, for the summary."""

    name: str
    root: Path
    jobs: list[ShardJob]
    classes: list[str] = field(default_factory=list)  # the feature table's class names, by class id
    shards: dict[str, ShardSummary] = field(default_factory=dict)
    resumed: list[str] = field(default_factory=list)  # shards done by an earlier run
    wall_s: float = 0.0
    interrupted: bool = False

    @property
    def frames(self) -> int:
        return sum(len(j.frames) for j in self.jobs)

    def split_frames(self, split: str) -> int:
        return sum(len(j.frames) for j in self.jobs if j.split == split)

    labels = _summed("labels", "label boxes written")
    rendered = _summed("rendered", "frames rendered by this run")
    render_s = _summed("render_s", "seconds inside mi.render")
    denoise_s = _summed("denoise_s", "seconds in the denoiser")
    rendered_frame_s = _summed("frame_s", "seconds of this run's rendered frames, whole")
    compiled = _summed("compiled", "JIT kernels first launched after a worker's first frame")
    recorded = _summed("recorded", "recordings of the frozen render or ray cast after a worker's first frame")
    blank = _summed("blank", "label boxes of rendered frames that show nothing")
    blank_frames = _summed("blank_frames", "rendered frames with such a box")

    @property
    def excluded(self) -> dict[str, int]:
        """Features excluded per reason, every reason named (0 where none)."""
        total = self._counted("excluded")
        return {r.reason: total.get(r.reason, 0) for r in Exclusion if r.reason}

    @property
    def never_labeled(self) -> list[int]:
        """The class ids no frame of the finished shards labels (empty where a shard's per-class
        counts are unknown, or without class names)."""
        known = [s.per_class for s in self.shards.values()]
        counts = [c for c in known if c is not None]
        if not self.classes or not counts or len(counts) < len(known):
            return []
        return [c for c in range(len(self.classes)) if not any(per[c] for per in counts)]

    @property
    def stages(self) -> dict[str, float]:
        """Seconds per stage of this run's rendered frames, the longest first."""
        return dict(self._counted("stages").most_common())

    def _counted(self, name: str) -> Counter:
        """A ShardSummary's per-key field added up over the shards."""
        total: Counter = Counter()
        for s in self.shards.values():
            total.update(getattr(s, name))
        return total

    @property
    def frames_this_run(self) -> int:
        return sum(s.frames for n, s in self.shards.items() if n not in self.resumed)

    def lines(self) -> list[str]:
        done = len(self.shards)
        out = [f"{self.name}: {self.frames} frames ({self.split_frames('train')} train, "
               f"{self.split_frames('val')} val) in {len(self.jobs)} shards -> {self.root}"]
        empty = [s for s in SPLITS if not self.split_frames(s)]
        if len(empty) == 1:
            other = "val" if empty[0] == "train" else "train"
            out.append(f"  no {empty[0]} frames: Ultralytics uses the {other} frames for both (data.yaml lists "
                       f"{other}.txt as {empty[0]}); dataset.val_fraction and the frames drawn decide the split")
        if self.resumed:
            out.append(f"  resumed: {len(self.resumed)} of {len(self.jobs)} shards were done by an earlier run")
        n, wall = self.frames_this_run, self.wall_s
        rate = n / wall if wall > 0 else 0.0
        out.append(f"  this run: {n} frames ({self.rendered} rendered) in {wall:.1f} s, "
                   f"{rate:.3f} frames/s = {3600 * rate:,.0f} frames/h")
        if self.rendered:
            k = self.rendered
            frame, render, denoise = self.rendered_frame_s / k, self.render_s / k, self.denoise_s / k
            other = max(frame - render - denoise, 0.0)
            share = (frame - render) / frame if frame > 0 else 0.0
            out.append(f"  per rendered frame: {frame:.2f} s = mi.render {render:.2f} s + denoise {denoise:.2f} s "
                       f"+ other {other:.2f} s ({share:.0%} outside mi.render)")
            rest = [(name, s / k) for name, s in rest_of_frame(self.stages) if round(s / k, 2) > 0]  # what shows
            if rest:
                out.append("  other, per rendered frame: " + ", ".join(f"{name} {s:.2f} s" for name, s in rest))
            out.append(f"  kernels compiled after each worker's first frame: {self.compiled}")
            if self.recorded:  # render.frozen: Dr.Jit recorded the path tracing or the cast again (render.frozen)
                out.append(f"  frozen render or ray cast recorded again after each worker's first frame: "
                           f"{self.recorded} times")
        excluded = ", ".join(f"{k} {v}" for k, v in self.excluded.items())
        scope = "" if done == len(self.jobs) else f" (in the {done} finished shards)"
        out.append(f"  labels: {self.labels} boxes{scope}; excluded: {excluded}")
        out += [f"    {r.reason}: {r.meaning}" for r in Exclusion if r.reason and self.excluded[r.reason]]
        unseen = self.never_labeled
        if unseen:
            names = ", ".join(self.classes[c] for c in unseen[:6]) + (", ..." if len(unseen) > 6 else "")
            out.append(f"  never labeled in this build: {len(unseen)} of {len(self.classes)} classes "
                       f"({_ranges(unseen)}: {names}); no frame showed them inside the image and its margins")
        if self.blank:
            out.append(f"  warning: {self.blank} label boxes in {self.blank_frames} of the {self.rendered} "
                       "rendered frames show "
                       "nothing in the image (saturated, black or flat): the config's draws (exposure, sensor, "
                       "field of view) make frames a detector cannot learn from; datagen audit names them")
        if self.interrupted:
            out.append(f"  interrupted: {len(self.jobs) - done} shards unfinished; run the same command "
                       "again to finish them")
        return out


def _ranges(ids: list[int]) -> str:
    """Sorted integers as ranges: ``6-39, 41``."""
    spans: list[list[int]] = []
    for i in ids:
        if spans and i == spans[-1][1] + 1:
            spans[-1][1] = i
        else:
            spans.append([i, i])
    return ", ".join(f"{a}-{b}" if b > a else f"{a}" for a, b in spans)
