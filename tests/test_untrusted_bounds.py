"""A dataset folder is untrusted input, second round: training reads nothing but the dataset's
own images, every file a command reads is bounded before it is read, every value a reader
computes with is range-checked, every JSON goes through the guarded reader, the lock and
``--overwrite`` touch nothing datagen did not write, names print escaped, and ``--out``
folders of the reports hold nobody else's files. Each case ends in one line (or a failed
check), within the hang guard and the memory bound of :mod:`tests.test_hostile`, with every
file outside the dataset and every user file inside it intact."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from datagen.paths import Unreadable, read_bytes
from tests.test_hostile import RSS_LIMIT_MB, TINY, datagen, refused, snapshot, write

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))
from bench_hostile import huge_exr  # the bench's bomb, made once

ESC = "\x1b"
LABELS_ONLY = TINY.replace("dataset: {frames: 8", "dataset: {frames: 12")


# --- datasets: a rendered one with EXR and a labels-only one, a copy of either per test -----------------------------
@pytest.fixture(scope="module")
def built(tmp_path_factory) -> Path:
    tmp = tmp_path_factory.mktemp("bounds")
    run = datagen("build", "--config", str(write(tmp, "t.yaml", TINY)), "--out", str(tmp / "ds"), "--exr")
    assert run.returncode == 0, run.stderr[-2000:]
    return tmp / "ds"


@pytest.fixture(scope="module")
def built_labels(tmp_path_factory) -> Path:
    tmp = tmp_path_factory.mktemp("bounds-labels")
    run = datagen("build", "--config", str(write(tmp, "t.yaml", LABELS_ONLY)), "--out", str(tmp / "ds"),
                  "--no-render")
    assert run.returncode == 0, run.stderr[-2000:]
    return tmp / "ds"


@pytest.fixture
def ds(built, tmp_path) -> Path:
    shutil.copytree(built, tmp_path / "ds", symlinks=True)
    return tmp_path / "ds"


@pytest.fixture
def lo(built_labels, tmp_path) -> Path:
    shutil.copytree(built_labels, tmp_path / "lo", symlinks=True)
    return tmp_path / "lo"


@pytest.fixture
def outside(tmp_path) -> Path:
    """A user's folder beside the dataset, with files no command may touch."""
    folder = tmp_path / "outside"
    (folder / "images").mkdir(parents=True)
    (folder / "secret.txt").write_text("root:x:0:0:root:/root:/bin/bash\n")
    return folder


def manifest(root: Path, split: str = "train") -> Path:
    return sorted((root / "manifests").glob(f"{split}-*.parquet"))[0]


def set_value(root: Path, column: str, value, row: int = 0, split: str = "train") -> Path:
    """Set ``column`` of one row of the first manifest of ``split`` (a struct list's field as
    ``features.FIELD``, in every record of the row)."""
    path = manifest(root, split)
    table = pq.read_table(path)
    meta = table.schema.metadata
    name, _, sub = column.partition(".")
    values = table.column(name).to_pylist()
    if sub:
        for record in values[row]:
            record[sub] = value
    else:
        values[row] = value
    index = table.schema.get_field_index(name)
    table = table.set_column(index, table.schema.field(index), pa.array(values, table.schema.field(index).type))
    pq.write_table(table.replace_schema_metadata(meta), path)
    return path


def no_escape(run) -> None:
    """Nothing the command printed acts on a terminal."""
    for text in (run.stdout, run.stderr):
        assert ESC not in text and "\x07" not in text and "\r" not in text


