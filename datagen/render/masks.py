"""Full-object silhouettes by ray casting: each object alone, as if nothing occluded it.

The BOP format records, besides the visible mask of an object (which datagen's EXR
``object_id`` pass gives), the mask of the whole object in the image and its pixel count
(``px_count_all``), from which ``visib_fract`` follows. :class:`Silhouettes` casts one ray
through every pixel centre (continuous pixels, :mod:`datagen.core.conventions`) against a
scene holding only that object's mesh.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
from numpy.typing import ArrayLike, NDArray

from datagen.core.camera import Intrinsics
from datagen.core.conventions import pixel_centres
from datagen.render.mitsuba import jit_vectors, mitsuba_mesh
from datagen.render.runtime import hold_scene, use_variant

__all__ = ["Silhouettes"]


class Silhouettes:
    """One Mitsuba scene per object mesh (``name -> (vertices (V, 3), faces (F, 3))``, body
    frame, metres), loaded when first needed (and again after :meth:`release`, when another
    holder took the process's scene: :func:`datagen.render.runtime.hold_scene`); :meth:`mask`
    casts a frame's pixel rays against one."""

    def __init__(self, meshes: Mapping[str, tuple[ArrayLike, ArrayLike]], intrinsics: Intrinsics,
                 variant: str = "auto") -> None:
        import mitsuba as mi

        use_variant(variant)
        self._mi = mi
        self.intrinsics = k = intrinsics
        self._meshes = meshes
        self.scenes: dict | None = None
        uu, vv = pixel_centres(k.width, k.height)
        self._d_cam = np.stack([(uu - k.cx) / k.fx, (vv - k.cy) / k.fy, np.ones_like(uu)], axis=-1).reshape(-1, 3)

    def release(self) -> None:
        """Drop the Mitsuba scenes (loaded again by the next :meth:`mask`)."""
        self.scenes = None

    def mask(self, name: str, cam_from_object: ArrayLike) -> NDArray[np.bool_]:
        """``(H, W)`` the pixels whose centre ray meets object ``name`` posed at ``cam_from_object``."""
        mi = self._mi
        if self.scenes is None:
            hold_scene(self)
            self.scenes = {n: mi.load_dict({"type": "scene", "object": mitsuba_mesh(n, v, f)}, optimize=False)
                           for n, (v, f) in self._meshes.items()}
        object_from_cam = np.linalg.inv(np.asarray(cam_from_object, dtype=np.float64))
        directions = self._d_cam @ object_from_cam[:3, :3].T
        origins = np.broadcast_to(object_from_cam[:3, 3], directions.shape)
        ray = mi.Ray3f(jit_vectors(mi.Point3f, origins), jit_vectors(mi.Vector3f, directions))
        hit = self.scenes[name].ray_test(ray)
        return np.asarray(hit, dtype=bool).reshape(self.intrinsics.height, self.intrinsics.width)
