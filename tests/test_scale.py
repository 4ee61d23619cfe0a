"""Audit and evaluate at scale (issue 20): read shard by shard, in worker processes, they
give what a whole-dataset view gives: the same checks, counts, worst offenders and
statistics, and the same per-frame PtD results."""

from __future__ import annotations

import dataclasses
import io
import json
import shutil
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from datagen.analysis.audit import audit
from datagen.analysis.evaluate import Run, evaluate_runs
from datagen.config import load_config, override_config
from datagen.console import ConsoleProgress
from datagen.dataset.reader import load_dataset, open_dataset
from datagen.parallel import IN_FLIGHT_PER_WORKER, map_in_order
from datagen.pipeline.build import build_dataset
from datagen.report.audit_report import report_document

from .support import run_cli, touch

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def built(tmp_path_factory) -> Path:
    """A labels-only wingcam55 build of 600 frames in shards of 80: train and val shards
    interleave in frame order (split_by frame), and approaches cross shard boundaries."""
    tmp = tmp_path_factory.mktemp("scale")
    config = override_config(load_config(ROOT / "scenes" / "wingcam55.yaml"),
                             {"dataset.frames": 600, "dataset.shard_size": 80})
    build_dataset(config, tmp / "ds", render=False)
    return tmp / "ds"


@pytest.fixture(scope="module")
def damaged(built, tmp_path_factory) -> Path:
    """``built`` with label files and a manifest damaged in many ways across shards of both
    splits: offenders of equal score in several shards, and several failures per line."""
    root = tmp_path_factory.mktemp("damaged") / "ds"
    shutil.copytree(built, root)
    files = sorted((root / "labels").rglob("*.txt"))
    rng = np.random.default_rng(5)
    for n, path in enumerate(rng.choice(files, 48, replace=False)):
        lines = path.read_text().splitlines()
        kind = n % 8
        if kind == 0 and lines:
            lines.append(lines[0])  # a duplicate row and a second line of its class
        elif kind == 1 and lines:
            lines.pop()  # a labeled feature without a line
        elif kind == 2 and lines:
            tokens = lines[0].split()
            tokens[1] = f"{float(tokens[1]) + 0.01:.6f}"  # off the manifest box and the true centre
            lines[0] = " ".join(tokens)
        elif kind == 3:
            lines += ["3 abc 0.5 0.1 0.1", "0 0.5 0.5 0.1", "77 0.5 0.5 0.1 0.1", "1 nan 0.5 0.1 0.1",
                      "0 0.5-0.1 0.5 0.1 0.2"]
        elif kind == 4 and lines:
            tokens = lines[-1].split()
            tokens[3] = "1.5"  # outside [0, 1]
            lines[-1] = " ".join(tokens)
        elif kind == 5:
            path.unlink()
            continue
        elif kind == 6 and lines:
            lines[0] = "  " + lines[0].replace(" ", "   ")  # the same values, other whitespace
        elif kind == 7 and lines:
            lines.append(" ".join([lines[0].split()[0], "0.001", "0.5", "0.001", "0.05"]))  # at the border
        path.write_text("\n".join(lines) + "\n")
    for manifest in sorted((root / "manifests").glob("*.parquet"))[1:3]:  # a train and a val shard
        table = pq.read_table(manifest)
        column = table.column("cam_from_world").combine_chunks()
        values = column.flatten().flatten().to_numpy().copy().reshape(len(column), 4, 4)
        values[[3, 5], :3, 3] += [[0.05, 0.0, 0.0], [0.0, 0.3, 0.0]]
        moved = pa.FixedSizeListArray.from_arrays(pa.FixedSizeListArray.from_arrays(pa.array(values.ravel()), 4), 4)
        table = table.set_column(table.schema.get_field_index("cam_from_world"), table.schema.field("cam_from_world"),
                                 moved.cast(column.type))
        pq.write_table(table.replace_schema_metadata(table.schema.metadata), manifest)
    return root


def _report(result) -> str:
    doc = report_document(result)
    doc.pop("dataset")
    return json.dumps(doc)


