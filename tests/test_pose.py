"""Pose labels in built datasets (labels.format: pose | both), their audit, pose predictions
in ``datagen evaluate``, and the COCO and BOP exports read back."""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest
import yaml

from datagen.analysis.audit import audit
from datagen.analysis.evaluate import evaluate
from datagen.analysis.predictions import parse_predictions
from datagen.config import load_config, override_config
from datagen.core.conventions import index_px, object_id
from datagen.core.errors import DatagenError
from datagen.core.keypoints import PoseLayout
from datagen.dataset.reader import load_dataset
from datagen.pipeline.build import build_dataset
from datagen.report.export import export_dataset, read_object_ids

from .support import ROOT, comparable, run_cli, tiny_config

#: Not a seed any shipped config uses.
HELD_OUT_SEED = 4242


def labels_only(root: Path, scene: str, frames: int, **overrides) -> Path:
    config = override_config(load_config(ROOT / "scenes" / f"{scene}.yaml"),
                             {"dataset.frames": frames, "dataset.seed": HELD_OUT_SEED, **overrides})
    build_dataset(config, root, render=False)
    return root


@pytest.fixture(scope="module")
def both(tmp_path_factory) -> Path:
    return labels_only(tmp_path_factory.mktemp("pose") / "ds", "wingcam55", 60, **{"labels.format": "both"})


def test_pose_set_beside_the_detect_set_has_its_own_data_yaml_and_passes_the_audit(both) -> None:
    pose = yaml.safe_load((both / "pose" / "data.yaml").read_text())
    assert pose["names"] == {0: "receiver", 1: "tanker"} and pose["nc"] == 2
    assert pose["kpt_shape"] == [40, 3]
    assert "flip_idx" not in pose  # the receiver's radome_seam_right has no mirror feature
    assert "no flip_idx: receiver: receiver.radome_seam_right" in (both / "pose" / "data.yaml").read_text()
    hyp = yaml.safe_load((both / "pose" / "hyp.yaml").read_text())
    assert hyp["fliplr"] == 0.0 and hyp["mosaic"] == 1.0 and hyp["scale"] > 0 and hyp["translate"] > 0
    assert yaml.safe_load((both / "data.yaml").read_text())["nc"] == 80  # the detect set is unchanged
    assert os.readlink(both / "pose" / "images") == "../images"
    result = audit(load_dataset(both))
    by_name = {c.name: c for c in result.checks}
    assert result.passed, [(c.name, c.offenders[:3]) for c in result.checks if not c.passed]
    assert {"pose_lines", "keypoint_flags", "ultralytics_pose_rules", "pose_names", "manifest_objects",
            "label_lines"} <= set(by_name)
    assert by_name["pose_lines"].checked > 0 and by_name["pose_lines"].worst < 1e-3


def test_pose_lines_are_the_true_centres_of_each_objects_features_in_class_order(both) -> None:
    view = load_dataset(both)
    layout = PoseLayout.from_features(view.features)
    k = view.intrinsics
    seen = 0
    for b, rel in enumerate(view.pose_label_path):
        for line in (both / rel).read_text().splitlines():
            v = np.array(line.split(), dtype=float)
            c = int(v[0])
            kp = v[5:].reshape(-1, 3)
            for slot, f in enumerate(layout.feature_at[c]):
                if f >= 0 and view.labeled[b, f]:
                    np.testing.assert_allclose(kp[slot, :2] * [k.width, k.height], view.center_px[b, f], atol=1.1e-4)
                    seen += 1
                else:
                    assert kp[slot].tolist() == [0, 0, 0]
    assert seen > 100


def test_tanker_instance_is_excluded_when_its_full_box_leaves_the_image(both) -> None:
    view = load_dataset(both)
    tanker = view.features.objects.index("tanker")
    box = view.object_tight_xyxy[:, tanker]
    k, m = view.intrinsics, view.edge_margin_px
    inside = (box[:, 0] >= m) & (box[:, 1] >= m) & (box[:, 2] <= k.width - m) & (box[:, 3] <= k.height - m)
    labeled = view.object_exclusion[:, tanker] == None  # noqa: E711 (element-wise on an object array)
    assert np.array_equal(labeled, inside)
    assert (~inside).any() and inside.any()


def _tampered(src: Path, dst: Path, edit) -> Path:
    shutil.copytree(src, dst, symlinks=True)
    view = load_dataset(dst)
    b = next(b for b, rel in enumerate(view.pose_label_path) if (dst / rel).read_text().strip())
    path = dst / view.pose_label_path[b]
    lines = path.read_text().splitlines()
    tokens = lines[0].split()
    edit(tokens)
    lines[0] = " ".join(tokens)
    path.write_text("\n".join(lines) + "\n")
    return dst


