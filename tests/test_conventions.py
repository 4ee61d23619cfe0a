"""The conventions module against Mitsuba's own sensor, and the seed rule."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from datagen.core.camera import Intrinsics, project_points
from datagen.core.conventions import CVCAM_FROM_MICAM, MICAM_FROM_CVCAM, frame_rng
from datagen.core.transforms import (
    Transform,
    apply_transform,
    invert_rigid,
    make_transform,
    rotation_from_ypr,
)

from .strategies import finite, rotations

mi = pytest.importorskip("mitsuba")


@pytest.fixture(scope="module")
def variant() -> str:
    for name in ("llvm_ad_rgb", "scalar_rgb"):
        if name in mi.variants():
            try:
                mi.set_variant(name)
                return name
            except Exception:
                continue
    pytest.skip("no usable Mitsuba variant")


@pytest.mark.parametrize("hfov_deg", [15.0, 25.0, 55.0, 75.0])
def test_mitsuba_sensor_rays_match_intrinsics(variant: str, hfov_deg: float) -> None:
    """A Mitsuba perspective sensor with fov_axis='x' shoots the ray through
    continuous pixel (u, v) that our K projects back to (u, v)."""
    width, height = 2048, 1080
    k = Intrinsics.from_hfov_deg(width, height, hfov_deg)
    sensor = mi.load_dict({
        "type": "perspective", "fov": hfov_deg, "fov_axis": "x",
        "film": {"type": "hdrfilm", "width": width, "height": height, "rfilter": {"type": "box"}},
    })
    uv = np.array([[0.0, 0.0], [1024.0, 540.0], [2048.0, 1080.0], [0.5, 1079.5], [1500.25, 200.75]])
    for u, v in uv:
        ray, _ = sensor.sample_ray(0.0, 0.5, mi.Point2f(float(u) / width, float(v) / height), mi.Point2f(0.5, 0.5))
        d_micam = np.array(ray.d, dtype=np.float64).reshape(3)
        d_cvcam = CVCAM_FROM_MICAM[:3, :3] @ d_micam
        # Mitsuba computes in float32: a few thousandths of a pixel at most.
        np.testing.assert_allclose(project_points(d_cvcam, k), [u, v], atol=2e-3)


def test_mitsuba_look_at_axes_are_left_up_forward(variant: str) -> None:
    """look_at's local axes are (left, up, forward): the constant flips x and y."""
    origin, target, up = np.array([1.0, 2.0, 3.0]), np.array([4.0, -2.0, 5.0]), np.array([0.0, 0.0, 1.0])
    m = np.array(mi.ScalarTransform4f().look_at(origin=origin, target=target, up=up).matrix, dtype=float)
    forward = (target - origin) / np.linalg.norm(target - origin)
    left = np.cross(up, forward)
    left /= np.linalg.norm(left)
    np.testing.assert_allclose(m[:3, 0], left, atol=1e-6)
    np.testing.assert_allclose(m[:3, 2], forward, atol=1e-6)
    # In OpenCV terms the same camera has x right (= -left) and y down.
    world_from_cvcam = m @ MICAM_FROM_CVCAM
    np.testing.assert_allclose(world_from_cvcam[:3, 0], -left, atol=1e-6)
    assert world_from_cvcam[:3, 1] @ up < 0
    np.testing.assert_array_equal(MICAM_FROM_CVCAM @ CVCAM_FROM_MICAM, np.eye(4))


def test_frame_rng_is_a_pure_function_of_seed_and_index() -> None:
    a = frame_rng(55, 7).random(5)
    np.testing.assert_array_equal(a, frame_rng(55, 7).random(5))
    assert not np.array_equal(a, frame_rng(55, 8).random(5))
    assert not np.array_equal(a, frame_rng(56, 7).random(5))
    # The documented derivation, spelled out.
    np.testing.assert_array_equal(
        a, np.random.default_rng(np.random.SeedSequence(55, spawn_key=(7,))).random(5))


@given(rot=rotations(), t=arrays(np.float64, 3, elements=st.floats(-100, 100, **finite)),
       pts=arrays(np.float64, (5, 3), elements=st.floats(-10, 10, **finite)))
def test_invert_rigid(rot, t, pts) -> None:
    b_from_a = make_transform(rot, t)
    np.testing.assert_allclose(invert_rigid(b_from_a) @ b_from_a, np.eye(4), atol=1e-12)
    np.testing.assert_allclose(apply_transform(invert_rigid(b_from_a), apply_transform(b_from_a, pts)), pts,
                               atol=1e-10)


@given(ypr=arrays(np.float64, 3, elements=st.floats(-math.pi, math.pi, **finite)))
def test_rotation_from_ypr_is_proper(ypr) -> None:
    r = rotation_from_ypr(*ypr)
    np.testing.assert_allclose(r @ r.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(r) == pytest.approx(1.0)


def test_rotation_from_ypr_senses() -> None:
    # Yaw +90 deg: nose (x) turns to the left (+y).
    np.testing.assert_allclose(rotation_from_ypr(math.pi / 2, 0, 0) @ [1, 0, 0], [0, 1, 0], atol=1e-15)
    # Pitch +90 deg about the left axis: nose goes down.
    np.testing.assert_allclose(rotation_from_ypr(0, math.pi / 2, 0) @ [1, 0, 0], [0, 0, -1], atol=1e-15)
    # Roll +90 deg: left wing (y) goes up, i.e. right wing down.
    np.testing.assert_allclose(rotation_from_ypr(0, 0, math.pi / 2) @ [0, 1, 0], [0, 0, 1], atol=1e-15)


def test_transform_frames_must_match() -> None:
    cam_from_world = Transform(np.eye(4), dst="cam", src="world")
    world_from_receiver = Transform(make_transform(np.eye(3), [1, 2, 3]), dst="world", src="receiver")
    cam_from_receiver = cam_from_world @ world_from_receiver
    assert cam_from_receiver.name == "cam_from_receiver"
    assert cam_from_receiver.inverse().name == "receiver_from_cam"
    with pytest.raises(ValueError, match="cannot compose cam_from_world @ cam_from_receiver"):
        cam_from_world @ cam_from_receiver
