"""A dataset folder is input from a stranger: no command reads or writes outside it through a
symbolic link, none hangs or prints a traceback on a value a config, a dataset or a
prediction file can hold, none works silently on part of a dataset, and the audit fails
frames that show nothing where their labels are."""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from hypothesis import given
from hypothesis import strategies as st

from tests.test_hostile import TINY, datagen, refused, snapshot, write


# --- a rendered dataset with EXR, and a copy of it per test ---------------------------------------------------------
@pytest.fixture(scope="module")
def built(tmp_path_factory) -> Path:
    tmp = tmp_path_factory.mktemp("untrusted")
    run = datagen("build", "--config", str(write(tmp, "t.yaml", TINY)), "--out", str(tmp / "ds"), "--exr")
    assert run.returncode == 0, run.stderr[-2000:]
    return tmp / "ds"


@pytest.fixture
def ds(built, tmp_path) -> Path:
    shutil.copytree(built, tmp_path / "ds", symlinks=True)
    return tmp_path / "ds"


@pytest.fixture
def outside(tmp_path) -> Path:
    """A user's folder beside the dataset, with a file the commands must never touch."""
    folder = tmp_path / "users"
    folder.mkdir()
    (folder / "report.json").write_text("the user's own\n")
    return folder


def set_column(root: Path, column: str, change) -> Path:
    """Apply ``change(values)`` to ``column`` of the first train manifest."""
    path = sorted((root / "manifests").glob("train-*.parquet"))[0]
    table = pq.read_table(path)
    values = table.column(column).to_pylist()
    change(values)
    index = table.schema.get_field_index(column)
    pq.write_table(table.set_column(index, table.schema.field(index), pa.array(values, table.schema.field(index).type)),
                   path)
    return path


def first_shard(root: Path) -> Path:
    return sorted((root / "images" / "train").iterdir())[0]


# --- nothing is read from outside the dataset ------------------------------------------------------------------------
@pytest.mark.render
@pytest.mark.parametrize("fmt", ["coco", "bop"])
def test_export_refuses_images_that_a_symbolic_link_leads_outside(ds, outside, tmp_path, fmt) -> None:
    shard = first_shard(ds)
    shutil.move(shard, outside / "images")
    shard.symlink_to(outside / "images", target_is_directory=True)
    line = refused(datagen("export", str(ds), "--format", fmt, "--out", str(tmp_path / "x")))
    assert "leads outside the dataset through a symbolic link" in line
    assert not (tmp_path / "x").exists() and not list(tmp_path.glob(".x*"))


@pytest.mark.render
def test_export_refuses_an_absolute_image_link_to_outside(ds, outside, tmp_path) -> None:
    image = sorted(first_shard(ds).iterdir())[0]
    shutil.move(image, outside / image.name)
    image.symlink_to(outside / image.name)
    refused(datagen("export", str(ds), "--format", "coco", "--out", str(tmp_path / "x")), "leads outside the dataset")
    assert not (tmp_path / "x").exists()


@pytest.mark.render
def test_the_audit_fails_a_dataset_that_holds_a_link_out_of_it(ds, outside) -> None:
    (ds / "labels" / "train" / "elsewhere").symlink_to(outside, target_is_directory=True)
    run = datagen("audit", str(ds))
    assert run.returncode == 1, run.stderr
    files = next(c for c in json.loads((ds / "audit" / "report.json").read_text())["checks"] if c["name"] == "files")
    assert any("labels/train/elsewhere: a symbolic link that leads outside" in o for o in files["offenders"])


@pytest.mark.render
def test_the_audit_copies_nothing_of_a_file_outside_the_dataset_into_its_report(ds, outside) -> None:
    (outside / "secret").write_text("root:x:0:0:root:/root:/bin/bash\n")
    (ds / "labels" / "train" / "evil").symlink_to(outside, target_is_directory=True)
    set_column(ds, "label_path", lambda values: values.__setitem__(0, "labels/train/evil/secret"))
    assert datagen("audit", str(ds)).returncode == 1
    for name in ("report.json", "report.html"):
        text = (ds / "audit" / name).read_text()
        assert "root:x" not in text and "labels/train/evil/secret: leads outside the dataset" in text