@pytest.mark.parametrize(("edit", "check", "what"), [
    (lambda t: t.__setitem__(next(i for i in range(5, len(t), 3) if t[i + 2] != "0"),
                             f"{float(t[next(i for i in range(5, len(t), 3) if t[i + 2] != '0')]) + 2e-6:.7f}"),
     "pose_lines", "from its true centre projection"),
    (lambda t: t.__setitem__(next(i for i in range(7, len(t), 3) if t[i] == "2"), "1"), "pose_lines", "flag 1"),
    (lambda t: t.__setitem__(3, f"{float(t[3]) * 1.01:.7f}"), "pose_lines", "box differs"),
    (lambda t: t.append("0"), "ultralytics_pose_rules", "columns"),
], ids=["keypoint moved 2e-6", "flag changed", "box widened", "extra column"])
def test_audit_fails_a_pose_line_that_differs_from_the_manifest(both, tmp_path, edit, check, what) -> None:
    result = audit(load_dataset(_tampered(both, tmp_path / "ds", edit)))
    failed = {c.name: c for c in result.checks if not c.passed}
    assert check in failed, [c.name for c in result.checks if not c.passed]
    assert any(what in o for o in failed[check].offenders), failed[check].offenders


def test_drogue_only_pose_set_flips_ribs_by_geometry_and_turns_fliplr_on(tmp_path) -> None:
    root = labels_only(tmp_path / "ds", "podcam15", 20, **{"labels.format": "pose", "features.objects": ["drogue"]})
    doc = yaml.safe_load((root / "data.yaml").read_text())
    names = PoseLayout.from_features(load_dataset(root).features).names(load_dataset(root).features)[0]
    flip = doc["flip_idx"]
    assert names[flip[names.index("drogue.rib_03_tip")]] == "drogue.rib_05_tip"
    assert names[flip[names.index("drogue.coupling_right")]] == "drogue.coupling_left"
    assert yaml.safe_load((root / "hyp.yaml").read_text())["fliplr"] == 0.5
    rows = pq.read_table(next((root / "manifests").glob("*.parquet"))).to_pylist()
    assert all(r["label_path"] is None and r["pose_label_path"].startswith("labels/") for r in rows)
    assert audit(load_dataset(root)).passed


def test_pose_labels_and_manifests_are_identical_for_one_and_two_workers(tmp_path) -> None:
    config = override_config(load_config(ROOT / "scenes" / "dashcam75.yaml"),
                             {"dataset.frames": 40, "dataset.shard_size": 10, "labels.format": "both",
                              "labels.truncated_objects": "clip"})
    one, two = tmp_path / "one", tmp_path / "two"
    build_dataset(config, one, render=False, workers=1)
    build_dataset(config, two, render=False, workers=2)
    files = {str(p.relative_to(one)): p.read_bytes() for p in sorted((one / "pose" / "labels").rglob("*.txt"))}
    assert files and files == {str(p.relative_to(two)): p.read_bytes()
                               for p in sorted((two / "pose" / "labels").rglob("*.txt"))}
    assert comparable(one) == comparable(two)


def test_clip_gives_the_receiver_an_instance_a_mounted_camera_never_sees_whole(tmp_path) -> None:
    root = labels_only(tmp_path / "ds", "dashcam75", 30,
                       **{"labels.format": "pose", "labels.truncated_objects": "clip"})
    view = load_dataset(root)
    receiver = view.features.objects.index("receiver")
    assert (view.object_exclusion[:, receiver] == None).all()  # noqa: E711 (element-wise)
    assert np.isnan(view.object_tight_xyxy[:, receiver]).all()  # its full box does not exist: behind the camera
    box = view.object_label_xyxy[:, receiver]
    assert (box[:, :2] >= 0).all() and (box[:, 2] <= view.intrinsics.width).all()
    assert audit(view).passed


