"""``datagen build``: a config's frames into a sharded, resumable dataset.

:func:`build_dataset` resolves the config once (:class:`~datagen.scene.resolved.Scene`),
checks the folder and the executor before anything is created, takes the
folder's lock, writes the metadata files, and has the executor run every shard
that has no manifest yet (:mod:`datagen.pipeline.executors`, :mod:`datagen.pipeline.writer`).
"""

from __future__ import annotations

import contextlib
import time
from pathlib import Path

from datagen.config.schema import Config
from datagen.console import NullProgress, Progress
from datagen.core.errors import DatagenError
from datagen.dataset.columns import read_manifest_summary
from datagen.dataset.layout import LOCK_NAME, Layout
from datagen.dataset.limits import ReadLimits
from datagen.parallel import cpu_count
from datagen.pipeline.dataset_card import write_dataset_card
from datagen.pipeline.dataset_document import config_fingerprint
from datagen.pipeline.estimate import frame_cost
from datagen.pipeline.executors import EXECUTORS, ExecutorName, ShardRun
from datagen.pipeline.folder import DatasetLock, check_folder, prepare_folder, remove_owned, sweep_temporaries
from datagen.pipeline.image_lists import write_image_lists
from datagen.pipeline.metadata import write_dataset_files
from datagen.pipeline.plan import dataset_layout, plan_shards
from datagen.pipeline.progress import BuildReport, ShardSummary
from datagen.render.runtime import cuda_mps_pipe, resolve_variant
from datagen.scene.resolved import Scene

__all__ = ["build_dataset"]

def build_dataset(config: Config, out: Path, *, workers: int | str | None = None, executor: ExecutorName = "local",
                  overwrite: bool = False, render: bool = True, progress: Progress | None = None,
                  threads: int | None = None) -> BuildReport:
    """Build (or resume) the dataset of ``config`` in ``out``.

    Args:
        config: the resolved config (command-line overrides already applied).
        out: dataset folder (created when missing).
        workers: shards in parallel (``local``: processes, default 1; ``ray``:
            tasks, default one per node); ``"auto"``: what suits the render's device
            (:func:`~datagen.pipeline.estimate.auto_workers`; ``ray``: one per node).
        executor: ``local`` or ``ray``.
        overwrite: replace a dataset of another config in ``out``.
        render: render images (False writes labels and manifests only).
        progress: where the build reports (:class:`datagen.console.Progress`); None: nowhere.
        threads: Mitsuba threads per worker (default: the cores divided among the
            workers). With 1, a seed gives the same image bytes on any machine, for
            any worker count and across resumptions.

    Raises:
        DatagenError: the folder is locked by another build, holds something
            else, or holds a dataset of another config (without ``overwrite``).
    """
    started = time.perf_counter()
    if threads is not None and not 1 <= threads <= cpu_count():
        raise DatagenError(f"--threads: {threads} is not between 1 and the {cpu_count()} cores this process may use")
    variant = resolve_variant(config.render.variant) if render else "labels only"
    kind = EXECUTORS[executor]
    workers = kind.workers(workers, variant, render)
    progress = progress or NullProgress()
    scene = Scene.resolve(config)
    root = Path(out).resolve()
    layout = dataset_layout(root, scene.config)
    check_folder(layout)  # refuse someone else's folder before anything (the lock included) is created
    jobs = plan_shards(config)
    fingerprint = config_fingerprint(scene, render=render)
    report = BuildReport(config.name, root, jobs, classes=list(scene.features.name))
    created = not root.exists()
    try:
        with kind.cluster(workers), DatasetLock(root):
            resumed = prepare_folder(layout, fingerprint, scene, render=render, overwrite=overwrite)
            write_dataset_files(layout, scene, jobs, fingerprint, describe=not resumed, render=render)
            todo = []
            limits = ReadLimits.of(scene.labelling, scene.config.frames_per_shard, {})
            for job in jobs:
                manifest = layout.manifest(job)
                if manifest.is_file():
                    try:
                        counts = read_manifest_summary(manifest, limits.manifest_bytes)
                        summary = ShardSummary.from_counts(job.name, counts, len(job.frames))
                    except DatagenError as exc:  # damaged outside datagen: manifests are written atomically
                        raise DatagenError(f"{' '.join(str(exc).split())}; delete it to render its shard again") \
                            from None
                    except Exception as exc:
                        raise DatagenError(f"{manifest}: unreadable manifest ({type(exc).__name__}); delete it to "
                                           "render its shard again") from None
                    report.shards[job.name] = summary
                    report.resumed.append(job.name)
                else:
                    todo.append(job)
            leftovers = [root, root / "manifests"] + [d for job in todo for d in layout.shard_dirs(job)]
            sweep_temporaries(leftovers)

            def shard_done(summary: ShardSummary) -> None:
                report.shards[summary.name] = summary
                progress.shard_done(summary)

            progress.start(report.frames, report.frames - sum(len(j.frames) for j in todo),
                           frame_cost(scene.config, kind.cores(workers, len(todo), threads), render=render,
                                      variant=variant, mps=(cuda_mps_pipe() or "") if executor == "local" else None))
            try:
                if todo:
                    kind.run(ShardRun(scene, layout, todo, workers, render, progress.advance, shard_done, threads))
                if len(report.shards) == len(jobs):  # finished: what describes the whole dataset
                    if render:
                        write_image_lists(layout, jobs)
                    write_dataset_card(layout, scene, jobs, render=render, labels=report.labels,
                                       excluded=report.excluded, never_labeled=report.never_labeled)
            except KeyboardInterrupt:
                report.interrupted = True
                sweep_temporaries(leftovers)
            except OSError as exc:  # disk full, permissions: the file and the reason, on one line
                sweep_temporaries(leftovers)
                raise DatagenError(f"{exc.filename or root}: {exc.strerror or exc}; the finished shards are kept, "
                                   "rerun the same command to finish the others") from None
            finally:
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
        remove_owned(layout)
        (layout.root / LOCK_NAME).unlink(missing_ok=True)
        layout.root.rmdir()
