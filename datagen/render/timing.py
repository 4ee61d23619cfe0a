"""Seconds per stage of a rendered frame: where a frame's time goes (``bench/bench_render.py``,
the build's summary)."""

from __future__ import annotations

import contextlib
import time
from collections.abc import Callable, Iterator
from typing import Final

__all__ = ["DENOISE", "PATH_TRACING", "StageClock", "rest_of_frame"]

#: The stages that are the physics (``mi.render`` and the denoiser); every other stage is
#: the rest of the frame.
PATH_TRACING: Final = "path tracing"
DENOISE: Final = "denoise"


class StageClock:
    """Wall seconds per named stage, in the order the stages first ended; a stage
    timed twice adds up, and a stage timed inside another counts for the inner one only."""

    def __init__(self, clock: Callable[[], float] = time.perf_counter) -> None:
        self.seconds: dict[str, float] = {}
        self._clock = clock  # seconds, monotonic
        self._inner: list[float] = []  # per open stage: seconds its nested stages took

    @contextlib.contextmanager
    def stage(self, name: str) -> Iterator[None]:
        start = self._clock()
        self._inner.append(0.0)
        try:
            yield
        finally:
            elapsed = self._clock() - start
            self.add(name, elapsed - self._inner.pop())
            if self._inner:
                self._inner[-1] += elapsed

    def add(self, name: str, seconds: float) -> None:
        self.seconds[name] = self.seconds.get(name, 0.0) + seconds


def rest_of_frame(stages: dict[str, float]) -> list[tuple[str, float]]:
    """``(name, seconds)`` of the stages outside path tracing and the denoiser, the longest first."""
    return sorted(((n, s) for n, s in stages.items() if n not in (PATH_TRACING, DENOISE)), key=lambda ns: -ns[1])
