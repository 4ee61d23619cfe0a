"""``datagen build``: render a config's frames into a sharded, resumable dataset.

The data flow per frame (:class:`ShardWriter`)::

    frame index -> approach state (poses) + look (sky, sun, materials)      [pure numpy]
                -> labels: true centres, tight and corrected boxes          [pure numpy]
                -> render (Mitsuba) -> PNG/JPEG (+ EXR), feature visibility
                -> label file + one manifest row

A shard's manifest is written after all its images and labels: a shard is done
exactly when its manifest exists. Every file goes through
:func:`datagen.dataset.files.atomic_path`, so an interrupted build leaves only complete
files and hidden temporaries, which the next run removes before it finishes the
missing shards. Frames whose image an interrupted run already wrote are not
rendered again (their labels and rows are recomputed, which is cheap).

Executors run shards in parallel: ``local`` uses processes (each with one scene
and a Mitsuba thread pool sized to its share of the cores; one worker runs in
this process), ``ray`` runs them as Ray tasks. Labels and manifest rows depend
on (config, seed, frame index) only, never on the executor or the worker count.
"""

from __future__ import annotations

import contextlib
import dataclasses
import math
import os
import platform
import signal
import sys
import time
from collections import Counter, deque
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

import numpy as np

from datagen.core.camera import Intrinsics
from datagen.config.schema import Config
from datagen.dataset.layout import (
    LOCK_NAME,
    DatasetLock,
    Layout,
    ShardJob,
    asset_files,
    check_folder,
    config_fingerprint,
    plan_shards,
    prepare_folder,
    remove_owned,
    sweep_temporaries,
    write_dataset_files,
    write_image_lists,
)
from datagen.core.errors import DatagenError
from datagen.core.labels import Exclusion
from datagen.core.training import label_options

__all__ = ["BuildProgress", "BuildReport", "ShardSummary", "ShardWriter", "build_dataset"]

Executor = Literal["local", "ray"]
Progress = Callable[[int], None]


@dataclass
class ShardSummary:
    """What one shard holds (deterministic counts) and what it cost (this run)."""

    name: str
    frames: int
    labels: int
    excluded: dict[str, int]
    rendered: int = 0  # frames rendered by this run (0 for a shard done earlier)
    render_s: float = 0.0  # seconds inside mi.render
    wall_s: float = 0.0

    def counts(self) -> dict:
        """The deterministic part, stored in the manifest's metadata."""
        return {"frames": self.frames, "labels": self.labels, "excluded": dict(sorted(self.excluded.items()))}


def _rss_mib() -> float:
    """Resident set size of this process now, MiB (Linux; NaN elsewhere)."""
    try:
        with open("/proc/self/statm") as f:
            return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20
    except OSError:
        return math.nan


#: Frames whose images may still be in the writer thread while the next one renders.
MAX_PENDING_WRITES = 1


