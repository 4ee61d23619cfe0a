"""Seconds per stage of a rendered frame: where a frame's time goes (``bench/bench_render.py``,
the build's summary)."""

from __future__ import annotations

import contextlib
import time
from collections.abc import Iterator

__all__ = ["StageClock"]


class StageClock:
    """Wall seconds per named stage, in the order the stages were first met; a stage
    timed twice adds up."""

    def __init__(self) -> None:
        self.seconds: dict[str, float] = {}

    @contextlib.contextmanager
    def stage(self, name: str) -> Iterator[None]:
        start = time.perf_counter()
        try:
            yield
        finally:
            self.seconds[name] = self.seconds.get(name, 0.0) + time.perf_counter() - start

    def add(self, name: str, seconds: float) -> None:
        self.seconds[name] = self.seconds.get(name, 0.0) + seconds
