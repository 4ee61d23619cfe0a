"""What a build did and how far it is: shard summaries, the build report, the progress display."""

from __future__ import annotations

import math
import sys
import time
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

from datagen.core.labels import Exclusion
from datagen.dataset.layout import ShardJob
from datagen.pipeline.estimate import FrameCost
from datagen.render.timing import rest_of_frame

__all__ = ["BuildProgress", "BuildReport", "ShardSummary"]

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
    blank: int = 0  # label boxes of the rendered frames that show nothing (datagen.core.content)
    blank_frames: int = 0  # rendered frames with such a box
    compiled: int = 0  # JIT kernels first launched by a rendered frame after its process's first

    def counts(self) -> dict:
        """The deterministic part, stored in the manifest's metadata."""
        return {"frames": self.frames, "labels": self.labels, "excluded": dict(sorted(self.excluded.items()))}


# --- the build ---------------------------------------------------------------------------
@dataclass
class BuildReport:
    """What a build did, for the summary."""

    name: str
    root: Path
    jobs: list[ShardJob]
    shards: dict[str, ShardSummary] = field(default_factory=dict)
    resumed: list[str] = field(default_factory=list)  # shards done by an earlier run
    wall_s: float = 0.0
    interrupted: bool = False

    @property
    def frames(self) -> int:
        return sum(len(j.frames) for j in self.jobs)

    def split_frames(self, split: str) -> int:
        return sum(len(j.frames) for j in self.jobs if j.split == split)

    @property
    def labels(self) -> int:
        return sum(s.labels for s in self.shards.values())

    @property
    def excluded(self) -> dict[str, int]:
        total: Counter = Counter()
        for s in self.shards.values():
            total.update(s.excluded)
        return {r.reason: total.get(r.reason, 0) for r in Exclusion if r.reason}

    @property
    def rendered(self) -> int:
        return sum(s.rendered for s in self.shards.values())

    @property
    def render_s(self) -> float:
        return sum(s.render_s for s in self.shards.values())

    @property
    def denoise_s(self) -> float:
        return sum(s.denoise_s for s in self.shards.values())

    @property
    def rendered_frame_s(self) -> float:
        return sum(s.frame_s for s in self.shards.values())

    @property
    def stages(self) -> dict[str, float]:
        """Seconds per stage of this run's rendered frames, the longest first."""
        total: Counter = Counter()
        for s in self.shards.values():
            total.update(s.stages)
        return dict(total.most_common())

    @property
    def frames_this_run(self) -> int:
        return sum(s.frames for n, s in self.shards.items() if n not in self.resumed)

    def lines(self) -> list[str]:
        done = len(self.shards)
        out = [f"{self.name}: {self.frames} frames ({self.split_frames('train')} train, "
               f"{self.split_frames('val')} val) in {len(self.jobs)} shards -> {self.root}"]
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
            compiled = sum(s.compiled for s in self.shards.values())
            out.append(f"  kernels compiled after each worker's first frame: {compiled}")
        excluded = ", ".join(f"{k} {v}" for k, v in self.excluded.items())
        scope = "" if done == len(self.jobs) else f" (in the {done} finished shards)"
        out.append(f"  labels: {self.labels} boxes{scope}; excluded: {excluded}")
        blank = sum(s.blank for s in self.shards.values())
        if blank:
            frames = sum(s.blank_frames for s in self.shards.values())
            out.append(f"  warning: {blank} label boxes in {frames} of the {self.rendered} rendered frames show "
                       "nothing in the image (saturated, black or flat): the config's draws (exposure, sensor, "
                       "field of view) make frames a detector cannot learn from; datagen audit names them")
        if self.interrupted:
            out.append(f"  interrupted: {len(self.jobs) - done} shards unfinished; run the same command "
                       "again to finish them")
        return out