# --- 1. training reads nothing outside the dataset ------------------------------------------------------------------
@pytest.mark.render
def test_training_refuses_an_image_list_naming_an_image_outside_the_dataset(ds, outside, tmp_path) -> None:
    shutil.copy(next((ds / "images").rglob("*.png")), outside / "images" / "private.png")
    with (ds / "train.txt").open("a") as f:
        f.write(f"{outside / 'images' / 'private.png'}\n")
    before = snapshot(outside)
    refused(datagen("train", str(ds), "--epochs", "1", "--runs", str(tmp_path / "runs")), "train.txt",
            "private.png", "which no manifest does")
    assert snapshot(outside) == before and not (tmp_path / "runs").exists()
    run = datagen("audit", str(ds))
    assert run.returncode == 1 and "FAIL  training_recipe" in run.stdout, run.stdout


@pytest.mark.render
def test_training_refuses_an_image_list_whose_image_is_a_fifo(ds, tmp_path) -> None:
    image = Path(ds / (ds / "val.txt").read_text().split()[0])
    image.unlink()
    os.mkfifo(image)
    refused(datagen("train", str(ds), "--epochs", "1", "--runs", str(tmp_path / "runs")), "val.txt",
            "not a regular file")


@pytest.mark.render
@pytest.mark.parametrize(("line", "expected"), [
    ("foo: 1", "'foo': not a setting a datagen recipe may hold"),
    ("epochs: 100000000\nsave_period: 1", "epochs: value '100000000'"),
    ("save_period: 1", "'save_period': not a setting"),
    ("cache: disk", "cache: value 'disk'"),
    ("lr0: .nan", "lr0: value 'nan'"),
])
def test_a_recipe_setting_out_of_the_table_fails_the_audit_and_training(ds, tmp_path, line, expected) -> None:
    with (ds / "hyp.yaml").open("a") as f:
        f.write(line + "\n")
    run = datagen("audit", str(ds))
    assert run.returncode == 1 and expected in run.stdout, run.stdout
    refused(datagen("train", str(ds), "--epochs", "1", "--runs", str(tmp_path / "runs")), "hyp.yaml", expected)


def test_the_recipe_a_build_writes_passes_its_own_table(lo) -> None:
    from datagen.config.inputs import parse_yaml
    from datagen.dataset.training_run import RECIPE_SETTINGS, recipe_problems

    doc = parse_yaml((lo / "hyp.yaml").read_text(), lo / "hyp.yaml")
    assert recipe_problems(doc) == [] and set(doc) <= set(RECIPE_SETTINGS)


# --- 2. memory: every file bounded before it is read -----------------------------------------------------------------
@pytest.mark.render
def test_a_huge_sparse_label_file_is_refused_unread(ds) -> None:
    label = next((ds / "labels").rglob("*.txt"))
    with label.open("r+b") as f:
        f.truncate(2 * 2**30)
    run = datagen("audit", str(ds))
    assert run.returncode == 1 and "larger than the" in run.stdout, run.stdout
    assert run.peak_rss_mb < RSS_LIMIT_MB, run.peak_rss_mb


@pytest.mark.render
def test_a_huge_sparse_prediction_file_is_refused_unread(ds, tmp_path) -> None:
    folder = tmp_path / "pred"
    folder.mkdir()
    stem = Path((ds / "val.txt").read_text().split()[0]).stem
    with (folder / f"{stem}.txt").open("wb") as f:
        f.truncate(256 * 2**20)
    refused(datagen("evaluate", str(ds), "--predictions", str(folder)), f"{stem}.txt", "larger than the")


@pytest.mark.render
def test_an_exr_declaring_a_huge_image_is_refused_before_it_is_decoded(ds, tmp_path) -> None:
    exr = huge_exr(ds)
    refused(datagen("export", str(ds), "--format", "bop", "--out", str(tmp_path / "x")), exr.name, "16000x16000")
    assert not (tmp_path / "x").exists()


@pytest.mark.render
@pytest.mark.parametrize("command", [["audit"], ["preview"], ["evaluate", "--noise-px", "0"]])
def test_a_manifest_of_more_rows_than_a_shard_holds_is_refused(ds, command) -> None:
    path = manifest(ds)
    table = pq.read_table(path)
    pq.write_table(pa.concat_tables([table.slice(0, 1)] * 100_000).replace_schema_metadata(table.schema.metadata),
                   path, compression="zstd")
    refused(datagen(command[0], str(ds), *command[1:]), path.name, "100000 rows", "shard_size")