@pytest.mark.render
@pytest.mark.parametrize("name", ["dataset.json", "features.parquet", "manifests"])
def test_metadata_a_link_leads_outside_is_not_read(ds, outside, name) -> None:
    target = outside / name
    shutil.move(ds / name, target)
    (ds / name).symlink_to(target, target_is_directory=target.is_dir())
    for args in (["audit"], ["evaluate", "--noise-px", "0"], ["preview"]):
        refused(datagen(args[0], str(ds), *args[1:]), f"{name}: leads outside the dataset")


# --- nothing is written outside the dataset or --out -----------------------------------------------------------------
@pytest.mark.render
@pytest.mark.parametrize(("command", "folder"), [("audit", "audit"), ("evaluate", "evaluation"), ("preview", "preview"),
                                                 ("audit", "audit/plots"), ("evaluate", "evaluation/plots")])
def test_a_report_folder_that_is_a_link_is_refused_and_nothing_is_written_through_it(ds, outside, command,
                                                                                         folder) -> None:
    link = ds / folder
    link.parent.mkdir(parents=True, exist_ok=True)
    link.symlink_to(outside, target_is_directory=True)
    before = snapshot(outside)
    extra = ["--noise-px", "0"] if command == "evaluate" else []
    refused(datagen(command, str(ds), *extra), "a symbolic link")
    assert snapshot(outside) == before


@pytest.mark.render
def test_an_empty_path_is_refused_and_the_working_folder_is_untouched(ds, outside) -> None:
    (outside / "notes.txt").write_text("0 0.5 0.5 0.1 0.1 0.9\n")
    before = snapshot(outside)
    refused(datagen("audit", str(ds), "--out", "", cwd=outside), "--out", "an empty path")
    refused(datagen("evaluate", str(ds), "--predictions", "", cwd=outside), "--predictions", "an empty path")
    refused(datagen("export", "", "--format", "coco", "--out", "x", cwd=outside), "an empty path")
    assert snapshot(outside) == before


@pytest.mark.render
def test_export_into_a_read_only_empty_folder_is_refused(ds, tmp_path) -> None:
    out = tmp_path / "readonly"
    out.mkdir(mode=0o555)
    refused(datagen("export", str(ds), "--format", "coco", "--out", str(out)), "read-only")
    assert out.stat().st_mode & 0o777 == 0o555 and not any(out.iterdir())


@pytest.mark.render
def test_a_build_refuses_to_resume_into_a_dataset_with_a_link_out_of_it(ds, outside, tmp_path) -> None:
    shard = first_shard(ds)
    shutil.rmtree(shard)
    shard.symlink_to(outside, target_is_directory=True)
    (ds / "manifests" / "train-00000.parquet").unlink()
    before = snapshot(outside)
    refused(datagen("build", "--config", str(write(tmp_path, "t.yaml", TINY)), "--out", str(ds)),
            "a symbolic link that leads outside the dataset")
    assert snapshot(outside) == before


# --- no silent partial result ----------------------------------------------------------------------------------------
@pytest.mark.render
def test_a_dataset_missing_a_manifest_is_refused_unless_partial(ds, tmp_path) -> None:
    (ds / "manifests" / "train-00001.parquet").unlink()
    for args in (["evaluate", "--noise-px", "0"], ["export", "--format", "coco", "--out", str(tmp_path / "x")],
                 ["preview"]):
        refused(datagen(args[0], str(ds), *args[1:]), "7 frames planned, 4 in the manifests", "--partial")
    run = datagen("export", str(ds), "--format", "coco", "--out", str(tmp_path / "x"), "--partial")
    assert run.returncode == 0 and "partial:" in run.stderr and "export of 5 frames" in run.stdout
    run = datagen("evaluate", str(ds), "--noise-px", "0", "--split", "val")  # the val split is whole
    assert run.returncode == 0 and "partial" not in run.stderr, run.stderr


