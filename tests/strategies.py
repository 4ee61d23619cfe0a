"""Hypothesis strategies shared by the geometry tests (kept in one place)."""

from __future__ import annotations

import numpy as np
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from datagen.core.camera import Intrinsics
from datagen.core.transforms import make_transform

finite = dict(allow_nan=False, allow_infinity=False)


@st.composite
def rotations(draw) -> np.ndarray:
    """Uniformly distributed rotation matrices (from normalized Gaussian quaternions)."""
    q = draw(arrays(np.float64, 4, elements=st.floats(-1.0, 1.0, **finite)))
    n = np.linalg.norm(q)
    if n < 1e-3:
        q, n = np.array([1.0, 0.0, 0.0, 0.0]), 1.0
    w, x, y, z = q / n
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


@st.composite
def intrinsics(draw) -> Intrinsics:
    """Table 1 cameras (any of the four FOVs) at a few resolutions."""
    hfov = draw(st.sampled_from([15.0, 25.0, 55.0, 75.0]))
    width, height = draw(st.sampled_from([(2048, 1080), (1024, 540), (640, 338), (101, 57)]))
    return Intrinsics.from_hfov_deg(width, height, hfov)


@st.composite
def point_sets(draw, min_points: int = 3, max_points: int = 16, extent_m: float = 2.0) -> np.ndarray:
    """A feature's point set ``(n, 3)`` in its model frame, well spread (no duplicates)."""
    n = draw(st.integers(min_points, max_points))
    pts = draw(arrays(np.float64, (n, 3), elements=st.floats(-extent_m, extent_m, **finite)))
    # Spread the points so that a set is never degenerate.
    pts = pts + np.linspace(-0.05, 0.05, n)[:, None] * np.array([1.0, -0.7, 0.3])
    return pts


@st.composite
def cam_from_model_in_front(draw, min_depth: float = 5.0, max_depth: float = 150.0) -> np.ndarray:
    """A camera-from-model pose that puts a ~2 m object well in front of the camera."""
    rot = draw(rotations())
    depth = draw(st.floats(min_depth, max_depth, **finite))
    lateral = draw(arrays(np.float64, 2, elements=st.floats(-0.3, 0.3, **finite))) * depth
    return make_transform(rot, [lateral[0], lateral[1], depth])


@st.composite
def lens_distortions(draw) -> np.ndarray:
    """OpenCV distortion coefficients ``(k1, k2, p1, p2, 0)`` within the config's default
    ranges (:class:`datagen.config.schema.SensorConfig`)."""
    from datagen.config.schema import SensorConfig

    s = SensorConfig()
    k1, k2 = draw(st.floats(*s.k1)), draw(st.floats(*s.k2))
    p1, p2 = draw(st.floats(*s.tangential)), draw(st.floats(*s.tangential))
    return np.array([k1, k2, p1, p2, 0.0])