class ShardWriter:
    """Renders and labels whole shards in one process: one scene, one feature table."""

    def __init__(self, config: Config, root: Path, *, threads: int | None = None, render: bool = True) -> None:
        from datagen.assets.files import feature_table

        self.config = config
        ext = ".jpg" if config.render.image_format == "jpg" else ".png"
        self.layout = Layout(Path(root), ext)
        self.features = feature_table(config)
        cam = config.camera
        self.intrinsics = Intrinsics.from_hfov_deg(cam.width, cam.height, cam.hfov_deg)
        self.label_options = label_options(config.labels, cam.width, cam.height)
        self.renderer = None
        self._stop: Callable[[], bool] = lambda: False
        # Images are encoded and written by one background thread while the next frame
        # renders; at most MAX_PENDING_WRITES frames wait, so memory stays bounded.
        self._io = ThreadPoolExecutor(1, thread_name_prefix="datagen-write")
        self._writes: deque[Future] = deque()
        if render:
            from datagen.render.renderer import Renderer

            self.renderer = Renderer(config, threads=threads)

    def set_threads(self, threads: int) -> None:
        if self.renderer is not None:
            import drjit as dr

            dr.set_thread_count(max(1, threads))

    def run(self, job: ShardJob, progress: Progress | None = None,
            stop: Callable[[], bool] | None = None) -> ShardSummary:
        """Write every frame of ``job``, then its manifest; return its summary.

        ``stop`` is polled between frames and right after each render: when it
        turns true the shard is abandoned with :class:`KeyboardInterrupt` before
        anything of the current frame is written (a render cut short by Ctrl-C
        never becomes a training image)."""
        from datagen.dataset.schema import write_manifest

        start = time.perf_counter()
        self._stop = stop or (lambda: False)
        rows, excluded, labels, rendered, render_s = [], Counter(), 0, 0, 0.0
        for frame in job.frames:
            if self._stop():
                raise KeyboardInterrupt
            row = self.frame(job, frame)
            rows.append(row)
            labels += row["n_labeled"]
            excluded.update(row["features"].exclusion_counts())
            if row["render_s"] is not None:
                rendered += 1
                render_s += row["render_s"]
            if progress is not None:
                progress(1)
        self._wait_for_writes(0)
        summary = ShardSummary(job.name, len(job.frames), labels, dict(excluded), rendered, render_s)
        write_manifest(self.layout.manifest(job), rows, summary.counts())
        summary.wall_s = time.perf_counter() - start
        return summary

    def frame(self, job: ShardJob, i: int) -> dict:
        """Render, label and write frame ``i``; return its manifest row."""
        from datagen.scene.approach import frame_state
        from datagen.core.conventions import frame_rng
        from datagen.dataset.files import atomic_path
        from datagen.core.labels import compute_labels, yolo_lines
        from datagen.dataset.schema import feature_records, matrix_field
        from datagen.render.renderer import Renderer, draw_look, render_seed

        started = time.perf_counter()
        cfg, k, features, layout = self.config, self.intrinsics, self.features, self.layout
        seed = cfg.dataset.seed
        sampler_seed = render_seed(seed, i)
        state = frame_state(cfg, i, seed)
        look = draw_look(cfg, frame_rng(seed, i))
        cam_from_world = state.cam_from_world
        cam_from_objects = np.stack([cam_from_world @ state.world_from(o) for o in features.objects])
        labels = compute_labels(features, cam_from_objects, k, **self.label_options)
        image_rel = exr_rel = None
        fraction = center_visible = render_s = None
        if self.renderer is not None:
            image_rel = layout.image_rel(job.split, job.shard, i)
            exr = cfg.render.exr
            exr_rel = layout.exr_rel(job.split, job.shard, i) if exr else None
            render_s = self._render(state, look, sampler_seed, layout.root / image_rel,
                                    layout.root / exr_rel if exr_rel else None)
            fraction, center_visible = self.renderer.feature_visibility(state, features)
            labels = labels.with_visibility(fraction, cfg.labels.min_visible_fraction)
        label_rel = layout.label_rel(job.split, job.shard, i)
        lines = yolo_lines(labels, features.class_id, k.width, k.height)
        with atomic_path(layout.root / label_rel) as tmp:
            tmp.write_text("".join(line + "\n" for line in lines))
        sun = Renderer.sun_direction_world(state, look)
        row = {
            "frame_id": i,
            "split": job.split,
            "shard": job.shard,
            "image_path": image_rel,
            "label_path": label_rel,
            "exr_path": exr_rel,
            "width": k.width,
            "height": k.height,
            "fx": k.fx,
            "fy": k.fy,
            "cx": k.cx,
            "cy": k.cy,
            "cam_from_world": matrix_field(cam_from_world),
            "world_from_tanker": matrix_field(state.world_from_tanker),
            "world_from_receiver": matrix_field(state.world_from_receiver),
            "world_from_drogue": matrix_field(state.world_from_drogue),
            "ptd_receiver_m": state.ptd_receiver_m.tolist(),
            "distance_m": state.distance_m,
            "seed": seed,
            "render_seed": sampler_seed,
            "spp": cfg.render.spp if self.renderer is not None else None,
            "mount": state.mount,
            "approach_index": state.approach_index,
            "approach_number": state.approach_number,
            "time_s": state.time_s,
            "turbulence_intensity": state.turbulence_intensity,
            "bank_deg": state.bank_deg,
            "sun_direction_world": np.asarray(sun, dtype=np.float64).tolist(),
            **{f.name: getattr(look, f.name) for f in dataclasses.fields(look) if f.name != "materials"},
            "materials": [
                {"object": obj, "part_class": cls, "base_color": list(m.base_color), "roughness": m.roughness,
                 "metallic": m.metallic, "specular": m.specular}
                for obj, classes in look.materials.items() for cls, m in classes.items()
            ],
            "n_labeled": len(lines),
            "features": feature_records(labels, features.class_id, fraction, center_visible),
            "render_s": render_s,
            "frame_s": time.perf_counter() - started,
            "worker": f"{platform.node()}:{os.getpid()}",
            "worker_rss_mib": _rss_mib(),
        }
        return row

    def _render(self, state, look, seed: int, image: Path, exr: Path | None) -> float | None:
        """Render and write the frame's image (and EXR); a frame whose files an earlier,
        interrupted run left complete is only posed. Returns seconds in mi.render."""
        from datagen.render.renderer import write_exr, write_png

        renderer = self.renderer
        if image.is_file() and (exr is None or exr.is_file()):
            renderer.pose(state, look)
            return None
        result = renderer.render(state, look, seed, geometry=exr is not None)
        if self._stop():
            raise KeyboardInterrupt
        quality = self.config.render.jpeg_quality

        def write() -> None:  # the PNG first: a frame is complete once its last file exists
            write_png(image, result.rgb, quality=quality)
            if exr is not None:
                write_exr(exr, result)

        self._writes.append(self._io.submit(write))
        self._wait_for_writes(MAX_PENDING_WRITES)
        return result.render_s

    def _wait_for_writes(self, keep: int) -> None:
        """Wait until at most ``keep`` image writes are pending; re-raise their errors."""
        while len(self._writes) > keep:
            self._writes.popleft().result()