@pytest.mark.render
def test_intrinsics_that_differ_from_the_manifests_are_refused(ds) -> None:
    doc = json.loads((ds / "dataset.json").read_text())
    doc["intrinsics"]["fx"] = 1e308
    (ds / "dataset.json").write_text(json.dumps(doc))
    for args in (["evaluate", "--noise-px", "0"], ["preview"]):
        refused(datagen(args[0], str(ds), *args[1:]), "intrinsics.fx", "a focal length")
    doc["intrinsics"]["fx"] *= 1e-305  # a focal length a camera can have, not the one the frames were made with
    (ds / "dataset.json").write_text(json.dumps(doc))
    refused(datagen("evaluate", str(ds), "--noise-px", "0"), "intrinsics differ from those of manifests/")


# --- predictions -----------------------------------------------------------------------------------------------------
@pytest.mark.render
@pytest.mark.parametrize(("line", "expected"), [
    ("0 1e200 0.5 0.1 0.1 0.9", "outside the image"),
    ("0 0.5 0.5 -0.1 0.1 0.9", "box size"),
    ("0 0.5 0.5 0.1 0.1 1e308", "confidence"),
])
def test_predictions_outside_the_image_or_their_ranges_are_refused(ds, tmp_path, line, expected) -> None:
    folder = tmp_path / "pred"
    folder.mkdir()
    (folder / "00000001.txt").write_text(line + "\n")
    refused(datagen("evaluate", str(ds), "--predictions", str(folder)), "00000001.txt:1", expected)


@pytest.mark.render
def test_prediction_files_of_no_frame_are_reported_and_two_of_one_frame_refused(ds, tmp_path) -> None:
    folder = tmp_path / "pred"
    (folder / "a").mkdir(parents=True)
    (folder / "a" / "00000001.txt").write_text("0 0.5 0.5 0.1 0.1 0.9\n")
    (folder / "a" / "holiday.txt").write_text("0 0.5 0.5 0.1 0.1 0.9\n")
    run = datagen("evaluate", str(ds), "--predictions", str(folder))
    assert run.returncode == 0, run.stderr
    assert "1 prediction files name no frame" in run.stderr and "holiday.txt" in run.stderr
    (folder / "b").mkdir()
    (folder / "b" / "00000001.txt").write_text("0 0.5 0.5 0.1 0.1 0.9\n")
    refused(datagen("evaluate", str(ds), "--predictions", str(folder)), "frame 00000001 has a second prediction file")


def test_pnp_on_points_far_outside_any_image_is_a_failed_solve() -> None:
    from datagen.analysis.evaluate import PnPSettings, solve_pose
    from datagen.core.camera import Intrinsics

    k = Intrinsics.from_hfov_deg(2048, 1080, 55.0)
    points = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], dtype=np.float64)
    assert solve_pose(points, np.array([[1e200, 5.0], [3.0, 4.0], [5.0, 6.0]]), k, PnPSettings()) is None


# --- assets the dataset names ----------------------------------------------------------------------------------------
@pytest.mark.render
@pytest.mark.parametrize(("change", "expected"), [
    (lambda doc: doc.__setitem__("assets", ["receiver"]), "assets.receiver: expected a mapping"),
    (lambda doc: doc["assets"]["receiver"].__setitem__("mesh", 7), "assets.receiver: expected a mapping"),
    (lambda doc: doc["assets"]["receiver"].__setitem__("mesh_sha256", "0" * 64), "mesh_sha256 differs"),
])
def test_the_bop_export_reads_only_the_mesh_the_dataset_was_built_with(ds, tmp_path, change, expected) -> None:
    doc = json.loads((ds / "dataset.json").read_text())
    change(doc)
    (ds / "dataset.json").write_text(json.dumps(doc))
    refused(datagen("export", str(ds), "--format", "bop", "--out", str(tmp_path / "x")), expected)
    assert not (tmp_path / "x").exists()


