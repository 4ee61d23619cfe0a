"""What a newcomer meets: sheets numbered by class id with titles that never overprint, small
builds that say what they lack, the trainer's stack checked before training, messages that say
what to write, help that reads, a license, and the build's estimate corrected by what it
measures (tests/test_build.py)."""

from __future__ import annotations

import os
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest
import yaml

from datagen.dataset.reader import load_dataset
from datagen.report.overlays import _overlap, _place_titles, draw_sheet
from tests.support import ROOT
from tests.test_hostile import datagen, refused, write

TINY_LABELS = ("name: tiny\ncamera: {mount: wingcam, hfov_deg: 55.0, width: 512, height: 270}\n"
               "labels: {edge_margin_px: 2.0}\ndataset: {frames: 6, min_shards: 1, seed: 3, val_fraction: 0.2}\n")


@pytest.fixture(scope="module")
def small(tmp_path_factory) -> Path:
    """A 6-frame labels-only build whose seed draws no val frame."""
    tmp = tmp_path_factory.mktemp("small")
    run = datagen("build", "--config", str(write(tmp, "t.yaml", TINY_LABELS)), "--out", str(tmp / "ds"),
                  "--no-render")
    assert run.returncode == 0, run.stderr
    (tmp / "ds" / "build.out").write_text(run.stdout)
    return tmp / "ds"


def test_sheets_number_features_by_the_class_id_their_label_lines_begin_with(small) -> None:
    view = load_dataset(small)
    labels = view.recompute()
    for b in range(len(view)):
        sheet = draw_sheet(view, b, labels)
        assert sheet.numbers, b
        assert all(number == view.features.class_id[f] for f, number in sheet.numbers.items())
        lines = (small / view.label_path[b]).read_text().split("\n")
        written = {int(line.split()[0]) for line in lines if line.strip()}
        assert written <= set(sheet.numbers.values())  # every label line's class is a number on the sheet


def test_region_titles_never_overprint_each_other_and_rarely_sit_on_an_outline() -> None:
    """2 to 7 regions anywhere, overlapping (crops of one object side by side, others inside
    them): no title overlaps another or leaves the frame, and almost none (under 2%, where
    the regions leave no free place) lies on a region's outline."""
    rng = np.random.default_rng(3)
    titles_drawn = on_outline = 0
    for _ in range(300):
        regions = []
        for _ in range(rng.integers(2, 8)):
            x, y = rng.uniform(0, 1400), rng.uniform(60, 700)
            w, h = rng.uniform(80, 500), rng.uniform(60, 300)
            regions.append((x, y, min(x + w, 1598), min(y + h, 898)))
        titles = [f"tanker ({i + 1} of {len(regions)})" for i in range(len(regions))]
        placed = _place_titles(regions, titles, (0, 40, 1600, 900))
        outlines = [e for a0, b0, a1, b1 in regions for e in ((a0, b0 - 1, a1, b0 + 1), (a0, b1 - 1, a1, b1 + 1),
                                                              (a0 - 1, b0, a0 + 1, b1), (a1 - 1, b0, a1 + 1, b1))]
        for i, a in enumerate(placed):
            assert 0 <= a[0] and a[2] <= 1600 and 40 <= a[1] and a[3] <= 900
            assert not any(_overlap(a, b) for b in placed[i + 1:]), (regions, placed)
            on_outline += any(_overlap(a, e) for e in outlines)
            titles_drawn += 1
    assert on_outline < 0.02 * titles_drawn, (on_outline, titles_drawn)


def test_a_build_without_val_frames_says_so_and_its_predict_command_names_the_list_there_is(small) -> None:
    out = (small / "build.out").read_text()
    assert "6 train, 0 val" in out and "no val frames: Ultralytics uses the train frames for both" in out
    data, hyp = ((small / name).read_text() for name in ("data.yaml", "hyp.yaml"))
    assert yaml.safe_load(data)["val"] == "train.txt"
    for text in (data, hyp):
        predict = next(line for line in text.splitlines() if " predict model=" in line)
        assert f"source={small / 'train.txt'} " in predict, predict


def test_scoring_predictions_of_a_split_without_frames_is_one_line(small, tmp_path) -> None:
    (tmp_path / "pred").mkdir()
    refused(datagen("evaluate", str(small), "--predictions", str(tmp_path / "pred"), "--split", "val"),
            "no val frames to score", "6 train, 0 val")


