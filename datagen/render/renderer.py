"""Physically based rendering of one frame with Mitsuba 3, aligned to the labels.

:class:`Renderer` loads the meshes once and builds one scene: each rigid object
is a ``shapegroup`` of its parts (one principled BSDF per part) placed by an
``instance``; the hose is a mesh of fixed topology; a ``sunsky`` emitter lights
a sea plane far below. Per frame only parameters change through
``mi.traverse``: instance transforms, hose vertices, sensor pose, sun and sky,
sea height and the materials. The scene is rendered in a camera-centred frame
(world translated so the camera is at the origin), because world coordinates
reach kilometres and Mitsuba computes in float32.

Besides the image, a geometry pass casts one ray through each pixel centre
(continuous convention: pixel (i, j) has its centre at (i + 0.5, j + 0.5)) for
the camera z-depth ``Z`` and the ``object_id`` of :data:`datagen.core.conventions.OBJECT_NAMES`
(0 where the ray hits the sea or nothing). Feature visibility is a ray cast from
the camera to each feature point: a point is visible when it is in front of the
camera and nothing is hit before it, up to :func:`visibility_tolerance_m`.
"""

from __future__ import annotations

import colorsys
import functools
import math
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Final

import numpy as np
from numpy.typing import NDArray

from datagen.assets.files import RIGID_OBJECTS, load_mesh, object_paths
from datagen.core.camera import Intrinsics
from datagen.core.conventions import OBJECT_NAMES, frame_seed_sequence
from datagen.assets.models import material_class
from datagen.render.mitsuba import jit_vectors, set_buffer, visible, world_from_micam
from datagen.assets.models.drogue import hose_faces, hose_vertices
from datagen.core.transforms import make_transform

if TYPE_CHECKING:
    from datagen.scene.approach import FrameState
    from datagen.config.schema import Config
    from datagen.core.features import FeatureTable

__all__ = [
    "FrameLook",
    "RenderResult",
    "Renderer",
    "draw_look",
    "object_ids",
    "render_seed",
    "to_srgb8",
    "visibility_tolerance_m",
]

#: Sea level is world z = 0; the sea plane is a square this many metres across (its edge
#: then lies under 0.04 degrees below the horizon, where sunsky is black, seen from 8 km).
SEA_SIZE_M: Final = 2.0e7
#: Linear radiance that maps to sRGB white at 0 EV (sunsky radiance is in W/(m^2 sr nm)-like units).
WHITE_RADIANCE: Final = 0.7
#: Number of distinct values sun_scale and sky_scale take (see :func:`_levels`).
SKY_SCALE_LEVELS: Final = 5
#: Haze visibility (distance at which contrast falls to 1/e), metres, when haze is on.
HAZE_VISIBILITY_M: Final = (15_000.0, 60_000.0)


def object_ids() -> dict[str, int]:
    """The ``object_id`` of every object: 1-based position in ``OBJECT_NAMES``; 0 is background."""
    return {name: i + 1 for i, name in enumerate(OBJECT_NAMES)}


def visibility_tolerance_m(distance_m: NDArray[np.float64]) -> NDArray[np.float64]:
    """How far before a feature point a hit still counts as the point itself: 1 cm
    plus 1e-4 of the distance (float32 intersection error and mesh rounding)."""
    return 0.01 + 1e-4 * np.asarray(distance_m)


def render_seed(seed: int, frame_index: int) -> int:
    """Mitsuba's sampler seed for a frame: derived from the frame's seed sequence."""
    return int(frame_seed_sequence(seed, frame_index).generate_state(1, dtype=np.uint32)[0])


@dataclass(frozen=True)
class Material:
    base_color: tuple[float, float, float]
    roughness: float
    metallic: float = 0.0
    specular: float = 0.5


@dataclass(frozen=True)
class FrameLook:
    """Every appearance draw of one frame (recorded in the manifests)."""

    sun_elevation_deg: float
    sun_azimuth_deg: float
    turbidity: float
    sun_scale: float
    sky_scale: float
    exposure_ev: float
    sea_roughness: float
    haze_visibility_m: float | None
    materials: dict[str, dict[str, Material]] = field(default_factory=dict)  # object -> class -> material

    def flat(self) -> dict[str, object]:
        """A flat record of the draws, for a manifest row."""
        out = {k: v for k, v in asdict(self).items() if k != "materials"}
        for obj, classes in self.materials.items():
            for cls, m in classes.items():
                out[f"{obj}_{cls}_rgb"] = list(m.base_color)
                out[f"{obj}_{cls}_roughness"] = m.roughness
        return out