# --- bounds that come from what a frame can be made with -------------------------------------------------------------
@pytest.mark.parametrize("hfov", ["179.9999", "1.0e-10", "5.0e-324", "4.0e-322", "0.0001"])
def test_fields_of_view_no_camera_can_be_made_with_are_refused_before_work(tmp_path, hfov) -> None:
    config = write(tmp_path, "t.yaml", TINY.replace("hfov_deg: 55.0", f"hfov_deg: {hfov}"))
    for args in (["validate", str(config)], ["build", "--config", str(config), "--out", str(tmp_path / "ds")]):
        refused(datagen(*args), "camera", "a pinhole of this width can be made with")
    assert not (tmp_path / "ds").exists()


@given(width=st.integers(1, 16384), t=st.floats(0.0, 1.0))
def test_every_field_of_view_within_the_bounds_makes_a_finite_camera(width, t) -> None:
    from datagen.core.camera import MIN_FOCAL_PX, MIN_PIXEL_ANGLE_RAD, Intrinsics, hfov_bounds_deg

    lo, hi = hfov_bounds_deg(width)
    k = Intrinsics.from_hfov_deg(width, 1, lo + t * (hi - lo))
    assert MIN_FOCAL_PX * (1 - 1e-9) <= k.fx <= (1 + 1e-9) / MIN_PIXEL_ANGLE_RAD


def test_a_lens_whose_inverse_does_not_converge_is_refused(tmp_path) -> None:
    config = write(tmp_path, "t.yaml", TINY.replace("hfov_deg: 55.0", "hfov_deg: 120.0")
                   + "randomization: {sensor: {distortion: true, k1: [-0.5, 0.5], k2: [-0.5, 0.5]}}\n")
    refused(datagen("validate", str(config)), "randomization.sensor.k1", "inverse does not converge")


def test_motion_blur_of_any_length_ends_in_bounded_time() -> None:
    from datagen.render.sensor import motion_blur

    rgb = np.random.default_rng(0).random((68, 128, 3), dtype=np.float32)
    for value in (1e13, np.inf, np.nan):
        displacement = np.full((68, 128, 2), value, np.float32)
        out = motion_blur(rgb, displacement)  # a reflected border once walked 1e13 px a width at a time
        assert out.shape == rgb.shape and np.isfinite(out).all()


def test_motion_longer_than_the_image_blurs_as_motion_across_its_diagonal() -> None:
    from datagen.render.sensor import motion_blur

    rgb = np.random.default_rng(0).random((68, 128, 3), dtype=np.float32)
    direction = np.array([0.6, 0.8], np.float32)
    diagonal = np.float32(np.hypot(128, 68))
    along = np.broadcast_to(direction * diagonal, (68, 128, 2))
    assert np.allclose(motion_blur(rgb, along * np.float32(7.0)), motion_blur(rgb, along), atol=1e-5)


# --- frames that show nothing ----------------------------------------------------------------------------------------
def test_blank_boxes_tell_saturated_black_flat_and_showing_apart() -> None:
    from datagen.core.box_content import BLANK_REASONS, blank_boxes

    image = np.zeros((20, 40, 3), np.uint8)
    image[:, :10] = 255
    image[:, 20:30] = 128
    image[:, 30:] = np.random.default_rng(0).integers(0, 255, (20, 10, 3))
    boxes = np.array([[1, 1, 9, 9], [11, 1, 19, 9], [21, 1, 29, 9], [31, 1, 39, 9], [41, 1, 45, 5]], np.float64)
    assert [BLANK_REASONS[c] for c in blank_boxes(image, boxes)] == ["saturated", "black", "flat", None, None]


