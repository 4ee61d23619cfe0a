"""datagen evaluate: dual-object PnP PtD vectors, the paper's metrics, prediction files,
and the extrinsic independence of the method."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from datagen.analysis.evaluate import (
    THREE_POINT_AGREEMENT,
    PnPSettings,
    evaluate,
    ptd_from_points,
    solve_pose,
    summarize,
)
from datagen.analysis.predictions import parse_predictions
from datagen.assets.table import feature_table
from datagen.config import load_config, override_config
from datagen.core.camera import Intrinsics, project_points
from datagen.core.errors import DatagenError
from datagen.core.transforms import apply_transform, invert_rigid, make_transform, rotation_from_ypr
from datagen.dataset.reader import load_dataset
from datagen.pipeline.build import build_dataset
from datagen.scene.approach import frame_state

ROOT = Path(__file__).resolve().parents[1]


def labels_only(tmp: Path, scene: str, frames: int):
    config = override_config(load_config(ROOT / "scenes" / f"{scene}.yaml"),
                             {"dataset.frames": frames, "dataset.shard_size": 100})
    build_dataset(config, tmp / scene, render=False)
    return load_dataset(tmp / scene)


@pytest.fixture(scope="module")
def wingcam(tmp_path_factory):
    return labels_only(tmp_path_factory.mktemp("eval"), "wingcam55", 160)


@pytest.fixture(scope="module")
def podcam(tmp_path_factory):
    return labels_only(tmp_path_factory.mktemp("eval"), "podcam15", 64)


def test_noise_free_points_give_the_true_vector_within_a_millimetre(wingcam) -> None:
    result = evaluate(wingcam, noise_px=0.0)
    ok = result.success
    assert ok.mean() > 0.9
    assert result.error_m[ok].max() < 1e-3
    summary = summarize(result)
    for b in summary.by_distance:
        assert b.stats.max_m is None or b.stats.max_m < 1e-3
    # Frames without a vector have a reason, and it is the right one.
    few = (result.matches_receiver < 3) | (result.matches_target < 3)
    assert np.array_equal(result.reason == 1, few)


def test_the_drogue_vector_is_the_manifests_true_ptd(podcam) -> None:
    result = evaluate(podcam, noise_px=0.0)
    assert result.target == "drogue"
    ok = result.success
    assert ok.mean() >= 0.35  # far out, the probe shows three features: poses they fit apart are refused
    np.testing.assert_allclose(result.truth_m, podcam.ptd_receiver_m, atol=1e-9)
    assert result.error_to_drogue_m[ok].max() < 1e-3


def test_a_pose_that_epnp_sqpnp_and_ransac_all_miss_is_still_found() -> None:
    """Five noise-free receiver points of a wingcam55 frame through a distorting lens (a
    labels-only build's frame 107): EPnP, SQPnP and RANSAC each return a pose 150 px RMS off."""
    points_model = np.array([[0.0, 0.0, 0.0], [-0.33949, 0.011759, 0.051578], [-1.875001, 0.065006, -0.029961],
                             [-0.9, 0.6, -0.6], [-7.02, 1.7, -0.405]])
    uv_px = np.array([[388.43838564331907, 381.162498430361], [359.2969919153867, 360.72207792840857],
                      [190.14706634613242, 333.0138871794457], [162.84189555236105, 504.9445451222356],
                      [1223.4060202455196, 549.2083341593636]])
    k = Intrinsics(2048, 1080, 1967.085698018474, 1967.085698018474, 1024.0, 540.0)
    distortion = np.array([-0.06771153366742941, -0.008843625624141538, -0.00086459420919736,
                           -0.0002554725282707035, 0.0])
    pose = solve_pose(points_model, uv_px, k, PnPSettings(), distortion=distortion)
    assert pose is not None
    np.testing.assert_allclose(pose[1], [-2.82798079123435, -0.7059709522174049, 8.688478933667705], atol=1e-4)


def test_three_noise_free_matches_give_the_true_pose_or_none_and_sometimes_the_pose() -> None:
    """Three points fit up to four poses: over 600 random three-point sets (0.5 m and 4 m
    objects, 3-80 m away, two focal lengths) every pose returned is the true one, and some
    are returned (where only one pose in front of the camera fits)."""
    rng = np.random.default_rng(2024)
    returned = 0
    for n in range(600):
        size = 0.5 if n % 2 else 4.0
        points_model = rng.uniform(-size / 2, size / 2, (3, 3))
        rotation = rotation_from_ypr(*rng.uniform(-60.0, 60.0, 3))
        distance = rng.uniform(3.0, 80.0)
        t = np.array([rng.uniform(-2, 2), rng.uniform(-2, 2), distance])
        camera = apply_transform(make_transform(rotation, t), points_model)
        if not np.all(camera[:, 2] > 1.0):
            continue
        focal = (1967.0, 7778.0)[n % 4 // 2]
        k = Intrinsics(2048, 1080, focal, focal, 1024.0, 540.0)
        pose = solve_pose(points_model, project_points(camera, k), k, PnPSettings())
        if pose is not None:
            returned += 1
            assert np.linalg.norm(pose[1] - t) <= 2 * THREE_POINT_AGREEMENT * np.linalg.norm(t), n
    assert returned >= 1


def test_three_matches_that_fit_two_poses_apart_give_none() -> None:
    """Three probe points of a podcam15 frame (15 degrees hFOV, about 32 m away): two exact
    poses lie metres apart, and SQPnP alone picked the wrong one."""
    import cv2

    points_model = np.array([[0.0, 0.0, 0.0], [-0.9, 0.6, -0.6], [-2.7, 0.12, -0.55]])
    uv_px = np.array([[1150.9504222276055, 31.859177545921], [1316.877833208613, 100.80622565925114],
                      [1211.9298498942246, 31.45695489917489]])
    k = Intrinsics(2048, 1080, 7778.052211430555, 7778.052211430555, 1024.0, 540.0)
    solved, _, tvecs = cv2.solveP3P(points_model, uv_px, k.K, None, flags=cv2.SOLVEPNP_AP3P)
    assert solved >= 2 and max(np.linalg.norm(a - b) for a in tvecs for b in tvecs) > 1.0
    assert solve_pose(points_model, uv_px, k, PnPSettings()) is None


def test_error_grows_with_the_noise_radius(wingcam) -> None:
    means = [summarize(evaluate(wingcam, noise_px=r, run=i)).overall.mean_m
             for i, r in enumerate((0.0, 0.5, 1.0, 2.5))]
    assert means == sorted(means) and means[0] < 1e-3 < means[1] and means[3] > 2 * means[1]
    # The noise is seeded: the same run gives the same vectors.
    a, b = evaluate(wingcam, noise_px=1.0, run=2), evaluate(wingcam, noise_px=1.0, run=2)
    np.testing.assert_array_equal(a.ptd_m, b.ptd_m)


def test_predictions_are_parsed_and_matched_by_stem(wingcam, tmp_path: Path) -> None:
    k = wingcam.intrinsics
    folder = tmp_path / "pred" / "labels"
    folder.mkdir(parents=True)
    dropped = 0
    for b in range(len(wingcam)):
        lines = []
        for f in np.flatnonzero(wingcam.labeled[b]):
            u, v = wingcam.center_px[b, f]
            if f % 7 == 0:
                dropped += 1
                continue  # a missing class
            good = f"{f} {u / k.width:.9f} {v / k.height:.9f} 0.01 0.01 0.90"
            worse = f"{f} {min(u + 40, k.width) / k.width:.9f} {v / k.height:.9f} 0.01 0.01 0.60"  # lower conf
            lines += [worse, good] if f % 2 else [good, worse]
            lines.append(f"{f} 0.5 0.5 0.01 0.01 0.10")  # below the confidence threshold
        (folder / Path(wingcam.label_path[b]).name).write_text("\n".join(lines) + "\n")
    found = parse_predictions(tmp_path / "pred", k.width, k.height, len(wingcam.features),
                              max_bytes=wingcam.limits.prediction_bytes)
    assert dropped and len(found) == len(wingcam)
    b = 0
    stem = Path(wingcam.label_path[b]).stem
    kept = {f for f in np.flatnonzero(wingcam.labeled[b]) if f % 7}
    assert set(found[stem]) == kept
    for f in kept:
        assert found[stem][f][2] == 0.9
        np.testing.assert_allclose(found[stem][f][:2], wingcam.center_px[b, f], atol=1e-5)
    result = evaluate(wingcam, predictions=found)
    ok = result.success
    assert ok.mean() > 0.8 and result.error_m[ok].max() < 5e-3


def test_a_bad_prediction_line_names_its_file(tmp_path: Path) -> None:
    (tmp_path / "00000001.txt").write_text("3 0.5 0.5 0.1 0.1 0.9\n81 0.5 0.5 0.1 0.1 0.9\n")
    with pytest.raises(DatagenError, match=r"00000001\.txt:2: not a detection line 'class cx cy w h \[conf\]': "
                       r"class 81 is not an integer in \[0, 80\)"):
        parse_predictions(tmp_path, 2048, 1080, 80, max_bytes=1 << 20)


@settings(max_examples=25)
@given(frame=st.integers(0, 63), yaw=st.floats(-8, 8), pitch=st.floats(-8, 8), roll=st.floats(-20, 20),
       shift=st.tuples(*[st.floats(-0.5, 0.5)] * 3))
def test_the_ptd_vector_does_not_depend_on_the_camera_mount(frame, yaw, pitch, roll, shift) -> None:
    """Paper 3.5: the same frame seen through a differently mounted camera gives the same
    vector, because it only uses the two objects' poses relative to one another."""
    config = load_config(ROOT / "scenes" / "podcam15.yaml")
    features = feature_table(config)
    state = frame_state(config, frame)
    k = Intrinsics.from_hfov_deg(2048, 1080, 15.0)
    mount = make_transform(rotation_from_ypr(*(math.radians(a) for a in (yaw, pitch, roll))), list(shift))
    cam_from_world = invert_rigid(state.world_from_cam @ mount)
    points = {}
    for obj in ("receiver", "drogue"):
        sel = np.array([features.objects[i] == obj for i in features.object_index])
        centres = features.center_model[sel]
        in_cam = apply_transform(cam_from_world @ state.world_from(obj), centres)
        front = in_cam[:, 2] > 0.1
        points[obj] = (centres[front], project_points(in_cam[front], k))
    assume(min(len(p[0]) for p in points.values()) >= 4)  # an object behind this camera: nothing to compare
    ptd = ptd_from_points(*points["receiver"], *points["drogue"], k)
    assert ptd is not None
    np.testing.assert_allclose(ptd, state.ptd_receiver_m, atol=1e-4)


def test_evaluate_command_writes_json_parquet_and_plots(wingcam, tmp_path: Path) -> None:
    out = subprocess.run([sys.executable, "-m", "datagen", "evaluate", str(wingcam.root), "--noise-px", "0,1",
                          "--out", str(tmp_path / "ev")], capture_output=True, text=True, timeout=300, cwd=ROOT)
    assert out.returncode == 0, out.stderr
    doc = json.loads((tmp_path / "ev" / "evaluation.json").read_text())
    assert [r["noise_px"] for r in doc["runs"]] == [0.0, 1.0]
    assert doc["settings"]["iterations"] == 500 and doc["settings"]["reprojection_px"] == 4.0
    import pyarrow.parquet as pq

    table = pq.read_table(tmp_path / "ev" / "results.parquet")
    assert table.num_rows == 2 * len(wingcam)
    assert {p.name for p in (tmp_path / "ev" / "plots").iterdir()} == {"error_vs_distance.png",
                                                                       "reliability_vs_distance.png"}
    bad = subprocess.run([sys.executable, "-m", "datagen", "evaluate", str(wingcam.root), "--noise-px", "a,b"],
                         capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert bad.returncode == 2 and bad.stderr.strip().count("\n") == 0 and "--noise-px" in bad.stderr


def test_split_limits_the_attempts_and_bad_inputs_are_one_line(wingcam, tmp_path: Path) -> None:
    val = evaluate(wingcam, noise_px=0.0, split="val")
    assert len(val) == wingcam.split.count("val") > 0
    assert set(val.frame_id.tolist()) == {int(f) for f, s in zip(wingcam.frame_id, wingcam.split) if s == "val"}
    out = subprocess.run([sys.executable, "-m", "datagen", "evaluate", str(wingcam.root), "--noise-px", "0,nan"],
                         capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert out.returncode == 2 and out.stderr.strip() == (
        "--noise-px: '0,nan': radii must be finite and not negative")
    (tmp_path / "x.txt").write_bytes(b"\xff\xfe\x00")
    with pytest.raises(DatagenError, match=r"x\.txt: unreadable prediction file"):
        parse_predictions(tmp_path, 2048, 1080, 80, max_bytes=1 << 20)


def write_predictions(view, folder: Path, frames, *, conf: float) -> None:
    """save_txt files of perfect detections (the true centres) at ``conf`` for the rows ``frames``."""
    k = view.intrinsics
    folder.mkdir(parents=True, exist_ok=True)
    for b in frames:
        lines = [f"{f} {view.center_px[b, f, 0] / k.width:.9f} {view.center_px[b, f, 1] / k.height:.9f} 0.01 0.01 "
                 f"{conf}" for f in np.flatnonzero(view.labeled[b])]
        (folder / f"{Path(view.label_path[b]).stem}.txt").write_text("".join(line + "\n" for line in lines))


def test_predictions_score_the_split_they_cover_and_name_every_failure(wingcam, tmp_path: Path) -> None:
    val = [b for b in range(len(wingcam)) if wingcam.split[b] == "val"]
    confident, timid = val[: len(val) // 2], val[len(val) // 2:-2]  # the last two val frames: no file at all
    write_predictions(wingcam, tmp_path / "pred", confident, conf=0.9)
    write_predictions(wingcam, tmp_path / "pred", timid, conf=0.1)
    out = subprocess.run([sys.executable, "-m", "datagen", "evaluate", str(wingcam.root), "--predictions",
                          str(tmp_path / "pred"), "--out", str(tmp_path / "ev")], capture_output=True, text=True,
                         timeout=300, cwd=ROOT)
    assert out.returncode == 0, out.stderr
    lines = out.stdout.splitlines()
    assert lines[0] == "scoring the val split: the frames the predictions cover (--split to choose)"
    failed = next(line for line in lines if line.startswith("  failed: "))
    n_timid = sum(1 for b in timid if wingcam.labeled[b].sum())  # a frame with no labeled feature has no line
    assert f"{n_timid} with all detections below --conf 0.25" in failed
    assert "2 with no prediction file (nothing detected, or not predicted)" in failed
    doc = json.loads((tmp_path / "ev" / "evaluation.json").read_text())
    run = doc["runs"][0]
    assert run["split"] == "val" and run["overall"]["attempts"] == len(val)
    assert run["reasons"]["below_conf"] == n_timid and run["reasons"]["no_detections"] >= 2
    everything = subprocess.run([sys.executable, "-m", "datagen", "evaluate", str(wingcam.root), "--predictions",
                                 str(tmp_path / "pred"), "--split", "all", "--out", str(tmp_path / "ev2")],
                                capture_output=True, text=True, timeout=300, cwd=ROOT)
    assert everything.returncode == 0 and "scoring" not in everything.stdout
    assert json.loads((tmp_path / "ev2" / "evaluation.json").read_text())["runs"][0]["overall"]["attempts"] == len(
        wingcam)


def test_predictions_that_match_no_frame_are_one_line(wingcam, tmp_path: Path) -> None:
    (tmp_path / "pred").mkdir()
    (tmp_path / "pred" / "holiday.txt").write_text("0 0.5 0.5 0.1 0.1 0.9\n")
    out = subprocess.run([sys.executable, "-m", "datagen", "evaluate", str(wingcam.root), "--predictions",
                          str(tmp_path / "pred")], capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert out.returncode == 2 and out.stderr.count("\n") == 1
    assert "no prediction file is named after an image of" in out.stderr


def test_failure_texts_state_the_settings_they_were_judged_by() -> None:
    from datagen.analysis.evaluate import REASONS, failure_text

    settings = PnPSettings(max_range_m=80.0, outlier_sigma=4.5, min_matches=5)
    assert failure_text("beyond_range", settings, 0.25) == "with a vector longer than 80 m"
    assert failure_text("outlier", settings, 0.25) == "beyond 4.5 sigma of the approach's rolling mean"
    assert failure_text("too_few_matches", settings, 0.25) == "with fewer than 5 matched features of an object"
    assert failure_text("below_conf", settings, 0.4) == "with all detections below --conf 0.4"
    assert all(failure_text(r, settings, 0.25) != r for r in REASONS if r != "ok")


def test_the_evaluate_lines_say_why_a_figure_is_missing_instead_of_a_dash() -> None:
    from datagen.analysis.evaluate import ErrorStats
    from datagen.cli.commands import _at_contact, _mean_error

    none = ErrorStats.of(np.zeros(0), np.zeros(0, bool))
    failed = ErrorStats.of(np.zeros(3), np.zeros(3, bool))
    solved = ErrorStats.of(np.array([0.018, 0.024, 9.0]), np.array([True, True, False]))
    assert _at_contact(none, 0.5) == "at contact: no figure (no frame within 0.5 m of contact)"
    assert _at_contact(failed, 0.5) == "at contact: no figure (none of the 3 frames within 0.5 m solved)"
    assert _at_contact(solved, 0.5) == "at contact 2.10 cm (+2 sigma 2.70 cm, 2 frames)"
    assert _mean_error(none) == "mean error: no figure (no frame solved)"
    assert _mean_error(solved) == "mean error 2.10 cm"


def test_an_evaluation_is_planned_without_the_command_line(wingcam, tmp_path: Path) -> None:
    """:func:`plan_evaluation` is what the command runs: truth runs per radius over every frame,
    or one predictions run on the split its files cover, with the note the command prints;
    its refusals are one line naming the option."""
    from datagen.analysis.evaluate import plan_evaluation
    from datagen.core.errors import DatagenError

    truth = plan_evaluation(wingcam, wingcam, noise_px="0,1.5")
    assert [r.noise_px for r in truth.runs] == [0.0, 1.5] and truth.split is None and truth.predictions is None
    assert [s["noise_px"] for s in truth.sources] == [0.0, 1.5] and not truth.notes and not truth.warnings
    assert plan_evaluation(wingcam, wingcam, noise_px="0", split="train").split == "train"
    val = [b for b in range(len(wingcam)) if wingcam.split[b] == "val"]
    write_predictions(wingcam, tmp_path / "pred", val[:3], conf=0.9)
    (tmp_path / "pred" / "holiday.txt").write_text("0 0.5 0.5 0.1 0.1 0.9\n")
    found = plan_evaluation(wingcam, wingcam, predictions=tmp_path / "pred")
    assert found.split == "val" and len(found.runs) == 1 and found.runs[0].predictions is found.predictions
    assert found.notes == ("scoring the val split: the frames the predictions cover (--split to choose)",)
    assert len(found.warnings) == 1 and "holiday.txt" in found.warnings[0]
    assert found.sources[0]["files_of_no_frame"] == ["holiday.txt"]
    for kwargs, message in (({"split": "test"}, "--split"), ({"noise_px": "a,b"}, "--noise-px")):
        with pytest.raises(DatagenError, match=message) as info:
            plan_evaluation(wingcam, wingcam, **kwargs)
        assert "\n" not in str(info.value)
