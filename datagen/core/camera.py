"""Pinhole camera: intrinsics from (width, height, hFOV) and vectorized projection.

Paper Table 1: no distortion, ``cx = W / 2``, ``cy = H / 2``,
``fx = fy = cx / tan(hFOV / 2)``. Pixel coordinates are continuous (see
:mod:`datagen.core.conventions`). Camera frame is OpenCV (x right, y down, z forward).

Lens distortion, when a frame has it, is OpenCV's Brown-Conrady model with the
coefficients ``(k1, k2, p1, p2, k3)`` (:func:`distort_normalized`), so that
``cv2.projectPoints`` with the same coefficients gives the same pixels, and
``cv2.solvePnP`` can take them back out. All zeros is the pinhole exactly.

A rolling shutter (:class:`RollingShutter`), when a frame has one, exposes each row at
its own time (:func:`datagen.core.conventions.row_time_s`): a moving point is projected
where it was when the row it lands on was exposed (:func:`project_rolling`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Final

import numpy as np
from numpy.typing import ArrayLike, NDArray

from datagen.core.conventions import NEAR_PLANE_M, row_time_s

__all__ = [
    "FOCAL_BOUNDS_PX",
    "MAX_IMAGE_PX",
    "MAX_READOUT_S",
    "MIN_FOCAL_PX",
    "MIN_PIXEL_ANGLE_RAD",
    "ROLLING_ITERATIONS",
    "Intrinsics",
    "RollingShutter",
    "depth_in_front",
    "distort_normalized",
    "distortion_margin_px",
    "hfov_bounds_deg",
    "in_front",
    "project_points",
    "project_rolling",
    "project_xyz",
    "undistort_px",
]

FloatArray = NDArray[np.float64]

#: The largest image side, pixels (a render's, margins included).
MAX_IMAGE_PX: Final = 16384
#: The narrowest lens: neighbouring pixels' rays at the image centre must differ by at least
#: this angle (2^-20 rad, eight float32 steps of a unit direction), or Mitsuba's float32 rays
#: would give neighbouring pixels the same ray.
MIN_PIXEL_ANGLE_RAD: Final = 2.0**-20
#: The widest lens: a focal length of at least one pixel (under it, the central pixel alone
#: spans more than 53 degrees and every feature falls into a few pixels).
MIN_FOCAL_PX: Final = 1.0


#: The focal lengths, pixels, a pinhole can be made with: from :data:`MIN_FOCAL_PX` to the
#: one whose neighbouring rays at the image centre are :data:`MIN_PIXEL_ANGLE_RAD` apart.
FOCAL_BOUNDS_PX: Final = (MIN_FOCAL_PX, 1.0 / MIN_PIXEL_ANGLE_RAD)


def hfov_bounds_deg(width: int) -> tuple[float, float]:
    """The horizontal fields of view, degrees, that a ``width``-pixel pinhole can be made
    with (:data:`FOCAL_BOUNDS_PX`), narrowest first."""
    shortest, longest = FOCAL_BOUNDS_PX
    half = width / 2.0
    return math.degrees(2.0 * math.atan(half / longest)), math.degrees(2.0 * math.atan(half / shortest))


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
        """Table 1's camera: square pixels, principal point at the image centre.

        >>> k = Intrinsics.from_hfov(2048, 1080, math.pi / 2)
        >>> k.cx, k.cy, round(k.fx, 9), round(math.degrees(k.vfov_rad), 3)
        (1024.0, 540.0, 1024.0, 55.609)
        """
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

    def with_margin(self, margin_px: int) -> Intrinsics:
        """The same camera's image grown by ``margin_px`` pixels on every side (same focal
        length and optical axis): a pixel ``(u, v)`` here is ``(u + margin, v + margin)`` there."""
        m = int(margin_px)
        return Intrinsics(self.width + 2 * m, self.height + 2 * m, self.fx, self.fy, self.cx + m, self.cy + m)

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


def distort_normalized(x: FloatArray, y: FloatArray, distortion: ArrayLike) -> tuple[FloatArray, FloatArray]:
    """OpenCV's distortion of normalized image coordinates ``x = X / Z``, ``y = Y / Z``;
    ``distortion`` ``(..., 5)`` holds ``k1, k2, p1, p2, k3`` and broadcasts against ``x``
    with its last axis dropped."""
    d = np.asarray(distortion, dtype=np.float64)
    k1, k2, p1, p2, k3 = (d[..., i] for i in range(5))
    r2 = x * x + y * y
    radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
    xy = x * y
    return (x * radial + 2.0 * p1 * xy + p2 * (r2 + 2.0 * x * x),
            y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * xy)


def undistort_px(uv_px: ArrayLike, intrinsics: Intrinsics, distortion: ArrayLike,
                 iterations: int = 30) -> FloatArray:
    """The pinhole pixels ``(..., 2)`` that ``distortion`` moves to ``uv_px``: the inverse of
    :func:`project_points` with distortion, by fixed-point iteration (OpenCV's own
    method for ``undistortPoints``, run to float64 convergence for moderate lenses)."""
    k = intrinsics
    uv = np.asarray(uv_px, dtype=np.float64)
    xd, yd = (uv[..., 0] - k.cx) / k.fx, (uv[..., 1] - k.cy) / k.fy
    d = np.asarray(distortion, dtype=np.float64)
    k1, k2, p1, p2, k3 = (d[..., i] for i in range(5))
    x, y = xd.copy(), yd.copy()
    for _ in range(iterations):
        r2 = x * x + y * y
        radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
        dx = 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)
        dy = p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y
        x, y = (xd - dx) / radial, (yd - dy) / radial
    return np.stack([x * k.fx + k.cx, y * k.fy + k.cy], axis=-1)


def project_points(points_cam: ArrayLike, intrinsics: Intrinsics) -> FloatArray:
    """Continuous pixel coordinates ``(..., 2)`` of camera-frame points ``(..., 3)``.

    Points at or behind the camera plane (``z <= NEAR_PLANE_M``) project to NaN:
    callers that need them flagged use :func:`in_front`; NaN can never pass a
    box-inside-image test, so such points can never produce a label.

    On the optical axis, 1 m right of it and 0.5 m above it (OpenCV camera: x right, y
    down, z forward) at 10 m, and behind the camera, with a 90-degree lens:

    >>> k = Intrinsics.from_hfov_deg(2048, 1080, 90.0)
    >>> project_points([[0.0, 0.0, 10.0], [1.0, -0.5, 10.0], [0.0, 0.0, -1.0]], k).round(6).tolist()
    [[1024.0, 540.0], [1126.4, 488.8], [nan, nan]]
    """
    points_cam = np.asarray(points_cam, dtype=np.float64)
    u, v = project_xyz(points_cam[..., 0], points_cam[..., 1], points_cam[..., 2], intrinsics)
    return np.stack([u, v], axis=-1)


def project_xyz(
    x: FloatArray, y: FloatArray, z: FloatArray, intrinsics: Intrinsics, distortion: ArrayLike | None = None
) -> tuple[FloatArray, FloatArray]:
    """:func:`project_points` on separate coordinate arrays (any equal shapes), through
    the lens ``distortion`` (``(..., 5)``, broadcasting as in :func:`distort_normalized`)
    when given.

    The layout the label hot path uses: reductions then run along contiguous memory.
    """
    inv_z = np.divide(1.0, z, out=np.full(np.shape(z), np.nan), where=depth_in_front(z))
    if distortion is not None:
        xn, yn = distort_normalized(x * inv_z, y * inv_z, distortion)
        return xn * intrinsics.fx + intrinsics.cx, yn * intrinsics.fy + intrinsics.cy
    u = x * inv_z
    u *= intrinsics.fx
    u += intrinsics.cx
    v = y * inv_z
    v *= intrinsics.fy
    v += intrinsics.cy
    return u, v


#: The longest rolling-shutter readout, seconds: a config's and a manifest's bound.
MAX_READOUT_S: Final = 0.1
#: Fixed-point steps of :func:`project_rolling`: each shrinks a row's error by the point's
#: vertical image speed times the readout over the image's height (under 0.1 for motion
#: that crosses less than a tenth of the image during the readout: 1e-16 after 16 steps).
ROLLING_ITERATIONS: Final = 16


@dataclass(frozen=True)
class RollingShutter:
    """A batch of frames' rolling shutters: each frame's readout time and the motion of its
    objects in its camera, to first order about the frame's time."""

    readout_s: NDArray[np.float64]  # (*B,) top-to-bottom readout, seconds (0: a global shutter)
    cam_from_objects_per_s: NDArray[np.float64]  # (*B, O, 4, 4) d/dt of cam_from_<object>, per second

    def __post_init__(self) -> None:
        r, m = np.asarray(self.readout_s, np.float64), np.asarray(self.cam_from_objects_per_s, np.float64)
        if m.shape[-2:] != (4, 4) or m.shape[:-3] != r.shape:
            raise ValueError(f"a rolling shutter of readouts {r.shape} needs rates (*B, O, 4, 4) of the same "
                             f"frames, got {m.shape}")
        object.__setattr__(self, "readout_s", r)
        object.__setattr__(self, "cam_from_objects_per_s", m)

    @property
    def any(self) -> bool:
        """Whether any frame's readout takes time."""
        return bool(np.any(self.readout_s != 0.0))