@pytest.mark.render
def test_the_audit_fails_frames_that_show_nothing_where_their_labels_are(ds) -> None:
    import cv2

    for path in (ds / "images").rglob("*.png"):
        cv2.imwrite(str(path), np.full((68, 128, 3), 255, np.uint8))
    assert datagen("audit", str(ds)).returncode == 1
    checks = {c["name"]: c for c in json.loads((ds / "audit" / "report.json").read_text())["checks"]}
    for name in ("image_content", "label_content"):
        assert not checks[name]["passed"] and checks[name]["failures"] == checks[name]["checked"] > 0
    assert "the label box is saturated in the image" in checks["label_content"]["offenders"][0]
    assert "label boxes shows anything (saturated)" in checks["image_content"]["offenders"][0]


@pytest.mark.render
def test_one_frame_that_shows_nothing_fails_the_audit_however_many_frames_show_something(ds) -> None:
    import cv2

    from datagen.dataset.reader import load_dataset

    view = load_dataset(ds)
    b = int(np.argmax(view.labeled.sum(axis=1)))
    cv2.imwrite(str(ds / view.image_path[b]), np.zeros((68, 128, 3), np.uint8))
    assert datagen("audit", str(ds)).returncode == 1
    checks = {c["name"]: c for c in json.loads((ds / "audit" / "report.json").read_text())["checks"]}
    assert not checks["image_content"]["passed"] and checks["image_content"]["failures"] == 1
    assert f"frame {view.frame_id[b]}: none of its" in checks["image_content"]["offenders"][0]


@pytest.mark.render
def test_a_build_whose_draws_make_white_frames_warns(tmp_path) -> None:
    config = write(tmp_path, "t.yaml", TINY.replace("frames: 8, shard_size: 3", "frames: 2, shard_size: 2")
                   + "randomization: {exposure_ev: [20.0, 20.0]}\n")
    run = datagen("build", "--config", str(config), "--out", str(tmp_path / "ds"))
    assert run.returncode == 0, run.stderr
    assert "warning:" in run.stdout and "show nothing in the image (saturated, black or flat)" in run.stdout


# --- smaller ones ----------------------------------------------------------------------------------------------------
@pytest.mark.render
def test_a_preview_of_one_frame_named_three_times_draws_it_once(ds) -> None:
    run = datagen("preview", str(ds), "--frames", "1,1,1")
    assert run.returncode == 0 and run.stdout.count("wrote") == 1, run.stdout


def test_messages_say_the_value_given(tmp_path) -> None:
    config = write(tmp_path, "t.yaml", TINY + "randomization: {sensor: {vignetting: [0.0, 1.0000001]}}\n")
    assert "got [0.0, 1.0000001]" in refused(datagen("validate", str(config)))
    config = write(tmp_path, "t.yaml", TINY.replace("hfov_deg: 55.0", "hfov_deg: 5.5e1"))
    line = refused(datagen("validate", str(config)))
    advice = line.split("as ")[-1].split(",")[0]
    import yaml

    assert isinstance(yaml.safe_load(f"a: {advice}")["a"], float), line
    refused(datagen("evaluate", str(tmp_path), "--conf", "nan"), "--conf", "expected a number from 0 to 1")


@pytest.mark.render
def test_an_export_folder_under_a_file_is_named_without_a_temporary(ds, tmp_path) -> None:
    (tmp_path / "afile").write_text("mine")
    line = refused(datagen("export", str(ds), "--format", "coco", "--out", str(tmp_path / "afile" / "x")))
    assert "a file is in the way" in line and "datagen" not in line.split(":")[-1] and "File exists" not in line
    assert (tmp_path / "afile").read_text() == "mine"


