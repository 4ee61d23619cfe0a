"""Executors: shards in parallel in local processes or as Ray tasks, and each worker's
process setup.

Each executor is a row of :data:`EXECUTORS` (an :class:`Executor`): ``local`` runs shards
in spawned processes (one scene and one Mitsuba thread pool of ``cores / workers`` threads
each; one worker runs in the build's own process); ``ray`` runs them as Ray tasks on the
cluster at ``RAY_ADDRESS``, else a local one.
A worker process is set up in one place, :func:`_bootstrap`: signals, dying with
its parent, Mitsuba's and OpenCV's thread counts (and numpy's BLAS and OpenMP's, from
the environment it is spawned with: :func:`worker_environment`), and its :class:`~datagen.pipeline.writer.ShardWriter`
(one scene per process, reused by every shard it runs). Labels and manifest rows
depend on (scene, frame index) only, never on the executor or the worker count.
"""

from __future__ import annotations

import contextlib
import os
import signal
import time
from collections.abc import Callable
from contextlib import AbstractContextManager
from dataclasses import dataclass
from typing import Any, Final, Literal, Protocol

from datagen.core.errors import DatagenError
from datagen.dataset.layout import Layout, ShardJob
from datagen.parallel import cpu_count
from datagen.pipeline.estimate import auto_workers
from datagen.pipeline.progress import ShardSummary
from datagen.pipeline.writer import FramesDone, ShardWriter, shard_groups
from datagen.scene.resolved import Scene

__all__ = ["EXECUTORS", "THREAD_VARIABLES", "Executor", "ExecutorName", "LocalExecutor", "RayExecutor", "ShardRun",
           "ctrl_c_flag", "local_threads", "ray_cluster", "run_local", "run_ray", "worker_environment"]

ExecutorName = Literal["local", "ray"]


@dataclass(frozen=True)
class ShardRun:
    """What an executor runs: the shards ``jobs`` of ``scene`` into ``layout``, ``workers`` at
    a time (None: the executor's default), each with ``threads`` Mitsuba threads (None: the
    cores shared among them), rendered or labels only (``render``); the frames done go to
    ``progress``, and each finished shard's summary to ``done``."""

    scene: Scene
    layout: Layout
    jobs: list[ShardJob]
    workers: int | None
    render: bool
    progress: FramesDone
    done: Callable[[ShardSummary], None]
    threads: int | None = None




class _Worker:
    """A worker process's state, made once by :func:`_bootstrap` (the process's entry point)."""

    writer: ShardWriter | None = None
    key: tuple | None = None
    queue: Any = None  # (a multiprocessing queue of frames done)
    args: tuple = ()


def _writer(scene: Scene, layout: Layout, threads: int, render: bool) -> ShardWriter:
    """This process's writer for (scene, layout): built once, reused by every shard."""
    key = (id(scene), scene.config.model_dump_json(), layout, render)
    if _Worker.writer is None or _Worker.key != key:
        _Worker.writer, _Worker.key = ShardWriter(scene, layout, render=render), key
    if render:
        from datagen.render.runtime import set_threads

        set_threads(threads)
    return _Worker.writer


def _die_with_parent() -> None:
    """Ask Linux to kill this worker when its parent dies (a SIGKILLed build must not
    leave workers writing into a folder whose lock is gone)."""
    with contextlib.suppress(Exception):
        import ctypes

        libc = ctypes.CDLL("libc.so.6", use_errno=True)
        libc.prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG


def _bootstrap(scene: Scene, layout: Layout, threads: int, render: bool, queue) -> None:
    """The entry point of a local worker process: everything process-wide is set here."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the parent handles Ctrl-C and terminates us
    _die_with_parent()
    _Worker.queue = queue
    _Worker.args = (scene, layout, threads, render)


#: The thread pools a native library sizes from its environment when it loads: a spawned
#: worker gets its share of the cores in each (numpy's BLAS, OpenMP) unless the user set them.
THREAD_VARIABLES: Final = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")


@contextlib.contextmanager
def worker_environment(threads: int):
    """:data:`THREAD_VARIABLES` set to ``threads`` for the processes spawned inside (each
    one the user has not set), restored after."""
    added = [name for name in THREAD_VARIABLES if name not in os.environ]
    os.environ.update({name: str(max(1, int(threads))) for name in added})
    try:
        yield
    finally:
        for name in added:
            os.environ.pop(name, None)


#: A worker sends its frame count to the parent at most this often (and after each shard).
PROGRESS_EVERY_S: Final = 0.25


class _Counts:
    """A worker's progress callback: frames added up and sent on by ``send`` at most every
    :data:`PROGRESS_EVERY_S` of ``clock`` (a message per frame would take the parent of a
    labels-only build a core's share of time in queue reads)."""

    def __init__(self, send: Callable[[int], None], clock: Callable[[], float] = time.monotonic) -> None:
        self.send, self.clock, self.frames = send, clock, 0
        self.last = clock()

    def __call__(self, n: int) -> None:
        self.frames += n
        if self.clock() - self.last >= PROGRESS_EVERY_S:
            self.flush()

    def flush(self) -> None:
        if self.frames:
            self.send(self.frames)
            self.frames = 0
        self.last = self.clock()


def _run_group(writer: ShardWriter, group: list[ShardJob], send: Callable[[int], None],
               clock: Callable[[], float] = time.monotonic) -> list[ShardSummary]:
    """A task of :func:`shard_groups` in a worker: its shards' summaries, the frames done
    sent on as they go (:class:`_Counts`, on ``clock``)."""
    counts = _Counts(send, clock)
    summaries = []
    try:
        for summary in writer.run_group(group, counts):
            counts.flush()
            summaries.append(summary)
    finally:
        counts.flush()
    return summaries


def _pool_run(group: list[ShardJob]) -> list[ShardSummary]:
    queue = _Worker.queue
    assert queue is not None  # (the pool's initializer sets it)
    return _run_group(_writer(*_Worker.args), group, queue.put)


@contextlib.contextmanager
def ctrl_c_flag():
    """Turn Ctrl-C into a flag the writer polls at safe points (a second Ctrl-C
    interrupts at once). Mitsuba cancels a render on SIGINT and then passes the
    signal on to this handler, so a cut-short image is caught by the flag."""
    state = {"requested": False}

    def handler(signum, frame):
        if state["requested"]:
            raise KeyboardInterrupt
        state["requested"] = True

    try:
        previous = signal.signal(signal.SIGINT, handler)
    except ValueError:  # not the main thread: leave signals alone
        yield lambda: False
        return
    try:
        yield lambda: state["requested"]
    finally:
        signal.signal(signal.SIGINT, previous)


def local_threads(workers: int, threads: int | None) -> int:
    """Mitsuba threads per local worker: ``threads``, or the cores shared among the workers."""
    return threads or max(1, cpu_count() // workers)


def run_local(work: ShardRun) -> None:
    """Run ``work``'s jobs in its workers' processes (one, the default: in this process), as
    the tasks of :func:`shard_groups`."""
    scene, layout, jobs, render, progress, done = (work.scene, work.layout, work.jobs, work.render, work.progress,
                                                   work.done)
    workers = min(work.workers or 1, len(jobs))
    threads = local_threads(workers, work.threads)
    groups = shard_groups(jobs, workers, together=not render)
    if workers == 1:
        writer = _writer(scene, layout, threads, render)
        with ctrl_c_flag() as stop:
            for group in groups:
                for summary in writer.run_group(group, progress, stop):
                    done(summary)
        return
    import multiprocessing as mp
    import queue as queue_module
    from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
    from concurrent.futures.process import BrokenProcessPool

    ctx = mp.get_context("spawn")  # never fork a process that may hold Dr.Jit threads
    queue = ctx.Queue()

    def drain() -> None:
        with contextlib.suppress(queue_module.Empty):
            while True:
                progress(queue.get_nowait())

    executor = ProcessPoolExecutor(workers, mp_context=ctx, initializer=_bootstrap,
                                   initargs=(scene, layout, threads, render, queue))
    try:
        with worker_environment(threads):  # the workers are spawned by the first submits
            pending = {executor.submit(_pool_run, group): group for group in groups}
        while pending:
            finished, _ = wait(pending, timeout=0.2, return_when=FIRST_COMPLETED)
            drain()
            for future in finished:
                group = pending.pop(future)
                try:
                    summaries = future.result()  # re-raises a worker's exception here
                except BrokenProcessPool:
                    names = ", ".join(job.name for job in group)
                    raise DatagenError(f"shard{'s' if len(group) > 1 else ''} {names}: a worker process died (out "
                                       "of memory, or killed); rerun the same command to finish the missing "
                                       "shards") from None
                for summary in summaries:
                    done(summary)
        drain()
    except BaseException:
        # Ctrl-C or a failed shard: stop every worker now (their files are atomic, the
        # temporaries they leave are swept) instead of waiting for their shards.
        for process in list(getattr(executor, "_processes", {}).values()):
            process.terminate()
        executor.shutdown(wait=True, cancel_futures=True)
        raise
    executor.shutdown(wait=True)


def _ray_run(scene: Scene, layout: Layout, group: list[ShardJob], threads: int, render: bool,
             queue) -> list[ShardSummary]:
    """A Ray task (the entry point of its worker process for this dataset): a task of
    :func:`shard_groups`."""
    return _run_group(_writer(scene, layout, threads, render), group, queue.put_nowait)


@contextlib.contextmanager
def ray_cluster(workers: int | None):
    """Connect to Ray (``RAY_ADDRESS``, else a local cluster) before any work starts and
    check ``workers`` against its CPUs; shuts down a cluster it started."""
    try:
        import ray
    except ImportError:
        raise DatagenError("--executor ray: Ray is not installed; install it with "
                           "`pip install 'datagen[ray]'` (or use --executor local)") from None
    started = False
    if not ray.is_initialized():
        address = os.environ.get("RAY_ADDRESS")
        if address:
            ray.init(address=address, log_to_driver=False)
        else:
            ray.init(include_dashboard=False, log_to_driver=False)
        started = True
    try:
        cpus = int(ray.cluster_resources().get("CPU", 1))
        if workers is not None and workers > cpus:
            raise DatagenError(f"--workers: {workers} is more than the {cpus} CPUs of the Ray cluster "
                               f"(at most {cpus})")
        yield
    finally:
        if started:
            ray.shutdown()


def run_ray(work: ShardRun) -> None:
    """``work``'s shards as Ray tasks on the cluster :func:`ray_cluster` connected to (its
    workers: one a node by default)."""
    import ray
    from ray.util.queue import Queue

    scene, layout, jobs, workers, render, progress, done, threads = (
        work.scene, work.layout, work.jobs, work.workers, work.render, work.progress, work.done, work.threads)

    cpus = int(ray.cluster_resources().get("CPU", 1))
    alive = [n for n in ray.nodes() if n.get("Alive")]
    largest = max((int(n.get("Resources", {}).get("CPU", 0)) for n in alive), default=1) or 1
    workers = workers or max(1, len(alive))
    # A task that asks for more CPUs than any one node has would never be scheduled.
    per_task = max(1, min(cpus // workers, largest))
    task = ray.remote(num_cpus=per_task, max_retries=0)(_ray_run)
    queue = Queue()
    groups = shard_groups(jobs, workers, together=not render)
    refs = {task.remote(scene, layout, group, threads or per_task, render, queue): group for group in groups}
    pending = list(refs)
    try:
        while pending:
            ready, pending = ray.wait(pending, num_returns=1, timeout=0.2)
            for n in queue.get_nowait_batch(queue.qsize()) if queue.qsize() else []:
                progress(n)
            for ref in ready:
                for summary in ray.get(ref):
                    done(summary)
        for n in queue.get_nowait_batch(queue.qsize()) if queue.qsize() else []:
            progress(n)
    except BaseException:
        for ref in pending:
            with contextlib.suppress(Exception):
                ray.cancel(ref, force=True)
        raise
    finally:
        with contextlib.suppress(Exception):
            queue.shutdown()


class Executor(Protocol):
    """What a build needs of an executor (a row of :data:`EXECUTORS`)."""

    def workers(self, requested: int | str | None, variant: str, render: bool) -> int | None:
        """The workers for ``--workers`` (``"auto"``, a number or None) on a Mitsuba variant
        (one line, :class:`~datagen.core.errors.DatagenError`, for a count it cannot run)."""

    def cluster(self, workers: int | None) -> AbstractContextManager:
        """What to connect to before any work (and leave after it)."""

    def cores(self, workers: int | None, shards: int, threads: int | None) -> int:
        """The cores its workers use for ``shards`` shards (the build's estimate)."""

    def run(self, work: ShardRun) -> None:
        """Run ``work`` (:class:`ShardRun`)."""


class LocalExecutor:
    """Shards in spawned processes on this machine (:func:`run_local`)."""

    def workers(self, requested: int | str | None, variant: str, render: bool) -> int:
        """``auto`` suits the device, the default is one, and no more than the cores this
        process may use."""
        if requested == "auto":
            return auto_workers(variant, cpu_count(), render=render)
        if requested is not None and int(requested) > cpu_count():
            raise DatagenError(f"--workers: {requested} is more than the {cpu_count()} cores this process may use "
                               f"(at most {cpu_count()}; --executor ray for a cluster)")
        return int(requested or 1)

    def cluster(self, workers: int | None) -> AbstractContextManager:
        return contextlib.nullcontext()

    def cores(self, workers: int | None, shards: int, threads: int | None) -> int:
        busy = max(1, min(workers or 1, shards))
        return min(busy * local_threads(busy, threads), cpu_count())

    def run(self, work: ShardRun) -> None:
        run_local(work)


class RayExecutor:
    """Shards as Ray tasks on the cluster at ``RAY_ADDRESS``, else a local one (:func:`run_ray`)."""

    def workers(self, requested: int | str | None, variant: str, render: bool) -> int | None:
        """``auto`` and the default: one per node (:func:`run_ray`); a count is checked
        against the cluster's CPUs when it connects."""
        return None if requested == "auto" else (int(requested) if requested is not None else None)

    def cluster(self, workers: int | None) -> AbstractContextManager:
        return ray_cluster(workers)

    def cores(self, workers: int | None, shards: int, threads: int | None) -> int:
        return cpu_count()

    def run(self, work: ShardRun) -> None:
        run_ray(work)


#: The executors ``datagen build --executor`` names.
EXECUTORS: Final[dict[ExecutorName, Executor]] = {"local": LocalExecutor(), "ray": RayExecutor()}