def test_reading_a_dataset_starts_no_thread_that_could_abort_the_exit(small) -> None:
    """Arrow's I/O pool, started by ``pq.read_table`` even single-threaded, aborted one refusal in
    ~40 at exit (-6, "terminate called without an active exception"): reading every table of a
    dataset (manifests, features, objects) leaves the process with the threads it had."""
    code = ("import os, sys\n"
            "from datagen.dataset.reader import load_dataset\n"
            "import cv2, pyarrow.parquet\n"
            "before = len(os.listdir('/proc/self/task'))\n"
            "view = load_dataset(sys.argv[1])\n"
            "assert len(view) == 6, len(view)\n"
            "print(before, len(os.listdir('/proc/self/task')))\n")
    run = subprocess.run([sys.executable, "-c", code, str(small)], capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr[-2000:]
    before, after = map(int, run.stdout.split())
    assert after == before, (before, after)


def test_an_integer_written_as_an_exponent_says_what_to_write(tmp_path) -> None:
    path = write(tmp_path, "c.yaml", "name: t\ncamera: {mount: wingcam, hfov_deg: 55}\ndataset: {frames: 1e4}\n")
    refused(datagen("validate", str(path)), "dataset.frames", "must be a whole number", "write 10000")


def test_help_keeps_sentences_whole_and_shows_no_type_for_a_flag() -> None:
    env = {**os.environ, "COLUMNS": "200"}
    out = subprocess.run([sys.executable, "-m", "datagen", "audit", "--help"], capture_output=True, text=True,
                         env=env, timeout=60)
    assert out.returncode == 0
    assert ("Check a dataset's labels against the true centre projections; write report.json, plots and "
            "report.html.") in out.stdout
    assert "<bool>" not in out.stdout and "--help" in out.stdout


def test_approach_prints_an_approach_as_a_number() -> None:
    run = datagen("approach", "--config", "wingcam55", "--approaches", "1", "--frames", "2")
    assert run.returncode == 0
    frames = [line for line in run.stdout.splitlines() if line.startswith("frame")]
    assert len(frames) == 2 and all("approach 0 t=" in line for line in frames), frames


def test_train_takes_batch_and_imgsz() -> None:
    from typer.testing import CliRunner

    from datagen.cli import app

    help_text = CliRunner().invoke(app, ["train", "--help"], env={"COLUMNS": "200"}).output
    assert "--batch" in help_text and "--imgsz" in help_text and "nbs" in help_text


def test_the_dataset_card_says_why_classes_were_never_labeled(small) -> None:
    card = (small / "README.md").read_text()
    assert "**Never labeled**" in card and "receiver.canopy_top" in card and "By design" in card


def test_the_package_states_its_license_and_how_to_cite_it(tmp_path) -> None:
    assert (ROOT / "LICENSE").read_text().startswith("BSD 3-Clause License")
    citation = yaml.safe_load((ROOT / "CITATION.cff").read_text())
    assert citation["license"] == "BSD-3-Clause" and citation["cff-version"] == "1.2.0"
    out = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-q", "-w",
                          str(tmp_path), str(ROOT)], capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr[-2000:]
    wheel = next(tmp_path.glob("datagen-*.whl"))
    with zipfile.ZipFile(wheel) as z:
        metadata = next(z.read(n).decode() for n in z.namelist() if n.endswith("METADATA"))
        assert "License-Expression: BSD-3-Clause" in metadata
        assert any(n.endswith("licenses/LICENSE") for n in z.namelist())


@pytest.mark.train
def test_a_torch_stack_whose_operators_fail_is_one_line_naming_what_to_install(monkeypatch) -> None:
    pytest.importorskip("ultralytics")
    import torchvision.ops

    from datagen.analysis.ultralytics import check_torch_stack
    from datagen.core.errors import DatagenError

    def broken(*args, **kwargs):
        raise RuntimeError("operator torchvision::nms does not exist")

    monkeypatch.setattr(torchvision.ops, "nms", broken)
    with pytest.raises(DatagenError) as caught:
        check_torch_stack()
    line = str(caught.value)
    assert "\n" not in line and "torchvision::nms does not exist" in line and "install torchvision 0." in line
