"""Corrected labels (paper 3.2): properties, a literal re-implementation, and the edge rule."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from datagen.core.camera import Intrinsics
from datagen.core.features import FeatureTable
from datagen.core.label_boxes import Exclusion, boxes_from_uv, compute_labels
from datagen.core.transforms import make_transform, rotation_from_ypr
from datagen.dataset.yolo import YOLO_DECIMALS, yolo_lines

from .strategies import cam_from_model_in_front, finite, intrinsics, lens_distortions, point_sets, rotations

WIDE = Intrinsics.from_hfov_deg(2048, 1080, 75.0)


def one_feature(points: np.ndarray, center: np.ndarray | None = None) -> FeatureTable:
    return FeatureTable.from_point_sets([points], objects=["receiver"], centers=[center])


def paper_recipe(points_model, center_model, cam_from_model, k: Intrinsics, distortion=None):
    """Fig. 10 as the paper words it, with cv2 doing the projection.

    Tight box from min/max; (dx, dy) = true - perceived; grow the side facing the
    true centre by 2*dx (resp. 2*dy).
    """
    distortion = np.zeros(5) if distortion is None else distortion
    rvec = cam_from_model[:3, :3]  # cv2 takes the 3x3 matrix as is
    tvec = cam_from_model[:3, 3]
    uv, _ = cv2.projectPoints(np.asarray(points_model, float), rvec, tvec, k.K, distortion)
    c, _ = cv2.projectPoints(np.asarray(center_model, float)[None], rvec, tvec, k.K, distortion)
    uv, c = uv.reshape(-1, 2), c.reshape(2)
    x0, y0 = uv.min(axis=0)
    x1, y1 = uv.max(axis=0)
    dx, dy = c - np.array([(x0 + x1) / 2, (y0 + y1) / 2])
    if dx > 0:
        x1 += 2 * dx
    else:
        x0 += 2 * dx
    if dy > 0:
        y1 += 2 * dy
    else:
        y0 += 2 * dy
    return c, np.array([x0, y0, x1, y1])


@given(k=intrinsics(), points=point_sets(), cam_from_model=cam_from_model_in_front())
def test_corrected_centre_is_projected_true_centre(k, points, cam_from_model) -> None:
    table = one_feature(points)
    labels = compute_labels(table, cam_from_model[None], k)
    box = labels.corrected_xyxy[0]
    true_c, _ = cv2.projectPoints(points.mean(axis=0)[None], cam_from_model[:3, :3], cam_from_model[:3, 3],
                                  k.K, np.zeros(5))
    centre = np.array([(box[0] + box[2]) / 2, (box[1] + box[3]) / 2])
    np.testing.assert_allclose(centre, true_c.reshape(2), rtol=0, atol=1e-9)


@given(k=intrinsics(), points=point_sets(), cam_from_model=cam_from_model_in_front(),
       explicit=st.booleans(), w=arrays(np.float64, 16, elements=st.floats(0.01, 1.0, **finite)))
def test_matches_paper_recipe(k, points, cam_from_model, explicit, w) -> None:
    # An explicit centre anywhere in the convex hull (a convex combination of the points).
    center = (w[: len(points), None] * points).sum(0) / w[: len(points)].sum() if explicit else None
    table = one_feature(points, center)
    labels = compute_labels(table, cam_from_model[None], k, corrected=True)
    c, box = paper_recipe(points, table.center_model[0], cam_from_model, k)
    np.testing.assert_allclose(labels.center_px[0], c, rtol=0, atol=1e-9)
    np.testing.assert_allclose(labels.corrected_xyxy[0], box, rtol=0, atol=1e-9)


@given(k=intrinsics(), points=point_sets(), cam_from_model=cam_from_model_in_front(), distortion=lens_distortions())
def test_labels_through_lens_distortion_are_cv2_project_points_with_the_same_coefficients(
        k, points, cam_from_model, distortion) -> None:
    """With the camera model's lens distortion on, the label centre is cv2.projectPoints of
    the true centre with the same distortion coefficients, and the corrected box the paper's
    recipe on the distorted projections."""
    table = one_feature(points)
    labels = compute_labels(table, cam_from_model[None], k, corrected=True, distortion=distortion)
    c, box = paper_recipe(points, table.center_model[0], cam_from_model, k, distortion)
    scale = max(1.0, float(np.abs(c).max()))
    np.testing.assert_allclose(labels.center_px[0], c, rtol=0, atol=1e-9 * scale)
    np.testing.assert_allclose(labels.corrected_xyxy[0], box, rtol=0, atol=1e-9 * max(scale, np.abs(box).max()))


@given(k=intrinsics(), points=point_sets(), cam_from_model=cam_from_model_in_front())
def test_corrected_box_contains_tight_box(k, points, cam_from_model) -> None:
    labels = compute_labels(one_feature(points), cam_from_model[None], k)
    t, c = labels.tight_xyxy[0], labels.corrected_xyxy[0]
    assert c[0] <= t[0] and c[1] <= t[1] and c[2] >= t[2] and c[3] >= t[3]


@given(
    k=intrinsics(),
    half=arrays(np.float64, 2, elements=st.floats(0.05, 3.0, **finite)),
    inner=arrays(np.float64, (6, 2), elements=st.floats(-1.0, 1.0, **finite)),
    shift=arrays(np.float64, 3, elements=st.floats(-20.0, 20.0, **finite)),
    depth=st.floats(3.0, 200.0, **finite),
    roll=st.floats(-np.pi, np.pi, **finite),
)
def test_translation_of_frontal_planar_feature_has_no_parallax(k, half, inner, shift, depth, roll) -> None:
    """Fig. 8, top row: parallel to the image plane, the perceived centre is the true one."""
    # A rectangle's corners plus points inside it, in the model plane z = 0, centred on the origin.
    corners = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]]) * half
    planar = np.vstack([corners, inner * half])
    points = np.column_stack([planar, np.zeros(len(planar))])
    # In-plane rotation keeps the plane parallel; the box's centre stays the rectangle's centre.
    rot = rotation_from_ypr(0.0, 0.0, 0.0)
    rot = np.array([[np.cos(roll), -np.sin(roll), 0], [np.sin(roll), np.cos(roll), 0], [0, 0, 1]]) @ rot
    rotated = points @ rot.T
    centre = 0.5 * (rotated.min(0) + rotated.max(0))
    table = one_feature(rotated, centre)
    pose = make_transform(np.eye(3), [shift[0], shift[1], depth])
    labels = compute_labels(table, pose[None], k)
    tight = labels.tight_xyxy[0]
    perceived = np.array([(tight[0] + tight[2]) / 2, (tight[1] + tight[3]) / 2])
    np.testing.assert_allclose(perceived, labels.center_px[0], rtol=0, atol=1e-9)


@given(
    k=intrinsics(),
    a=st.floats(0.1, 2.0, **finite),
    depth=st.floats(5.0, 50.0, **finite),
    angle=st.floats(np.radians(10), np.radians(80), **finite),
    axis=st.sampled_from(["x", "y"]),
)
def test_rotated_planar_feature_has_parallax(k, a, depth, angle, axis) -> None:
    """Fig. 8, bottom row: tilt the same square away from the image plane and the centres diverge."""
    square = np.array([[-a, -a, 0], [a, -a, 0], [a, a, 0], [-a, a, 0]], float)
    c, s = np.cos(angle), np.sin(angle)
    rot = np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]]) if axis == "y" else np.array([[1, 0, 0], [0, c, -s], [0, s, c]])
    labels = compute_labels(one_feature(square, np.zeros(3)), make_transform(rot, [0, 0, depth])[None], k)
    tight = labels.tight_xyxy[0]
    delta = labels.center_px[0] - np.array([(tight[0] + tight[2]) / 2, (tight[1] + tight[3]) / 2])
    assert np.abs(delta).max() > 1e-6


@given(k=intrinsics(), sets=st.lists(point_sets(min_points=3, max_points=9), min_size=1, max_size=6),
       poses=st.lists(cam_from_model_in_front(min_depth=2.0, max_depth=60.0), min_size=4, max_size=4),
       corrected=st.booleans(), margin=st.sampled_from([0.0, 10.0, 25.0]))
def test_labeled_features_normalize_into_unit_square(k, sets, poses, corrected, margin) -> None:
    objects = ["receiver", "tanker"] * 3
    table = FeatureTable.from_point_sets(sets, objects=objects[: len(sets)])
    n_obj = len(table.objects)
    cam_from_objects = np.stack([np.stack(poses[:n_obj])])
    labels = compute_labels(table, cam_from_objects, k, edge_margin_px=margin, corrected=corrected).frame(0)
    lines = yolo_lines(labels, table.class_id, k.width, k.height)
    assert len(lines) == int(labels.labeled.sum())
    for line in lines:
        cls, *vals = line.split()
        assert 0 <= int(cls) < len(table)
        assert all(0.0 <= float(v) <= 1.0 for v in vals)


@given(
    side=st.sampled_from(["left", "top", "right", "bottom"]),
    margin=st.sampled_from([0.0, 1.0, 10.0, 12.5]),
    outward=st.booleans(),
    corrected=st.booleans(),
)
def test_edge_rule_at_exactly_the_margin(side, margin, outward, corrected) -> None:
    """A box side exactly at the margin is labeled; one ulp further out is not."""
    width, height = 640, 480
    box = np.array([100.0, 100.0, 200.0, 200.0])
    index, limit = {"left": (0, margin), "top": (1, margin), "right": (2, width - margin),
                    "bottom": (3, height - margin)}[side]
    box[index] = limit
    if outward:
        box[index] = np.nextafter(limit, -np.inf if index < 2 else np.inf)
    # A symmetric point set: the tight box is the corrected box, centred on the centre.
    corners = np.array([[box[0], box[1]], [box[2], box[1]], [box[2], box[3]], [box[0], box[3]]])
    centre = corners.mean(0)
    labels = boxes_from_uv(corners[None], centre[None], np.array([True]), width=width, height=height,
                           edge_margin_px=margin, corrected=corrected)
    got = labels.label_xyxy[0][index]
    if outward:
        assert got < limit if index < 2 else got > limit
    else:
        assert got == limit
    expected = Exclusion.NONE
    if outward:
        expected = Exclusion.OFF_FRAME if margin == 0.0 else Exclusion.EDGE_MARGIN
    assert labels.exclusion[0] == expected


def test_exclusion_reasons() -> None:
    width, height = 100, 80
    uv = np.array([
        [[40, 30], [60, 50]],    # inside
        [[5, 30], [20, 50]],     # within 10 px of the left border
        [[-5, 30], [20, 50]],    # reaches off the left border
        [[-50, -50], [-20, -20]],  # wholly off frame
        [[40, 30], [60, 50]],    # behind the camera
    ], float)
    centre = uv.mean(axis=1)
    front = np.array([True, True, True, True, False])
    labels = boxes_from_uv(uv, centre, front, width=width, height=height, edge_margin_px=10)
    assert [Exclusion(e).reason for e in labels.exclusion] == [
        None, "edge_margin", "off_frame", "off_frame", "behind_camera"]


@given(points=point_sets(), behind=st.integers(0, 15), z=st.floats(-50.0, 0.0, **finite),
       margin=st.sampled_from([0.0, 10.0]), corrected=st.booleans())
def test_points_behind_the_camera_are_never_labeled(points, behind, z, margin, corrected) -> None:
    """Even when the other points would make a box inside the image."""
    pts = points * 0.01 + np.array([0.0, 0.0, 10.0])
    pts[behind % len(pts), 2] = z
    table = one_feature(pts)
    labels = compute_labels(table, np.eye(4)[None], WIDE, edge_margin_px=margin, corrected=corrected)
    assert labels.exclusion[0] == Exclusion.BEHIND_CAMERA
    assert yolo_lines(labels, table.class_id, WIDE.width, WIDE.height) == []


def test_centre_behind_the_camera_is_never_labeled() -> None:
    pts = np.array([[0, 0, 1.0], [0.1, 0, 1.0], [0, 0.1, 1.0]])
    labels = compute_labels(one_feature(pts, np.array([0, 0, -1.0])), np.eye(4)[None], WIDE)
    assert labels.exclusion[0] == Exclusion.BEHIND_CAMERA


@given(k=intrinsics(), sets=st.lists(point_sets(max_points=12), min_size=2, max_size=5),
       poses=st.lists(cam_from_model_in_front(), min_size=6, max_size=6), corrected=st.booleans())
def test_batched_equals_per_frame_and_per_feature(k, sets, poses, corrected) -> None:
    """Ragged sets padded into one table, 3 frames in one call == each alone."""
    objects = ["receiver", "tanker", "receiver", "drogue", "tanker"][: len(sets)]
    table = FeatureTable.from_point_sets(sets, objects=objects)
    n_obj = len(table.objects)
    batch = np.stack([np.stack(poses[i * 2 : i * 2 + n_obj]) if n_obj <= 2 else np.stack(poses[:n_obj])
                      for i in range(3)])
    all_frames = compute_labels(table, batch, k, corrected=corrected)
    for b in range(3):
        for f, pts in enumerate(sets):
            single = compute_labels(one_feature(pts), batch[b, table.object_index[f]][None, None], k,
                                    corrected=corrected)
            np.testing.assert_array_equal(all_frames.tight_xyxy[b, f], single.tight_xyxy[0, 0])
            np.testing.assert_array_equal(all_frames.corrected_xyxy[b, f], single.corrected_xyxy[0, 0])
            assert all_frames.exclusion[b, f] == single.exclusion[0, 0]


def test_uncorrected_labels_use_the_tight_box() -> None:
    # A tilted square: tight and corrected boxes differ.
    a, depth = 1.0, 6.0
    square = np.array([[-a, -a, 0], [a, -a, 0], [a, a, 0], [-a, a, 0]], float)
    pose = make_transform(rotation_from_ypr(0.0, 0.0, 0.0) @ np.array(
        [[np.cos(1), 0, np.sin(1)], [0, 1, 0], [-np.sin(1), 0, np.cos(1)]]), [0, 0, depth])
    table = one_feature(square, np.zeros(3))
    tight = compute_labels(table, pose[None], WIDE, corrected=False)
    corr = compute_labels(table, pose[None], WIDE, corrected=True)
    np.testing.assert_array_equal(tight.label_xyxy, tight.tight_xyxy)
    np.testing.assert_array_equal(corr.label_xyxy, corr.corrected_xyxy)
    assert not np.allclose(tight.label_center_px, corr.label_center_px, atol=1.0)
    np.testing.assert_array_equal(corr.label_center_px, corr.center_px)


def test_yolo_line_format_and_order() -> None:
    width, height = 200, 100
    uv = np.array([[[10.0, 10.0], [30.0, 50.0]], [[100.0, 20.0], [150.0, 60.0]], [[0.0, 0.0], [1.0, 1.0]]])
    labels = boxes_from_uv(uv, uv.mean(1), np.ones(3, bool), width=width, height=height, edge_margin_px=5)
    lines = yolo_lines(labels, np.array([7, 2, 3]), width, height)
    assert lines == ["2 0.6250000 0.4000000 0.2500000 0.4000000", "7 0.1000000 0.3000000 0.1000000 0.4000000"]


def test_yolo_lines_round_trip_to_corrected_centre() -> None:
    rng = np.random.default_rng(3)
    sets = [rng.uniform(-1, 1, size=(16, 3)) for _ in range(80)]
    table = FeatureTable.from_point_sets(sets, objects=["receiver"] * 40 + ["tanker"] * 40)
    k = Intrinsics.from_hfov_deg(2048, 1080, 55.0)
    cam_from_objects = np.stack([make_transform(np.eye(3), [-3, 0, 30]), make_transform(np.eye(3), [3, 1, 40])])
    labels = compute_labels(table, cam_from_objects[None], k).frame(0)
    lines = yolo_lines(labels, table.class_id, k.width, k.height)
    assert len(lines) > 40
    for line in lines:
        cls, cx, cy, w, h = line.split()
        assert all(len(v.split(".")[1]) == YOLO_DECIMALS for v in (cx, cy, w, h))
        c = labels.center_px[int(cls)]
        assert abs(float(cx) * k.width - c[0]) <= 0.5e-7 * k.width
        assert abs(float(cy) * k.height - c[1]) <= 0.5e-7 * k.height


def test_rejects_wrong_object_count() -> None:
    table = FeatureTable.from_point_sets([np.eye(3)], objects=["receiver"])
    with pytest.raises(ValueError, match="cam_from_objects"):
        compute_labels(table, np.stack([np.eye(4), np.eye(4)])[None], WIDE)


@given(rot=rotations())
def test_strategy_rotations_are_proper(rot) -> None:
    np.testing.assert_allclose(rot @ rot.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(rot) == pytest.approx(1.0)


# --- the minimum label size (labels.min_box_px) ------------------------------------------
@given(k=intrinsics(), points=point_sets(), cam_from_model=cam_from_model_in_front(),
       min_w=st.floats(0.0, 60.0, **finite), min_h=st.floats(0.0, 60.0, **finite), corrected=st.booleans())
def test_grow_widens_small_sides_to_the_minimum_or_the_border_about_the_unmoved_centre(
        k, points, cam_from_model, min_w, min_h, corrected) -> None:
    table = one_feature(points)
    plain = compute_labels(table, cam_from_model[None], k, edge_margin_px=0.0, corrected=corrected)
    grown = compute_labels(table, cam_from_model[None], k, edge_margin_px=0.0, corrected=corrected,
                           min_size_px=(min_w, min_h), small_boxes="grow")
    base, box = plain.label_xyxy[0], grown.label_xyxy[0]
    # The paper's boxes, the true centre and what is labeled do not change.
    np.testing.assert_array_equal(grown.corrected_xyxy, plain.corrected_xyxy)
    np.testing.assert_array_equal(grown.center_px, plain.center_px)
    np.testing.assert_array_equal(grown.exclusion, plain.exclusion)
    # The label box contains the paper's box and keeps its centre (the true centre when corrected).
    assert box[0] <= base[0] and box[1] <= base[1] and box[2] >= base[2] and box[3] >= base[3]
    centre = 0.5 * (box[:2] + box[2:])
    scale = max(1.0, float(np.abs(box).max()))
    np.testing.assert_allclose(centre, 0.5 * (base[:2] + base[2:]), rtol=0, atol=1e-12 * scale)
    if corrected:
        np.testing.assert_array_equal(grown.label_center_px, grown.center_px)
    for axis, need, size in ((0, min_w, k.width), (1, min_h, k.height)):
        side, old = box[axis + 2] - box[axis], base[axis + 2] - base[axis]
        c = 0.5 * (base[axis] + base[axis + 2])
        room = 2 * min(c, size - c)  # the widest box about c that stays in the image
        if old >= need:
            assert side == old  # a side already long enough is left alone
        else:  # a short side becomes exactly the minimum, or reaches the nearer border
            assert abs(side - max(old, min(need, room))) <= 1e-12 * scale


@given(side=st.floats(0.01, 150.0, **finite), aspect=st.floats(0.2, 5.0, **finite),
       above=st.booleans(), corrected=st.booleans())
def test_exclude_drops_a_box_exactly_when_a_side_is_under_the_minimum(side, aspect, above, corrected) -> None:
    """At the size boundary: a side equal to the minimum is kept; one ulp more minimum excludes it."""
    w, h = side, side * aspect
    corners = np.array([[300.0, 200.0], [300.0 + w, 200.0], [300.0 + w, 200.0 + h], [300.0, 200.0 + h]])
    centre = corners.mean(0)
    box = boxes_from_uv(corners[None], centre[None], np.array([True]), width=2048, height=1080,
                        edge_margin_px=10.0, corrected=corrected).label_xyxy[0]
    exact = (box[2] - box[0], box[3] - box[1])
    need = (np.nextafter(exact[0], np.inf), exact[1]) if above else exact
    labels = boxes_from_uv(corners[None], centre[None], np.array([True]), width=2048, height=1080,
                           edge_margin_px=10.0, corrected=corrected, min_size_px=need, small_boxes="exclude")
    assert labels.exclusion[0] == (Exclusion.TOO_SMALL if above else Exclusion.NONE)
    np.testing.assert_array_equal(labels.label_xyxy[0], box)  # exclude never changes a box
    grown = boxes_from_uv(corners[None], centre[None], np.array([True]), width=2048, height=1080,
                          edge_margin_px=10.0, corrected=corrected, min_size_px=need, small_boxes="grow")
    assert grown.exclusion[0] == Exclusion.NONE


def test_a_box_near_the_border_grows_only_to_the_edge_margin_and_stays_labeled() -> None:
    """A 2 px feature 12 px from the left border with a 10 px margin: grown to 20 px it would
    cross the margin, so it grows to 6 px across (3 px each side of its centre) and keeps its line;
    the other axis, far from a border, grows to the full 20 px."""
    corners = np.array([[12.0, 500.0], [14.0, 500.0], [14.0, 502.0], [12.0, 502.0]])
    centre = corners.mean(0)
    args = dict(width=2048, height=1080, edge_margin_px=10.0)
    small = boxes_from_uv(corners[None], centre[None], np.array([True]), **args)
    assert small.exclusion[0] == Exclusion.NONE
    grown = boxes_from_uv(corners[None], centre[None], np.array([True]), min_size_px=20.0, **args)
    np.testing.assert_array_equal(grown.label_xyxy[0], [10.0, 491.0, 16.0, 511.0])
    assert grown.exclusion[0] == Exclusion.NONE
    # A box already inside the margin before growing is excluded as before.
    near = corners - [5.0, 0.0]
    assert boxes_from_uv(near[None], near.mean(0)[None], np.array([True]), min_size_px=20.0,
                         **args).exclusion[0] == Exclusion.EDGE_MARGIN


def test_uncorrected_labels_grow_about_the_tight_box_centre() -> None:
    """Model H gets the same treatment around its tight-box centre, not the true centre."""
    corners = np.array([[500.0, 500.0], [504.0, 500.0], [504.0, 503.0], [500.0, 503.0]])
    true_centre = np.array([503.0, 502.0])  # off the tight box's centre (parallax)
    labels = boxes_from_uv(corners[None], true_centre[None], np.array([True]), width=2048, height=1080,
                           edge_margin_px=10.0, corrected=False, min_size_px=(10.0, 12.0))
    np.testing.assert_allclose(labels.label_xyxy[0], [497.0, 495.5, 507.0, 507.5])
    np.testing.assert_allclose(labels.label_center_px[0], [502.0, 501.5])


@pytest.mark.parametrize("bad", [-1.0, float("nan"), float("inf"), (1.0, -2.0)])
def test_a_bad_minimum_size_is_refused(bad) -> None:
    corners = np.array([[0.0, 0.0], [1.0, 1.0]])
    with pytest.raises(ValueError, match="min_size_px must be finite and not negative"):
        boxes_from_uv(corners[None], corners.mean(0)[None], np.array([True]), width=10, height=10,
                      edge_margin_px=0.0, min_size_px=bad)
    with pytest.raises(ValueError, match="small_boxes must be 'grow' or 'exclude'"):
        boxes_from_uv(corners[None], corners.mean(0)[None], np.array([True]), width=10, height=10,
                      edge_margin_px=0.0, small_boxes="shrink")