@pytest.mark.render
def test_a_data_yaml_larger_than_its_bound_is_refused(ds) -> None:
    (ds / "data.yaml").write_text("names: '" + "x" * 300_000 + "'\n")
    refused(datagen("audit", str(ds)), "data.yaml", "larger than the 262,144 bytes")


def test_a_fifo_is_refused_without_blocking(tmp_path) -> None:
    os.mkfifo(tmp_path / "fifo")
    with pytest.raises(Unreadable, match="not a regular file"):
        read_bytes(tmp_path / "fifo", "a label file", 1024)
    (tmp_path / "big").write_bytes(b"x" * 2048)
    with pytest.raises(Unreadable, match="2,048 bytes: larger than the 1,024"):
        read_bytes(tmp_path / "big", "a label file", 1024)
    assert read_bytes(tmp_path / "big", "x", 4096, head=10) == b"x" * 10


# --- 3. values range-checked where they are read ---------------------------------------------------------------------
READERS = {"audit": ["audit"], "evaluate": ["evaluate", "--noise-px", "0,1"], "preview": ["preview"],
           "export": ["export", "--format", "bop", "--out"]}


@pytest.mark.render
@pytest.mark.parametrize(("column", "value", "expected", "commands"), [
    ("distance_m", 1e8, "distance_m: value 100000000.0", ["audit", "evaluate", "preview", "export"]),
    ("distance_m", 1e308, "distance_m: value 1e+308", ["audit"]),
    ("distance_m", float("nan"), "distance_m: value nan", ["audit", "evaluate"]),
    ("distance_m", -5.0, "distance_m: value -5.0", ["evaluate"]),
    ("frame_id", -5, "frame_id: value -5", ["evaluate", "export"]),
    ("frame_id", 2**62, "frame_id: value 4611686018427387904", ["export"]),
    ("features.keypoint_flag", -128, "features.keypoint_flag: value [-128, -128,", ["export"]),
    ("cam_from_world", [[0.0] * 4] * 4, "cam_from_world", ["export"]),
    ("cam_from_world", [[1e308] * 4] * 4, "cam_from_world", ["export", "evaluate"]),
])
def test_a_value_out_of_its_range_is_one_line(ds, tmp_path, column, value, expected, commands) -> None:
    """The range checks are the reader's, which every reading command uses: each value is
    tried with the commands it hurt before (the audit's histograms, evaluate's distance bins,
    the exports' ids and matrices)."""
    set_value(ds, column, value)
    for command in commands:
        extra = [str(tmp_path / "x")] if command == "export" else []
        refused(datagen(READERS[command][0], str(ds), *READERS[command][1:], *extra), expected)
    assert not (tmp_path / "x").exists()


@pytest.mark.render
def test_a_nan_feature_point_is_one_line(ds) -> None:
    table = pq.read_table(ds / "features.parquet")
    points = table.column("points_m").to_pylist()
    points[3][0] = [float("nan")] * 3
    index = table.schema.get_field_index("points_m")
    pq.write_table(table.set_column(index, table.schema.field(index), pa.array(points, table.schema.field(index).type)),
                   ds / "features.parquet")
    for args in (["audit"], ["evaluate", "--noise-px", "0"]):
        refused(datagen(args[0], str(ds), *args[1:]), "features.parquet", "finite metres")


# --- 4. no traceback: every JSON guarded, empty manifests, undecodable names ----------------------------------------
DEEP = "[" * 100_000 + "]" * 100_000