# --- executors ---------------------------------------------------------------------------
def _cpu_count() -> int:
    with contextlib.suppress(AttributeError):
        return len(os.sched_getaffinity(0))
    return os.cpu_count() or 1


#: The :class:`ShardWriter` of a worker process (one scene per process).
_WORKER: dict = {}


def _worker_writer(config: Config, root: str, threads: int, render: bool) -> ShardWriter:
    """This process's writer for (config, root): built once, reused by every shard."""
    key = (config.model_dump_json(), root, render)
    writer = _WORKER.get("writer")
    if writer is None or _WORKER.get("key") != key:
        writer = ShardWriter(config, Path(root), threads=threads, render=render)
        _WORKER.update(writer=writer, key=key)
    writer.set_threads(threads)
    return writer


def _die_with_parent() -> None:
    """Ask Linux to kill this worker when its parent dies (a SIGKILLed build must not
    leave workers writing into a folder whose lock is gone)."""
    with contextlib.suppress(Exception):
        import ctypes

        libc = ctypes.CDLL("libc.so.6", use_errno=True)
        libc.prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG


def _pool_init(config: Config, root: str, threads: int, render: bool, queue) -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the parent handles Ctrl-C and terminates us
    _die_with_parent()
    _WORKER["queue"] = queue
    _WORKER["args"] = (config, root, threads, render)


def _pool_run(job: ShardJob) -> ShardSummary:
    queue = _WORKER["queue"]
    writer = _worker_writer(*_WORKER["args"])
    return writer.run(job, lambda n: queue.put(n))


@contextlib.contextmanager
def _ctrl_c_flag():
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