def project_rolling(x: FloatArray, y: FloatArray, z: FloatArray, rate: tuple[FloatArray, ...],
                    intrinsics: Intrinsics, distortion: ArrayLike | None, readout_s: ArrayLike
                    ) -> tuple[FloatArray, FloatArray, FloatArray]:
    """:func:`project_xyz` of camera-frame points ``(x, y, z)`` (at the frame's time) moving
    at ``rate`` (their ``(dx, dy, dz)``, metres per second) through a rolling shutter of
    ``readout_s`` (broadcasting against ``x``): each point where it was when the row it
    lands on was exposed, the fixed point ``v = project(p + rate * row_time_s(v))``, in
    :data:`ROLLING_ITERATIONS` steps from the frame's time (a fixed count: the same numbers
    for a frame alone or in any batch). Returns ``u, v`` and the depth at that time."""
    dx, dy, dz = rate
    u, v = project_xyz(x, y, z, intrinsics, distortion)
    zt = z
    for _ in range(ROLLING_ITERATIONS):
        t = row_time_s(v, intrinsics.height, readout_s)
        zt = z + dz * t
        u, v = project_xyz(x + dx * t, y + dy * t, zt, intrinsics, distortion)
    return u, v, zt


def distortion_margin_px(intrinsics: Intrinsics, k1, k2, tangential) -> float:
    """Pixels the pinhole render must extend beyond the image on every side so that
    every distorted pixel finds its source, for every lens the ranges allow (the
    coefficient ranges ``(low, high)`` of k1, k2 and of p1 and p2 alike); ``inf`` where
    a lens's inverse does not converge (:func:`undistort_px`): no render can serve it."""
    k = intrinsics
    edge = np.linspace(0.0, 1.0, 33)
    border = np.concatenate([np.stack([edge * k.width, np.zeros_like(edge)], 1),
                             np.stack([edge * k.width, np.full_like(edge, k.height)], 1),
                             np.stack([np.zeros_like(edge), edge * k.height], 1),
                             np.stack([np.full_like(edge, k.width), edge * k.height], 1)])
    worst = 0.0
    for a in k1:
        for b in k2:
            for p1 in tangential:
                for p2 in tangential:
                    lens = np.array([a, b, p1, p2, 0.0])
                    src = undistort_px(border, k, lens)
                    x, y = distort_normalized((src[:, 0] - k.cx) / k.fx, (src[:, 1] - k.cy) / k.fy, lens)
                    back = np.stack([x * k.fx + k.cx, y * k.fy + k.cy], axis=-1)
                    if not np.all(np.abs(back - border) < 0.01):  # the inverse did not converge
                        return math.inf
                    over = np.maximum(np.maximum(-src, src - [k.width, k.height]), 0.0)
                    worst = max(worst, float(over.max()))
    return math.ceil(worst) + 2