def _uniform(rng: np.random.Generator, bounds) -> float:
    lo, hi = bounds
    return float(rng.uniform(lo, hi))


def _levels(rng: np.random.Generator, bounds) -> float:
    """One of :data:`SKY_SCALE_LEVELS` evenly spaced values across ``bounds``, each
    equally likely. Mitsuba's ``sunsky`` keeps its sun and sky scales as scalars that
    are baked into the compiled kernel: a continuous draw would compile (and keep in
    memory) a new kernel for every frame; a few levels bound the kernels at
    ``SKY_SCALE_LEVELS**2`` for the whole dataset."""
    lo, hi = bounds
    step = int(rng.integers(SKY_SCALE_LEVELS))  # every level equally likely
    return lo + (hi - lo) * step / (SKY_SCALE_LEVELS - 1)


def _hsv(rng: np.random.Generator, saturation, value) -> tuple[float, float, float]:
    h = float(rng.uniform(0.0, 1.0))
    return tuple(float(c) for c in colorsys.hsv_to_rgb(h, _uniform(rng, saturation), _uniform(rng, value)))


def draw_look(config: Config, rng: np.random.Generator) -> FrameLook:
    """Draw a frame's sky, sun, exposure, haze and per-part materials, in a fixed order."""
    r = config.randomization
    sky, mat = r.sky, r.materials
    look = dict(
        sun_elevation_deg=_uniform(rng, sky.sun_elevation_deg),
        sun_azimuth_deg=_uniform(rng, sky.sun_azimuth_deg),
        turbidity=_uniform(rng, sky.turbidity),
        sun_scale=_levels(rng, sky.sun_scale),
        sky_scale=_levels(rng, sky.sky_scale),
        exposure_ev=_uniform(rng, r.exposure_ev),
        sea_roughness=_uniform(rng, (0.05, 0.25)),
    )
    haze = _uniform(rng, HAZE_VISIBILITY_M) if r.haze else None
    materials: dict[str, dict[str, Material]] = {}
    for obj in (*RIGID_OBJECTS, "hose"):
        materials[obj] = {
            "paint": Material(_hsv(rng, mat.paint_saturation, mat.paint_value), _uniform(rng, mat.paint_roughness)),
            "metal": Material(_hsv(rng, (0.0, 0.05), (0.6, 0.9)), _uniform(rng, mat.metal_roughness), 1.0),
            "glass": Material(_hsv(rng, (0.0, 0.3), (0.01, 0.06)), _uniform(rng, (0.02, 0.08)), 0.0, 1.0),
            "markings": Material(_hsv(rng, (0.0, 0.8), (0.05, 0.6)), _uniform(rng, mat.paint_roughness)),
            "dark": Material(_hsv(rng, (0.0, 0.1), (0.005, 0.03)), _uniform(rng, (0.4, 0.8))),
            "fabric": Material(_hsv(rng, (0.0, 0.2), (0.55, 0.9)), _uniform(rng, (0.6, 0.9))),
            "rubber": Material(_hsv(rng, (0.0, 0.1), (0.02, 0.06)), _uniform(rng, (0.5, 0.8))),
        }
    return FrameLook(**look, haze_visibility_m=haze, materials=materials)


@dataclass(frozen=True)
class RenderResult:
    """One rendered frame: linear RGB, z-depth and object ids at pixel centres."""

    rgb: NDArray[np.float32]  # (H, W, 3) linear radiance, exposure applied
    depth: NDArray[np.float32] | None  # (H, W) camera z-depth, metres, +inf where nothing is hit
    object_id: NDArray[np.uint32] | None  # (H, W); both None unless the geometry pass ran
    render_s: float  # seconds inside mi.render


#: Linear values are quantized to 16 bits before the sRGB table: finer than one 8-bit
#: step everywhere (the steepest part, near black, moves by 0.05 of a step).
_SRGB_LEVELS: Final = 65536


@functools.cache
def _srgb_table() -> NDArray[np.uint8]:
    x = np.linspace(0.0, 1.0, _SRGB_LEVELS)
    srgb = np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)
    return np.round(srgb * 255.0).astype(np.uint8)