@pytest.mark.render
def test_deeply_nested_report_records_are_not_records(ds) -> None:
    for folder, record, command in (("audit", "report.json", ["audit"]), ("preview", "preview.json", ["preview"])):
        (ds / folder).mkdir(exist_ok=True)
        (ds / folder / record).write_text(DEEP)
        refused(datagen(command[0], str(ds), *command[1:]), record, "not a record datagen can read")
        assert (ds / folder / record).read_text() == DEEP  # the user's file is kept


@pytest.mark.render
def test_a_deeply_nested_dataset_json_is_one_line_for_a_build(ds, tmp_path) -> None:
    config = write(tmp_path, "t.yaml", TINY)
    (ds / "dataset.json").write_text(DEEP)
    refused(datagen("build", "--config", str(config), "--out", str(ds)), "dataset.json", "nested deeper than 64",
            "--overwrite")
    (ds / "evaluation").mkdir()
    (ds / "evaluation" / "evaluation.json").write_text(DEEP)
    run = datagen("build", "--config", str(config), "--out", str(ds), "--overwrite")
    assert run.returncode == 0 and "Traceback" not in run.stderr, run.stderr[-2000:]
    assert (ds / "evaluation" / "evaluation.json").read_text() == DEEP  # no record of datagen's: kept


@pytest.mark.render
def test_an_empty_manifest_is_one_line(ds, tmp_path) -> None:
    path = manifest(ds)
    table = pq.read_table(path)
    pq.write_table(table.slice(0, 0), path)
    for args in (["audit"], ["preview"], ["export", "--format", "coco", "--out", str(tmp_path / "x")]):
        refused(datagen(args[0], str(ds), *args[1:]), path.name, "0 rows")


@pytest.mark.render
def test_an_undecodable_file_name_is_reported_escaped(ds) -> None:
    shard = next((ds / "images" / "train").iterdir())
    with open(os.path.join(os.fsencode(shard), b"\xff\x1b[2J.png"), "wb") as f:
        f.write(b"x")
    run = datagen("audit", str(ds))
    assert run.returncode == 1, run.stderr
    no_escape(run)
    html = (ds / "audit" / "report.html").read_text()
    assert "\\udcff\\x1b[2J.png: orphan" in html and ESC not in html


# --- 5, 6. the lock and --overwrite touch nothing datagen did not write -----------------------------------------------
@pytest.mark.render
def test_a_hard_linked_lock_is_refused_and_its_other_name_untouched(ds, outside, tmp_path) -> None:
    (ds / ".datagen.lock").unlink()
    os.link(outside / "secret.txt", ds / ".datagen.lock")
    before = snapshot(outside)
    refused(datagen("build", "--config", str(write(tmp_path, "t.yaml", TINY)), "--out", str(ds)), ".datagen.lock",
            "hard link")
    refused(datagen("build", "--config", str(write(tmp_path, "o.yaml", TINY.replace("seed: 7", "seed: 9"))),
                    "--out", str(ds)), ".datagen.lock", "hard link")
    assert snapshot(outside) == before


@pytest.mark.render
def test_overwrite_removes_no_file_a_tampered_manifest_names(ds, tmp_path) -> None:
    (ds / "notes").mkdir()
    (ds / "notes" / "important.csv").write_text("a,b\n1,2\n")
    set_value(ds, "exr_path", "notes/important.csv")
    other = write(tmp_path, "o.yaml", TINY.replace("seed: 7", "seed: 9"))
    assert datagen("build", "--config", str(other), "--out", str(ds), "--overwrite", "--no-render").returncode == 0
    assert (ds / "notes" / "important.csv").read_text() == "a,b\n1,2\n"


def test_overwrite_does_not_plan_the_frames_dataset_json_claims(lo, tmp_path) -> None:
    doc = json.loads((lo / "dataset.json").read_text())
    doc["config"]["dataset"]["frames"] = 10_000_000
    (lo / "dataset.json").write_text(json.dumps(doc))
    run = datagen("build", "--config", str(write(tmp_path, "o.yaml", LABELS_ONLY.replace("seed: 7", "seed: 9"))),
                  "--out", str(lo), "--overwrite", "--no-render")
    assert run.returncode == 0, run.stderr[-2000:]