def test_streaming_audit_of_a_damaged_dataset_equals_the_whole_dataset_audit(damaged) -> None:
    whole = audit(load_dataset(damaged, allow_duplicates=True))
    assert not whole.passed
    failing = {c.name for c in whole.checks if c.failures}
    assert {"manifest_boxes", "label_lines", "centre_drift", "edge_margin_and_front", "ultralytics_rules",
            "files"} <= failing
    assert any(len(c.offenders) == 20 and c.failures > 20 for c in whole.checks)  # the top 20 is a choice
    for workers in (1, 2):
        assert _report(audit(open_dataset(damaged), workers=workers)) == _report(whole), workers


def test_streaming_audit_of_a_good_dataset_passes_with_the_same_statistics(built) -> None:
    whole = audit(load_dataset(built))
    streamed = audit(open_dataset(built), workers=2)
    assert whole.passed and streamed.passed
    assert _report(streamed) == _report(whole)
    assert np.array_equal(streamed.plot.scatter, whole.plot.scatter)
    assert streamed.plot.boxes == whole.plot.boxes


@pytest.mark.parametrize(("split", "workers"), [(None, 2), ("val", 1)])
def test_streaming_evaluate_gives_the_loaded_views_results_for_any_worker_count(built, split, workers) -> None:
    runs = [Run(0.0, 0), Run(1.0, 1)]
    whole = evaluate_runs(load_dataset(built), runs, split=split)
    source = open_dataset(built)
    for count in (1, workers):
        streamed = evaluate_runs(source, runs, split=split, workers=count)
        for a, b in zip(whole, streamed, strict=True):
            for field in dataclasses.fields(a):
                key = field.name
                if key != "solve_s":
                    x, y = getattr(a, key), getattr(b, key)
                    assert np.array_equal(x, y, equal_nan=True) if isinstance(x, np.ndarray) else x == y, (count, key)
    assert len(whole[0]) == (600 if split is None else load_dataset(built).split.count("val"))
    assert np.all(np.diff(whole[0].frame_id) > 0)


def test_audit_and_evaluate_with_workers_give_their_usual_results(built, tmp_path) -> None:
    done = run_cli("audit", str(built), "--workers", "2", "--overlays", "1", "--out", str(tmp_path / "a"))
    assert done.returncode == 0, done.stderr[-2000:]
    whole = report_document(audit(load_dataset(built)))
    assert _report_file(tmp_path / "a") == {k: v for k, v in json.loads(json.dumps(whole)).items() if k != "dataset"}
    done = run_cli("evaluate", str(built), "--noise-px", "0,1", "--workers", "2", "--out", str(tmp_path / "e"))
    assert done.returncode == 0, done.stderr[-2000:]
    doc = json.loads((tmp_path / "e" / "evaluation.json").read_text())
    assert [r["noise_px"] for r in doc["runs"]] == [0.0, 1.0]
    assert all(r["overall"]["attempts"] == 600 for r in doc["runs"])


def test_audit_and_evaluate_report_their_progress_in_frames(built) -> None:
    for verb, work in (("audit", lambda p: audit(open_dataset(built), progress=p)),
                       ("evaluate", lambda p: evaluate_runs(open_dataset(built), [Run()], progress=p))):
        stream = io.StringIO()
        work(ConsoleProgress("ds", verb=verb, stream=stream, interval_s=0.0, live=False))
        lines = stream.getvalue().splitlines()
        assert lines[0] == f"{verb} ds: 600 frames, 0 already done"
        assert lines[-1].startswith(f"{verb} ds: 600/600 frames (100%)"), lines[-1]
        assert sum("(100%)" in line for line in lines) == 1  # 599/600 is 99%, not a rounded 100%


def _report_file(folder: Path) -> dict:
    doc = json.loads((folder / "report.json").read_text())
    for key in ("dataset", "files"):
        doc.pop(key)
    return doc


