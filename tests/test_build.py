"""datagen build: layout, labels recomputed from the manifests, determinism across
workers and executors, atomic resumption, locking and refusal."""

from __future__ import annotations

import itertools
import json
import math
import os
import platform
import re
import signal
import subprocess
import sys
import time
from collections import Counter
from pathlib import Path

import cv2
import numpy as np
import pyarrow.parquet as pq
import pytest
import yaml
from hypothesis import given
from hypothesis import strategies as st

from datagen.assets.table import feature_table
from datagen.config import LabelsConfig, load_config, override_config
from datagen.core.camera import Intrinsics
from datagen.core.errors import ConfigError, DatagenError
from datagen.core.label_boxes import compute_labels
from datagen.core.training import TrainView
from datagen.dataset.columns import MANIFEST_VERSION, features_schema, manifest_schema, read_features
from datagen.dataset.layout import SPLITS
from datagen.pipeline.build import build_dataset
from datagen.pipeline.executors import PROGRESS_EVERY_S, THREAD_VARIABLES, _run_group, worker_environment
from datagen.pipeline.folder import DatasetLock
from datagen.pipeline.plan import dataset_layout, frame_split, plan_shards
from datagen.pipeline.writer import MAX_GROUP_SHARDS, ShardWriter, shard_groups
from datagen.scene.resolved import Scene

from .support import (
    ROOT,
    comparable,
    image_files,
    label_files,
    manifest_rows,
    run_cli,
    temporaries,
    tiny_config,
)


# --- the plan --------------------------------------------------------------------------
@given(frames=st.integers(1, 300), shard_size=st.integers(1, 64), val=st.floats(0.0, 0.9),
       seed=st.integers(0, 2**63 - 1), by=st.sampled_from(["frame", "approach"]))
def test_shards_partition_the_frames(tmp_path_factory, frames, shard_size, val, seed, by) -> None:
    config = override_config(load_config(ROOT / "scenes/wingcam55.yaml"), {
        "dataset.frames": frames, "dataset.shard_size": shard_size, "dataset.val_fraction": val,
        "dataset.seed": seed, "dataset.split_by": by})
    jobs = plan_shards(config)
    every = sorted(i for job in jobs for i in job.frames)
    assert every == list(range(frames))
    assert len(jobs) >= min(frames, config.dataset.min_shards)  # a small build still keeps workers busy
    if frames >= shard_size * config.dataset.min_shards:
        assert config.frames_per_shard == shard_size
    for split in SPLITS:
        mine = [job for job in jobs if job.split == split]
        assert [job.shard for job in mine] == list(range(len(mine)))
        assert all(0 < len(job.frames) <= config.frames_per_shard for job in mine)
        assert all(len(job.frames) == config.frames_per_shard for job in mine[:-1])  # only the last is short
        flat = [i for job in mine for i in job.frames]
        assert flat == sorted(flat)
        assert all(frame_split(config, i) == split for i in flat)
    if by == "approach":
        k = config.frames_per_chain
        assert all(frame_split(config, i) == frame_split(config, i - i % k) for i in range(frames))


@given(frames=st.integers(1, 3000), shard_size=st.integers(1, 200), val=st.floats(0.0, 0.9),
       by=st.sampled_from(["frame", "approach"]), workers=st.integers(1, 8), together=st.booleans())