def _run_local(config: Config, root: Path, jobs: list[ShardJob], workers: int, render: bool,
               progress: Progress, done: Callable[[ShardSummary], None], threads: int | None = None) -> None:
    workers = min(workers, len(jobs))
    threads = threads or max(1, _cpu_count() // workers)
    if workers == 1:
        writer = ShardWriter(config, root, threads=threads, render=render)
        with _ctrl_c_flag() as stop:
            for job in jobs:
                done(writer.run(job, progress, stop))
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

    executor = ProcessPoolExecutor(workers, mp_context=ctx, initializer=_pool_init,
                                   initargs=(config, str(root), threads, render, queue))
    try:
        pending = {executor.submit(_pool_run, job): job for job in jobs}
        while pending:
            finished, _ = wait(pending, timeout=0.2, return_when=FIRST_COMPLETED)
            drain()
            for future in finished:
                job = pending.pop(future)
                try:
                    done(future.result())  # re-raises a worker's exception here
                except BrokenProcessPool:
                    raise DatagenError(f"shard {job.name}: a worker process died (out of memory, or killed); "
                                       "rerun the same command to finish the missing shards") from None
        drain()
    except BaseException:
        # Ctrl-C or a failed shard: stop every worker now (their files are atomic, the
        # temporaries they leave are swept) instead of waiting for their shards.
        for process in list(getattr(executor, "_processes", {}).values()):
            process.terminate()
        executor.shutdown(wait=True, cancel_futures=True)
        raise
    executor.shutdown(wait=True)


def _ray_run(config: Config, root: str, job: ShardJob, threads: int, render: bool, queue) -> ShardSummary:
    writer = _worker_writer(config, root, threads, render)
    return writer.run(job, lambda n: queue.put_nowait(n))


@contextlib.contextmanager
def _ray_cluster(workers: int | None):
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


def _run_ray(config: Config, root: Path, jobs: list[ShardJob], workers: int | None, render: bool,
             progress: Progress, done: Callable[[ShardSummary], None], threads: int | None = None) -> None:
    """Shards as Ray tasks on the cluster :func:`_ray_cluster` connected to."""
    import ray
    from ray.util.queue import Queue

    cpus = int(ray.cluster_resources().get("CPU", 1))
    alive = [n for n in ray.nodes() if n.get("Alive")]
    largest = max((int(n.get("Resources", {}).get("CPU", 0)) for n in alive), default=1) or 1
    workers = workers or max(1, len(alive))
    # A task that asks for more CPUs than any one node has would never be scheduled.
    per_task = max(1, min(cpus // workers, largest))
    task = ray.remote(num_cpus=per_task, max_retries=0)(_ray_run)
    queue = Queue()
    refs = {task.remote(config, str(root), job, threads or per_task, render, queue): job for job in jobs}
    pending = list(refs)
    try:
        while pending:
            ready, pending = ray.wait(pending, num_returns=1, timeout=0.2)
            for n in queue.get_nowait_batch(queue.qsize()) if queue.qsize() else []:
                progress(n)
            for ref in ready:
                done(ray.get(ref))
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
        per_frame = f"; mi.render {self.render_s / self.rendered:.2f} s per frame" if self.rendered else ""
        out.append(f"  this run: {n} frames ({self.rendered} rendered) in {wall:.1f} s, "
                   f"{rate:.3f} frames/s = {3600 * rate:,.0f} frames/h{per_frame}")
        excluded = ", ".join(f"{k} {v}" for k, v in self.excluded.items())
        scope = "" if done == len(self.jobs) else f" (in the {done} finished shards)"
        out.append(f"  labels: {self.labels} boxes{scope}; excluded: {excluded}")
        if self.interrupted:
            out.append(f"  interrupted: {len(self.jobs) - done} shards unfinished; run the same command "
                       "again to finish them")
        return out


def build_dataset(config: Config, out: Path, *, workers: int | None = None, executor: Executor = "local",
                  overwrite: bool = False, render: bool = True, progress=None,
                  threads: int | None = None) -> BuildReport:
    """Build (or resume) the dataset of ``config`` in ``out``.

    Args:
        config: the resolved config (command-line overrides already applied).
        out: dataset folder (created when missing).
        workers: shards in parallel (``local``: processes, default 1; ``ray``:
            tasks, default one per node).
        executor: ``local`` or ``ray``.
        overwrite: replace a dataset of another config in ``out``.
        render: render images (False writes labels and manifests only).
        progress: a :class:`BuildProgress`-like object (``start``, ``advance``,
            ``shard_done``, ``close``), or None.
        threads: Mitsuba threads per worker (default: the cores divided among the
            workers). With 1, a seed gives the same image bytes on any machine, for
            any worker count and across resumptions.

    Raises:
        DatagenError: the folder is locked by another build, holds something
            else, or holds a dataset of another config (without ``overwrite``).
    """
    from datagen.assets.files import check_assets

    started = time.perf_counter()
    if threads is not None and not 1 <= threads <= _cpu_count():
        raise DatagenError(f"--threads: {threads} is not between 1 and the {_cpu_count()} cores this process may use")
    if executor == "local" and workers is not None and workers > _cpu_count():
        raise DatagenError(f"--workers: {workers} is more than the {_cpu_count()} cores this process may use "
                           f"(at most {_cpu_count()}; --executor ray for a cluster)")
    check_assets(config)
    root = Path(out).resolve()
    layout = Layout(root, ".jpg" if config.render.image_format == "jpg" else ".png")
    check_folder(layout)  # refuse someone else's folder before anything (the lock included) is created
    jobs = plan_shards(config)
    assets = asset_files(config)
    fingerprint = config_fingerprint(config, assets, render=render)
    report = BuildReport(config.name, root, jobs)
    cluster = _ray_cluster(workers) if executor == "ray" else contextlib.nullcontext()
    created = not root.exists()
    try:
        with cluster, DatasetLock(root):
            resumed = prepare_folder(layout, fingerprint, config, assets, render=render, overwrite=overwrite)
            write_dataset_files(layout, config, jobs, fingerprint, assets, describe=not resumed, render=render)
            todo = []
            for job in jobs:
                manifest = layout.manifest(job)
                if manifest.is_file():
                    from datagen.dataset.schema import read_manifest_summary

                    try:
                        counts = read_manifest_summary(manifest)
                    except Exception as exc:  # damaged outside datagen: manifests are written atomically
                        raise DatagenError(f"{manifest}: unreadable manifest ({type(exc).__name__}); delete it to "
                                           "render its shard again") from None
                    report.shards[job.name] = ShardSummary(job.name, counts.get("frames", len(job.frames)),
                                                           counts.get("labels", 0), counts.get("excluded", {}))
                    report.resumed.append(job.name)
                else:
                    todo.append(job)
            leftovers = [root, root / "manifests"] + [d for job in todo for d in layout.shard_dirs(job)]
            sweep_temporaries(leftovers)

            def shard_done(summary: ShardSummary) -> None:
                report.shards[summary.name] = summary
                if progress is not None:
                    progress.shard_done(summary)

            if progress is not None:
                progress.start(report.frames, report.frames - sum(len(j.frames) for j in todo))
            try:
                if todo:
                    run = _run_ray if executor == "ray" else _run_local
                    if executor == "local":
                        workers = workers or 1
                    run(config, root, todo, workers, render, progress.advance if progress else (lambda n: None),
                        shard_done, threads)
                if render and len(report.shards) == len(jobs):
                    write_image_lists(layout, jobs)
            except KeyboardInterrupt:
                report.interrupted = True
                sweep_temporaries(leftovers)
            except OSError as exc:  # disk full, permissions: the file and the reason, on one line
                sweep_temporaries(leftovers)
                raise DatagenError(f"{exc.filename or root}: {exc.strerror or exc}; the finished shards are kept, "
                                   "rerun the same command to finish the others") from None
            finally:
                if progress is not None:
                    progress.close()
    except (DatagenError, OSError):
        if created and not any(layout.manifest(job).is_file() for job in jobs):
            _discard_new(layout, config)  # a folder this build made and finished nothing in: leave no trace
        raise
    report.wall_s = time.perf_counter() - started
    return report


def _discard_new(layout: Layout, config: Config) -> None:
    """Remove a dataset folder this build created: every file it wrote (its own plan names
    them), its lock, and the folders left empty."""
    with contextlib.suppress(OSError, DatagenError):
        remove_owned(layout, {"config": config.model_dump(mode="json")})
        (layout.root / LOCK_NAME).unlink(missing_ok=True)
        layout.root.rmdir()


class BuildProgress:
    """Frames done, frames/s and ETA: a live bar on a terminal, else a plain line
    every ``interval_s`` seconds and one per finished shard (on stderr)."""

    def __init__(self, name: str, *, stream=None, interval_s: float = 30.0, live: bool | None = None) -> None:
        self.name = name
        self.stream = stream or sys.stderr
        self.live = self.stream.isatty() if live is None else live
        self.interval_s = interval_s
        self._bar = None

    def start(self, total: int, done: int) -> None:
        self.total, self.done, self.first = total, done, done
        self.t0 = self._last = time.perf_counter()
        if self.live:
            from rich.console import Console
            from rich.progress import (BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn,
                                       TimeRemainingColumn)

            self._bar = Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(),
                                 TextColumn("{task.fields[rate]}"), TimeElapsedColumn(), TextColumn("ETA"),
                                 TimeRemainingColumn(), console=Console(file=self.stream))
            self._task = self._bar.add_task(self.name, total=total, completed=done, rate="")
            self._bar.start()
        else:
            self._print(f"build {self.name}: {total} frames, {done} already done")

    def _rate(self) -> tuple[float, float]:
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
        self._print(f"build {self.name}: {self.done}/{self.total} frames ({100 * self.done / max(1, self.total):.0f}%),"
                    f" {rate:.3f} frames/s, ETA {eta_text}")

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
