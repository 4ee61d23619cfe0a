"""Contact sheets of the assets: each object from six views, feature centres marked.

Rendered with Mitsuba (:mod:`datagen.render.views`) through the same camera model
as the labels, so a marker sits where a label's centre would.
Filled markers are centres the camera sees; hollow ones are hidden behind the
object (ray cast, 1 cm tolerance).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Final

import cv2
import numpy as np
from numpy.typing import NDArray

from datagen.assets.loader import Feature, ObjectMesh
from datagen.assets.rig import body_from_cam_looking
from datagen.atomic import write_image
from datagen.core.camera import Intrinsics, project_points
from datagen.core.conventions import drawing_px
from datagen.core.transforms import apply_transform, invert_rigid
from datagen.render.views import render_views
from datagen.report.overlays import INK, draw_text

__all__ = ["VIEWS", "contact_sheet", "write_contact_sheet"]

#: (title, azimuth from +x towards +y, elevation), degrees: where the camera sits.
VIEWS: Final = (
    ("front left, above", 35.0, 20.0),
    ("front", 0.0, 4.0),
    ("right side", -90.0, 0.0),
    ("top", 180.0, 75.0),
    ("rear right, below", -145.0, -25.0),
    ("rear, below", 180.0, -45.0),
)
_TILE: Final = (480, 360)
_HFOV_DEG: Final = 40.0







def _view_pose(center: NDArray, distance: float, azimuth_deg: float, elevation_deg: float) -> NDArray:
    az, el = math.radians(azimuth_deg), math.radians(elevation_deg)
    offset = distance * np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)])
    return body_from_cam_looking(center + offset, -offset)


def contact_sheet(mesh: ObjectMesh, features: Sequence[Feature], *, spp: int = 64,
                  variant: str = "auto") -> NDArray[np.uint8]:
    """The object from each of :data:`VIEWS` with its feature centres marked, as one
    8-bit BGR image (3 x 2 tiles)."""
    bounds = mesh.combined.bounds
    center = bounds.mean(axis=0)
    intrinsics = Intrinsics.from_hfov_deg(*_TILE, _HFOV_DEG)
    # Far enough that the bounding sphere fits the (narrower) vertical field of view.
    distance = 0.5 * float(np.linalg.norm(bounds[1] - bounds[0])) / math.tan(intrinsics.vfov_rad / 2)
    centers = np.array([f.center_m for f in features])
    poses = [_view_pose(center, distance, az, el) for _, az, el in VIEWS]
    tiles = []
    rendered = render_views(mesh, poses, intrinsics, centers, spp=spp, variant=variant)
    for (title, _, _), world_from_cam, (image, seen) in zip(VIEWS, poses, rendered, strict=True):
        uv = project_points(apply_transform(invert_rigid(world_from_cam), centers), intrinsics)
        _mark(image, uv, seen, [f.class_id for f in features])
        draw_text(image, title, (8, 20), INK, 0.55)
        tiles.append(image)
    rows = [np.concatenate(tiles[i : i + 3], axis=1) for i in range(0, len(tiles), 3)]
    sheet = np.concatenate(rows, axis=0)
    label = f"{mesh.name}: {len(features)} features (filled: centre visible, hollow: hidden); {mesh.path.name}"
    draw_text(sheet, label, (8, sheet.shape[0] - 10), INK, 0.55)
    return sheet


def _mark(image: NDArray[np.uint8], uv: NDArray, seen: NDArray[np.bool_], ids: Sequence[int]) -> None:
    for (u, v), ok, cid in zip(uv, seen, ids, strict=True):
        if not (np.isfinite(u) and np.isfinite(v)):
            continue
        # Continuous pixel coordinates to OpenCV's integer drawing grid (shift 4: 1/16 px).
        x, y = drawing_px((u, v))
        point = (round(x * 16), round(y * 16))
        color = (40, 220, 40) if ok else (60, 60, 255)
        cv2.circle(image, point, 4 * 16, color, -1 if ok else 1, cv2.LINE_AA, shift=4)
        if ok:  # light text outlined in black: legible on the light grey hull and the dark sky alike
            draw_text(image, str(cid), (round(u) + 5, round(v) - 4), INK, 0.4)


def write_contact_sheet(path: Path, mesh: ObjectMesh, features: Sequence[Feature], **kwargs) -> Path:
    """Render :func:`contact_sheet` and write it as PNG, atomically."""
    return write_image(path, contact_sheet(mesh, features, **kwargs))