def to_srgb8(linear: NDArray[np.floating]) -> NDArray[np.uint8]:
    """8-bit sRGB from linear RGB in [0, 1] (clipped), the IEC 61966-2-1 transfer."""
    x = np.clip(np.asarray(linear, dtype=np.float32), 0.0, 1.0)
    return _srgb_table()[np.rint(x * np.float32(_SRGB_LEVELS - 1)).astype(np.int32)]


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

    def __init__(self, config: Config, *, spp: int | None = None, variant: str | None = None,
                 threads: int | None = None, width: int | None = None, height: int | None = None) -> None:
        import drjit as dr
        import mitsuba as mi

        from datagen.render.mitsuba import mitsuba_mesh, select_variant, sensor_dict

        self.variant = select_variant(variant or config.render.variant)
        if threads is not None:
            dr.set_thread_count(threads)
        self.config = config
        cam = config.camera
        self.intrinsics = Intrinsics.from_hfov_deg(width or cam.width, height or cam.height, cam.hfov_deg)
        self.spp = spp or config.render.spp
        self._ids = object_ids()
        first = draw_look(config, np.random.default_rng(0))
        scene: dict = {
            "type": "scene",
            "integrator": {"type": "path", "max_depth": config.render.max_depth},
            "sensor": sensor_dict(self.intrinsics, np.eye(4), self.spp),
            # Mitsuba 3.9's sunsky is z-up, like our world frame (measured: black below z = 0).
            "sky": {"type": "sunsky", "sun_direction": [0.0, 0.5, 0.866]},
            "sea": {"type": "rectangle", "bsdf": _principled(Material((0.01, 0.03, 0.05), 0.1, 0.0, 0.5))},
        }
        self._parts: dict[str, list[tuple[str, str]]] = {}  # object -> [(param key prefix, material class)]
        meshes = {}
        for obj in RIGID_OBJECTS:
            mesh = load_mesh(object_paths(config, obj)[0], obj)
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
            scene[f"{obj}_group"] = group
            scene[obj] = {"type": "instance", "shapegroup": {"type": "ref", "id": f"{obj}_group"}}
        self._hose_points = None
        self.scene = None
        self._scene_dict = scene
        self._meshes = meshes
        self._mi, self._dr = mi, dr
        self._mitsuba_mesh = mitsuba_mesh
        self._first = first

    # -- scene construction (deferred until the hose's point count is known) --------------
    def _build(self, hose_points: int) -> None:
        mi, dr = self._mi, self._dr
        faces = hose_faces(hose_points)
        placeholder = np.zeros((hose_points * 12 + 2, 3))
        placeholder[:, 0] = np.arange(len(placeholder)) * 1e-3  # non-degenerate until posed
        hose = self._mitsuba_mesh("hose", placeholder, faces,
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
            lookup[int(dr.reinterpret_array(mi.UInt32, mi.ShapePtr(shape))[0])] = self._ids[obj]
        lookup[int(dr.reinterpret_array(mi.UInt32, mi.ShapePtr(hose))[0])] = self._ids["hose"]
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
        p["sky.sun_direction"] = mi.Vector3f(*(float(v) for v in self.sun_direction_world(state, look)))
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

    @staticmethod
    def sun_direction_world(state: FrameState, look: FrameLook) -> NDArray[np.float64]:
        """Unit vector towards the sun, world frame: elevation above the horizon,
        azimuth counter-clockwise from the tanker's heading at this frame."""
        x_axis = state.world_from_tanker[:3, 0]
        heading = math.atan2(x_axis[1], x_axis[0])
        az = heading + math.radians(look.sun_azimuth_deg)
        el = math.radians(look.sun_elevation_deg)
        return np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)])

    def render(self, state: FrameState, look: FrameLook, seed: int, *, geometry: bool = False) -> RenderResult:
        """Pose the scene and render it: exposure-scaled linear RGB, plus the geometry
        pass (depth, object ids) when ``geometry`` is asked for or haze needs it."""
        import time

        mi = self._mi
        self.pose(state, look)
        start = time.perf_counter()
        image = mi.render(self.scene, seed=seed, spp=self.spp)
        rgb = np.array(image, dtype=np.float32)[..., :3]
        render_s = time.perf_counter() - start
        depth = ids = None
        if geometry or look.haze_visibility_m is not None:
            depth, ids = self.geometry_pass()
        rgb *= np.float32(2.0 ** look.exposure_ev / WHITE_RADIANCE)
        if look.haze_visibility_m is not None:
            rgb = _haze(rgb, depth, ids, look.haze_visibility_m)
        return RenderResult(rgb, depth, ids, render_s)

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
                ids[i] = self._ids.get(str(si.shape.id()).split("_")[0], 0)  # ids are object_pN or hose
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