# --- 7. names print escaped ------------------------------------------------------------------------------------------
@pytest.mark.render
def test_escape_sequences_in_names_reach_no_terminal(ds, tmp_path) -> None:
    shard = next((ds / "labels" / "train").iterdir())
    (shard / "\x1b[2J\x1b[32mALL CHECKS PASSED\x07\nfake line.txt").write_text("")
    set_value(ds, "image_path", "images/train/00000/\x1b]0;title\x07.png", row=0)
    run = datagen("audit", str(ds))
    no_escape(run)
    assert run.returncode in (1, 2)
    assert all("fake line" not in line or "\\n" in line for line in (run.stdout + run.stderr).splitlines())
    folder = tmp_path / "pred"
    folder.mkdir()
    (folder / "\x1b[2Jx.txt").write_text("0 0.5 0.5 0.1 0.1 0.9\n")
    stem = Path((ds / "val.txt").read_text().split()[0]).stem
    (folder / f"{stem}.txt").write_text("0 0.5 0.5 0.1 0.1 0.9\n")
    no_escape(datagen("evaluate", str(ds), "--predictions", str(folder)))


@pytest.mark.render
def test_class_names_with_escape_sequences_fail_and_print_escaped(ds, tmp_path) -> None:
    text = (ds / "data.yaml").read_text().replace("0: receiver.probe_tip", '0: "\\e[2Jreceiver.probe_tip"')
    (ds / "data.yaml").write_text(text)
    run = datagen("audit", str(ds))
    assert run.returncode == 1 and "FAIL  class_names" in run.stdout
    no_escape(run)
    train = datagen("train", str(ds), "--epochs", "1", "--runs", str(tmp_path / "r"))
    refused(train, "names.0")
    no_escape(train)


# --- 9. --out of a report holds nobody else's files ------------------------------------------------------------------
@pytest.mark.render
@pytest.mark.parametrize(("command", "mine"), [
    (["audit"], "report.html"), (["audit"], "report.json"), (["audit"], "plots/drift_vs_distance.png"),
    (["evaluate", "--noise-px", "0"], "evaluation.json"), (["preview", "--frames", "0"], "00000000.jpg"),
])
def test_a_report_folder_with_a_users_files_is_refused(ds, tmp_path, command, mine) -> None:
    out = tmp_path / "mine"
    (out / mine).parent.mkdir(parents=True, exist_ok=True)
    (out / mine).write_text("the user's own\n")
    before = snapshot(out)
    refused(datagen(command[0], str(ds), *command[1:], "--out", str(out)), "--out", mine.split("/")[-1])
    assert snapshot(out) == before
    if mine == "report.html":  # a new folder, then the command's own earlier report in it, are the command's
        assert datagen(command[0], str(ds), *command[1:], "--out", str(tmp_path / "new")).returncode == 0
        assert datagen(command[0], str(ds), *command[1:], "--out", str(tmp_path / "new")).returncode == 0


# --- 10. the lower ones -----------------------------------------------------------------------------------------------
@pytest.mark.render
def test_a_hard_linked_label_files_text_reaches_no_report(ds, outside) -> None:
    label = next((ds / "labels").rglob("*.txt"))
    label.unlink()
    os.link(outside / "secret.txt", label)
    run = datagen("audit", str(ds))
    assert run.returncode == 1
    for text in (run.stdout, run.stderr, (ds / "audit" / "report.json").read_text(),
                 (ds / "audit" / "report.html").read_text()):
        assert "root:x" not in text and "/bin/bash" not in text


