"""Running work on this machine's cores, shared by the build (:mod:`datagen.pipeline`) and
the reading commands (:mod:`datagen.analysis`): the cores a process may use, results of
tasks in spawned processes taken in task order, and a progress display that shows nothing."""

from __future__ import annotations

import contextlib
import ctypes
import functools
import itertools
import os
from collections import deque
from collections.abc import Callable, Iterator
from typing import Final

__all__ = ["IN_FLIGHT_PER_WORKER", "MMAP_THRESHOLD_BYTES", "cpu_count", "fixed_mmap_threshold",
           "map_in_order"]


def cpu_count() -> int:
    """The cores this process may run on."""
    with contextlib.suppress(AttributeError):
        return len(os.sched_getaffinity(0))
    return os.cpu_count() or 1


#: Tasks :func:`map_in_order` keeps submitted per worker: enough to keep the workers busy
#: while the caller takes the results in order, few enough that results never pile up.
IN_FLIGHT_PER_WORKER: Final = 2


def map_in_order(fn: Callable, tasks: list[tuple], workers: int) -> Iterator:
    """``fn(*task)`` of each task, yielded in task order: in this process, or in ``workers``
    spawned processes (for the reading commands: each task reads what it needs itself and
    returns a compact result). At most :data:`IN_FLIGHT_PER_WORKER` tasks per worker are
    submitted or done and not yet taken, and a result is let go once yielded, so that
    memory does not grow with the number of tasks (:func:`fixed_mmap_threshold`)."""
    fixed_mmap_threshold()
    if workers <= 1 or len(tasks) <= 1:
        for task in tasks:
            yield fn(*task)
        return
    import multiprocessing as mp
    from concurrent.futures import ProcessPoolExecutor

    workers = min(workers, len(tasks))
    with ProcessPoolExecutor(workers, mp_context=mp.get_context("spawn")) as pool:
        todo = iter(tasks)
        pending = deque(pool.submit(fn, *task) for task in itertools.islice(todo, IN_FLIGHT_PER_WORKER * workers))
        while pending:
            result = pending.popleft().result()
            following = next(todo, None)
            if following is not None:
                pending.append(pool.submit(fn, *following))
            yield result
            del result


#: glibc's ``mallopt`` parameter of the size above which an allocation gets pages of its own.
_M_MMAP_THRESHOLD: Final = -3
#: Allocations of at least this many bytes get pages of their own, returned when freed.
MMAP_THRESHOLD_BYTES: Final = 64 * 1024


@functools.cache
def fixed_mmap_threshold() -> bool:
    """Make glibc give every allocation of :data:`MMAP_THRESHOLD_BYTES` or more pages of its
    own, handed back to the system when freed (once per process; False where the C library
    is not glibc). By default glibc raises that threshold to the largest block freed so far
    (up to 32 MiB), and a reader that takes shard after shard of arrays then keeps them in a
    heap that fragments and grows with the number of shards; with the threshold fixed, the
    memory of a shard's arrays goes back to the system when they are let go."""
    try:
        return bool(ctypes.CDLL("libc.so.6").mallopt(_M_MMAP_THRESHOLD, MMAP_THRESHOLD_BYTES))
    except (OSError, AttributeError):
        return False