@pytest.mark.parametrize("lines", [
    ["0 0.5 0.5 0.1 0.2", "3 0.25 0.75 0.01 0.02"],
    ["0 0.5-0.1 0.5 0.1 0.2"], ["0 0.51.2 0.5 0.1 0.2"], ["1 1e400 0.5 0.1 0.2"], ["1.5 0.5 0.5 0.1 0.2"],
    ["7 0.5 0.5 0.1 0.2"], ["0 0.5 0.5 0.1"], ["-0 -0.5 0.5 0.1 0.2"], ["0 1_0 0.5 0.1 0.2"], ["0\t0.5  0.5 0.1 0.2 "],
])
def test_bulk_label_parsing_gives_what_parse_line_gives_line_by_line(lines) -> None:
    from datagen.analysis.audit.label_lines import _parse_lines
    from datagen.dataset.yolo import parse_line

    values, problems = _parse_lines(lines, 5, 5)
    for line, row, problem in zip(lines, values, problems, strict=True):
        expected, why = parse_line(line, 5)
        assert problem == why
        assert (np.isnan(row).all() if expected is None else row.tolist() == expected)


def test_map_in_order_submits_only_a_few_tasks_ahead_of_the_results_taken(monkeypatch) -> None:
    """Results are not piled up: while the caller holds the first result, at most
    IN_FLIGHT_PER_WORKER tasks per worker (and the one that replaced it) were submitted.
    Counted on a pool that records its submissions and runs them at once (no clock)."""
    import concurrent.futures

    submitted: list[int] = []

    class RecordingPool:
        def __init__(self, workers, mp_context=None) -> None:
            assert workers == 2

        def __enter__(self):
            return self

        def __exit__(self, *exc) -> None:
            return None

        def submit(self, fn, *args) -> concurrent.futures.Future:
            submitted.append(args[0])
            done: concurrent.futures.Future = concurrent.futures.Future()
            done.set_result(fn(*args))
            return done

    monkeypatch.setattr(concurrent.futures, "ProcessPoolExecutor", RecordingPool)
    results = map_in_order(abs, [(-i,) for i in range(40)], 2)
    assert next(results) == 0
    assert submitted == [-i for i in range(IN_FLIGHT_PER_WORKER * 2 + 1)]
    assert list(results) == list(range(1, 40)) and len(submitted) == 40


def test_map_in_order_yields_every_result_in_task_order_from_worker_processes(tmp_path) -> None:
    assert list(map_in_order(touch, [(tmp_path, i) for i in range(40)], 2)) == list(range(40))
    assert len(list(tmp_path.iterdir())) == 40


@pytest.mark.parametrize("split", [None, "train", "val"])
def test_a_source_and_a_loaded_view_walk_to_the_same_frames_for_any_positions(built, split) -> None:
    """The one walk (DatasetMeta.walk): for positions in frame order or not, every frame or a
    split's, a source read shard by shard and a loaded view give the same frames in the order
    asked for, and the frames of the split alone."""
    view, source = load_dataset(built), open_dataset(built)
    order = source.frames()
    assert np.array_equal(order.frame_id, view.frame_id)
    rng = np.random.default_rng(3)
    for positions in (None, np.sort(rng.choice(len(order), 97, replace=False)), rng.permutation(len(order))[:61]):
        wanted = np.arange(len(order)) if positions is None else positions
        wanted = wanted[[split is None or order.split[p] == split for p in wanted.tolist()]]
        for dataset in (source, view):
            walked = [(v.frame_id[rows], [v.split[r] for r in rows.tolist()]) for v, rows in
                      dataset.walk(positions, split=split)]
            ids = np.concatenate([w[0] for w in walked]) if walked else np.zeros(0, np.int64)
            assert np.array_equal(ids, order.frame_id[wanted]), type(dataset).__name__
            assert split is None or all(s == split for w in walked for s in w[1])


def test_walking_a_source_in_frame_order_reads_each_shard_once_though_train_and_val_interleave(built,
                                                                                             monkeypatch) -> None:
    from datagen.dataset.reader import DatasetSource

    source = open_dataset(built)
    order = source.frames()
    switches = sum(a != b for a, b in zip(order.manifest_file, order.manifest_file[1:]))
    assert switches > len(source.manifests)  # the frame order goes back and forth between shards
    reads: list[str] = []
    real = DatasetSource.read_shard
    monkeypatch.setattr(DatasetSource, "read_shard",
                        lambda self, name, **kw: reads.append(name) or real(self, name, **kw))
    rows = sum(len(r) for _, r in source.walk())
    assert rows == len(order) and sorted(reads) == sorted(source.manifests)
