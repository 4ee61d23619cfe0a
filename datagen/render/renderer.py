"""Physically based rendering of one frame with Mitsuba 3, aligned to the labels.

:class:`Renderer` loads the meshes once and builds one scene: each rigid object
is a ``shapegroup`` of its parts (one principled BSDF per part) placed by an
``instance``; the hose is a mesh of fixed topology; the sun and sky
(:mod:`datagen.render.sky`) light the sea far below, the earth's round surface
(:func:`~datagen.render.world.earth_cap`, a shape group an instance places under the
camera). Per frame only parameters
change, as kernel inputs (``mi.traverse``, opaque values; the sensors' pose assigned
without reading it back, :func:`~datagen.render.mitsuba.place_sensor`): instance transforms, hose
vertices, sensor pose, sun and sky, sea height and the materials of the frame's
:class:`~datagen.scene.look.FrameLook`. The scene is rendered in a camera-centred
frame (world translated so the camera is at the origin), because world coordinates
reach kilometres and Mitsuba computes in float32. A renderer builds its Mitsuba
objects when first posed and holds the process's only scene while it does
(:func:`datagen.render.runtime.hold_scene`).

Besides the image, the geometry pass and feature visibility cast rays in the posed scene
(:class:`~datagen.render.raycast.RayCasting`); the geometry pass's distances give the
aerial perspective (:mod:`datagen.render.atmosphere`).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Final, Protocol

import numpy as np
from numpy.typing import NDArray

from datagen.assets.drogues import HOSE_TEXEL_M, HOSE_TEXELS, hose_band_texture
from datagen.assets.loader import load_mesh
from datagen.assets.models import material_class
from datagen.assets.models.drogue import hose_faces, hose_placeholder, hose_texcoords, hose_vertices
from datagen.assets.rig import MOUNTS
from datagen.core.camera import Intrinsics, distortion_margin_px
from datagen.core.conventions import OTHER_AIRCRAFT_ID, RIGID_OBJECTS, object_id, target_render_seed
from datagen.core.transforms import make_transform
from datagen.render.aerial import AIRLIGHT_STEP_PX
from datagen.render.atmosphere import Atmosphere
from datagen.render.frozen import Frozen, frozen_cast, frozen_render, settle
from datagen.render.mitsuba import (
    jit_array,
    mitsuba_mesh,
    place_sensor,
    scene_array,
    sensor_dict,
    set_buffer,
    world_from_micam,
)
from datagen.render.paintwork import Paintwork
from datagen.render.raycast import RayCasting, cast_kernel
from datagen.render.runtime import hold_scene, use_variant
from datagen.render.sky import sky_class
from datagen.render.target import (
    PLACEMENT_STRIDE_PX,
    TARGET_SENSOR,
    TargetWindow,
    merge_target,
    target_size,
    target_window,
    window_offsets,
)
from datagen.render.timing import DENOISE, PATH_TRACING, StageClock
from datagen.render.tonemap import exposure_scale
from datagen.render.world import CLOUD_LAYERS, SEA_COLOUR, World, earth_cap
from datagen.scene.look import FrameLook, Material, neutral_look, sun_direction_world
from datagen.scene.traffic import world_from_traffic

if TYPE_CHECKING:
    from datagen.core.features import FeatureTable
    from datagen.scene.approach import FrameState
    from datagen.scene.resolved import Scene

__all__ = ["FrameRenderer", "RenderResult", "Renderer"]

#: The kinds of other aircraft (datagen.scene.traffic): an instance of each object's meshes.
TRAFFIC_KINDS: Final = ("receiver", "tanker")
#: The windscreen frame's paint: a dark, matte cockpit frame, nearly black as seen from the unlit cockpit
#: (the render has no cockpit to shade its inner side from the sky).
WINDSCREEN_FRAME: Final = Material((0.008, 0.008, 0.009), 0.9, 0.0, 0.02)
#: An other aircraft not in the frame waits this far below the sea.
HIDDEN_DEPTH_M: Final = 5000.0
#: The stage that sees the frame through the air.
AERIAL_PERSPECTIVE: Final = "aerial perspective"
#: With clouds, the render frame's origin is at a multiple of this altitude (see Renderer._render_origin).
CLOUD_REFERENCE_STEP_M: Final = 50.0
#: The cloud-lighting probe counts its sky samples within SUN_CONE_DEG of the sun as the
#: sun's light (its disc is 0.53 degrees across), the rest as the sky's.
SUN_CONE_DEG: Final = 1.0


@dataclass(frozen=True)
class RenderResult:
    """One rendered frame: linear RGB, z-depth and object ids at pixel centres."""

    linear: NDArray[np.float32] | Callable[[], NDArray[np.float32]]  # rgb, or where the device holds it its copy
    depth: NDArray[np.float32] | None  # (H, W) camera z-depth, metres, +inf where nothing is hit
    object_id: NDArray[np.uint32] | None  # (H, W); both None unless the geometry pass ran
    render_s: float  # seconds inside mi.render
    denoise_s: float | None = None  # seconds in the denoiser (None: not denoised)
    surface: NDArray[np.uint8] | None = None  # (H, W) datagen.render.world.SURFACES codes (geometry pass)
    measured: dict | None = None  # what the camera model measured (datagen.render.sensor.apply_sensor)
    stages: dict[str, float] | None = None  # wall seconds per stage (datagen.render.timing.StageClock)
    srgb8: NDArray[np.uint8] | None = None  # the 8-bit image, tone curve included, where the camera model made it

    @functools.cached_property
    def rgb(self) -> NDArray[np.float32]:
        """(H, W, 3) linear radiance, exposure applied (copied from the device when first asked)."""
        return self.linear() if callable(self.linear) else self.linear


class FrameRenderer(Protocol):
    """What the build asks of a renderer (:class:`Renderer` is the one there is): a frame's
    image and geometry from its state and look, and its features' visibility after it."""

    def render(self, state: FrameState, look: FrameLook, seed: int, *, geometry: bool = False) -> RenderResult:
        """The frame, posed and rendered with Mitsuba's sampler seed ``seed``."""

    @property
    def recordings(self) -> int:
        """How many times the path tracing was recorded (0: it is traced every frame)."""

    @property
    def cast_recordings(self) -> int:
        """How many times the geometry pass's ray cast was recorded (0: traced every frame)."""

    def feature_visibility(self, state: FrameState, features: FeatureTable
                           ) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
        """Per feature: the share of its points the camera sees, and whether it sees the centre."""


