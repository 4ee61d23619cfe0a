"""An object rendered from several viewpoints, for its contact sheet (Mitsuba).

The object's parts get fixed preview materials per material class; the scene is
loaded once and each view only moves the sensor. Besides each image, the ray
casts say which of the given points (feature centres) the camera sees.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Final

import numpy as np
from numpy.typing import NDArray

from datagen.assets.loader import ObjectMesh
from datagen.assets.models import material_class
from datagen.core.camera import Intrinsics
from datagen.render.mitsuba import mitsuba_mesh, sensor_dict, visible, world_from_micam
from datagen.render.runtime import hold_scene, use_variant

__all__ = ["render_views"]

_COLORS: Final = {
    "paint": (0.58, 0.60, 0.63),
    "glass": (0.02, 0.03, 0.05),
    "metal": (0.80, 0.80, 0.82),
    "markings": (0.55, 0.12, 0.08),
    "dark": (0.015, 0.015, 0.015),
    "fabric": (0.85, 0.84, 0.78),
    "fabric_alt": (0.85, 0.84, 0.78),
    "fabric_band": (0.85, 0.84, 0.78),
    "tape": (0.75, 0.75, 0.77),
    "strut": (0.80, 0.80, 0.82),
    "rubber": (0.03, 0.03, 0.03),
}


def _bsdf(part: str) -> dict:
    cls = material_class(part)
    color = (0.40, 0.41, 0.43) if part == "radome" else _COLORS[cls]
    return {
        "type": "principled",
        "base_color": {"type": "rgb", "value": color},
        "metallic": 1.0 if cls == "metal" else 0.0,
        "roughness": 0.05 if cls == "glass" else 0.3 if cls == "metal" else 0.55,
    }


def _scene(mesh: ObjectMesh, world_from_cam: NDArray, intrinsics: Intrinsics, spp: int):
    import mitsuba as mi

    scene: dict = {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": 4},
        "sensor": sensor_dict(intrinsics, world_from_cam, spp),
        "sky": {"type": "constant", "radiance": {"type": "rgb", "value": (0.45, 0.5, 0.6)}},
        "sun": {"type": "directional", "direction": [-0.4, -0.3, -1.0], "irradiance": {"type": "rgb", "value": 2.5}},
    }
    for name, part in mesh.parts.items():
        scene[f"part_{name}"] = mitsuba_mesh(name, part.vertices, part.faces, mi.load_dict(_bsdf(name)))
    return mi.load_dict(scene, optimize=False)


class _Views:
    """The views' scene, held for :func:`datagen.render.runtime.hold_scene` while they render."""

    def __init__(self) -> None:
        self.scene = None

    def release(self) -> None:
        self.scene = None


def render_views(mesh: ObjectMesh, poses: Sequence[NDArray], intrinsics: Intrinsics, points: NDArray, *,
                 spp: int = 64, variant: str = "auto") -> list[tuple[NDArray[np.uint8], NDArray[np.bool_]]]:
    """Per OpenCV-convention ``world_from_cam`` pose: the 8-bit BGR image of ``mesh`` and which
    of ``points`` (``(N, 3)``, the mesh's frame) the camera sees (ray casts, 1 cm tolerance)."""
    import mitsuba as mi

    use_variant(variant)
    held = _Views()
    hold_scene(held)  # no other scene in the views' kernels
    held.scene = scene = _scene(mesh, poses[0], intrinsics, spp)  # loaded once; each view only moves the sensor
    params = mi.traverse(scene)
    out = []
    for world_from_cam in poses:
        params["sensor.to_world"] = mi.Transform4f(world_from_micam(world_from_cam).tolist())
        params.update()
        image = np.asarray(mi.util.convert_to_bitmap(mi.render(scene, seed=mi.UInt32(0))))[..., ::-1].copy()
        out.append((image, visible(scene, world_from_cam[:3, 3], points, tolerance_m=0.01)))
    return out