def test_evaluate_scores_pose_predictions_at_the_true_centres_like_the_truth(tmp_path) -> None:
    root = labels_only(tmp_path / "ds", "dashcam75", 24,
                       **{"labels.format": "pose", "labels.truncated_objects": "clip"})
    view = load_dataset(root)
    predictions = tmp_path / "predictions"
    predictions.mkdir()
    for rel in view.pose_label_path:  # yolo pose predict save_conf: x y conf per keypoint, then the box conf
        lines = []
        for line in (root / rel).read_text().splitlines():
            v = line.split()
            kp = np.array(v[5:], dtype=float).reshape(-1, 3)
            kp[:, 2] = np.where(kp[:, 2] > 0, 0.9, 0.01)
            lines.append(" ".join(v[:5] + [f"{x:.7f}" for x in kp.ravel()] + ["0.95"]))
        (predictions / Path(rel).name).write_text("\n".join(lines) + "\n")
    k = view.intrinsics
    found = parse_predictions(predictions, k.width, k.height, len(view.features), min_conf=0.25,
                              pose=PoseLayout.from_features(view.features), max_bytes=view.limits.prediction_bytes)
    scored, truth = evaluate(view, predictions=found), evaluate(view)
    # The same features are found in every frame, and the same frames succeed.
    for key in ("matches_receiver", "matches_target", "success"):
        np.testing.assert_array_equal(getattr(scored, key), getattr(truth, key), err_msg=key)
    # The same vectors where PnP is well posed: with exactly three matches an object's pose
    # is ambiguous (P3P has up to four solutions), and the 7-decimal keypoints can tip it.
    posed = scored.success & (truth.matches_receiver >= 4) & (truth.matches_target >= 4)
    assert posed.sum() > 0
    np.testing.assert_allclose(scored.ptd_m[posed], truth.ptd_m[posed], atol=1e-3)


def test_overwrite_removes_the_pose_set_and_unlinks_its_link_without_following_it(tmp_path) -> None:
    root = labels_only(tmp_path / "ds", "wingcam55", 10, **{"labels.format": "both"})
    (root / "images").mkdir()
    mine = root / "images" / "mine.txt"
    mine.write_text("a user's file")
    config = override_config(load_config(ROOT / "scenes" / "wingcam55.yaml"), {"dataset.frames": 5})
    build_dataset(config, root, render=False, overwrite=True)
    assert mine.read_text() == "a user's file"
    assert not (root / "pose").exists()


def test_a_users_folder_where_the_pose_link_goes_is_refused_and_kept(tmp_path) -> None:
    config = override_config(load_config(ROOT / "scenes" / "wingcam55.yaml"), {"dataset.frames": 5})
    root = tmp_path / "ds"
    build_dataset(config, root, render=False)
    (root / "pose" / "images").mkdir(parents=True)
    (root / "pose" / "images" / "mine.png").write_bytes(b"user")
    with pytest.raises(DatagenError, match=r"pose/images: exists and is not datagen's link to \.\./images"):
        build_dataset(override_config(config, {"labels.format": "both"}), root, render=False, overwrite=True)
    assert (root / "pose" / "images" / "mine.png").read_bytes() == b"user"


# --- exports -------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def rendered(tmp_path_factory) -> Path:
    """A tiny rendered pose dataset with EXR object ids (the exports need images and masks)."""
    tmp = tmp_path_factory.mktemp("export")
    config = tiny_config(tmp, exr=True, **{"labels.format": "both", "labels.truncated_objects": "clip",
                                           "dataset.frames": 6})
    build_dataset(config, tmp / "ds", threads=1)
    return tmp / "ds"


def test_coco_export_reads_back_with_pycocotools_keypoints_on_the_true_centres(rendered, tmp_path) -> None:
    coco_api = pytest.importorskip("pycocotools.coco", reason="needs pycocotools (the test extra)")
    out = export_dataset(load_dataset(rendered), tmp_path / "coco", "coco")
    view = load_dataset(rendered)
    layout = PoseLayout.from_features(view.features)
    checked = 0
    for split in ("train", "val"):
        path = out / "annotations" / f"{split}.json"
        if not path.exists():
            continue
        coco = coco_api.COCO(str(path))
        for cat in coco.loadCats(coco.getCatIds()):
            assert cat["keypoints"] == layout.names(view.features)[cat["id"] - 1]
        for image in coco.loadImgs(coco.getImgIds()):
            assert (out / image["file_name"]).is_file()
            b = int(np.flatnonzero(view.frame_id == image["id"])[0])
            for ann in coco.loadAnns(coco.getAnnIds(imgIds=image["id"])):
                members = layout.feature_at[ann["category_id"] - 1]
                members = members[members >= 0]
                kp = np.array(ann["keypoints"], dtype=float).reshape(-1, 3)
                flags = view.keypoint_flag[b, members]
                assert kp[:, 2].tolist() == flags.tolist() and ann["num_keypoints"] == int((flags > 0).sum())
                on = flags > 0
                np.testing.assert_allclose(kp[on, :2], index_px(view.center_px[b, members[on]]), atol=1e-9)
                checked += int(on.sum())
    assert checked > 0