# --- held-out kinds: split names, temporaries, locks, FIFOs, damaged values ----------------------------------------
@pytest.mark.render
def test_a_split_that_is_a_path_is_refused_before_anything_is_written(ds, tmp_path) -> None:
    path = sorted((ds / "manifests").glob("val-*.parquet"))[0]
    table = pq.read_table(path)
    table = table.set_column(table.schema.get_field_index("split"), "split",
                             pa.array([f"../../../{tmp_path.name}-evil"] * table.num_rows))
    pq.write_table(table, path)
    for args in (["export", "--format", "bop", "--out", str(tmp_path / "x")], ["evaluate", "--noise-px", "0"],
                 ["audit"]):
        refused(datagen(args[0], str(ds), *args[1:]), "split", "val-00000.parquet")
    assert not list(tmp_path.parent.glob("*-evil")) and not (tmp_path / "x").exists()


@pytest.mark.parametrize("kind", ["link", "fifo"])
def test_a_file_in_the_temporarys_place_is_neither_written_through_nor_waited_on(tmp_path, kind) -> None:
    from datagen.atomic import write_bytes, write_parquet

    victim = tmp_path / "victim"
    victim.write_text("the user's own")
    for name in ("report.json", "results.parquet"):
        planted = tmp_path / f".{name}.{os.getpid()}.datagen-tmp"
        if kind == "link":
            planted.symlink_to(victim)
        else:
            os.mkfifo(planted)
    write_bytes(tmp_path / "report.json", b"{}")
    write_parquet(tmp_path / "results.parquet", pa.table({"a": [1]}))
    assert victim.read_text() == "the user's own"
    assert (tmp_path / "report.json").read_bytes() == b"{}" and not (tmp_path / "report.json").is_symlink()
    assert pq.read_table(tmp_path / "results.parquet").num_rows == 1


def test_a_lock_that_is_a_link_out_of_the_folder_is_refused(tmp_path) -> None:
    victim = tmp_path / "victim"
    victim.write_text("SECRET")
    (tmp_path / "ds").mkdir()
    (tmp_path / "ds" / ".datagen.lock").symlink_to(victim)
    refused(datagen("build", "--config", str(write(tmp_path, "t.yaml", TINY)), "--out", str(tmp_path / "ds"),
                    "--no-render"), "a symbolic link that leads outside the dataset")
    assert victim.read_text() == "SECRET"


@pytest.mark.render
def test_fifos_in_a_dataset_block_no_command(ds, tmp_path) -> None:
    exr = sorted((ds / "exr").rglob("*.exr"))[0]
    exr.unlink()
    os.mkfifo(exr)
    refused(datagen("export", str(ds), "--format", "bop", "--out", str(tmp_path / "x")), "not a regular file")
    (ds / "preview").mkdir()
    os.mkfifo(ds / "preview" / "preview.json")
    refused(datagen("preview", str(ds), "--frames", "0"), "preview.json", "not a record datagen can read")


@pytest.mark.render
@pytest.mark.parametrize(("change", "expected"), [
    (lambda doc: doc.__setitem__("seed", "abc"), "seed"),
    (lambda doc: doc["splits"].__setitem__("val", 3), "splits.'val'"),
    (lambda doc: doc.__setitem__("splits", None), "splits: expected a mapping"),
])
def test_damaged_dataset_values_are_one_line(ds, change, expected) -> None:
    doc = json.loads((ds / "dataset.json").read_text())
    change(doc)
    (ds / "dataset.json").write_text(json.dumps(doc))
    refused(datagen("evaluate", str(ds), "--noise-px", "0"), expected)


@pytest.mark.render
def test_two_prediction_files_of_no_frame_are_reported_not_refused(ds, tmp_path) -> None:
    folder = tmp_path / "pred"
    for sub in ("a", "b"):
        (folder / sub).mkdir(parents=True)
        (folder / sub / "99999999.txt").write_text("0 0.5 0.5 0.1 0.1 0.9\n")
    (folder / "a" / "00000001.txt").write_text("0 0.5 0.5 0.1 0.1 0.9\n")
    run = datagen("evaluate", str(ds), "--predictions", str(folder))
    assert run.returncode == 0 and "2 prediction files name no frame" in run.stderr, run.stderr
