"""Physically based rendering of one frame with Mitsuba 3, aligned to the labels.

:class:`Renderer` loads the meshes once and builds one scene: each rigid object
is a ``shapegroup`` of its parts (one principled BSDF per part) placed by an
``instance``; the hose is a mesh of fixed topology; a ``sunsky`` emitter lights
a sea plane far below. Per frame only parameters change through
``mi.traverse``: instance transforms, hose vertices, sensor pose, sun and sky,
sea height and the materials of the frame's :class:`~datagen.scene.look.FrameLook`.
The scene is rendered in a camera-centred frame (world translated so the camera
is at the origin), because world coordinates reach kilometres and Mitsuba
computes in float32.

Besides the image, a geometry pass casts one ray through each pixel centre
(continuous convention: pixel (i, j) has its centre at (i + 0.5, j + 0.5)) for
the camera z-depth ``Z`` and the :func:`~datagen.core.conventions.object_id` of
each object (0 where the ray hits the sea or nothing). Feature visibility is a
ray cast from the camera to each feature point: a point is visible when it is in
front of the camera and nothing is hit before it, up to
:func:`visibility_tolerance_m`.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import TYPE_CHECKING, Final

import numpy as np
from numpy.typing import NDArray

from datagen.assets.files import load_mesh
from datagen.assets.models import material_class
from datagen.assets.models.drogue import hose_faces, hose_placeholder, hose_vertices
from datagen.core.camera import Intrinsics
from datagen.core.conventions import OBJECT_NAMES, RIGID_OBJECTS, object_id
from datagen.core.transforms import make_transform
from datagen.render.mitsuba import (
    jit_vectors,
    mitsuba_mesh,
    sensor_dict,
    set_buffer,
    visible,
    world_from_micam,
)
from datagen.render.runtime import use_variant
from datagen.render.tonemap import exposure_scale, haze
from datagen.scene.look import FrameLook, Material, neutral_look, sun_direction_world

if TYPE_CHECKING:
    from datagen.core.features import FeatureTable
    from datagen.scene.approach import FrameState
    from datagen.scene.resolved import Scene

__all__ = ["RenderResult", "Renderer", "visibility_tolerance_m"]

#: Sea level is world z = 0; the sea plane is a square this many metres across (its edge
#: then lies under 0.04 degrees below the horizon, where sunsky is black, seen from 8 km).
SEA_SIZE_M: Final = 2.0e7


def visibility_tolerance_m(distance_m: NDArray[np.float64]) -> NDArray[np.float64]:
    """How far before a feature point a hit still counts as the point itself: 1 cm
    plus 1e-4 of the distance (float32 intersection error and mesh rounding)."""
    return 0.01 + 1e-4 * np.asarray(distance_m)


@dataclass(frozen=True)
class RenderResult:
    """One rendered frame: linear RGB, z-depth and object ids at pixel centres."""

    rgb: NDArray[np.float32]  # (H, W, 3) linear radiance, exposure applied
    depth: NDArray[np.float32] | None  # (H, W) camera z-depth, metres, +inf where nothing is hit
    object_id: NDArray[np.uint32] | None  # (H, W); both None unless the geometry pass ran
    render_s: float  # seconds inside mi.render
    denoise_s: float | None = None  # seconds in the denoiser (None: not denoised)


def _principled(m: Material) -> dict:
    return {
        "type": "principled",
        "base_color": {"type": "rgb", "value": list(m.base_color)},
        "roughness": m.roughness,
        "metallic": m.metallic,
        "specular": m.specular,
    }


class Renderer:
    """A scene loaded once; :meth:`render` poses and re-dresses it per frame."""

    def __init__(self, scene: Scene, *, spp: int | None = None, variant: str | None = None,
                 width: int | None = None, height: int | None = None) -> None:
        import drjit as dr
        import mitsuba as mi

        config = scene.config
        self.variant = use_variant(variant or config.render.variant)
        self.config = config
        cam = config.camera
        self.intrinsics = scene.intrinsics if width is None and height is None else \
            Intrinsics.from_hfov_deg(width or cam.width, height or cam.height, cam.hfov_deg)
        self.spp = spp or config.render.spp
        self.denoise = config.render.denoise
        self.guides = self.denoise != "off" and config.render.denoise_guides
        if self.denoise != "off":
            from datagen.render.denoise import oidn_version

            oidn_version()  # one line saying how to install it, before any rendering
        first = neutral_look(config)
        integrator: dict = {"type": "path", "max_depth": config.render.max_depth}
        if self.guides:  # the beauty channels are the path tracer's own (same samples, same bytes)
            from datagen.render.denoise import guided_integrator

            integrator = guided_integrator(integrator)
        description: dict = {
            "type": "scene",
            "integrator": integrator,
            "sensor": sensor_dict(self.intrinsics, np.eye(4), self.spp),
            # Mitsuba 3.9's sunsky is z-up, like our world frame (measured: black below z = 0).
            "sky": {"type": "sunsky", "sun_direction": [0.0, 0.5, 0.866]},
            "sea": {"type": "rectangle", "bsdf": _principled(Material((0.01, 0.03, 0.05), 0.1, 0.0, 0.5))},
        }
        self._parts: dict[str, list[tuple[str, str]]] = {}  # object -> [(param key prefix, material class)]
        meshes = {}
        for obj in RIGID_OBJECTS:
            mesh = load_mesh(scene.mesh_path(obj), obj)
            group = {"type": "shapegroup"}
            self._parts[obj] = []
            for i, (part, tm) in enumerate(mesh.parts.items()):
                cls = material_class(part)
                bsdf = mi.load_dict(_principled(first.materials[obj][cls]))
                key = f"{obj}_p{i}"  # unique: scalar variants tell objects apart by shape id
                shape = mitsuba_mesh(f"{obj}.{part}", tm.vertices, tm.faces, bsdf)
                group[key] = shape
                meshes[(obj, key)] = shape
                self._parts[obj].append((f"{obj}_group.{key}", cls))
            description[f"{obj}_group"] = group
            description[obj] = {"type": "instance", "shapegroup": {"type": "ref", "id": f"{obj}_group"}}
        self._hose_points = None
        self.scene = None
        self._scene_dict = description
        self._meshes = meshes
        self._mi, self._dr = mi, dr
        self._first = first

    # -- scene construction (deferred until the hose's point count is known) --------------
    def _build(self, hose_points: int) -> None:
        mi, dr = self._mi, self._dr
        hose = mitsuba_mesh("hose", hose_placeholder(hose_points), hose_faces(hose_points),
                            mi.load_dict(_principled(self._first.materials["hose"]["rubber"])))
        scene = dict(self._scene_dict, hose=hose)
        self.scene = mi.load_dict(scene, optimize=False)
        self.params = mi.traverse(self.scene)
        self._hose_points = hose_points
        # Map every shape's registry id to its object id (scalar variants name shapes instead).
        self._id_table = np.zeros(1, dtype=np.uint32)
        if self.variant.startswith("scalar"):
            return
        lookup = {}
        for (obj, _), shape in self._meshes.items():
            lookup[int(dr.reinterpret_array(mi.UInt32, mi.ShapePtr(shape))[0])] = object_id(obj)
        lookup[int(dr.reinterpret_array(mi.UInt32, mi.ShapePtr(hose))[0])] = object_id("hose")
        self._id_table = np.zeros(max(lookup) + 1, dtype=np.uint32)
        for k, v in lookup.items():
            self._id_table[k] = v

    # -- per frame ----------------------------------------------------------------------------
    def pose(self, state: FrameState, look: FrameLook) -> None:
        """Set every per-frame parameter of the scene from a frame's state and look.

        The first update after a scene is loaded leaves Mitsuba in another state than
        every later one: a frame rendered first in its process differed from the same
        frame rendered after any other (measured: 33 of 138,240 pixels at 512x270,
        one thread), so that images of a resumed build differed from an uninterrupted
        one's. A freshly loaded scene is therefore posed twice; after that, a frame's
        image does not depend on what its process rendered before."""
        fresh = self.scene is None or len(state.hose_points_world) != self._hose_points
        if fresh:
            self._build(len(state.hose_points_world))
        for _ in range(2 if fresh else 1):
            self._apply(state, look)

    def _apply(self, state: FrameState, look: FrameLook) -> None:
        mi = self._mi
        p = self.params
        cam_pos = state.world_from_cam[:3, 3]
        render_from_world = make_transform(np.eye(3), -cam_pos)
        self._world_from_cam = state.world_from_cam
        for obj in RIGID_OBJECTS:
            p[f"{obj}.to_world"] = mi.Transform4f((render_from_world @ state.world_from(obj)).tolist())
            for key, cls in self._parts[obj]:
                self._set_material(f"{key}.bsdf", look.materials[obj][cls])
        self._set_material("hose.bsdf", look.materials["hose"]["rubber"])
        hose = hose_vertices(state.hose_points_world - cam_pos)
        set_buffer(p, "hose.vertex_positions", hose.astype(np.float32))
        sensor = world_from_micam(render_from_world @ state.world_from_cam)
        p["sensor.to_world"] = mi.Transform4f(sensor.tolist())
        sea = make_transform(np.eye(3), [0.0, 0.0, -cam_pos[2]]) @ np.diag([SEA_SIZE_M / 2, SEA_SIZE_M / 2, 1.0, 1.0])
        p["sea.to_world"] = mi.Transform4f(sea.tolist())
        p["sea.bsdf.roughness.value"] = look.sea_roughness
        p["sky.sun_direction"] = mi.Vector3f(*(float(v) for v in sun_direction_world(state, look)))
        p["sky.turbidity"] = look.turbidity
        p["sky.sun_scale"] = look.sun_scale
        p["sky.sky_scale"] = look.sky_scale
        p.update()

    def _set_material(self, prefix: str, m: Material) -> None:
        p = self.params
        p[f"{prefix}.base_color.value"] = self._mi.Color3f(*m.base_color)
        p[f"{prefix}.roughness.value"] = m.roughness
        p[f"{prefix}.metallic.value"] = m.metallic
        p[f"{prefix}.specular"] = m.specular

    def render(self, state: FrameState, look: FrameLook, seed: int, *, geometry: bool = False) -> RenderResult:
        """Pose the scene and render it: exposure-scaled linear RGB, plus the geometry
        pass (depth, object ids) when ``geometry`` is asked for or haze needs it."""
        import time

        mi = self._mi
        self.pose(state, look)
        start = time.perf_counter()
        image = mi.render(self.scene, seed=seed, spp=self.spp)
        self._dr.eval(image)  # the render happens here (Dr.Jit evaluates lazily)
        self._dr.sync_thread()
        render_s = time.perf_counter() - start
        denoise_s = None
        if self.denoise == "off":
            rgb = np.array(image, dtype=np.float32)[..., :3]
        else:
            start = time.perf_counter()
            rgb = self._denoised(image)
            denoise_s = time.perf_counter() - start
        depth = ids = None
        if geometry or look.haze_visibility_m is not None:
            depth, ids = self.geometry_pass()
        rgb *= exposure_scale(look.exposure_ev)
        if look.haze_visibility_m is not None:
            rgb = haze(rgb, depth, ids, look.haze_visibility_m)
        return RenderResult(rgb, depth, ids, render_s, denoise_s)

    def _denoised(self, image) -> NDArray[np.float32]:
        """OIDN on the render's linear RGB, guided by its albedo and normal channels when
        the aov integrator made them. The channels are sliced as Dr.Jit tensors, so that
        the filter runs on the variant's device (the GPU with cuda_ad_rgb)."""
        from datagen.render.denoise import denoise_render

        out = denoise_render(image, guides=self.guides, quality=self.config.render.denoise_quality)
        return np.maximum(np.array(out, dtype=np.float32), np.float32(0.0))

    @functools.cached_property
    def _pixel_rays(self) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
        """Unit directions (camera frame) through every pixel centre, and their z
        components (z-depth per unit of ray length); computed once."""
        k = self.intrinsics
        uu, vv = np.meshgrid(np.arange(k.width) + 0.5, np.arange(k.height) + 0.5)
        d_cam = np.stack([(uu - k.cx) / k.fx, (vv - k.cy) / k.fy, np.ones_like(uu)], axis=-1).reshape(-1, 3)
        norm = np.linalg.norm(d_cam, axis=1)
        return (d_cam / norm[:, None]).astype(np.float32), (1.0 / norm).astype(np.float32)

    def cast(self, origin_render: NDArray, directions_render: NDArray):
        """Intersect rays (render frame); returns (t, object id) as numpy arrays."""
        mi, dr = self._mi, self._dr
        n = len(directions_render)
        if self.variant.startswith("scalar"):
            return self._cast_scalar(origin_render, directions_render)
        o = np.broadcast_to(np.asarray(origin_render, dtype=np.float32), (n, 3))
        ray = mi.Ray3f(jit_vectors(mi.Point3f, o), jit_vectors(mi.Vector3f, directions_render))
        si = self.scene.ray_intersect(ray, ray_flags=mi.RayFlags.Minimal, coherent=True)
        valid_dr, shape_dr = si.is_valid(), dr.reinterpret_array(mi.UInt32, si.shape)
        dr.eval(valid_dr, si.t, shape_dr)
        valid = np.asarray(valid_dr, dtype=bool)
        t = np.where(valid, np.asarray(si.t, dtype=np.float64), np.inf)
        shape_ids = np.asarray(shape_dr, dtype=np.int64)
        shape_ids = np.where(valid & (shape_ids < len(self._id_table)), shape_ids, 0)
        return t, self._id_table[shape_ids]

    def _cast_scalar(self, origin, directions):
        """:meth:`cast` one ray at a time, for the scalar_rgb fallback (slow)."""
        mi = self._mi
        o = mi.Point3f(*(float(v) for v in origin))
        t = np.full(len(directions), np.inf)
        ids = np.zeros(len(directions), dtype=np.uint32)
        for i, d in enumerate(directions):
            ray = mi.Ray3f(o, mi.Vector3f(*(float(v) for v in d)))
            si = self.scene.ray_intersect(ray)
            if si.is_valid():
                t[i] = si.t
                name = str(si.shape.id()).split("_")[0]  # shape ids are object_pN or hose
                ids[i] = object_id(name) if name in OBJECT_NAMES else 0
        return t, ids

    def geometry_pass(self) -> tuple[NDArray[np.float32], NDArray[np.uint32]]:
        """Camera z-depth and object id at every pixel centre."""
        k = self.intrinsics
        d_cam, z_per_t = self._pixel_rays
        r = self._world_from_cam[:3, :3].astype(np.float32)  # the render frame shares the world's axes
        t, ids = self.cast(np.zeros(3), d_cam @ r.T)
        depth = (t * z_per_t).reshape(k.height, k.width).astype(np.float32)
        return depth, ids.reshape(k.height, k.width).astype(np.uint32)

    def feature_visibility(self, state: FrameState, features: FeatureTable
                           ) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
        """Per feature: the fraction of its points visible from the camera and whether
        its centre is. Call after :meth:`pose` (or :meth:`render`) for the same state."""
        cam_pos = state.world_from_cam[:3, 3]
        world_from_obj = np.stack([state.world_from(o) for o in features.objects])[features.object_index]
        pts = np.concatenate([features.points_model, features.center_model[:, None]], axis=1)  # (F, P+1, 3)
        world = np.einsum("fij,fpj->fpi", world_from_obj[:, :3, :3], pts) + world_from_obj[:, None, :3, 3]
        rel = world.reshape(-1, 3) - cam_pos  # the render frame: camera at the origin
        tolerance = visibility_tolerance_m(np.linalg.norm(rel, axis=1))
        in_front = rel @ state.world_from_cam[:3, 2] > 0
        seen = (visible(self.scene, np.zeros(3), rel, tolerance) & in_front).reshape(world.shape[:2])
        p = features.points_model.shape[1]
        mask = np.arange(p)[None, :] < features.n_points[:, None]
        fraction = (seen[:, :p] & mask).sum(axis=1) / features.n_points
        return fraction, seen[:, p]
