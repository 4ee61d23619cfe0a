"""Pinhole camera: intrinsics from (width, height, hFOV) and vectorized projection.

Paper Table 1: no distortion, ``cx = W / 2``, ``cy = H / 2``,
``fx = fy = cx / tan(hFOV / 2)``. Pixel coordinates are continuous (see
:mod:`datagen.core.conventions`). Camera frame is OpenCV (x right, y down, z forward).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from datagen.core.conventions import NEAR_PLANE_M

__all__ = ["Intrinsics", "depth_in_front", "in_front", "project_points", "project_xyz"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class Intrinsics:
    """Pinhole intrinsics of a ``width`` x ``height`` image, in continuous pixels."""

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float

    @classmethod
    def from_hfov(cls, width: int, height: int, hfov_rad: float) -> Intrinsics:
        """Table 1's camera: square pixels, principal point at the image centre."""
        if width <= 0 or height <= 0:
            raise ValueError(f"image size must be positive, got {width}x{height}")
        if not 0.0 < hfov_rad < math.pi:
            raise ValueError(f"hFOV must lie in (0, pi) radians, got {hfov_rad}")
        cx = width / 2.0
        cy = height / 2.0
        f = cx / math.tan(hfov_rad / 2.0)
        return cls(width=width, height=height, fx=f, fy=f, cx=cx, cy=cy)

    @classmethod
    def from_hfov_deg(cls, width: int, height: int, hfov_deg: float) -> Intrinsics:
        return cls.from_hfov(width, height, math.radians(hfov_deg))

    @property
    def K(self) -> FloatArray:
        """The 3x3 camera matrix."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    @property
    def hfov_rad(self) -> float:
        return 2.0 * math.atan(self.cx / self.fx)

    @property
    def vfov_rad(self) -> float:
        return 2.0 * math.atan(self.cy / self.fy)


def in_front(points_cam: ArrayLike) -> NDArray[np.bool_]:
    """``(...,)`` mask of points ``(..., 3)`` strictly in front of the camera plane."""
    return depth_in_front(np.asarray(points_cam)[..., 2])


def depth_in_front(z_cam: ArrayLike) -> NDArray[np.bool_]:
    """:func:`in_front` on camera-frame depths ``z`` alone."""
    return np.asarray(z_cam) > NEAR_PLANE_M


def project_points(points_cam: ArrayLike, intrinsics: Intrinsics) -> FloatArray:
    """Continuous pixel coordinates ``(..., 2)`` of camera-frame points ``(..., 3)``.

    Points at or behind the camera plane (``z <= NEAR_PLANE_M``) project to NaN:
    callers that need them flagged use :func:`in_front`; NaN can never pass a
    box-inside-image test, so such points can never produce a label.
    """
    points_cam = np.asarray(points_cam, dtype=np.float64)
    u, v = project_xyz(points_cam[..., 0], points_cam[..., 1], points_cam[..., 2], intrinsics)
    return np.stack([u, v], axis=-1)


def project_xyz(
    x: FloatArray, y: FloatArray, z: FloatArray, intrinsics: Intrinsics
) -> tuple[FloatArray, FloatArray]:
    """:func:`project_points` on separate coordinate arrays (any equal shapes).

    The layout the label hot path uses: reductions then run along contiguous memory.
    """
    inv_z = np.divide(1.0, z, out=np.full(np.shape(z), np.nan), where=depth_in_front(z))
    u = x * inv_z
    u *= intrinsics.fx
    u += intrinsics.cx
    v = y * inv_z
    v *= intrinsics.fy
    v += intrinsics.cy
    return u, v