def _haze(rgb: NDArray[np.float32], depth: NDArray[np.float32], ids: NDArray[np.uint32],
          visibility_m: float) -> NDArray[np.float32]:
    """Atmospheric perspective: blend towards the sky's own colour with distance."""
    sky = ~np.isfinite(depth)
    airlight = rgb[sky].mean(axis=0) if sky.any() else rgb.reshape(-1, 3).mean(axis=0)
    transmittance = np.exp(-np.where(np.isfinite(depth), depth, np.inf) / visibility_m)[..., None]
    return (rgb * transmittance + airlight * (1 - transmittance)).astype(np.float32)


def write_png(path: Path, rgb_linear: NDArray[np.float32], *, quality: int | None = None) -> None:
    """Write 8-bit sRGB (PNG, or JPEG when the suffix says so) atomically."""
    from datagen.dataset.files import write_image

    write_image(path, to_srgb8(rgb_linear)[..., ::-1], jpeg_quality=quality or 95)


def write_exr(path: Path, result: RenderResult) -> None:
    """Linear EXR with channels R, G, B (float32), Z (float32, +inf on no hit) and
    object_id (uint32), written atomically with the OpenEXR package."""
    import OpenEXR

    from datagen.dataset.files import atomic_path

    channels = {
        "R": np.ascontiguousarray(result.rgb[..., 0]),
        "G": np.ascontiguousarray(result.rgb[..., 1]),
        "B": np.ascontiguousarray(result.rgb[..., 2]),
        "Z": np.ascontiguousarray(result.depth, dtype=np.float32),
        "object_id": np.ascontiguousarray(result.object_id, dtype=np.uint32),
    }
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    with atomic_path(path) as tmp:
        with OpenEXR.File(header, channels) as exr:
            exr.write(str(tmp))


def render_frames(config: Config, frames, out: Path, *, spp: int | None = None, scale: float = 1.0,
                  exr: bool = False, seed: int | None = None) -> list[Path]:
    """Render frames of a config into ``out`` as ``{name}-{frame:06d}.png`` (and ``.exr``)."""
    from datagen.scene.approach import frame_state
    from datagen.core.conventions import frame_rng

    seed = config.dataset.seed if seed is None else seed
    cam = config.camera
    renderer = Renderer(config, spp=spp, width=max(1, round(cam.width * scale)),
                        height=max(1, round(cam.height * scale)))
    written = []
    for i in frames:
        state = frame_state(config, i, seed)
        result = renderer.render(state, draw_look(config, frame_rng(seed, i)), render_seed(seed, i),
                                 geometry=exr or config.render.exr)
        stem = Path(out) / f"{config.name}-{i:06d}"
        ext = ".jpg" if config.render.image_format == "jpg" else ".png"
        write_png(stem.with_suffix(ext), result.rgb, quality=config.render.jpeg_quality)
        written.append(stem.with_suffix(ext))
        if exr or config.render.exr:
            write_exr(stem.with_suffix(".exr"), result)
            written.append(stem.with_suffix(".exr"))
    return written


#: Frames of the gallery: spread over each config's approach chains and distances.
GALLERY_FRAMES: Final = (0, 7, 21, 45)


def write_gallery(configs, out: Path, *, spp: int = 16, tile=(512, 270)) -> Path:
    """Render :data:`GALLERY_FRAMES` of each config at twice the tile size, scale
    them down and write one sheet (a row per config) with captions."""
    import cv2

    from datagen.scene.approach import frame_state
    from datagen.core.conventions import frame_rng
    from datagen.dataset.files import write_image

    rows = []
    for config in configs:
        seed = config.dataset.seed
        renderer = Renderer(config, spp=spp, width=2 * tile[0], height=2 * tile[1])
        tiles = []
        for i in GALLERY_FRAMES:
            state = frame_state(config, i, seed)
            result = renderer.render(state, draw_look(config, frame_rng(seed, i)), render_seed(seed, i))
            image = cv2.resize(to_srgb8(result.rgb)[..., ::-1], tile, interpolation=cv2.INTER_AREA)
            caption = f"{config.name} #{i}  PtD {state.distance_m:.1f} m"
            cv2.putText(image, caption, (6, 18), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (255, 255, 255), 1, cv2.LINE_AA)
            tiles.append(image)
        rows.append(np.concatenate(tiles, axis=1))
    return write_image(out, np.concatenate(rows, axis=0), jpeg_quality=90)
