"""Camera intrinsics and projection against the paper's Table 1 and OpenCV."""

from __future__ import annotations

import json
import math
from pathlib import Path

import cv2
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from datagen.core.camera import Intrinsics, in_front, project_points
from datagen.core.transforms import apply_transform, make_transform

from .strategies import intrinsics, point_sets

REFERENCE = json.loads((Path(__file__).parent / "data" / "projection_reference.json").read_text())


@pytest.mark.parametrize("hfov_deg", [15.0, 25.0, 55.0, 75.0])
def test_table1_intrinsics(hfov_deg: float) -> None:
    k = Intrinsics.from_hfov_deg(2048, 1080, hfov_deg)
    assert (k.cx, k.cy) == (1024.0, 540.0)
    assert k.fx == k.fy == pytest.approx(1024.0 / math.tan(math.radians(hfov_deg) / 2.0), rel=1e-15)
    assert k.hfov_rad == pytest.approx(math.radians(hfov_deg), rel=1e-12)
    np.testing.assert_array_equal(k.K, [[k.fx, 0, 1024.0], [0, k.fy, 540.0], [0, 0, 1]])


def test_wingcam55_focal_length() -> None:
    # fx = 1024 / tan(27.5 deg) = 1024 / 0.5205671 = 1967.0857 (by hand)
    assert Intrinsics.from_hfov_deg(2048, 1080, 55.0).fx == pytest.approx(1967.0857, abs=1e-4)


@pytest.mark.parametrize("case", REFERENCE["cases"], ids=lambda c: f"hfov{c['hfov_deg']:g}-{c['width']}")
def test_matches_stored_cv2_reference(case: dict) -> None:
    k = Intrinsics.from_hfov_deg(case["width"], case["height"], case["hfov_deg"])
    np.testing.assert_allclose(k.K, case["K"], rtol=1e-15, atol=0)
    cam_from_model = make_transform(case["cam_from_model_rotation"], case["cam_from_model_translation"])
    uv_px = project_points(apply_transform(cam_from_model, case["points_model"]), k)
    np.testing.assert_allclose(uv_px, case["uv_px"], rtol=0, atol=1e-9)


@given(
    k=intrinsics(),
    rvec=arrays(np.float64, 3, elements=st.floats(-3.0, 3.0, allow_nan=False)),
    depth=st.floats(5.0, 150.0),
    points=point_sets(max_points=40),
)
def test_matches_live_cv2(k: Intrinsics, rvec: np.ndarray, depth: float, points: np.ndarray) -> None:
    tvec = np.array([0.1 * depth, -0.05 * depth, depth])
    expected, _ = cv2.projectPoints(points, rvec, tvec, k.K, np.zeros(5))
    # The same rotation cv2 uses internally, so that both sides see identical inputs.
    rotation, _ = cv2.Rodrigues(rvec)
    got = project_points(apply_transform(make_transform(rotation, tvec), points), k)
    np.testing.assert_allclose(got, expected.reshape(-1, 2), rtol=0, atol=1e-9)


def test_principal_point_and_corners() -> None:
    k = Intrinsics.from_hfov_deg(2048, 1080, 55.0)
    half_w = math.tan(math.radians(55.0) / 2.0)
    pts = np.array([[0.0, 0.0, 7.0], [-half_w, 0.0, 1.0], [half_w, 0.0, 1.0], [0.0, 540.0 / k.fy, 1.0]])
    np.testing.assert_allclose(project_points(pts, k), [[1024, 540], [0, 540], [2048, 540], [1024, 1080]],
                               atol=1e-9)


@given(z=st.floats(-1e6, 1e-6, allow_nan=False), xy=st.tuples(st.floats(-1e3, 1e3), st.floats(-1e3, 1e3)))
def test_points_at_or_behind_camera_are_flagged_and_nan(z: float, xy: tuple[float, float]) -> None:
    pts = np.array([[xy[0], xy[1], z]])
    assert not in_front(pts)[0]
    assert np.isnan(project_points(pts, Intrinsics.from_hfov_deg(64, 32, 55.0))).all()


def test_batched_projection_shapes() -> None:
    k = Intrinsics.from_hfov_deg(64, 32, 55.0)
    pts = np.random.default_rng(0).uniform(1, 2, size=(5, 7, 11, 3))
    uv = project_points(pts, k)
    assert uv.shape == (5, 7, 11, 2)
    np.testing.assert_allclose(uv[3, 2], project_points(pts[3, 2], k))


@pytest.mark.parametrize("bad", [(0, 10, 1.0), (10, -1, 1.0), (10, 10, 0.0), (10, 10, math.pi)])
def test_invalid_intrinsics(bad: tuple) -> None:
    with pytest.raises(ValueError):
        Intrinsics.from_hfov(*bad)