def test_shard_groups_cut_the_shards_in_frame_order_only_before_a_second_rare_shard_or_at_the_cap(
        frames, shard_size, val, by, workers, together) -> None:
    config = override_config(load_config(ROOT / "scenes/wingcam55.yaml"), {
        "dataset.frames": frames, "dataset.shard_size": shard_size, "dataset.val_fraction": val,
        "dataset.split_by": by})
    jobs = plan_shards(config)
    groups = shard_groups(jobs, workers, together)
    assert [job for group in groups for job in group] == sorted(jobs, key=lambda job: job.frames[0])
    assert all(groups)
    counts = Counter(job.split for job in jobs)
    cap = min(MAX_GROUP_SHARDS, len(jobs) // (2 * workers))
    if not together or len(counts) < 2 or cap < 2:
        assert all(len(group) == 1 for group in groups)
        return
    rare = min(counts, key=lambda split: (counts[split], split))
    assert all(len(group) <= cap for group in groups)
    assert all(sum(job.split == rare for job in group) <= 1 for group in groups)
    for group, following in itertools.pairwise(groups):
        assert len(group) == cap or (following[0].split == rare and any(job.split == rare for job in group))


def test_labels_only_builds_in_shard_groups_write_what_each_shard_writes_alone(tmp_path: Path) -> None:
    config = override_config(load_config(ROOT / "scenes/wingcam55.yaml"),
                             {"dataset.frames": 600, "dataset.shard_size": 80})
    jobs = plan_shards(config)
    assert max(len(group) for group in shard_groups(jobs, 1)) > 1  # the build below runs groups
    build_dataset(config, tmp_path / "grouped", render=False)
    alone = tmp_path / "alone"
    layout = dataset_layout(alone, config)
    (alone / "manifests").mkdir(parents=True)
    scene = Scene.resolve(config)
    for job in jobs:  # each shard by a writer of its own: nothing simulated or drawn for another shard
        for folder in layout.shard_dirs(job):
            folder.mkdir(parents=True, exist_ok=True)
        ShardWriter(scene, layout, render=False).run(job)
    assert label_files(alone) == label_files(tmp_path / "grouped")
    assert comparable(alone) == comparable(tmp_path / "grouped")


def _thread_environment() -> dict[str, str | None]:
    return {name: os.environ.get(name) for name in THREAD_VARIABLES}


def test_a_spawned_worker_gets_its_share_of_blas_and_openmp_threads_unless_the_user_set_them(monkeypatch) -> None:
    import multiprocessing as mp
    from concurrent.futures import ProcessPoolExecutor

    for name in THREAD_VARIABLES:
        monkeypatch.delenv(name, raising=False)
    monkeypatch.setenv("OMP_NUM_THREADS", "7")  # the user's own choice stays
    with worker_environment(3), ProcessPoolExecutor(1, mp_context=mp.get_context("spawn")) as pool:
        seen = pool.submit(_thread_environment).result()
    assert seen == {"OMP_NUM_THREADS": "7", "OPENBLAS_NUM_THREADS": "3", "MKL_NUM_THREADS": "3"}
    assert _thread_environment() == {"OMP_NUM_THREADS": "7", "OPENBLAS_NUM_THREADS": None, "MKL_NUM_THREADS": None}


@pytest.mark.render
def test_a_workers_thread_count_sizes_opencvs_pool_as_well_as_drjits() -> None:
    import cv2

    from datagen.render.runtime import set_threads, thread_count

    before = thread_count()
    try:
        for n in (1, 3):
            set_threads(n)
            assert (thread_count(), cv2.getNumThreads()) == (n, n)
    finally:
        set_threads(before)


_FAULTS_SCRIPT = """
import resource, sys
import numpy as np
if sys.argv[1] == "keep":
    from datagen.render.runtime import keep_freed_memory
    assert keep_freed_memory()
faults = []
for _ in range(4):  # three 2048x1080 float32 RGB images at once, as a frame's camera model holds them
    before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    images = [np.ones((1080, 2048, 3), np.float32) for _ in range(3)]
    del images
    faults.append(resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before)
print(faults[-1])
"""


@pytest.mark.skipif(sys.platform != "linux" or platform.libc_ver()[0] != "glibc", reason="glibc's malloc")
def test_a_rendering_process_reuses_the_memory_a_frame_freed_where_by_default_each_frame_faults_in_new_pages() -> None:
    """:func:`~datagen.render.runtime.keep_freed_memory` (which set_threads calls): a frame's
    full-size images, freed and made again, take no new page; in a process without it the
    same frames fault pages in every time (glibc's default, which the test shows it fixes)."""
    def faults(mode: str) -> int:
        run = subprocess.run([sys.executable, "-c", _FAULTS_SCRIPT, mode], capture_output=True, text=True, check=True)
        return int(run.stdout.split()[-1])

    assert faults("default") > 100
    assert faults("keep") == 0


def test_a_worker_sends_its_frames_in_few_messages_and_all_of_them_at_each_shards_end(tmp_path: Path) -> None:
    config = override_config(load_config(ROOT / "scenes/wingcam55.yaml"),
                             {"dataset.frames": 600, "dataset.shard_size": 80})
    group = max(shard_groups(plan_shards(config), 1), key=len)
    layout = dataset_layout(tmp_path, config)
    (tmp_path / "manifests").mkdir()
    for job in group:
        for folder in layout.shard_dirs(job):
            folder.mkdir(parents=True, exist_ok=True)
    writer = ShardWriter(Scene.resolve(config), layout, render=False)
    ends = list(itertools.accumulate(len(job.frames) for job in group))
    still: list[int] = []  # a clock that stands still: no interval ever passes
    summaries = _run_group(writer, group, still.append, clock=lambda: 0.0)
    assert [s.name for s in summaries] == [job.name for job in group]
    assert list(itertools.accumulate(still)) == ends  # one message per shard, at its end: not one per frame
    ticks = itertools.count(step=PROGRESS_EVERY_S)  # a clock that passes an interval at every reading
    each: list[int] = []
    _run_group(writer, group, each.append, clock=lambda: next(ticks))
    assert each == [1] * ends[-1]  # an interval passed since the last message: the frame is sent


def test_split_fraction_and_independence_from_sharding() -> None:
    config = override_config(load_config(ROOT / "scenes/wingcam55.yaml"), {"dataset.frames": 5000})
    splits = [frame_split(config, i) for i in range(5000)]
    share = splits.count("val") / 5000
    assert abs(share - 0.2) < 4 * math.sqrt(0.2 * 0.8 / 5000)
    resharded = override_config(config, {"dataset.shard_size": 7})
    assert [frame_split(resharded, i) for i in range(5000)] == splits
    # More validation moves frames train -> val only, never the other way.
    more = override_config(config, {"dataset.val_fraction": 0.3})
    assert all(frame_split(more, i) == "val" for i, s in enumerate(splits) if s == "val")


def test_overrides_are_validated_and_named() -> None:
    config = load_config(ROOT / "scenes/wingcam55.yaml")
    assert override_config(config, {"render.spp": 4}).render.spp == 4
    with pytest.raises(ConfigError) as err:
        override_config(config, {"dataset.shard_size": 0})
    assert str(err.value).startswith("command line: dataset.shard_size: value 0:")


def test_a_dataset_json_without_the_small_build_keys_plans_the_shards_its_build_made() -> None:
    """A config recorded before approach.min_approaches and dataset.min_shards existed plans
    (for --overwrite and resumption) the shards and chains that build made, not today's."""
    from datagen.config.load import stored_config

    config = override_config(load_config(ROOT / "scenes/wingcam55.yaml"),
                             {"dataset.frames": 40, "dataset.shard_size": 30})
    recorded = config.model_dump(mode="json")
    del recorded["approach"]["min_approaches"], recorded["dataset"]["min_shards"]
    old = stored_config(recorded)
    assert (old.frames_per_shard, old.frames_per_chain) == (30, 16)
    assert (config.frames_per_shard, config.frames_per_chain) == (2, 5)
    assert stored_config(config.model_dump(mode="json")) == config


# --- metadata files -----------------------------------------------------------------------
def test_manifest_readme_documents_every_column() -> None:
    text = (ROOT / "manifests" / "README.md").read_text()
    documented = set()
    for line in text.splitlines():
        if line.startswith("| `"):
            documented.update(re.findall(r"`([a-z_0-9]+)`", line.split("|")[1]))
    columns = set(manifest_schema().names) | set(features_schema().names)
    feature_fields = {f.name for f in manifest_schema().field("features").type.value_type}
    assert columns | feature_fields <= documented, sorted((columns | feature_fields) - documented)


def test_the_manifest_readme_holds_the_table_of_columns_derived_from_the_column_table() -> None:
    """manifests/README.md's table of manifest columns is :func:`manifest_table` as it is
    derived from ``MANIFEST_COLUMNS``, which is also the schema, column for column."""
    from datagen.dataset.columns import MANIFEST_COLUMNS, manifest_table

    text = (ROOT / "manifests" / "README.md").read_text()
    assert manifest_table() in text, "run: python -c 'from datagen.dataset.columns import manifest_table; " \
                                     "print(manifest_table())' and paste it under Manifest rows"
    assert [c.name for c in MANIFEST_COLUMNS] == manifest_schema().names
    assert MANIFEST_COLUMNS[0].meaning and all(c.type_text for c in MANIFEST_COLUMNS)


def test_features_parquet_round_trips(tmp_path: Path) -> None:
    from datagen.dataset.columns import write_features

    config = load_config(ROOT / "scenes/wingcam55-random.yaml")
    table = feature_table(config)
    back = read_features(write_features(tmp_path / "f.parquet", table))
    assert back.name == table.name and back.objects == table.objects and back.size == table.size
    np.testing.assert_array_equal(back.class_id, table.class_id)
    np.testing.assert_array_equal(back.n_points, table.n_points)
    np.testing.assert_array_equal(back.points_model, table.points_model)
    np.testing.assert_array_equal(back.center_model, table.center_model)


# Keys every Ultralytics release since 8.0 accepts in a cfg file.
ULTRALYTICS_KEYS = {
    "imgsz", "epochs", "batch", "rect", "close_mosaic", "hsv_h", "hsv_s", "hsv_v", "degrees", "translate",
    "scale", "shear", "perspective", "flipud", "fliplr", "mosaic", "mixup", "cutmix", "copy_paste",
    "optimizer", "lr0", "nbs",
}


def test_labels_only_build_and_its_metadata(tmp_path: Path) -> None:
    config = tiny_config(tmp_path)
    report = build_dataset(config, tmp_path / "ds", render=False)
    root = tmp_path / "ds"
    assert report.frames == 8 and not report.interrupted and report.rendered == 0
    data = yaml.safe_load((root / "data.yaml").read_text())
    assert "path" not in data
    assert (data["train"], data["val"]) == ("train.txt", "val.txt")
    assert not (root / "train.txt").exists()  # no images, nothing to list
    assert data["names"] == dict(enumerate(feature_table(config).name)) and data["nc"] == 80
    hyp = yaml.safe_load((root / "hyp.yaml").read_text())
    assert set(hyp) <= ULTRALYTICS_KEYS
    assert hyp["fliplr"] == 0.0 and hyp["mosaic"] == 0.0 and hyp["translate"] == 0.0 and hyp["scale"] == 0.0
    assert hyp["imgsz"] == config.labels.train_imgsz == 864
    assert hyp["optimizer"] == "SGD" and hyp["nbs"] == hyp["batch"]  # a step per batch, no 'auto' AdamW
    doc = json.loads((root / "dataset.json").read_text())
    assert doc["image_width"] == 128 and doc["image_height"] == 68
    assert doc["edge_margin_px"] == 2.0 and doc["corrected"] is True and doc["pixel_convention"] == "continuous"
    assert [o["name"] for o in doc["objects"]] == ["tanker", "receiver", "drogue", "hose"]
    assert [o["id"] for o in doc["objects"]] == [1, 2, 3, 4]
    assert doc["config"]["dataset"]["frames"] == 8 and doc["manifest_version"] == MANIFEST_VERSION
    assert doc["label_size"]["train_imgsz"] == 864 and doc["label_size"]["min_box_px"] == 48.0
    np.testing.assert_allclose(doc["label_size"]["min_label_size_px"], [48 / 6.75, 48 / 6.75], rtol=1e-12)
    assert doc["schema"] == "datagen.dataset" and doc["schema_version"] == 1
    assert {"datagen", "mitsuba", "drjit", "numpy", "pyarrow"} <= set(doc["versions"])
    assert sum(s["frames"] for s in doc["splits"].values()) == 8
    rows = manifest_rows(root)
    assert sorted(rows) == list(range(8))
    assert all(r["image_path"] is None and r["render_s"] is None for r in rows.values())
    assert all(f["visible_fraction"] is None for r in rows.values() for f in r["features"])
    assert pq.read_schema(next((root / "manifests").glob("*.parquet"))).metadata[
        b"datagen.manifest_version"] == MANIFEST_VERSION.encode()
    assert not temporaries(root)


def test_a_version_8_manifest_reads_with_the_columns_added_since_as_nulls(tmp_path: Path) -> None:
    """A dataset built before a column was added (``COLUMNS_SINCE``) stays readable: its
    rows read with that column null, every other value as written."""
    from datagen.dataset.columns import COLUMNS_SINCE
    from datagen.dataset.reader import load_dataset, open_dataset

    config = tiny_config(tmp_path)
    build_dataset(config, tmp_path / "ds", render=False)
    before = manifest_rows(tmp_path / "ds")
    for path in (tmp_path / "ds" / "manifests").glob("*.parquet"):
        table = pq.read_table(path)
        old = table.drop_columns([c for c in COLUMNS_SINCE if c in table.column_names])
        meta = {**table.schema.metadata, b"datagen.manifest_version": b"8"}
        pq.write_table(old.replace_schema_metadata(meta), path)
    tables = open_dataset(tmp_path / "ds").read_manifests()
    after = {row["frame_id"]: row for table in tables for row in table.to_pylist()}
    assert sorted(after) == sorted(before) and len(load_dataset(tmp_path / "ds")) == len(before)
    assert all(row[c] is None for row in after.values() for c in COLUMNS_SINCE)
    for frame, row in before.items():
        for column, value in row.items():
            if column not in COLUMNS_SINCE:
                assert after[frame][column] == value, column


def test_a_folder_that_is_not_a_dataset_is_never_touched(tmp_path: Path) -> None:
    config = tiny_config(tmp_path)
    (tmp_path / "ds").mkdir()
    precious = tmp_path / "ds" / "thesis.tex"
    precious.write_text("years of work")
    for overwrite in (False, True):
        with pytest.raises(DatagenError, match="not a datagen dataset"):
            build_dataset(config, tmp_path / "ds", render=False, overwrite=overwrite)
    assert sorted(p.name for p in (tmp_path / "ds").iterdir()) == ["thesis.tex"]  # not even a lock
    assert precious.read_text() == "years of work"


def test_a_split_without_frames_borrows_the_other_in_data_yaml(tmp_path: Path) -> None:
    config = tiny_config(tmp_path, **{"dataset.val_fraction": 0.0})
    build_dataset(config, tmp_path / "ds", render=False)
    data = yaml.safe_load((tmp_path / "ds" / "data.yaml").read_text())
    assert data["train"] == data["val"] == "train.txt"
    assert "# no val frames in this build: val uses train.txt" in (tmp_path / "ds" / "data.yaml").read_text()


def test_another_config_is_refused_unless_overwrite(tmp_path: Path) -> None:
    root = tmp_path / "ds"
    build_dataset(tiny_config(tmp_path), root, render=False)
    before = label_files(root)
    other = tiny_config(tmp_path, **{"dataset.seed": 8})
    with pytest.raises(DatagenError, match=r"\(dataset\.seed 7 -> 8\); use --overwrite"):
        build_dataset(other, root, render=False)
    assert label_files(root) == before
    build_dataset(other, root, render=False, overwrite=True)
    fresh = tmp_path / "fresh"
    build_dataset(other, fresh, render=False)
    assert label_files(root) == label_files(fresh) and comparable(root) == comparable(fresh)
    assert json.loads((root / "dataset.json").read_text())["config"]["dataset"]["seed"] == 8


def test_a_running_build_locks_the_folder(tmp_path: Path) -> None:
    config_path = tmp_path / "tiny.yaml"
    tiny_config(tmp_path)
    root = tmp_path / "ds"
    holder = subprocess.Popen(
        [sys.executable, "-c", "import sys, time; from pathlib import Path; from datagen.pipeline.folder import "
         "DatasetLock; DatasetLock(Path(sys.argv[1])).acquire(); print('locked', flush=True); time.sleep(120)",
         str(root)], stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "locked"
        out = run_cli("build", "--config", str(config_path), "--out", str(root), "--no-render")
        assert out.returncode == 2, out.stderr
        assert out.stderr.strip() == (f"{root}: another datagen build (pid {holder.pid} on {os.uname().nodename}) "
                                      "is writing this dataset; wait for it to finish or choose another --out")
        assert [p.name for p in root.iterdir()] == [".datagen.lock"]  # nothing written
        with pytest.raises(DatagenError):
            DatasetLock(root).acquire()  # the same refusal in-process
    finally:
        holder.kill()
        holder.wait()
    with DatasetLock(root):  # released by the kernel when its holder died
        pass


def test_bad_executor_is_one_line(tmp_path: Path) -> None:
    tiny_config(tmp_path)
    out = run_cli("build", "--config", str(tmp_path / "tiny.yaml"), "--out", str(tmp_path / "ds"),
                  "--executor", "spark")
    assert out.returncode == 2 and out.stderr.strip().splitlines() == [
        "--executor: unknown executor 'spark' (choose local or ray)"]
    assert not (tmp_path / "ds").exists()


# --- rendered builds ---------------------------------------------------------------------------
@pytest.fixture(scope="module")
def reference(tmp_path_factory) -> tuple[Path, object]:
    """A tiny rendered build (with EXR), one worker with one Mitsuba thread, in this process."""
    tmp = tmp_path_factory.mktemp("reference")
    config = tiny_config(tmp, exr=True)
    report = build_dataset(config, tmp / "ds", workers=1, threads=1)
    assert report.rendered == 8 and not report.interrupted
    return tmp / "ds", config


def img2label(image: str) -> str:
    """Ultralytics' rule: last /images/ -> /labels/, extension -> .txt."""
    sa, sb = f"{os.sep}images{os.sep}", f"{os.sep}labels{os.sep}"
    return sb.join(image.rsplit(sa, 1)).rsplit(".", 1)[0] + ".txt"


@pytest.mark.render
def test_a_rendered_builds_stages_add_up_to_its_frames_and_the_summary_names_them_and_its_compiles(reference
                                                                                                    ) -> None:
    root, config = reference
    report = build_dataset(config, root, workers=1, threads=1)  # resumed: nothing rendered, no stages
    assert report.rendered == 0 and report.stages == {}
    tmp = root.parent / "stages"
    report = build_dataset(config, tmp, workers=1, threads=1)
    stages, k = report.stages, report.rendered
    assert k == 8 and {"pose", "path tracing", "denoise", "geometry pass", "feature visibility"} <= set(stages)
    assert stages["path tracing"] == pytest.approx(report.render_s, rel=1e-9)
    assert stages["denoise"] == pytest.approx(report.denoise_s, rel=1e-9)
    assert sum(stages.values()) == pytest.approx(report.rendered_frame_s, rel=1e-6)
    assert list(stages.values()) == sorted(stages.values(), reverse=True)
    other = next(line for line in report.lines() if line.startswith("  other, per rendered frame: "))
    assert all((f"{name} {t / k:.2f} s" in other) == (round(t / k, 2) > 0)
               for name, t in stages.items() if name not in ("path tracing", "denoise"))
    assert "path tracing" not in other
    assert "  kernels compiled after each worker's first frame: 0" in report.lines()  # 7 frames, none compiled


def test_a_stage_timed_inside_another_counts_for_the_inner_one_only() -> None:
    from datagen.render.timing import StageClock, rest_of_frame

    now = [0.0]
    clock = StageClock(clock=lambda: now[0])
    with clock.stage("outer"):
        now[0] += 0.01
        with clock.stage("inner"):
            now[0] += 0.15
    with clock.stage("inner"):
        now[0] += 0.05
    with clock.stage("path tracing"):
        pass
    s = clock.seconds
    assert list(s) == ["inner", "outer", "path tracing"]  # in the order they ended
    assert s["inner"] == pytest.approx(0.2) and s["outer"] == pytest.approx(0.01)  # without the inner 0.15 s
    assert [name for name, _ in rest_of_frame(s)] == ["inner", "outer"]


def test_the_estimate_gives_way_to_the_first_measured_frames() -> None:
    """A machine busier or slower than the model's: after the first frames the progress says
    what they measured beside the estimate and what is left at the measured rate."""
    import io
    from types import SimpleNamespace

    from datagen.console import ConsoleProgress

    now = [0.0]
    stream = io.StringIO()
    progress = ConsoleProgress("w", stream=stream, interval_s=1e9, live=False, clock=lambda: now[0])
    progress.start(40, 0, SimpleNamespace(seconds=1.0, cores=2, setting="x", disk_bytes=1.0, frames_per_hour=3600))
    for _ in range(5):  # 3 s a frame, three times the estimate
        now[0] += 3.0
        progress.advance(1)
    lines = stream.getvalue().splitlines()
    assert "corrected after the first 5 frames" in lines[0]
    assert lines[2:] == ["build w: measured 3.00 s a frame over the first 5 frames (estimated 1.00, 3.0x); "
                         "1 min 45 s left at 1,200 frames/h"]


def test_a_build_prints_its_estimate_first_and_the_model_grows_with_the_work(tmp_path: Path) -> None:
    import io

    from datagen.console import ConsoleProgress
    from datagen.pipeline.estimate import frame_cost

    config = tiny_config(tmp_path)
    stream = io.StringIO()
    build_dataset(config, tmp_path / "ds", render=False,
                  progress=ConsoleProgress("tiny", stream=stream, interval_s=1e9, live=False))
    first = stream.getvalue().splitlines()[0]
    assert re.fullmatch(r"build tiny: estimate [0-9.]+ s a frame = [0-9,]+ frames/h on \d+ cores \(labels only\), "
                        r".* for 8 frames \(a model of an idle machine; corrected after the first 2 frames\)",
                        first), first
    shipped = load_config("wingcam55")
    cost = frame_cost(shipped, 2)
    assert cost.frames_per_hour == pytest.approx(3600 / cost.seconds)
    assert "2048x1080" in cost.setting and f"{shipped.render.spp} spp" in cost.setting
    assert frame_cost(shipped, 1).seconds == pytest.approx(2 * cost.seconds)
    for more in ({"render.spp": 4 * shipped.render.spp}, {"render.denoise_guides": True},
                 {"camera.width": 4096, "camera.height": 2160}):
        assert frame_cost(override_config(shipped, more), 2).seconds > cost.seconds, more
    assert frame_cost(shipped, 2, render=False).seconds < cost.seconds / 100



def test_the_estimate_knows_the_device_a_gpu_frame_bounded_by_its_kernels_or_its_host_work() -> None:
    from datagen.pipeline.estimate import GPU_TRACE_S, frame_cost

    shipped = load_config("wingcam55")
    cpu, gpu = frame_cost(shipped, 16), frame_cost(shipped, 16, variant="cuda_ad_rgb")
    assert "cuda_ad_rgb" in gpu.setting and "llvm_ad_rgb" in cpu.setting
    assert gpu.seconds < cpu.seconds / 2  # path tracing and OIDN move to the GPU
    assert frame_cost(shipped, 1, variant="cuda_ad_rgb").seconds == pytest.approx(16 * gpu.seconds)  # host-bound
    heavy = override_config(shipped, {"render.spp": 1024})  # the GPU's own time bounds it
    mpx = shipped.camera.width * shipped.camera.height / 1e6
    assert frame_cost(heavy, 16, variant="cuda_ad_rgb").seconds >= 1024 * mpx * GPU_TRACE_S


def test_a_running_cuda_mps_daemon_is_found_by_its_control_pipe_and_said_in_a_gpu_builds_estimate(
        tmp_path, monkeypatch) -> None:
    import os

    from datagen.pipeline.estimate import frame_cost
    from datagen.render.runtime import cuda_mps_pipe

    monkeypatch.setenv("CUDA_MPS_PIPE_DIRECTORY", str(tmp_path))
    assert cuda_mps_pipe() is None  # no daemon: no control pipe
    (tmp_path / "control").write_text("")
    assert cuda_mps_pipe() is None  # a file of that name is not the daemon's pipe
    (tmp_path / "control").unlink()
    os.mkfifo(tmp_path / "control")
    assert cuda_mps_pipe() == str(tmp_path)
    shipped = load_config("wingcam55")
    assert f"CUDA MPS ({tmp_path})" in frame_cost(shipped, 16, variant="cuda_ad_rgb", mps=str(tmp_path)).setting
    assert "no CUDA MPS" in frame_cost(shipped, 16, variant="cuda_ad_rgb", mps="").setting
    assert "MPS" not in frame_cost(shipped, 16, variant="cuda_ad_rgb").setting  # not known (a cluster's nodes)
    assert "MPS" not in frame_cost(shipped, 16, mps=str(tmp_path)).setting  # the CPU's build shares no GPU


@pytest.mark.parametrize(("variant", "cores", "render", "expected"), [
    ("cuda_ad_rgb", 16, True, 16), ("cuda_ad_rgb", 1, True, 1), ("llvm_ad_rgb", 16, True, "cpu"),
    ("llvm_ad_rgb", 1, True, 1), ("scalar_rgb", 4, True, "cpu"), ("cuda_ad_rgb", 16, False, "cpu")])
def test_auto_workers_fill_a_gpu_machines_cores_and_share_a_cpus(variant, cores, render, expected) -> None:
    from datagen.pipeline.estimate import CPU_WORKERS, auto_workers

    want = min(cores, CPU_WORKERS) if expected == "cpu" else expected
    assert auto_workers(variant, cores, render=render) == want


def test_workers_auto_builds_and_a_bad_count_is_one_line(tmp_path: Path) -> None:
    from tests.test_hostile import TINY, datagen, refused, write

    config = write(tmp_path, "t.yaml", TINY)
    done = datagen("build", "--config", str(config), "--no-render", "--workers", "auto", "--out", str(tmp_path / "a"))
    assert done.returncode == 0, done.stderr
    for bad in ("0", "many", "-2"):
        refused(datagen("build", "--config", str(config), "--no-render", "--workers", bad,
                        "--out", str(tmp_path / "b")), "--workers")
    assert not (tmp_path / "b").exists()

@pytest.mark.render
def test_layout_is_what_ultralytics_reads(reference) -> None:
    root, _ = reference
    rows = manifest_rows(root)
    images = sorted((root / "images").rglob("*.png"))
    assert len(images) == 8 == len(rows)
    for row in rows.values():
        image = root / row["image_path"]
        assert img2label(str(image)) == str(root / row["label_path"])
        assert row["image_path"].startswith(f"images/{row['split']}/{row['shard']:05d}/")
        pixels = cv2.imread(str(image), cv2.IMREAD_UNCHANGED)
        assert pixels.dtype == np.uint8 and pixels.shape == (68, 128, 3)
        assert (root / row["exr_path"]).is_file()
    data = yaml.safe_load((root / "data.yaml").read_text())
    for split in SPLITS:
        # Ultralytics reads a list line './x' as x beside the list file, in the order given.
        lines = (root / data[split]).read_text().splitlines()
        assert all(line.startswith("./") for line in lines)
        listed = [str(root / line[2:]) for line in lines]
        assert listed == [str(root / rows[i]["image_path"]) for i in sorted(rows) if rows[i]["split"] == split]
    assert not temporaries(root)


@pytest.mark.render
def test_labels_recompute_from_manifest_and_features_alone(reference) -> None:
    root, _ = reference
    features = read_features(root / "features.parquet")
    doc = json.loads((root / "dataset.json").read_text())
    lines_checked = 0
    for row in manifest_rows(root).values():
        k = Intrinsics(row["width"], row["height"], row["fx"], row["fy"], row["cx"], row["cy"])
        cam_from_world = np.reshape(row["cam_from_world"], (4, 4))
        cam_from_objects = np.stack([cam_from_world @ np.reshape(row[f"world_from_{o}"], (4, 4))
                                     for o in features.objects])
        rules = LabelsConfig.model_validate(doc["config"]["labels"])
        min_size = TrainView(k.width, k.height, rules.train_imgsz).min_label_size_px(rules.min_box_px)
        labels = compute_labels(features, cam_from_objects, k, edge_margin_px=rules.edge_margin_px,
                                corrected=rules.corrected, min_size_px=min_size, small_boxes=rules.small_boxes)
        stored = row["features"]
        assert [f["class_id"] for f in stored] == features.class_id.tolist()
        for name in ("center_px", "tight_xyxy", "corrected_xyxy"):
            fresh = getattr(labels, name)
            # A projection that does not exist (a point behind the camera) is stored as a null.
            assert [f[name] is None for f in stored] == (~np.isfinite(fresh).all(axis=1)).tolist()
            values = np.array([f[name] or [np.nan] * fresh.shape[1] for f in stored], dtype=float)
            np.testing.assert_allclose(values, fresh, rtol=0, atol=1e-6)
        labeled = np.array([f["labeled"] for f in stored])
        np.testing.assert_array_equal(labeled, labels.labeled)
        assert all((f["label_xyxy"] is None) == (not f["labeled"]) for f in stored)
        np.testing.assert_allclose(np.array([f["label_xyxy"] for f in stored if f["labeled"]], dtype=float),
                                   labels.label_xyxy[labeled], rtol=0, atol=1e-6)
        # The label file holds exactly the labeled features, centred on the true centre.
        lines = (root / row["label_path"]).read_text().splitlines()
        assert len(lines) == labeled.sum() == row["n_labeled"]
        for line in lines:
            cls, cx, cy, w, h = line.split()
            f = int(cls)
            box = labels.label_xyxy[f]
            expected = [labels.center_px[f, 0] / k.width, labels.center_px[f, 1] / k.height,
                        (box[2] - box[0]) / k.width, (box[3] - box[1]) / k.height]
            np.testing.assert_allclose([float(cx), float(cy), float(w), float(h)], expected, atol=5e-8)
            lines_checked += 1
    assert lines_checked > 100


@pytest.mark.render
def test_label_files_follow_ultralytics_rules(reference) -> None:
    root, _ = reference
    nc = yaml.safe_load((root / "data.yaml").read_text())["nc"]
    for path in (root / "labels").rglob("*.txt"):
        text = path.read_text()
        if not text:
            continue
        assert text.endswith("\n")
        rows = np.array([[float(v) for v in line.split()] for line in text.splitlines()])
        assert rows.shape[1] == 5
        assert np.all(rows[:, 0] == np.round(rows[:, 0])) and rows[:, 0].max() < nc and rows.min() >= 0
        assert rows[:, 1:].max() <= 1.0
        assert np.all(rows[:, 3:] > 0)
        assert len(np.unique(rows, axis=0)) == len(rows)
        # Each box lies inside the image.
        assert np.all(rows[:, 1] - rows[:, 3] / 2 >= -1e-6) and np.all(rows[:, 1] + rows[:, 3] / 2 <= 1 + 1e-6)


@pytest.mark.render
def test_rendered_and_labels_only_builds_label_alike(reference, tmp_path: Path) -> None:
    root, config = reference
    build_dataset(config, tmp_path / "ds", render=False)
    assert label_files(tmp_path / "ds") == label_files(root)


@pytest.mark.render
def test_two_workers_give_the_same_dataset(reference, tmp_path: Path) -> None:
    root, config = reference
    report = build_dataset(config, tmp_path / "ds", workers=2, threads=1)
    assert report.rendered == 8
    assert label_files(tmp_path / "ds") == label_files(root)
    assert comparable(tmp_path / "ds") == comparable(root)
    assert image_files(tmp_path / "ds") == image_files(root)  # one Mitsuba thread each: the same bytes
    rows = manifest_rows(tmp_path / "ds").values()
    workers = {row["worker"] for row in rows}
    assert len(workers) == 2 and f"{platform.node()}:{os.getpid()}" not in workers  # two processes did it
    assert all(row["worker_rss_mib"] > 0 for row in rows)


@pytest.mark.render
def test_any_worker_count_with_default_threads_gives_the_same_labels_and_manifests(reference, tmp_path: Path) -> None:
    """The promise as :data:`datagen.dataset.columns.PIXEL_COLUMNS` states it: with the default
    threads (here 2 for one worker, 1 each for two) the label files and every manifest column
    but the run's and the pixel statistics are identical, and those agree to 1e-5."""
    from datagen.dataset.columns import PIXEL_COLUMNS, RUN_COLUMNS

    root, config = reference
    one, two = tmp_path / "one", tmp_path / "two"
    build_dataset(config, one, workers=1)
    build_dataset(config, two, workers=2)
    assert label_files(one) == label_files(two) == label_files(root)
    rows = [manifest_rows(r) for r in (one, two)]
    for frame, row in rows[0].items():
        other = rows[1][frame]
        for column, value in row.items():
            if column in PIXEL_COLUMNS and value is not None:  # (the drogue's are null where it is not seen)
                assert value == pytest.approx(other[column], rel=1e-5, abs=1e-9), column
            elif column not in RUN_COLUMNS:
                assert json.dumps(value) == json.dumps(other[column]), column


@pytest.mark.render
@pytest.mark.ray
def test_ray_gives_the_same_dataset(reference, ray_cluster, tmp_path: Path) -> None:
    root, config = reference
    report = build_dataset(config, tmp_path / "ds", workers=2, executor="ray")
    assert report.rendered == 8
    assert label_files(tmp_path / "ds") == label_files(root)
    assert comparable(tmp_path / "ds") == comparable(root)


@pytest.mark.render
@pytest.mark.parametrize("sig", [signal.SIGKILL, signal.SIGINT], ids=["SIGKILL", "Ctrl-C"])
def test_resume_after_an_interruption_finishes_only_the_missing_shards(reference, tmp_path: Path, sig) -> None:
    root, _ = reference
    config_path = tmp_path / "tiny.yaml"
    tiny_config(tmp_path, exr=True)
    out = tmp_path / "ds"
    args = [sys.executable, "-m", "datagen", "build", "--config", str(config_path), "--out", str(out),
            "--threads", "1"]
    proc = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    try:
        # Wait until a shard has a finished frame (its EXR, written after the PNG) but no
        # manifest yet: then kill.
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and proc.poll() is None:
            done = {p.stem for p in (out / "manifests").glob("*.parquet")} if (out / "manifests").is_dir() else set()
            started = {f"{p.parent.parent.name}-{p.parent.name}" for p in (out / "exr").rglob("*.exr")} \
                if (out / "exr").is_dir() else set()
            if done and started - done:
                break
            time.sleep(0.005)
        proc.send_signal(sig)
        stdout, _ = proc.communicate(timeout=60)
    finally:
        proc.kill()
        proc.wait()
    if sig == signal.SIGINT:
        assert proc.returncode == 130
        assert "interrupted:" in stdout and "run the same command again" in stdout
        assert not temporaries(out)
    done_before = {p.name: p.stat().st_mtime_ns for p in (out / "manifests").glob("*.parquet")}
    assert 0 < len(done_before) < len(plan_shards(reference[1]))
    rerun = run_cli(*args[3:])
    assert rerun.returncode == 0, rerun.stderr
    assert f"resumed: {len(done_before)} of" in rerun.stdout
    # Finished shards were left alone; the rest match an uninterrupted build.
    assert {name: (out / "manifests" / name).stat().st_mtime_ns for name in done_before} == done_before
    assert label_files(out) == label_files(root)
    assert comparable(out) == comparable(root)
    assert not temporaries(out)
    # Frames of unfinished shards were rendered again (what the render measured is in their
    # manifest rows, equal to the uninterrupted build's: compared above).
    assert all(r["image_mean_luminance"] is not None for r in manifest_rows(out).values())
    # One Mitsuba thread: the images (and EXRs) are byte for byte those of the uninterrupted build,
    # although the resumed process rendered its frames in another order after another start.
    assert image_files(out) == image_files(root) and len(image_files(out)) == 16


def test_out_must_be_a_folder_and_temporaries_do_not_make_it_foreign(tmp_path: Path) -> None:
    config = tiny_config(tmp_path)
    (tmp_path / "file").write_text("x")
    with pytest.raises(DatagenError, match="--out is a file, not a folder"):
        build_dataset(config, tmp_path / "file", render=False)
    # A first run killed while writing dataset.json leaves only its temporary: not someone's data.
    (tmp_path / "ds").mkdir()
    (tmp_path / "ds" / ".dataset.json.123.datagen-tmp").write_text("{")
    report = build_dataset(config, tmp_path / "ds", render=False)
    assert report.frames == 8 and not temporaries(tmp_path / "ds")


def test_exclude_mode_drops_boxes_under_the_minimum_as_too_small(tmp_path: Path) -> None:
    config = tiny_config(tmp_path, **{"labels.small_boxes": "exclude", "labels.min_box_px": 16.0})
    report = build_dataset(config, tmp_path / "ds", render=False)
    need = np.array(TrainView(128, 68, config.labels.train_imgsz).min_label_size_px(config.labels.min_box_px))
    records = [f for row in manifest_rows(tmp_path / "ds").values() for f in row["features"]]
    small = [f for f in records if f["exclusion"] == "too_small"]
    assert len(small) == report.excluded["too_small"] > 0
    for f in small:  # the paper's box is recorded; a side of it is under the minimum
        box = np.array(f["corrected_xyxy"])
        assert f["label_xyxy"] is None and np.any(box[2:] - box[:2] < need)
    for f in records:
        if f["labeled"]:  # a written box is the corrected one, never grown, at least the minimum
            assert f["label_xyxy"] == f["corrected_xyxy"]
            assert np.all(np.diff(np.reshape(f["label_xyxy"], (2, 2)), axis=0) >= need)


def test_the_manifest_readme_recompute_example_runs_and_matches(tmp_path: Path) -> None:
    """manifests/README.md's 'Recomputing a label' snippet, run as written on a built dataset."""
    build_dataset(tiny_config(tmp_path), tmp_path / "ds", render=False)
    text = (ROOT / "manifests" / "README.md").read_text()
    section = text[text.index("## Recomputing a label"):]
    code = section[section.index("```python") + len("```python"):]
    code = code[:code.index("```")].replace("DATASET", str(tmp_path / "ds"))
    scope: dict = {}
    exec(compile(code, "manifests/README.md", "exec"), scope)
    labels, row = scope["labels"], scope["row"]
    stored = row["features"]
    np.testing.assert_allclose(labels.center_px, np.array([f["center_px"] or [np.nan] * 2 for f in stored],
                                                          dtype=float), atol=1e-6)
    labeled = np.array([f["labeled"] for f in stored])
    np.testing.assert_array_equal(labels.labeled, labeled)
    np.testing.assert_allclose(labels.label_xyxy[labeled], np.array([f["label_xyxy"] for f in stored if f["labeled"]]),
                               atol=1e-6)


def test_the_summary_explains_each_exclusion_and_names_the_classes_no_frame_labels(tmp_path: Path) -> None:
    """The summary's classes never labeled are those with no label line in any label file,
    for a new build and for a resumed one (from the manifests' metadata), and each reason
    with features excluded is explained."""
    from datagen.core.label_boxes import Exclusion

    config = override_config(load_config("wingcam55"), {"dataset.frames": 40, "dataset.shard_size": 20})
    root = tmp_path / "ds"
    report = build_dataset(config, root, render=False)
    lines_per_class = Counter(int(line.split()[0]) for path in root.glob("labels/**/*.txt")
                              for line in path.read_text().splitlines())
    unseen = [c for c in range(len(report.classes)) if not lines_per_class[c]]
    assert report.never_labeled == unseen and 0 < len(unseen) < len(report.classes)
    summary = "\n".join(report.lines())
    assert f"never labeled in this build: {len(unseen)} of {len(report.classes)} classes" in summary
    assert report.classes[unseen[0]] in summary
    for reason in Exclusion:
        if reason.reason and report.excluded[reason.reason]:
            assert f"    {reason.reason}: {reason.meaning}" in summary
    resumed = build_dataset(config, root, render=False)
    assert resumed.resumed and resumed.never_labeled == unseen


def test_every_exclusion_reason_has_a_meaning_of_its_own() -> None:
    from datagen.core.label_boxes import Exclusion

    meanings = [reason.meaning for reason in Exclusion]
    assert all(meanings) and len(set(meanings)) == len(meanings)


def test_the_estimate_says_the_disk_a_build_will_use_within_a_factor_of_what_it_writes(tmp_path: Path) -> None:
    import io

    from datagen.console import ConsoleProgress
    from datagen.pipeline.estimate import frame_cost

    config = override_config(load_config("wingcam55"), {"dataset.frames": 120, "dataset.shard_size": 60})
    stream = io.StringIO()
    build_dataset(config, tmp_path / "ds", render=False,
                  progress=ConsoleProgress("w", stream=stream, interval_s=1e9, live=False))
    assert re.search(r", 0 s and about [0-9.]+ (KB|MB) on disk for 120 frames \(", stream.getvalue().splitlines()[0])
    written = sum(p.stat().st_size for p in (tmp_path / "ds").rglob("*") if p.is_file())
    predicted = 120 * frame_cost(config, 2, render=False).disk_bytes
    assert 0.5 < written / predicted < 2.0, (written, predicted)
    rendered = frame_cost(config, 2)  # a 2048x1080 PNG is megabytes; the EXR is several times more
    exr = frame_cost(override_config(config, {"render.exr": True}), 2)
    assert 1e6 < rendered.disk_bytes < 1e7 and exr.disk_bytes > 5 * rendered.disk_bytes