def test_bop_export_follows_the_format_spec_poses_reproject_and_masks_are_the_object_ids(rendered, tmp_path) -> None:
    import trimesh

    view = load_dataset(rendered)
    out = export_dataset(view, tmp_path / "bop", "bop")
    info = json.loads((out / "models" / "models_info.json").read_text())
    for name in view.features.objects:
        obj = object_id(name)
        model = trimesh.load(out / "models" / f"obj_{obj:06d}.ply", process=False)
        assert np.allclose(model.vertices.min(axis=0), [info[str(obj)][k] for k in ("min_x", "min_y", "min_z")],
                           atol=1e-3)
        hull_mm = view.hulls[name] * 1000.0
        assert info[str(obj)]["diameter"] == pytest.approx(
            max(np.linalg.norm(hull_mm - p, axis=1).max() for p in hull_mm))
    f = view.features
    projected = 0
    for scene in sorted(p for split in out.iterdir() if split.name != "models" and split.is_dir()
                        for p in split.iterdir()):
        cams = json.loads((scene / "scene_camera.json").read_text())
        gts = json.loads((scene / "scene_gt.json").read_text())
        infos = json.loads((scene / "scene_gt_info.json").read_text())
        for im, gt_list in gts.items():
            b = int(np.flatnonzero(view.frame_id == int(im))[0])
            k = np.array(cams[im]["cam_K"]).reshape(3, 3)
            ids = read_object_ids(rendered / view.exr_path[b], view.limits)
            assert (scene / "rgb" / f"{int(im):06d}.png").is_file()
            for index, gt in enumerate(gt_list):
                name = next(o for o in f.objects if object_id(o) == gt["obj_id"])
                mine = f.object_index == f.objects.index(name)
                r, t = np.array(gt["cam_R_m2c"]).reshape(3, 3), np.array(gt["cam_t_m2c"])
                p = (f.center_model[mine] * 1000.0) @ r.T + t  # bop_toolkit misc.project_pts, in mm
                uv = (p @ k.T)[:, :2] / p[:, 2:]
                want = index_px(view.center_px[b, mine])
                ok = np.isfinite(want).all(axis=1) & (p[:, 2] > 0)
                np.testing.assert_allclose(uv[ok], want[ok], atol=1e-6)
                projected += int(ok.sum())
                visib = read_png(scene / "mask_visib" / f"{int(im):06d}_{index:06d}.png") > 0
                full = read_png(scene / "mask" / f"{int(im):06d}_{index:06d}.png") > 0
                assert np.array_equal(visib, ids == gt["obj_id"])
                assert infos[im][index]["px_count_visib"] == int(visib.sum())
                assert infos[im][index]["px_count_all"] == int(full.sum())
                assert int((visib & ~full).sum()) <= max(2, 0.02 * visib.sum())  # edge pixels of two ray sets
    assert projected > 0


def read_png(path: Path) -> np.ndarray:
    import cv2

    return cv2.imread(str(path), cv2.IMREAD_UNCHANGED)


def test_export_refuses_what_a_dataset_lacks_in_one_line_and_writes_nothing(both, rendered, tmp_path) -> None:
    for dataset, fmt, message in ((both, "coco", "needs the images"),):
        result = run_cli("export", str(dataset), "--format", fmt, "--out", str(tmp_path / "x"))
        assert result.returncode != 0 and message in result.stderr and len(result.stderr.strip().splitlines()) == 1
    taken = tmp_path / "taken"
    taken.mkdir()
    (taken / "mine.txt").write_text("keep")
    result = run_cli("export", str(rendered), "--format", "coco", "--out", str(taken))
    assert result.returncode != 0 and "exists and is not an empty folder" in result.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["taken"] and (taken / "mine.txt").read_text() == "keep"


def test_bop_export_of_a_dataset_without_exr_is_refused(tmp_path) -> None:
    config = tiny_config(tmp_path, **{"dataset.frames": 2})
    build_dataset(config, tmp_path / "ds", threads=1)
    with pytest.raises(DatagenError, match="needs the EXR object ids for its masks: build the dataset with --exr"):
        export_dataset(load_dataset(tmp_path / "ds"), tmp_path / "bop", "bop")
    assert not (tmp_path / "bop").exists()


def test_audit_names_a_frame_whose_manifest_names_no_label_file_instead_of_failing(both, tmp_path) -> None:
    """label_path is nullable since pose-only datasets have none: a detect dataset's manifest with
    a null one (edited by hand) is an audit failure naming the frame, not a traceback."""
    import pyarrow as pa

    dst = tmp_path / "ds"
    shutil.copytree(both, dst, symlinks=True)
    manifest = min((dst / "manifests").glob("*.parquet"))
    table = pq.read_table(manifest)
    paths = table.column("label_path").to_pylist()
    paths[0] = None
    index = table.schema.get_field_index("label_path")
    pq.write_table(table.set_column(index, table.schema.field("label_path"), pa.array(paths, pa.string())), manifest)
    result = run_cli("audit", str(dst), "--overlays", "0")
    assert result.returncode == 1, result.stderr
    assert "no label file named" in result.stdout and "Traceback" not in result.stderr