def _principled(m: Material) -> dict:
    return {
        "type": "principled",
        "base_color": {"type": "rgb", "value": list(m.base_color)},
        "roughness": m.roughness,
        "metallic": m.metallic,
        "specular": m.specular,
    }


class Renderer(RayCasting):
    """A scene loaded once; :meth:`render` poses and re-dresses it per frame."""

    def __init__(self, scene: Scene, *, spp: int | None = None, variant: str | None = None,
                 width: int | None = None, height: int | None = None) -> None:
        import drjit as dr
        import mitsuba as mi

        config = scene.config
        self.variant = use_variant(variant or config.render.variant)
        self.config = config
        cam = config.camera
        #: The image the renderer returns; with lens distortion, the pinhole render has a margin.
        self.output_intrinsics = scene.intrinsics if width is None and height is None else \
            Intrinsics.from_hfov_deg(width or cam.width, height or cam.height, cam.hfov_deg)
        self.release()  # no Mitsuba object yet: each build makes them (and the World that holds some)
        sensor = config.randomization.sensor
        self.sensor = sensor if sensor.enabled else None
        self.margin_px = 0
        if self.sensor is not None and sensor.distortion:
            self.margin_px = int(distortion_margin_px(self.output_intrinsics, sensor.k1, sensor.k2, sensor.tangential))
        #: The pinhole render's grid (the output image grown by the margin).
        self.intrinsics = self.output_intrinsics.with_margin(self.margin_px)
        self.spp = spp or config.render.spp
        #: Samples added over a window on the objects (datagen.render.target; 0: none, as in
        #: scalar variants, which render no second sensor) and the window's size.
        self.target_spp = 0 if self.variant.startswith("scalar") else config.render.target_spp
        self._target_size = target_size(self.intrinsics, config.render.target_window)
        #: Run the geometry pass on every frame: the camera model, the image statistics and the
        #: target pass's window (its coarse grid rides in the pass's cast) need it.
        self.always_geometry = self.sensor is not None or self.world.any or self.target_spp > 0
        # The path tracing recorded once and replayed (datagen.render.frozen); None: traced each frame.
        frozen = config.render.frozen and not self.variant.startswith("scalar")
        self._frozen = Frozen(lambda: frozen_render(self.trace)) if frozen else None
        # The geometry pass's ray cast, frozen with the render (datagen.render.raycast.cast_kernel).
        self._frozen_cast = Frozen(lambda: frozen_cast(cast_kernel)) if frozen else None
        self.denoise = config.render.denoise
        self.guides = self.denoise != "off" and config.render.denoise_guides
        if self.denoise != "off":
            from datagen.render.denoise import oidn_version

            oidn_version()  # one line saying how to install it, before any rendering
        self._first = neutral_look(config)
        self._meshes_loaded = {obj: load_mesh(scene.mesh_path(obj), obj) for obj in RIGID_OBJECTS}
        self._mi, self._dr = mi, dr
        self._camera_render = np.zeros(3)
        self._irradiance: Any = None  # the frame's sun and sky irradiance (where the clouds or the lights need it)

    # -- scene construction (deferred until the hose's point count is known) --------------
    def release(self) -> None:
        """Drop every Mitsuba object of the scene (:func:`datagen.render.runtime.hold_scene`);
        the next :meth:`pose` builds them again."""
        # Mitsuba's objects (their types are the variant's).
        self.scene: Any = None
        self.params: Any = None
        self.sky: Any = None
        self.aerial: Any = None
        self._target_params: Any = None
        self._meshes: dict = {}
        self._parts: dict[str, list[tuple[str, str]]] = {}  # object -> [(param key prefix, material class)]
        self._sky_probe_inputs: tuple[Any, Any] | None = None
        self._hose_points: int | None = None  # the hose's point count
        randomization = self.config.randomization
        self.world = World(randomization, pixel_rad=1.0 / self.output_intrinsics.fx)
        self.paintwork = Paintwork(randomization.livery, pixel_rad=1.0 / self.output_intrinsics.fx)

    def _description(self) -> dict:
        """The scene's ``mi.load_dict`` entries, the hose aside (its Mitsuba objects made here)."""
        mi, config, first = self._mi, self.config, self._first
        sea_bsdf = self.world.sea_bsdf(_principled(Material(SEA_COLOUR, 0.1, 0.0, 0.5)))
        integrator: dict = {"type": self.world.integrator, "max_depth": config.render.max_depth}
        if config.randomization.haze.enabled and not self.variant.startswith("scalar"):
            from datagen.render.aerial import aerial_class

            # Each camera sample seen through the air (the path tracer wrapped; scalar
            # variants see the finished image through it: aerial_perspective).
            self.aerial = aerial_class(self.variant)(mi.load_dict(integrator))
            integrator = self.aerial
        if self.guides:  # the beauty channels are the path tracer's own (same samples, same bytes)
            from datagen.render.denoise import guided_integrator

            integrator = guided_integrator(integrator)
        self.sky = sky_class(self.variant)()
        description: dict = {
            "type": "scene",
            "integrator": integrator,
            "sensor": sensor_dict(self.intrinsics, np.eye(4), self.spp),
            **({"target_sensor": sensor_dict(self.intrinsics, np.eye(4), self.target_spp, size=self._target_size)}
               if self.target_spp else {}),
            # Mitsuba 3.9's sunsky is z-up, like our world frame (it is black below z = 0).
            "sky": self.sky,
            "sea_group": {"type": "shapegroup", "sea": self._sea_mesh(sea_bsdf)},
            "earth": {"type": "instance", "shapegroup": {"type": "ref", "id": "sea_group"}},
            **self.world.cloud_shapes(),
        }
        for obj, mesh in self._meshes_loaded.items():
            group = {"type": "shapegroup"}
            self._parts[obj] = []
            for i, (part, tm) in enumerate(mesh.parts.items()):
                cls = material_class(part)
                key = f"{obj}_p{i}"  # unique: scalar variants tell objects apart by shape id
                wear = self.paintwork.wears(obj, cls)
                if wear is not None:  # the paintwork's (datagen.render.paintwork): one BSDF per object
                    self.paintwork.airframe(obj, mesh)
                    vertices, faces, uv = self.paintwork.part(obj, mesh, wear, tm)
                    bsdf = self.paintwork.bsdf(obj, wear, _principled(first.materials[obj][cls]))
                    shape = mitsuba_mesh(f"{obj}.{part}", vertices, faces, bsdf, texcoords=uv)
                    cls = wear if all(c != wear for _, c in self._parts[obj]) else "shared"
                else:
                    bsdf = mi.load_dict(_principled(first.materials[obj][cls]))
                    shape = mitsuba_mesh(f"{obj}.{part}", tm.vertices, tm.faces, bsdf)
                group[key] = shape
                self._meshes[(obj, key)] = shape
                self._parts[obj].append((f"{obj}_group.{key}", cls))
            description[f"{obj}_group"] = group
            description[obj] = {"type": "instance", "shapegroup": {"type": "ref", "id": f"{obj}_group"}}
            if obj in TRAFFIC_KINDS and config.randomization.traffic.enabled:  # another of it (scene.traffic)
                description[f"other_{obj}"] = {"type": "instance", "shapegroup": {"type": "ref", "id": f"{obj}_group"}}
        if self._windscreen:  # a cockpit camera's windscreen frame (datagen.assets.models.windscreen)
            from datagen.assets.models.windscreen import windscreen_frame

            frame = windscreen_frame(MOUNTS[config.camera.mount])
            description["windscreen_group"] = {"type": "shapegroup", "frame": mitsuba_mesh(
                "windscreen_frame", frame.vertices, frame.faces, mi.load_dict(_principled(WINDSCREEN_FRAME)))}
            description["windscreen_frame"] = {"type": "instance",
                                               "shapegroup": {"type": "ref", "id": "windscreen_group"}}
        return description

    @property
    def _windscreen(self) -> bool:
        w = self.config.randomization.window
        return w.enabled and w.canopy_frame and MOUNTS[self.config.camera.mount].window == "windscreen"

    def _sea_mesh(self, bsdf: dict):
        """The sea: the earth's cap (:func:`~datagen.render.world.earth_cap`) under ``bsdf``."""
        vertices, faces, uv, normals = earth_cap()
        return mitsuba_mesh("sea", vertices, faces, self._mi.load_dict(bsdf), texcoords=uv, normals=normals)

    def _build(self, hose_points: int) -> None:
        mi, dr = self._mi, self._dr
        hold_scene(self)
        self.release()
        description = self._description()
        hose_bsdf = _principled(self._first.materials["hose"]["rubber"])
        banded = self._hose_banded
        if banded:  # the marker bands: a texture along the hose (datagen.assets.drogues)
            hose_bsdf["base_color"] = {"type": "bitmap", "raw": True, "wrap_mode": "clamp", "filter_type": "nearest",
                                       "data": scene_array(mi.TensorXf, np.zeros((2, HOSE_TEXELS, 3), np.float32))}
        placeholder = hose_placeholder(hose_points)
        hose = mitsuba_mesh("hose", placeholder, hose_faces(hose_points), mi.load_dict(hose_bsdf),
                            texcoords=np.zeros((len(placeholder), 2), np.float32) if banded else None)
        self._hose_key: tuple | None = None
        self._assigned: dict[str, Any] = {}  # what _assign last set each key to
        self.scene = mi.load_dict(dict(description, hose=hose), optimize=False)
        self.params = mi.traverse(self.scene)
        self._unsettled = True  # the frozen render's first pose settles the scene (_apply)
        if self._frozen is not None:  # the films and samplers as a render leaves them: one recording
            for sensor in self.scene.sensors():
                sensor.film().prepare(self.scene.integrator().aov_names())
                settle(sensor.film(), literals=True)  # (frozen.settle)
                settle(sensor.sampler(), literals=True)
        self._hose_points = hose_points
        if self.variant.startswith("scalar"):  # its ray casts name the shapes they hit
            return

        def registry_id(shape) -> int:
            return int(dr.reinterpret_array(mi.UInt32, mi.ShapePtr(shape))[0])

        # Per registry id of what a ray meets (raycast.hit_key: an instance, else a top-level
        # shape): its object id; per id + 1 (0: no hit): its index in ("sea", *CLOUD_LAYERS), -1
        # for the rest. Tables on the device (the geometry pass's cast, the air's).
        top = {shape.id(): shape for shape in self.scene.shapes()}
        objects = {registry_id(top[obj]): object_id(obj) for obj in self._meshes_loaded}
        objects[registry_id(hose)] = object_id("hose")
        twins = {kind: registry_id(top[f"other_{kind}"]) for kind in TRAFFIC_KINDS if f"other_{kind}" in top}
        objects.update(dict.fromkeys(twins.values(), OTHER_AIRCRAFT_ID))  # another aircraft (scene.traffic)
        self.paintwork.bind_twins(twins)
        layers = ("sea", *CLOUD_LAYERS)
        backgrounds = {registry_id(shape): layers.index(name) for name, shape in
                       (("sea", top["earth"]), *self.world.cloud_meshes.items())}
        ids = np.zeros(max(objects) + 1, dtype=np.uint32)
        ids[list(objects)] = list(objects.values())
        codes = np.full(max(backgrounds) + 2, -1, dtype=np.int32)
        codes[[k + 1 for k in backgrounds]] = list(backgrounds.values())
        # In Dr.Jit's memory: the frozen ray cast takes both as inputs (datagen.render.frozen).
        self._id_table, self._background_codes = scene_array(mi.UInt32, ids), scene_array(mi.Int32, codes)
        if self.sensor is not None and self.sensor.motion_blur:
            from datagen.render.sensor import warm_up_on_device

            warm_up_on_device()

    # -- per frame ----------------------------------------------------------------------------
    def pose(self, state: FrameState, look: FrameLook, clock: StageClock | None = None) -> None:
        """Set every per-frame parameter of the scene from a frame's state and look.

        The first update after a scene is loaded leaves Mitsuba in another state than
        every later one (a few pixels of a frame rendered first in its process differ
        from the same frame rendered after another), so a freshly loaded scene is posed
        twice: a frame's image does not depend on what its process rendered before, and a
        resumed build's images are an uninterrupted one's."""
        fresh = self.scene is None or len(state.hose_points_world) != self._hose_points
        if fresh:
            self._build(len(state.hose_points_world))
        for _ in range(2 if fresh else 1):
            if fresh:
                self._assigned.clear()  # each of the two poses sets every parameter
            self._apply(state, look, clock or StageClock())

    def _apply(self, state: FrameState, look: FrameLook, clock: StageClock) -> None:
        mi = self._mi
        p = self.params
        cam_pos = state.world_from_cam[:3, 3]
        origin = self._render_origin(cam_pos)
        render_from_world = make_transform(np.eye(3), -origin)
        self._world_from_cam = state.world_from_cam
        self._camera_render = cam_pos - origin
        sun = sun_direction_world(state, look)
        self.sky.set(sun, look.turbidity, look.sun_scale, look.sky_scale)
        with clock.stage("cloud-lighting probe"):
            irradiance = self._sky_irradiance(sun) if self.world.clouds or self.paintwork.lights else None
        render_from_body = {}
        for obj in RIGID_OBJECTS:
            render_from_body[obj] = render_from_world @ state.world_from(obj)
            p[f"{obj}.to_world"] = mi.Transform4f(render_from_body[obj].tolist())
            for key, cls in self._parts[obj]:
                if cls == "livery":
                    self._set_livery(self.paintwork.material_prefix(f"{key}.bsdf", cls), look, obj)
                elif cls == "markings":
                    self._set_paint(f"{key}.bsdf", look.materials[obj][cls])
                    self._assign(f"{key}.bsdf.roughness.value", look.materials[obj][cls].roughness)
                elif cls != "shared":
                    self._set_material(f"{key}.bsdf", look.materials[obj][cls])
        render_from_twin = {}
        if self.config.randomization.traffic.enabled:
            other = world_from_traffic(state, look.other_aircraft_tanker_m, look.other_aircraft_heading_deg)
            for kind in TRAFFIC_KINDS:
                # Where there is none: far below the sea, under the camera (hidden by the earth).
                pose = (render_from_world @ other if other is not None and look.other_aircraft == kind
                        else make_transform(np.eye(3), [0.0, 0.0, -origin[2] - HIDDEN_DEPTH_M]))
                p[f"other_{kind}.to_world"] = mi.Transform4f(pose.tolist())
                render_from_twin[kind] = pose
        self.paintwork.apply(look, render_from_body, self._camera_render, render_from_twin)
        self._irradiance = irradiance
        hose = hose_vertices(state.hose_points_world - origin)
        set_buffer(p, "hose.vertex_positions", hose.astype(np.float32))
        self._set_hose(look, state.hose_points_world)
        if self._windscreen:
            p["windscreen_frame.to_world"] = mi.Transform4f((render_from_world @ state.world_from("receiver")).tolist())
        sensor = world_from_micam(render_from_world @ state.world_from_cam)
        for camera in self.scene.sensors():  # the frame's and the target pass's (its window: aim_target)
            place_sensor(camera, sensor)
        # The earth's top under the camera (the render frame's origin is over the camera's nadir).
        p["earth.to_world"] = mi.Transform4f(make_transform(np.eye(3), [0.0, 0.0, -origin[2]]).tolist())
        self.world.apply(p, look, float(origin[2]), irradiance, camera_render=self._camera_render, sun_direction=sun)
        p.update()
        with clock.stage("texture values"):  # outside the render: a recording of it reads them as data
            for texture in self._textures():
                texture.prepare()
        if self._frozen is not None:  # nothing left pending for the frozen render (frozen.settle)
            settle(self.sky)  # every frame: the sun's angles
            if self._unsettled:  # once a scene: what loading it left (the hose's buffers)
                settle(self.scene)
                self._unsettled = False

    def _textures(self) -> tuple:
        """Every procedural texture of the scene: the world's and the paintwork's."""
        return (*self.world.textures(), *self.paintwork.textures())

    @property
    def camera_render(self) -> NDArray[np.float64]:
        """The posed camera's position in the render frame (the origin, or with clouds a
        point at most :data:`CLOUD_REFERENCE_STEP_M` / 2 from it: :meth:`_render_origin`)."""
        return self._camera_render.copy()

    def _render_origin(self, cam_pos: NDArray[np.float64]) -> NDArray[np.float64]:
        """Where the render frame's origin is in the world: the camera, or with clouds the
        point above it at a multiple of :data:`CLOUD_REFERENCE_STEP_M` metres altitude, so
        that the cloud layers' meshes stay where they are while the camera climbs or sinks
        a few metres (Mitsuba rebuilds a mesh's acceleration structure when it moves)."""
        if not self.world.clouds:
            return np.asarray(cam_pos, dtype=np.float64)
        z = round(float(cam_pos[2]) / CLOUD_REFERENCE_STEP_M) * CLOUD_REFERENCE_STEP_M
        return np.array([cam_pos[0], cam_pos[1], z])

    def _sky_irradiance(self, sun: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """RGB irradiance of the frame's sun (the samples within :data:`SUN_CONE_DEG` of
        ``sun``) and of the rest of its sky on a horizontal surface, no occluders, from a
        fixed stratified set of the scene's own sky's importance samples (deterministic;
        nothing else of the scene is involved). The samples' inputs are made once and
        opaque: built per call, they sometimes compiled three new kernels (a literal folded
        into one frame's probe and not another's)."""
        mi, dr = self._mi, self._dr
        sky = self.sky
        scalar = self.variant.startswith("scalar")
        n = 16 if scalar else 64  # the scalar fallback samples one direction per call
        grid = ((np.stack(np.meshgrid(np.arange(n), np.arange(n)), -1).reshape(-1, 2) + 0.5) / n).astype(np.float32)
        if scalar:
            samples = [sky.sample_direction(dr.zeros(mi.Interaction3f), mi.Point2f(float(u), float(v)))
                       for u, v in grid]
            weights = np.asarray([[weight[c] for c in range(3)] for _, weight in samples], np.float64)
            directions = np.asarray([[ds.d.x, ds.d.y, ds.d.z] for ds, _ in samples], np.float64)
        else:
            if self._sky_probe_inputs is None:
                it = dr.zeros(mi.Interaction3f, n * n)
                uv = mi.Point2f(jit_array(mi.Float, grid[:, 0]), jit_array(mi.Float, grid[:, 1]))
                dr.make_opaque(it, uv)
                self._sky_probe_inputs = it, uv
            ds, weight = sky.sample_direction(*self._sky_probe_inputs)
            dr.eval(ds.d, weight)
            weights = np.stack([np.asarray(weight[c], np.float64) for c in range(3)], -1)
            directions = np.stack([np.asarray(ds.d[c], np.float64) for c in range(3)], -1)
        e = weights * np.maximum(directions[:, 2:3], 0.0) / len(grid)
        in_sun = directions @ np.asarray(sun, np.float64) > math.cos(math.radians(SUN_CONE_DEG))
        return e[in_sun].sum(axis=0), e[~in_sun].sum(axis=0)

    def _set_livery(self, prefix: str, look: FrameLook, obj: str) -> None:
        """An object's painted parts under its livery (their colour and roughness are the
        paintwork's textures): the paint's draws (or, for bare metal, the metal's) give the rest."""
        bare = getattr(look, f"{obj}_livery", None) == "bare_metal"
        self._set_paint(prefix, look.materials[obj]["metal" if bare else "paint"])

    def _set_paint(self, prefix: str, m: Material) -> None:
        """A principled BSDF's scalar draws (its colour and roughness being textures)."""
        self._assign(f"{prefix}.metallic.value", m.metallic)
        self._assign(f"{prefix}.specular", m.specular)

    def _assign(self, key: str, value: float | tuple[float, ...], make: Callable[[], Any] | None = None) -> None:
        """Set the scene's parameter ``key`` to ``value`` (or to what ``make`` makes of it: a
        Mitsuba type), unless what it holds is the value this set last: a parameter drawn
        once an approach, and the object it belongs to, are not touched again every frame."""
        if key in self._assigned and self._assigned[key] == value:
            return
        self.params[key] = value if make is None else make()
        self._assigned[key] = value

    @property
    def _hose_banded(self) -> bool:
        d = self.config.randomization.drogue
        return d.enabled and d.hose_bands

    def _set_hose(self, look: FrameLook, points: NDArray[np.float64]) -> None:
        """The hose's rubber, and where it has marker bands their texture (made once per
        approach) and the frame's texture coordinates along it."""
        rubber = look.materials["hose"]["rubber"]
        if not self._hose_banded:
            self._set_material("hose.bsdf", rubber)
            return
        p = self.params
        key = (rubber.base_color, look.hose_band_colour, look.hose_band_spacing_m, look.hose_band_width_m)
        if key != self._hose_key:
            texture = hose_band_texture(rubber.base_color, look.hose_band_colour, look.hose_band_spacing_m,
                                        look.hose_band_width_m)
            p["hose.bsdf.base_color.data"] = scene_array(self._mi.TensorXf, texture)
            self._hose_key = key
        self._assign("hose.bsdf.roughness.value", rubber.roughness)
        self._assign("hose.bsdf.metallic.value", rubber.metallic)
        self._assign("hose.bsdf.specular", rubber.specular)
        set_buffer(p, "hose.vertex_texcoords", hose_texcoords(points, HOSE_TEXELS * HOSE_TEXEL_M))

    def _set_material(self, prefix: str, m: Material) -> None:
        self._assign(f"{prefix}.base_color.value", tuple(m.base_color), lambda: self._mi.Color3f(*m.base_color))
        self._assign(f"{prefix}.roughness.value", m.roughness)
        self._assign(f"{prefix}.metallic.value", m.metallic)
        self._assign(f"{prefix}.specular", m.specular)

    def path_trace(self, seed: int, window: TargetWindow | None = None):
        """The posed scene path traced with sampler seed ``seed``, and over ``window`` by the
        target pass (:mod:`datagen.render.target`; None: not), merged: Mitsuba's image (not
        yet evaluated), through the frozen render where there is one."""
        mi, dr = self._mi, self._dr
        offsets = None
        if window is not None:
            self.aim_target(window)
            offsets = window_offsets(mi, dr, window)
        if self._frozen is None:
            return self.trace(self.scene, seed, target_render_seed(seed), offsets)
        args = (self.scene, dr.opaque(mi.UInt32, seed), dr.opaque(mi.UInt32, target_render_seed(seed)), offsets,
                tuple(t.inputs() for t in self._textures()))
        return self._frozen(self.trace, *args)  # traced where refused

    def trace(self, scene, seed, target_seed, offsets, textures: tuple = ()):
        """What the frozen render records: the frame's path tracing with sampler seed
        ``seed`` and, with ``offsets`` (:func:`~datagen.render.target.window_offsets`), the
        target pass's with ``target_seed`` merged into it (:func:`~datagen.render.target.merge_target`).
        ``textures``: the procedural textures' device values (their ``inputs``), which the
        render reads through the scene; a frozen function finds its inputs among its
        arguments, and the textures hold theirs where its walk over the scene passes by."""
        mi = self._mi
        image = mi.render(scene, seed=seed, spp=self.spp)
        if offsets is not None:
            window_image = mi.render(scene, sensor=TARGET_SENSOR, seed=target_seed, spp=self.target_spp)
            merge_target(mi, self._dr, image, window_image, offsets, self.spp, self.target_spp)
        return image

    def aim_target(self, window: TargetWindow) -> None:
        """Point the target pass's sensor at ``window``: its principal point moved (opaque
        values, so that the recording reads them as data), everything else the frame's."""
        mi, dr = self._mi, self._dr
        sensor = self.scene.sensors()[TARGET_SENSOR]
        if self._target_params is None:  # the sensor's own: an update walks its keys, not the scene's
            self._target_params = mi.traverse(sensor)
        x, y = window.principal_point_offset
        self._target_params["principal_point_offset_x"] = dr.opaque(mi.Float, x)
        self._target_params["principal_point_offset_y"] = dr.opaque(mi.Float, y)
        self._target_params.update()
        if self._frozen is not None:
            settle(sensor)  # nothing pending for the frozen render's inputs (frozen.settle)

    @property
    def recordings(self) -> int:
        """How many times the frozen render recorded the path tracing (the frame's and the
        target pass's, in one recording; 0: traced every frame)."""
        return 0 if self._frozen is None else self._frozen.recordings

    @property
    def cast_recordings(self) -> int:
        """How many times the frozen ray cast recorded (0: traced every frame)."""
        return 0 if self._frozen_cast is None else self._frozen_cast.recordings

    @property
    def refused_recordings(self) -> int:
        """Recordings Dr.Jit refused, of the render and of the cast (those calls traced)."""
        return sum(f.refused for f in (self._frozen, self._frozen_cast) if f is not None)

    def render(self, state: FrameState, look: FrameLook, seed: int, *, geometry: bool = False) -> RenderResult:
        """Pose the scene and render it: exposure-scaled linear RGB seen through the air,
        plus the geometry pass (depth, object ids) when ``geometry`` is asked for or the
        aerial perspective needs it. The result's ``stages`` says where the time went."""
        clock = StageClock()
        with clock.stage("pose"):  # the cloud-lighting probe inside it is a stage of its own
            self.pose(state, look, clock)
        haze = look.haze_visibility_m is not None
        if self.aerial is not None:  # before the cast, which sees the scene's air as the render does
            with clock.stage(AERIAL_PERSPECTIVE):
                self._set_air(state, look)
        with clock.stage("geometry pass"):  # with the sun's ray and the lights' in the same cast
            lights = self._light_rays(state, look)
            sun_world = None if self.sensor is None else sun_direction_world(state, look)
            directions = np.concatenate([np.zeros((0, 3), np.float32) if sun_world is None else sun_world[None, :],
                                         np.zeros((0, 3)) if lights is None else lights.directions]).astype(np.float32)
            if geometry or self.always_geometry:  # the camera model and the statistics: half resolution will do
                (depth, ids, surface), t, grid_ids = self.frame_cast(directions, full=geometry)
            else:
                depth = ids = surface = grid_ids = None  # type: ignore[assignment]  # (no geometry pass)
                t = self.cast(self._camera_render, directions)[0] if len(directions) else np.zeros(0, np.float32)
            t_sun, t_lights = (None, t) if sun_world is None else (t[0], t[1:])
            texels = self.world.texel_footprint_px(depth, ids, surface, self.intrinsics.fx)
        window = None if grid_ids is None else \
            target_window(grid_ids, self._target_size, (self.intrinsics.width, self.intrinsics.height))
        with clock.stage(PATH_TRACING):
            image = self.path_trace(seed, window)
            self._dr.eval(image)  # the render happens here (Dr.Jit evaluates lazily)
            self._dr.sync_thread()
        render_s = clock.seconds[PATH_TRACING]
        beauty = None
        if haze and self.aerial is None:  # a scalar variant: the finished image through the air
            with clock.stage(AERIAL_PERSPECTIVE):
                beauty = self.aerial_perspective(np.array(image, dtype=np.float32)[..., :3], state, look)
        denoise_s = None
        if self.denoise == "off":
            rgb = beauty if beauty is not None else np.array(image, dtype=np.float32)[..., :3]
        else:
            with clock.stage(DENOISE):
                rgb = self._denoised(image, beauty)
            denoise_s = clock.seconds[DENOISE]
        if lights is not None:
            with clock.stage("lights"):
                self._draw_lights(rgb, lights, t_lights)
        if self.sensor is None:
            with clock.stage("exposure"):
                rgb *= exposure_scale(look.exposure_ev)
            return RenderResult(rgb, depth, ids, render_s, denoise_s, surface, texels, stages=clock.seconds)
        from datagen.render.sensor import apply_sensor

        assert sun_world is not None and t_sun is not None  # (cast where there is a sensor)
        out = apply_sensor(rgb, look, state, render=self.intrinsics, output=self.output_intrinsics,
                           margin_px=self.margin_px, depth=depth, ids=ids, surface=surface,
                           sun_cam=state.cam_from_world[:3, :3] @ sun_world,
                           sun_transmittance=float(not np.isfinite(t_sun)),
                           auto_exposure=self.sensor.auto_exposure, clock=clock,
                           device=not self.variant.startswith("scalar"))
        return RenderResult(out.linear, out.depth, out.object_id, render_s, denoise_s, out.surface,
                            {**out.measured, **texels}, clock.seconds, out.srgb8)

    def frame_cast(self, directions: NDArray[np.float32], *, full: bool = False
                   ) -> tuple[tuple[NDArray, ...], NDArray, NDArray | None]:
        """A frame's geometry pass with its other rays from the camera (``directions``, render
        frame) in one cast, as :meth:`render` makes it: at half resolution (``full``: every
        pixel), with the target pass's grid where there is one (:meth:`geometry_and_cast`)."""
        return self.geometry_and_cast(1 if full else 2, directions, grid=PLACEMENT_STRIDE_PX if self.target_spp else 0)

    def _light_rays(self, state: FrameState, look: FrameLook) -> _LightRays | None:
        """The aircraft's lit lights (:meth:`Paintwork.light_spots`) in front of the camera
        and the render-frame directions to them, to be cast from the camera (None: none)."""
        from datagen.core.camera import project_points

        spots = self.paintwork.light_spots(look, {obj: state.world_from(obj) for obj in RIGID_OBJECTS},
                                           state.time_s, self._irradiance)
        if not spots:
            return None
        world = np.array([p for p, _ in spots])
        cam = (state.cam_from_world @ np.c_[world, np.ones(len(world))].T).T[:, :3]
        front = cam[:, 2] > 1.0
        if not front.any():
            return None
        world, cam = world[front], cam[front]
        radiance = np.array([r for (_, r), f in zip(spots, front, strict=True) if f])
        towards = world - self._world_from_cam[:3, 3]
        distance = np.linalg.norm(towards, axis=1)
        return _LightRays(project_points(cam, self.intrinsics), distance, radiance,
                          (towards / distance[:, None]).astype(np.float32))

    def _draw_lights(self, rgb: NDArray[np.float32], lights: _LightRays, t: NDArray[np.float32]) -> None:
        """``lights`` added to the linear image where the camera sees them: nothing hit on
        the way (``t``, the distance along each light's ray to the first hit)."""
        from datagen.render.paintwork import LIGHT_STANDOFF_M, add_light_spots

        seen = t >= lights.distance - LIGHT_STANDOFF_M  # the lens stands off the skin: what it stands on is behind it
        if seen.any():
            add_light_spots(rgb, lights.pixels[seen], lights.distance[seen], lights.radiance[seen],
                            self.intrinsics.fx)

    def _set_air(self, state: FrameState, look: FrameLook) -> None:
        """The frame's air as the render's kernel inputs (:mod:`datagen.render.aerial`); a
        look without it (a config drawn with haze off): air that dims nothing."""
        from datagen.render.aerial import airlight_grid

        if look.haze_visibility_m is None or look.haze_scale_height_m is None:
            air = Atmosphere(0.0, 1e9, 1.0)
            air.rayleigh = air.aerosol = np.zeros(3)
        else:
            air = Atmosphere(float(state.world_from_cam[2, 3]), look.haze_visibility_m, look.haze_scale_height_m)
        grid = airlight_grid(self.sky, air, self.intrinsics, state.world_from_cam)
        self.aerial.set_frame(air=air, grid=grid, intrinsics=self.intrinsics,
                              cam_from_render=state.world_from_cam[:3, :3].T, codes=self._background_codes,
                              opacities=self.world.cloud_opacities())

    def aerial_perspective(self, rgb: NDArray[np.float32], state: FrameState, look: FrameLook) -> NDArray[np.float32]:
        """``rgb`` (the finished render's linear radiance) seen through the frame's air, per
        pixel along its centre's ray (:class:`~datagen.render.atmosphere.Atmosphere`): what
        a scalar variant does instead of :mod:`datagen.render.aerial`'s per-sample air."""
        from datagen.render.aerial import airlight_grid

        k = self.intrinsics
        assert look.haze_visibility_m is not None and look.haze_scale_height_m is not None  # (called with haze)
        air = Atmosphere(float(state.world_from_cam[2, 3]), look.haze_visibility_m, look.haze_scale_height_m)
        depth, _, _ = self.geometry_pass()
        grid = airlight_grid(self.sky, air, k, state.world_from_cam, step=4 * AIRLIGHT_STEP_PX)
        pixels = _upsampled(grid, k.width, k.height)
        unit, z_per_t = self._pixel_rays()
        sin_elevation = (unit @ state.world_from_cam[2, :3]).reshape(k.height, k.width)
        distance = np.where(np.isfinite(depth), depth / z_per_t.reshape(k.height, k.width), 0.0)
        out = air.seen_through([rgb[..., c] for c in range(3)], [pixels[..., c] for c in range(3)],
                               [pixels[..., 3 + c] for c in range(3)], sin_elevation, [distance])
        return np.stack(out, axis=-1).astype(np.float32)

    def _denoised(self, image, beauty: NDArray[np.float32] | None = None) -> NDArray[np.float32]:
        """OIDN on the render's linear RGB (or ``beauty``, the same seen through the air),
        guided by its albedo and normal channels when the aov integrator made them. The
        channels are sliced as Dr.Jit tensors, so that the filter runs on the variant's
        device (the GPU with cuda_ad_rgb)."""
        from datagen.render.denoise import denoise_render

        on_device = beauty if beauty is None or self.variant.startswith("scalar") else \
            self._mi.TensorXf(np.ascontiguousarray(beauty))
        out = denoise_render(image, guides=self.guides, quality=self.config.render.denoise_quality, beauty=on_device)
        return np.maximum(np.array(out, dtype=np.float32), np.float32(0.0))


@dataclass(frozen=True)
class _LightRays:
    """A frame's lights in front of the camera: their pixels, distances (m), radiance, and
    the render-frame directions to them from the camera."""

    pixels: NDArray[np.float64]
    distance: NDArray[np.float64]
    radiance: NDArray[np.float64]
    directions: NDArray[np.float32]


def _upsampled(grid: NDArray[np.float32], width: int, height: int) -> NDArray[np.float32]:
    """``grid`` (gh, gw, C) of values at pixel centres spread evenly from the first pixel's
    to the last's, interpolated bilinearly to every pixel centre: (height, width, C)."""
    import cv2

    gh, gw = grid.shape[:2]
    x = np.arange(width, dtype=np.float32) * np.float32((gw - 1) / max(width - 1, 1))
    y = np.arange(height, dtype=np.float32) * np.float32((gh - 1) / max(height - 1, 1))
    map_x, map_y = np.broadcast_to(x, (height, width)), np.broadcast_to(y[:, None], (height, width))
    out = cv2.remap(grid, np.ascontiguousarray(map_x), np.ascontiguousarray(map_y), cv2.INTER_LINEAR,
                    borderMode=cv2.BORDER_REPLICATE)
    return np.asarray(out, dtype=np.float32).reshape(height, width, -1)
