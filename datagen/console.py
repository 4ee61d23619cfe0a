"""Progress on the console: the :class:`Progress` protocol every long command reports to
(a build, an audit, an evaluation), the display that prints it (:class:`ConsoleProgress`)
and the reporter that shows nothing (:class:`NullProgress`)."""

from __future__ import annotations

import math
import sys
import time
from typing import Any, Protocol

__all__ = ["ConsoleProgress", "Estimate", "NullProgress", "Progress", "ShardDone"]


class Estimate(Protocol):
    """What a command predicts a frame costs (:class:`datagen.pipeline.estimate.FrameCost`)."""

    @property
    def seconds(self) -> float: ...

    @property
    def cores(self) -> int: ...

    @property
    def setting(self) -> str: ...

    @property
    def disk_bytes(self) -> float: ...  # per frame

    @property
    def frames_per_hour(self) -> float: ...


class ShardDone(Protocol):
    """A finished shard as a build reports it (:class:`datagen.pipeline.progress.ShardSummary`)."""

    @property
    def name(self) -> str: ...

    @property
    def frames(self) -> int: ...

    @property
    def labels(self) -> int: ...

    @property
    def wall_s(self) -> float: ...


class Progress(Protocol):
    """What a long command tells its reporter: the frames to do and those an earlier run did
    (and, for a build, the estimate), the frames done as they finish, each finished shard,
    and the end."""

    def start(self, total: int, done: int, estimate: Estimate | None = None) -> None: ...

    def advance(self, n: int) -> None: ...

    def shard_done(self, summary: ShardDone) -> None: ...

    def close(self) -> None: ...


class NullProgress:
    """A :class:`Progress` that shows nothing (a caller that passed none)."""

    def start(self, total: int, done: int, estimate: Estimate | None = None) -> None:
        pass

    def advance(self, n: int) -> None:
        pass

    def shard_done(self, summary: ShardDone) -> None:
        pass

    def close(self) -> None:
        pass


class ConsoleProgress:
    """Frames done, frames/s and ETA: a live bar on a terminal, else a plain line
    every ``interval_s`` seconds and one per finished shard (on stderr)."""

    def __init__(self, name: str, *, stream=None, interval_s: float = 30.0, live: bool | None = None,
                 verb: str = "build", announce: bool = True, clock=time.perf_counter) -> None:
        self.name = name
        self.verb = verb  # what the lines say is under way: build, audit, evaluate
        self.announce = announce  # a line at the start (else the first after interval_s)
        self.stream = stream or sys.stderr
        self.live = self.stream.isatty() if live is None else live
        self.interval_s = interval_s
        self.clock = clock
        self._bar: Any = None  # rich's Progress, where the stream is a terminal
        self._estimate: Estimate | None = None  # the model's, until the first frames are measured

    def start(self, total: int, done: int, estimate: Estimate | None = None) -> None:
        """Begin: ``total`` frames, ``done`` of them by an earlier run; ``estimate``, the
        model's cost of a frame, is printed with what it predicts for the rest."""
        self.total, self.done, self.first = total, done, done
        self._estimate = estimate
        if estimate is not None:
            todo = total - done
            self._print(f"{self.verb} {self.name}: estimate {estimate.seconds:.2f} s a frame = "
                        f"{estimate.frames_per_hour:,.0f} frames/h on {estimate.cores} cores ({estimate.setting}), "
                        f"{_duration(todo * estimate.seconds)} and about {_size(todo * estimate.disk_bytes)} on disk "
                        f"for {todo} frames (a model of an idle machine; corrected after the first "
                        f"{self._measured_after()} frames)")
        self.t0 = self._last = self.clock()
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

    def _measured_after(self) -> int:
        """Frames after which the estimate gives way to the measured rate: the first two (a
        worker's first frame compiles its kernels), more for a longer build (an eighth of it,
        at most 16)."""
        return max(2, min(16, (self.total - self.first) // 8))

    def _correct(self) -> None:
        """Once the first frames are measured, say what they cost beside the estimate and what
        is left at the measured rate (a busy or slower machine is not the model's)."""
        measured = self.done - self.first
        if self._estimate is None or measured < min(self._measured_after(), self.total - self.first):
            return
        elapsed = self.clock() - self.t0
        per_frame = elapsed / measured
        rate, eta = self._rate()
        said = self._estimate.seconds  # wall seconds a frame on the cores the build uses
        self._estimate = None
        if self.total == self.done:
            return
        self._print(f"{self.verb} {self.name}: measured {per_frame:.2f} s a frame over the first {measured} frames "
                    f"(estimated {said:.2f}, {per_frame / said:.1f}x); {_duration(eta)} left at "
                    f"{3600 * rate:,.0f} frames/h")

    def _rate(self) -> tuple[float, float]:
        """Frames per second so far and the seconds still to go."""
        elapsed = self.clock() - self.t0
        rate = (self.done - self.first) / elapsed if elapsed > 0 else 0.0
        eta = (self.total - self.done) / rate if rate > 0 else math.inf
        return rate, eta

    def advance(self, n: int) -> None:
        self.done += n
        rate, _ = self._rate()
        if self._bar is not None:
            self._bar.update(self._task, advance=n, rate=f"{rate:.2f} frames/s")
        self._correct()
        if self._bar is None and self.clock() - self._last >= self.interval_s:
            self._status()

    def _status(self) -> None:
        rate, eta = self._rate()
        eta_text = time.strftime("%H:%M:%S", time.gmtime(eta)) if math.isfinite(eta) and eta < 86400 * 365 else "?"
        share = 100 * self.done // max(1, self.total)  # 100% only when every frame is done
        self._print(f"{self.verb} {self.name}: {self.done}/{self.total} frames ({share}%),"
                    f" {rate:.3f} frames/s = {3600 * rate:,.0f} frames/h, ETA {eta_text}")

    def shard_done(self, summary: ShardDone) -> None:
        if self._bar is None:
            self._print(f"shard {summary.name}: {summary.frames} frames, {summary.labels} labels, "
                        f"{summary.wall_s:.1f} s")
            self._status()

    def _print(self, text: str) -> None:
        self._last = self.clock()
        if self._bar is not None:
            self._bar.console.print(text, markup=False, highlight=False)
        else:
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


def _size(n_bytes: float) -> str:
    """``n_bytes`` as ``2.3 GB``, ``19 MB`` or ``640 KB`` (decimal units, two or three figures)."""
    for unit, scale in (("TB", 1e12), ("GB", 1e9), ("MB", 1e6)):
        if n_bytes >= scale:
            value = n_bytes / scale
            return f"{value:.1f} {unit}" if value < 10 else f"{value:.0f} {unit}"
    return f"{max(1.0, n_bytes / 1e3):.0f} KB"