class BuildProgress:
    """Frames done, frames/s and ETA: a live bar on a terminal, else a plain line
    every ``interval_s`` seconds and one per finished shard (on stderr)."""

    def __init__(self, name: str, *, stream=None, interval_s: float = 30.0, live: bool | None = None,
                 verb: str = "build", announce: bool = True) -> None:
        self.name = name
        self.verb = verb  # what the lines say is under way: build, audit, evaluate
        self.announce = announce  # a line at the start (else the first after interval_s)
        self.stream = stream or sys.stderr
        self.live = self.stream.isatty() if live is None else live
        self.interval_s = interval_s
        self._bar = None

    def start(self, total: int, done: int, estimate: FrameCost | None = None) -> None:
        """Begin: ``total`` frames, ``done`` of them by an earlier run; ``estimate``, the
        model's cost of a frame, is printed with what it predicts for the rest."""
        self.total, self.done, self.first = total, done, done
        if estimate is not None:
            todo = total - done
            self._print(f"{self.verb} {self.name}: estimate {estimate.seconds:.2f} s a frame = "
                        f"{estimate.frames_per_hour:,.0f} frames/h on {estimate.cores} cores ({estimate.setting}), "
                        f"{_duration(todo * estimate.seconds)} for {todo} frames; measured rates follow")
        self.t0 = self._last = time.perf_counter()
        if self.live:
            from rich.console import Console
            from rich.progress import (
                BarColumn,
                MofNCompleteColumn,
                Progress,
                TextColumn,
                TimeElapsedColumn,
                TimeRemainingColumn,
            )

            self._bar = Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(),
                                 TextColumn("{task.fields[rate]}"), TimeElapsedColumn(), TextColumn("ETA"),
                                 TimeRemainingColumn(), console=Console(file=self.stream))
            self._task = self._bar.add_task(f"{self.verb} {self.name}", total=total, completed=done, rate="")
            self._bar.start()
        elif self.announce:
            self._print(f"{self.verb} {self.name}: {total} frames, {done} already done")

    def _rate(self) -> tuple[float, float]:
        """Frames per second so far and the seconds still to go."""
        elapsed = time.perf_counter() - self.t0
        rate = (self.done - self.first) / elapsed if elapsed > 0 else 0.0
        eta = (self.total - self.done) / rate if rate > 0 else math.inf
        return rate, eta

    def advance(self, n: int) -> None:
        self.done += n
        rate, _ = self._rate()
        if self._bar is not None:
            self._bar.update(self._task, advance=n, rate=f"{rate:.2f} frames/s")
        elif time.perf_counter() - self._last >= self.interval_s:
            self._status()

    def _status(self) -> None:
        rate, eta = self._rate()
        eta_text = time.strftime("%H:%M:%S", time.gmtime(eta)) if math.isfinite(eta) and eta < 86400 * 365 else "?"
        share = 100 * self.done / max(1, self.total)
        self._print(f"{self.verb} {self.name}: {self.done}/{self.total} frames ({share:.0f}%),"
                    f" {rate:.3f} frames/s = {3600 * rate:,.0f} frames/h, ETA {eta_text}")

    def shard_done(self, summary: ShardSummary) -> None:
        if self._bar is None:
            self._print(f"shard {summary.name}: {summary.frames} frames, {summary.labels} labels, "
                        f"{summary.wall_s:.1f} s")
            self._status()

    def _print(self, text: str) -> None:
        self._last = time.perf_counter()
        print(text, file=self.stream, flush=True)

    def close(self) -> None:
        if self._bar is not None:
            self._bar.stop()
            self._bar = None


def _duration(seconds: float) -> str:
    """``seconds`` as ``1 h 05 min``, ``4 min 10 s`` or ``12 s``."""
    s = round(seconds)
    if s >= 3600:
        return f"{s // 3600} h {s % 3600 // 60:02d} min"
    return f"{s // 60} min {s % 60:02d} s" if s >= 60 else f"{s} s"
