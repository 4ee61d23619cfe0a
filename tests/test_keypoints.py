"""Pose instances (datagen.core.keypoints): mirror pairs and flip_idx, keypoint slots and
flags, and the object boxes that come from the projected convex hull."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from datagen.assets.loader import builtin_paths, load_mesh, mesh_hull
from datagen.config import load_config
from datagen.core.camera import Intrinsics, project_points
from datagen.core.features import FeatureTable
from datagen.core.keypoints import (
    FLAG_HIDDEN,
    FLAG_OFF,
    FLAG_VISIBLE,
    PoseLayout,
    flip_index,
    keypoint_flags,
    mirror_name,
    object_boxes,
    object_table,
    pose_rows,
)
from datagen.core.label_boxes import Exclusion
from datagen.core.transforms import make_transform
from datagen.dataset.yolo import pose_lines
from datagen.scene.resolved import Scene

from .strategies import cam_from_model_in_front, finite, intrinsics, rotations

ROOT_SCENES = "scenes"
def project(points_model: np.ndarray, cam_from_model: np.ndarray, k: Intrinsics) -> np.ndarray:
    return project_points(points_model @ cam_from_model[:3, :3].T + cam_from_model[:3, 3], k)


OPTIONS = {"edge_margin_px": 0.0, "corrected": True, "min_size_px": 0.0, "small_boxes": "grow"}


def test_mirror_name_swaps_left_and_right_as_whole_words_only() -> None:
    assert mirror_name("receiver.wing_left_tip_le") == "receiver.wing_right_tip_le"
    assert mirror_name("tanker.stab_right_root_te") == "tanker.stab_left_root_te"
    assert mirror_name("drogue.coupling_left") == "drogue.coupling_right"
    assert mirror_name("receiver.leftover_panel") is None
    assert mirror_name("receiver.probe_tip") is None


@st.composite
def symmetric_objects(draw):
    """A random bilaterally symmetric feature set: named left/right pairs mirrored in the
    plane y = y0, and unnamed features on the plane."""
    pairs = draw(st.integers(1, 6))
    centre = draw(st.integers(0, 4))
    y0 = draw(st.floats(-2.0, 2.0, **finite))
    xz = draw(arrays(np.float64, (pairs + centre, 2), elements=st.floats(-10.0, 10.0, **finite)))
    xz += np.arange(pairs + centre)[:, None] * 0.37  # distinct features
    dy = draw(arrays(np.float64, pairs, elements=st.floats(0.2, 6.0, **finite)))
    names, centres = [], []
    for i in range(pairs):
        for side, sign in (("left", 1.0), ("right", -1.0)):
            names.append(f"obj.part_{i}_{side}")
            centres.append([xz[i, 0], y0 + sign * dy[i], xz[i, 1]])
    for j in range(centre):
        names.append(f"obj.centre_{j}")
        centres.append([xz[pairs + j, 0], y0, xz[pairs + j, 1]])
    order = draw(st.permutations(range(len(names))))
    return [names[i] for i in order], np.array([centres[i] for i in order])


@given(symmetric_objects())
@settings(max_examples=80, deadline=None)
def test_flip_index_of_a_symmetric_object_is_the_involution_of_its_name_pairs(obj) -> None:
    names, centres = obj
    flip, why = flip_index(names, centres)
    assert why is None
    assert np.array_equal(flip[flip], np.arange(len(names)))
    for i, j in enumerate(flip):
        assert names[j] == (mirror_name(names[i]) or names[i])


@given(symmetric_objects(), st.floats(0.05, 1.0, **finite))
@settings(max_examples=60, deadline=None)
def test_flip_index_refuses_a_named_pair_that_is_not_a_mirror_image(obj, shift) -> None:
    names, centres = obj
    i = next(n for n, name in enumerate(names) if "_left" in name)
    moved = centres.copy()
    moved[i, 0] += shift
    flip, why = flip_index(names, moved)
    assert flip is None and "not mirror images" in why


def test_builtin_drogue_ribs_mirror_by_geometry_and_receiver_seam_has_no_mirror() -> None:
    scene = Scene.resolve(load_config(f"{ROOT_SCENES}/podcam15.yaml"))
    f = scene.features
    drogue = [i for i in range(len(f)) if f.objects[f.object_index[i]] == "drogue"]
    flip, why = flip_index([f.name[i] for i in drogue], f.center_model[drogue])
    names = [f.name[i] for i in drogue]
    assert why is None
    assert names[flip[names.index("drogue.rib_00_tip")]] == "drogue.rib_08_tip"  # y -> -y on the rim
    assert names[flip[names.index("drogue.coupling_left")]] == "drogue.coupling_right"
    assert names[flip[names.index("drogue.coupling_top")]] == "drogue.coupling_top"
    receiver = [i for i in range(len(f)) if f.objects[f.object_index[i]] == "receiver"]
    flip, why = flip_index([f.name[i] for i in receiver], f.center_model[receiver])
    assert flip is None and "radome_seam_right has no receiver.radome_seam_left" in why


def _table(names_by_object: dict[str, list[str]], centres_by_object: dict[str, np.ndarray]) -> FeatureTable:
    names, objects, sets = [], [], []
    for obj, names_o in names_by_object.items():
        for name, c in zip(names_o, centres_by_object[obj], strict=True):
            names.append(name)
            objects.append(obj)
            sets.append(np.asarray(c)[None, :])
    return FeatureTable.from_point_sets(sets, objects=objects, names=names)


def test_pose_layout_slots_follow_class_ids_and_pad_to_the_largest_object() -> None:
    table = _table({"a": ["a.mid", "a.x_left", "a.x_right"], "b": ["b.y"]},
                   {"a": np.array([[1, 0, 0], [0, 1, 0], [0, -1, 0]]), "b": np.array([[0, 0, 0]])})
    layout = PoseLayout.from_features(table)
    assert layout.kpt_count == 3 and layout.columns == 5 + 9
    assert layout.feature_at.tolist() == [[0, 1, 2], [3, -1, -1]]
    assert layout.slot.tolist() == [0, 1, 2, 0]
    assert layout.flip_idx == (0, 2, 1)  # b's one feature, on its plane, agrees with a's slot 0


def test_pose_layout_has_no_flip_idx_when_objects_pair_different_slots() -> None:
    table = _table({"a": ["a.x_left", "a.x_right", "a.mid"], "b": ["b.mid", "b.y_left", "b.y_right"]},
                   {"a": np.array([[0, 1, 0], [0, -1, 0], [1, 0, 0]]),
                    "b": np.array([[1, 0, 0], [0, 1, 0], [0, -1, 0]])})
    layout = PoseLayout.from_features(table)
    assert layout.flip_idx is None
    assert "slot 0 mirrors to slot 0 on b (b.mid -> b.mid) but to slot 1 on a" in layout.flip_problem


def test_keypoint_flags_are_zero_when_excluded_one_when_hidden_two_when_visible_or_unknown() -> None:
    exclusion = np.array([0, 0, 0, Exclusion.OFF_FRAME, Exclusion.OCCLUDED])
    visible = np.array([1.0, 0.0, np.nan, 1.0, 0.0])
    assert keypoint_flags(exclusion, visible).tolist() == [FLAG_VISIBLE, FLAG_HIDDEN, FLAG_VISIBLE, FLAG_OFF,
                                                           FLAG_OFF]
    assert keypoint_flags(exclusion).tolist() == [2, 2, 2, 0, 0]


@pytest.fixture(scope="module")
def tanker_mesh():
    mesh = load_mesh(builtin_paths("tanker")[0], "tanker")
    return np.asarray(mesh.combined.vertices), mesh_hull(mesh)


@given(intrinsics(), rotations(), st.floats(60.0, 400.0, **finite),
       arrays(np.float64, 2, elements=st.floats(-0.3, 0.3, **finite)))
@settings(max_examples=60, deadline=None)
def test_pose_box_is_exactly_the_box_of_every_projected_mesh_vertex(tanker_mesh, k, rot, depth, lateral) -> None:
    vertices, hull = tanker_mesh
    cam_from_model = make_transform(rot, [lateral[0] * depth, lateral[1] * depth, depth])
    boxes = object_boxes(object_table(("tanker",), {"tanker": hull}), cam_from_model[None], k, options=OPTIONS)
    uv = project(vertices, cam_from_model, k)
    want = np.array([uv[:, 0].min(), uv[:, 1].min(), uv[:, 0].max(), uv[:, 1].max()])
    np.testing.assert_allclose(boxes.tight_xyxy[0], want, rtol=0, atol=1e-7 * max(k.width, k.height))


def test_clip_keeps_an_object_reaching_behind_the_camera_with_the_box_of_its_in_view_part(tanker_mesh) -> None:
    vertices, hull = tanker_mesh
    k = Intrinsics.from_hfov_deg(640, 338, 55.0)
    # The camera 2 m under the middle of the tanker's belly, looking aft: the fuselage reaches behind it.
    look_aft = np.array([[0, -1, 0], [0, 0, -1], [-1, 0, 0]], dtype=float)
    at = np.array([hull[:, 0].mean(), hull[:, 1].mean(), hull[:, 2].min() - 2.0])
    cam_from_model = make_transform(look_aft, -look_aft @ at)
    table = object_table(("tanker",), {"tanker": hull})
    exclude = object_boxes(table, cam_from_model[None], k, options=OPTIONS)
    clip = object_boxes(table, cam_from_model[None], k, options=OPTIONS, truncated="clip")
    assert exclude.exclusion[0] == Exclusion.BEHIND_CAMERA
    assert clip.exclusion[0] == Exclusion.NONE
    x0, y0, x1, y1 = clip.label_xyxy[0]
    assert 0 <= x0 < x1 <= k.width and 0 <= y0 < y1 <= k.height
    # Every mesh vertex in front of the camera that projects into the image lies in the box.
    p = vertices @ cam_from_model[:3, :3].T + cam_from_model[:3, 3]
    front = p[:, 2] > 1e-3
    uv = project(vertices[front], cam_from_model, k)
    inside = (uv[:, 0] >= 0) & (uv[:, 0] <= k.width) & (uv[:, 1] >= 0) & (uv[:, 1] <= k.height)
    assert inside.any()
    assert np.all((uv[inside, 0] >= x0 - 1e-6) & (uv[inside, 0] <= x1 + 1e-6)
                  & (uv[inside, 1] >= y0 - 1e-6) & (uv[inside, 1] <= y1 + 1e-6))


@given(cam_from_model_in_front(min_depth=40.0, max_depth=200.0))
@settings(max_examples=30, deadline=None)
def test_pose_line_holds_the_true_centres_in_slot_order_and_zeros_for_flag_zero(cam_from_model) -> None:
    k = Intrinsics.from_hfov_deg(2048, 1080, 55.0)
    table = _table({"a": ["a.mid", "a.x_left", "a.x_right"], "b": ["b.y"]},
                   {"a": np.array([[1, 0, 0], [0, 1, 0], [0, -1, 0]]), "b": np.array([[0, 0, 0]])})
    layout = PoseLayout.from_features(table)
    hull = {"a": np.array([[-2, -2, -2], [2, 2, 2]], float), "b": np.array([[-1, -1, -1], [1, 1, 1]], float)}
    poses = np.stack([cam_from_model, cam_from_model])
    objects = object_boxes(object_table(("a", "b"), hull), poses, k, options=OPTIONS)
    uv = project(table.center_model, cam_from_model, k)
    flags = np.array([2, 0, 1, 2])
    rows = pose_rows(objects, uv, flags, layout, k.width, k.height)
    lines = pose_lines(rows)
    assert len(lines) == int(objects.labeled.sum())
    for line, c in zip(lines, np.flatnonzero(objects.labeled), strict=True):
        tokens = line.split()
        assert len(tokens) == layout.columns and int(tokens[0]) == c
        kp = np.array(tokens[5:], dtype=float).reshape(-1, 3)
        for s, f in enumerate(layout.feature_at[c]):
            if f < 0 or flags[f] == 0:
                assert tokens[5 + 3 * s:8 + 3 * s] == ["0", "0", "0"]
            else:
                np.testing.assert_allclose(kp[s, :2] * [k.width, k.height], uv[f], atol=1.1e-4)
                assert kp[s, 2] == flags[f]
