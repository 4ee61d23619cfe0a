"""Rigid transforms as 4x4 homogeneous matrices, batched over leading axes.

Conventions (see :mod:`datagen.core.conventions`): a matrix ``b_from_a`` maps
coordinates in frame ``a`` to frame ``b``; composition reads right to left.

The plain functions work on arrays of shape ``(..., 4, 4)`` and points of shape
``(..., N, 3)``. :class:`Transform` wraps one matrix with the names of its two
frames, so that composing mismatched frames raises instead of silently
producing a wrong pose.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "Transform",
    "apply_transform",
    "invert_rigid",
    "make_transform",
    "rotation_from_rotvec",
    "rotation_from_ypr",
    "rotation_rows_from_rotvecs",
    "rotvec_from_rotation",
    "vec3",
]

FloatArray = NDArray[np.float64]
#: Three floats: a point, direction or colour held as Python numbers.
Vec3 = tuple[float, float, float]


def vec3(values: ArrayLike) -> Vec3:
    """The three values of ``values`` as Python floats (a point, direction or colour kept
    out of numpy: hashable, and the same in a config, a dataclass and JSON)."""
    x, y, z = np.asarray(values, dtype=np.float64).reshape(3).tolist()
    return x, y, z


def make_transform(rotation: ArrayLike, translation: ArrayLike) -> FloatArray:
    """Homogeneous ``(..., 4, 4)`` from rotations ``(..., 3, 3)`` and translations ``(..., 3)``."""
    rotation = np.asarray(rotation, dtype=np.float64)
    translation = np.asarray(translation, dtype=np.float64)
    batch = np.broadcast_shapes(rotation.shape[:-2], translation.shape[:-1])
    out = np.zeros(batch + (4, 4))
    out[..., :3, :3] = rotation
    out[..., :3, 3] = translation
    out[..., 3, 3] = 1.0
    return out


def invert_rigid(b_from_a: ArrayLike) -> FloatArray:
    """``a_from_b`` for rigid ``b_from_a`` of shape ``(..., 4, 4)`` (exact transpose, no solve)."""
    b_from_a = np.asarray(b_from_a, dtype=np.float64)
    rot_t = np.swapaxes(b_from_a[..., :3, :3], -1, -2)
    trans = -np.einsum("...ij,...j->...i", rot_t, b_from_a[..., :3, 3])
    return make_transform(rot_t, trans)


def apply_transform(b_from_a: ArrayLike, points_a: ArrayLike) -> FloatArray:
    """Points ``(..., N, 3)`` in frame ``a`` mapped to frame ``b`` by ``(..., 4, 4)``.

    A drogue 20 m ahead of the receiver (body x forward), the receiver 100 m along the
    world's x axis and yawed 90 degrees to its left (z up: its nose along the world's y);
    :func:`invert_rigid` maps back:

    >>> world_from_receiver = make_transform(rotation_from_ypr(np.pi / 2, 0.0, 0.0), [100.0, 0.0, 0.0])
    >>> drogue_world = apply_transform(world_from_receiver, [[20.0, 0.0, 0.0]])
    >>> drogue_world.round(9).tolist()
    [[100.0, 20.0, 0.0]]
    >>> apply_transform(invert_rigid(world_from_receiver), drogue_world).round(9).tolist()
    [[20.0, 0.0, 0.0]]
    """
    b_from_a = np.asarray(b_from_a, dtype=np.float64)
    points_a = np.asarray(points_a, dtype=np.float64)
    rot = b_from_a[..., :3, :3]
    return points_a @ np.swapaxes(rot, -1, -2) + b_from_a[..., None, :3, 3]


def rotation_from_ypr(yaw: ArrayLike, pitch: ArrayLike, roll: ArrayLike) -> FloatArray:
    """Body-to-parent rotation ``(..., 3, 3)`` from yaw, pitch, roll in radians.

    Aerospace order on the paper's body axes (x forward, y left, z up): yaw about
    z (nose left positive), then pitch about the new y (nose *down* positive, as
    a right-handed rotation about a left-pointing axis), then roll about the new
    x (right wing down positive). ``R = Rz(yaw) @ Ry(pitch) @ Rx(roll)``.
    """
    yaw, pitch, roll = np.broadcast_arrays(
        np.asarray(yaw, dtype=np.float64),
        np.asarray(pitch, dtype=np.float64),
        np.asarray(roll, dtype=np.float64),
    )
    cy, sy = np.cos(yaw), np.sin(yaw)
    cp, sp = np.cos(pitch), np.sin(pitch)
    cr, sr = np.cos(roll), np.sin(roll)
    out = np.empty(yaw.shape + (3, 3))
    out[..., 0, 0] = cy * cp
    out[..., 0, 1] = cy * sp * sr - sy * cr
    out[..., 0, 2] = cy * sp * cr + sy * sr
    out[..., 1, 0] = sy * cp
    out[..., 1, 1] = sy * sp * sr + cy * cr
    out[..., 1, 2] = sy * sp * cr - cy * sr
    out[..., 2, 0] = -sp
    out[..., 2, 1] = cp * sr
    out[..., 2, 2] = cp * cr
    return out


def rotation_from_rotvec(rotvec: ArrayLike) -> FloatArray:
    """Rotation matrix ``(3, 3)`` of a rotation vector (axis times angle, radians)."""
    rotvec = np.asarray(rotvec, dtype=np.float64)
    angle = float(np.linalg.norm(rotvec))
    if angle < 1e-12:
        k = np.array([[0.0, -rotvec[2], rotvec[1]], [rotvec[2], 0.0, -rotvec[0]], [-rotvec[1], rotvec[0], 0.0]])
        return np.eye(3) + k
    axis = rotvec / angle
    k = np.array([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]], [-axis[1], axis[0], 0.0]])
    return np.eye(3) + np.sin(angle) * k + (1.0 - np.cos(angle)) * (k @ k)


def rotation_rows_from_rotvecs(rotvecs: ArrayLike) -> FloatArray:
    """Row-major rotation matrices ``(C, 9)`` of rotation vectors ``(C, 3)``: Rodrigues'
    formula written out per element (each matrix entry one expression, sines and cosines
    per row through :mod:`math`), so that a row's matrix does not depend on the other rows
    (:func:`rotation_from_rotvec` computes the same rotation through ``K @ K``: the two
    differ in the last bits)."""
    rotvec = np.asarray(rotvecs, dtype=np.float64).reshape(-1, 3)
    rx, ry, rz = rotvec[:, 0], rotvec[:, 1], rotvec[:, 2]
    angle = np.sqrt(rx * rx + ry * ry + rz * rz)
    small = angle < 1e-12
    safe = np.where(small, 1.0, angle)
    x, y, z = rx / safe, ry / safe, rz / safe
    s = np.array([math.sin(v) for v in angle.tolist()])
    c = np.array([1.0 - math.cos(v) for v in angle.tolist()])
    full = np.stack([1.0 - c * (y * y + z * z), -s * z + c * x * y, s * y + c * x * z,
                     s * z + c * x * y, 1.0 - c * (x * x + z * z), -s * x + c * y * z,
                     -s * y + c * x * z, s * x + c * y * z, 1.0 - c * (x * x + y * y)], axis=1)
    if small.any():
        one = np.ones_like(rx)
        tiny = np.stack([one, -rz, ry, rz, one, -rx, -ry, rx, one], axis=1)
        full = np.where(small[:, None], tiny, full)
    return full


def rotvec_from_rotation(rotation: ArrayLike) -> FloatArray:
    """Rotation vector ``(3,)`` of a rotation matrix, angle in [0, pi] (via a unit quaternion)."""
    m = np.asarray(rotation, dtype=np.float64)
    trace = m[0, 0] + m[1, 1] + m[2, 2]
    # Shepperd's method: divide by the largest of the four quaternion components.
    candidates = [trace, m[0, 0], m[1, 1], m[2, 2]]
    i = int(np.argmax(candidates))
    if i == 0:
        w = 0.5 * np.sqrt(1.0 + trace)
        xyz = np.array([m[2, 1] - m[1, 2], m[0, 2] - m[2, 0], m[1, 0] - m[0, 1]]) / (4.0 * w)
    else:
        j, k = (i % 3), ((i + 1) % 3)
        a = i - 1
        q = np.empty(3)
        q[a] = 0.5 * np.sqrt(max(0.0, 1.0 + 2.0 * m[a, a] - trace))
        q[j] = (m[j, a] + m[a, j]) / (4.0 * q[a])
        q[k] = (m[k, a] + m[a, k]) / (4.0 * q[a])
        w = (m[k, j] - m[j, k]) / (4.0 * q[a])
        xyz = q
    if w < 0.0:
        w, xyz = -w, -xyz
    s = float(np.linalg.norm(xyz))
    if s < 1e-15:
        return 2.0 * xyz / max(w, 1e-300)
    return xyz / s * (2.0 * np.arctan2(s, w))


@dataclass(frozen=True)
class Transform:
    """One rigid transform ``dst_from_src`` that knows its frames.

    ``Transform(m, dst="cam", src="world") @ Transform(n, dst="world", src="receiver")``
    gives ``cam_from_receiver``; composing ``cam_from_world @ drogue_from_receiver``
    raises :class:`ValueError`.
    """

    matrix: FloatArray
    dst: str
    src: str

    def __post_init__(self) -> None:
        m = np.array(self.matrix, dtype=np.float64)
        if m.shape != (4, 4):
            raise ValueError(f"{self.name}: expected a 4x4 matrix, got shape {m.shape}")
        m.setflags(write=False)
        object.__setattr__(self, "matrix", m)

    @property
    def name(self) -> str:
        return f"{self.dst}_from_{self.src}"

    def __matmul__(self, other: Transform) -> Transform:
        if not isinstance(other, Transform):
            return NotImplemented
        if self.src != other.dst:
            raise ValueError(
                f"cannot compose {self.name} @ {other.name}: frame {self.src!r} != {other.dst!r}"
            )
        return Transform(self.matrix @ other.matrix, dst=self.dst, src=other.src)

    def inverse(self) -> Transform:
        return Transform(invert_rigid(self.matrix), dst=self.src, src=self.dst)

    def apply(self, points_src: ArrayLike) -> FloatArray:
        """Points ``(N, 3)`` in ``src`` expressed in ``dst``."""
        return apply_transform(self.matrix, points_src)
