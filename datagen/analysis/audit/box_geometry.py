"""The geometry of the audit's statistics: pure functions of boxes, centres and poses."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray


# --- geometry of the statistics (pure functions) ---------------------------------------
def tight_centre_drift_px(tight_xyxy: NDArray[np.float64], center_px: NDArray[np.float64]) -> NDArray[np.float64]:
    """``(...)`` distance in pixels between the tight box's centre (the perceived centre)
    and the projection of the true 3D centre."""
    tight_centre = 0.5 * (tight_xyxy[..., :2] + tight_xyxy[..., 2:])
    return np.hypot(*np.moveaxis(tight_centre - center_px, -1, 0))


def feature_normals(points_model: NDArray[np.float64], n_points: NDArray[np.int64]) -> NDArray[np.float64]:
    """``(F, 3)`` unit normal of each feature's point set: the direction of least spread
    (the ring of a surface feature lies in the surface's tangent plane)."""
    normals = np.empty((len(points_model), 3))
    for i, (pts, n) in enumerate(zip(points_model, n_points, strict=True)):
        p = pts[:n] - pts[:n].mean(axis=0)
        normals[i] = np.linalg.svd(p, full_matrices=True)[2][-1]
    return normals


def obliqueness_deg(cam_from_model: NDArray[np.float64], normal_model: NDArray[np.float64],
                    center_model: NDArray[np.float64]) -> NDArray[np.float64]:
    """Angle between a feature's normal and the line of sight to its centre, degrees:
    0 when the camera looks straight at the feature, 90 when it is seen edge-on.

    Args:
        cam_from_model: ``(..., F, 4, 4)``.
        normal_model, center_model: ``(F, 3)`` in the feature's object frame.
    """
    rot = cam_from_model[..., :3, :3]
    n_cam = np.einsum("...ij,...j->...i", rot, normal_model)
    c_cam = np.einsum("...ij,...j->...i", rot, center_model) + cam_from_model[..., :3, 3]
    cos = np.abs(np.sum(n_cam * c_cam, axis=-1)) / np.maximum(np.linalg.norm(c_cam, axis=-1), 1e-12)
    return np.degrees(np.arccos(np.clip(cos, 0.0, 1.0)))