@pytest.mark.render
@pytest.mark.parametrize("kind", ["huge", "jpeg"])
def test_an_export_links_only_images_of_the_datasets_size_and_format(ds, tmp_path, kind) -> None:
    import cv2

    image = next((ds / "images").rglob("*.png"))
    if kind == "huge":  # a PNG header claiming 30000x30000
        data = bytearray(image.read_bytes())
        data[16:24] = (30000).to_bytes(4, "big") * 2
        image.write_bytes(bytes(data))
        expected = "30000x30000 px"
    else:
        image.write_bytes(cv2.imencode(".jpg", cv2.imread(str(image)))[1].tobytes())
        expected = "a JPG image named .png"
    refused(datagen("export", str(ds), "--format", "coco", "--out", str(tmp_path / "x")), image.name, expected)
    assert not (tmp_path / "x").exists()


@pytest.mark.render
def test_preview_says_which_frame_it_draws_without_its_image(ds) -> None:
    image = ds / (ds / "train.txt").read_text().split()[0]
    frame = int(Path(image).stem)
    image.write_bytes(b"not an image")
    run = datagen("preview", str(ds), "--frames", str(frame))
    assert run.returncode == 0, run.stderr
    assert f"not a PNG or JPEG image; frame {frame} drawn without its image" in run.stderr
    assert (ds / "preview" / f"{frame:08d}.jpg").is_file()


@pytest.mark.render
def test_export_into_the_working_folder_keeps_the_folder(ds, tmp_path) -> None:
    here = tmp_path / "here"
    here.mkdir()
    inode = here.stat().st_ino
    run = datagen("export", str(ds), "--format", "coco", "--out", ".", cwd=here)
    assert run.returncode == 0, run.stderr
    assert here.stat().st_ino == inode and (here / "annotations").is_dir()


def test_a_full_disk_during_a_copy_names_the_destination(tmp_path, monkeypatch) -> None:
    import errno

    from datagen import atomic

    def full(src, dst, **kw):
        raise OSError(errno.ENOSPC, "No space left on device", str(src))

    source = write(tmp_path, "a.png", b"x")
    monkeypatch.setattr(atomic.os, "link", lambda *a: (_ for _ in ()).throw(OSError(errno.EXDEV, "cross")))
    monkeypatch.setattr(atomic.shutil, "copy2", full)
    with pytest.raises(OSError) as caught:
        atomic.link_or_copy(source, tmp_path / "out" / "a.png")
    assert caught.value.filename == str(tmp_path / "out" / "a.png")


def test_an_interrupted_command_says_so(lo) -> None:
    code = ("import sys, datagen.dataset.reader as r\n"
            "def stop(*a, **k): raise KeyboardInterrupt\n"
            "r.open_dataset = stop\n"
            f"sys.argv = ['datagen', 'audit', {str(lo)!r}]\n"
            "from datagen.cli import main\nmain()\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 130
    assert out.stderr.strip() == "datagen audit: interrupted; no file is left half-written (each is written whole, " \
                                 "then renamed into place)"


@pytest.mark.render
def test_an_unreadable_folder_fails_the_files_check(ds) -> None:
    if not shutil.which("setpriv") or os.geteuid() != 0:
        pytest.skip("needs setpriv and root to run as another user")
    import tempfile

    shared = Path(tempfile.mkdtemp(prefix="datagen-unreadable-"))  # a folder another user may enter
    shared.chmod(0o755)
    ds = Path(shutil.move(ds, shared / "ds"))
    for path in [ds, *ds.rglob("*")]:
        os.chown(path, 65534, 65534, follow_symlinks=False)
    shard = next((ds / "labels" / "train").iterdir())
    shard.chmod(0o000)
    out = subprocess.run(["setpriv", "--reuid=65534", "--regid=65534", "--clear-groups", sys.executable, "-m",
                          "datagen", "audit", str(ds)], capture_output=True, text=True, timeout=300,
                         env={**os.environ, "HOME": str(ds.parent)})
    shard.chmod(0o755)
    shutil.rmtree(shared)
    assert out.returncode == 1, out.stderr[-2000:]
    assert "a folder that cannot be read" in out.stdout and "Traceback" not in out.stderr
