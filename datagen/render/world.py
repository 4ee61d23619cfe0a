"""The world's Mitsuba side: cloud layers, the sea's waves, whitecaps and colour, and the
aircraft liveries, built into the scene once and re-dressed per frame through
``mi.traverse`` from a frame's :class:`~datagen.scene.look.FrameLook`.

Each piece exists in the scene only when its randomizer is on: with it off, the scene
holds nothing of it (no mesh, texture or kernel). Texture contents change per frame
(data updates and opaque kernel inputs: no new kernel).

- The sea's shape, always there: the earth's round surface under the camera (:func:`earth_cap`).
- Clouds: two sheets of cells (deck and scattered layer) on the spheres of their altitudes,
  curving down with the earth, whose ``mask`` opacity
  is a :class:`datagen.assets.clouds.CloudLayer`, procedural noise evaluated at each
  shading point and filtered to the pixel there (:mod:`datagen.render.procedural`), each
  emitting the light its tops or bases send back (:meth:`World.cloud_shapes`).
- Sea: the principled BSDF under a ``normalmap`` of :class:`~datagen.assets.sea.SeaWaves`,
  wave trains summed at each shading point as far as the pixel there resolves them, the
  rest of the sea's slope variance its roughness there; its albedo is a
  :class:`~datagen.assets.sea.SeaSurface`: the drawn body colour,
  tinted over kilometres, with whitecaps shaped where a pixel resolves them and their mean
  where it does not.
- Ground: where the approach's ground type (:class:`~datagen.assets.ground.Ground`) has
  land, the same surface takes the land's albedo, relief normal and matte roughness in
  place of the sea's (one kernel whatever the type: open sea is a ground with no land).
- Liveries are the paintwork's (:mod:`datagen.render.paintwork`); the world reports their
  texel (none: they are procedural too).
"""

from __future__ import annotations

import functools
import math
from typing import TYPE_CHECKING, Any, Final

import numpy as np
from numpy.typing import NDArray

from datagen.assets.clouds import CLOUD_FORMS, CloudLayer, CloudLight
from datagen.assets.ground import GROUND_TYPES, LAND_ROUGHNESS, NO_SHORE, Ground
from datagen.assets.sea import SeaSurface, SeaWaves
from datagen.core.conventions import EARTH_RADIUS_M, texture_rng
from datagen.core.transforms import vec3
from datagen.scene.look import FrameLook

if TYPE_CHECKING:
    from datagen.config.schema import RandomizationConfig

__all__ = ["CLOUD_LAYERS", "CLOUD_SIZE_M", "EARTH_CAP_M", "SEA_COLOUR", "SURFACES", "World",
           "earth_cap", "sphere_drop"]

#: The cloud layers' shape names (in the scene) and the FrameLook fields that place them
#: (coverage, altitude, thickness).
CLOUD_LAYERS: Final = {
    "cloud_deck": ("cloud_deck_coverage", "cloud_deck_altitude_m", "cloud_deck_thickness_m"),
    "cloud_layer": ("cloud_layer_coverage", "cloud_layer_altitude_m", "cloud_layer_thickness_m"),
}
#: A cloud layer's emitter is found by paths and never sampled (its sampling weight). Its
#: radiance then tells Mitsuba it does not vary over the surface
#: (procedural.FieldTexture.is_spatially_varying): the emission pdf Mitsuba takes instead is
#: multiplied by this weight.
CLOUD_EMITTER_WEIGHT: Final = 0.0
#: A cloud layer is a square CLOUD_SIZE_M across, centred under or over the camera, as a mesh
#: of cells CLOUD_CELL_M across: a cell exists (has area) only where the layer's field may
#: reach its threshold there, so that rays through clear sky meet nothing (a plane with a
#: mask would cost every ray that crosses it an extra path vertex and shadow ray). 1.5 km
#: cells (25,000 triangles) rebuild with the scene's top level in 0.02 s when an aircraft
#: moves; 375 m cells (400,000 triangles) took 0.24 s a frame and saved no measurable
#: path-tracing time. Around it, out to CLOUD_REACH_M from the camera each way, a ring of
#: cells CLOUD_FAR_CELL_M across (edge to edge with the grid: a whole number of them spans
#: CLOUD_SIZE_M / 2) carries the layer to the horizon (a layer 4 km above the
#: camera sinks to its horizontal 230 km away; below it, a deck's own horizon from 8 km
#: above it lies 320 km away), where a pixel spans hundreds of metres.
CLOUD_SIZE_M: Final = 168_000.0
CLOUD_CELL_M: Final = 1_500.0
CLOUD_REACH_M: Final = 408_000.0
CLOUD_FAR_CELL_M: Final = 12_000.0
#: A cell's cloud is bounded from the field's first CULL_OCTAVES octaves on a grid of
#: CULL_SAMPLES x CULL_SAMPLES points per cell (near or far: a far cell's are wider apart), plus
#: what the grid's spacing and the finer octaves can add (:func:`_cloudy_cells`).
CULL_OCTAVES: Final = 7
CULL_SAMPLES: Final = 32
#: Every CULL_SUBSET-th of those samples along each side is looked at first (1/16 of them):
#: most cells are kept on these alone, and only the rest are sampled in full.
CULL_SUBSET: Final = 4
#: Bound on the slope of one octave of gradient noise, per lattice unit (measured: 2.4).
NOISE_SLOPE_BOUND: Final = 3.0
#: The sea mesh's parameter prefix (the mesh in its shape group, which an instance places).
SEA_KEY: Final = "sea_group.sea"
#: What a pixel's ray meets first, as the geometry pass classifies it (index = code).
SURFACES: Final = ("sky", "sea", "cloud", "object")
#: The sea's body colour when it is not drawn (linear RGB).
SEA_COLOUR: Final = (0.01, 0.03, 0.05)
#: The sea is the part of the earth's sphere within EARTH_CAP_M metres (horizontally) of the
#: camera's nadir: beyond the horizon from any altitude a config allows (505 km at 20 km).
EARTH_CAP_M: Final = 600_000.0
#: The cap's mesh: rings of EARTH_CAP_AZIMUTHS vertices, from EARTH_CAP_FIRST_M out, each
#: EARTH_CAP_GROWTH of the one before or nearer: a flat triangle sags below the sphere by
#: L^2 / 8R for a longest edge of L, which moves what a camera above the cap sees there by
#: at most that over its distance from the nadir r, kept under EARTH_CAP_SAG radians (0.08
#: px of podcam15 at 2K, the narrowest camera; the edges grow as sqrt(8 R EARTH_CAP_SAG r),
#: about 10 km at the horizon from 7 km). 26,000 vertices, built once (an instance moves it
#: with the camera); five times as many, each a fixed size, cost every ray 10-20% more to
#: trace.
EARTH_CAP_AZIMUTHS: Final = 256
EARTH_CAP_FIRST_M: Final = 50.0
EARTH_CAP_GROWTH: Final = 1.25
EARTH_CAP_SAG: Final = 1e-5


def sphere_drop(r_m, radius_m: float = EARTH_RADIUS_M):
    """How far below its top a sphere of ``radius_m`` lies at horizontal distance ``r_m``
    from it (``R - sqrt(R^2 - r^2)``, computed as ``r^2 / (R + sqrt(R^2 - r^2))``)."""
    r2 = np.square(np.asarray(r_m, dtype=np.float64))
    return r2 / (radius_m + np.sqrt(radius_m * radius_m - r2))


@functools.cache
def earth_cap() -> tuple[NDArray[np.float32], NDArray[np.uint32], NDArray[np.float32], NDArray[np.float32]]:
    """The sea's mesh, its top at the origin: vertices, faces (facing up), texture
    coordinates (linear in x and y: the waves' normal map keeps its frame along x) and
    vertex normals (the sphere's)."""
    radii = [0.0, EARTH_CAP_FIRST_M]
    while radii[-1] < EARTH_CAP_M:
        r = radii[-1]
        # A quad's diagonal is its longest edge: the ring step and the outer ring's chord together.
        chord = 2.0 * math.pi * 1.05 * r / EARTH_CAP_AZIMUTHS
        radii.append(r + min(r * (EARTH_CAP_GROWTH - 1.0),
                             math.sqrt(8.0 * EARTH_RADIUS_M * EARTH_CAP_SAG * r - chord * chord)))
    ring = np.asarray(radii)
    step = 2.0 * np.pi / EARTH_CAP_AZIMUTHS
    phi = np.arange(EARTH_CAP_AZIMUTHS) * step
    # The rings' centre lies off the top, in a direction between two spokes: no spoke's
    # vertical plane holds the camera's nadir, so no ray from the camera runs along an edge
    # (Embree's triangle test is not watertight there: one pixel of a podcam frame saw the
    # sky through the sea where every spoke passed under the camera).
    centre = EARTH_CAP_FIRST_M * np.array([np.cos(22.5 * step), np.sin(22.5 * step)])
    ring_r = ring[1:, None]
    x, y = centre[0] + ring_r * np.cos(phi), centre[1] + ring_r * np.sin(phi)
    xy = np.concatenate([centre[None], np.stack([x, y], -1).reshape(-1, 2)])
    verts = np.concatenate([xy, -sphere_drop(np.hypot(xy[:, 0], xy[:, 1]))[:, None]], axis=1)
    normals = verts + np.array([0.0, 0.0, EARTH_RADIUS_M])
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    n, rings = EARTH_CAP_AZIMUTHS, len(ring) - 1
    j = np.arange(n)
    fan = np.stack([np.zeros(n, int), 1 + j, 1 + (j + 1) % n], -1)
    k = np.arange(rings - 1)[:, None]
    a, b = 1 + k * n + j, 1 + k * n + (j + 1) % n  # ring k
    c, d = a + n, b + n  # ring k + 1
    quads = np.concatenate([np.stack([a, c, d], -1), np.stack([a, d, b], -1)], axis=1).reshape(-1, 3)
    faces = np.concatenate([fan, quads]).astype(np.uint32)
    uv = verts[:, :2] / (2.0 * EARTH_CAP_M) + 0.5
    return verts.astype(np.float32), faces, uv.astype(np.float32), normals.astype(np.float32)


class World:
    """Which world pieces a config's randomization renders, their scene entries and their
    per-frame updates."""

    def __init__(self, randomization: RandomizationConfig, pixel_rad: float) -> None:
        r = randomization
        self.clouds = r.clouds.enabled
        self.waves = r.sea.waves
        self.whitecaps = r.sea.whitecaps
        self.sea_colour = r.sea.colour
        self.ground = r.ground.enabled
        self.livery = r.livery.enabled
        #: The earth's surface is procedural (a sea with waves, whitecaps or colour, or land).
        self.earth = self.waves or self.whitecaps or self.sea_colour or self.ground
        #: Any world piece on (the renderer then classifies every pixel's surface).
        self.any = self.clouds or self.earth or self.livery
        self._ground: Ground | None = None
        self.pixel_rad = pixel_rad  # the angle one pixel subtends (1 / fx): procedural textures filter to it
        self._cloud_layers: dict[str, CloudLayer] = {}
        self._cloud_textures: dict = {}  # layer name -> (opacity, radiance) procedural textures
        self._cloudy: dict[str, NDArray[np.bool_]] = {}
        self._cloud_key: tuple | None = None
        self._sea_key: tuple | None = None
        self._sea_texture: Any = None  # the sea's procedural albedo (whitecaps, colour), where either is on
        self._wave_textures: tuple[Any, Any] | None = None  # the sea's (normals, roughness), where waves are on
        self._waves: SeaWaves | None = None
        self.cloud_meshes: dict = {}
        self._cloud_down: dict[str, bool] = {}
        self._cloud_height: dict[str, float] = {}  # layer name -> its mi.Mesh (the geometry pass tells them apart)

    # -- construction ------------------------------------------------------------------
    @property
    def integrator(self) -> str:
        """The Mitsuba integrator: ``volpath`` where cloud layers are, ``path`` otherwise.

        A cloud layer is a ``mask`` (null transmission ``1 - opacity``). ``path``'s shadow
        rays stop at any surface, so the sun seen through a thin cloud edge reached the
        sea and the aircraft only by BSDF sampling, with full MIS weight after the null
        crossing: rare, very bright samples, fireflies that 1,024 spp did not average out.
        ``volpath`` multiplies a shadow ray's weight by the null transmission of every
        surface it crosses, so next-event estimation sees the sun through the cloud and
        MIS stays balanced; on surfaces it is the same path tracer. Without clouds the
        scene has no null surfaces, and ``path``, the cheaper of the two, renders it."""
        return "volpath" if self.clouds else "path"

    def sea_bsdf(self, principled: dict) -> dict:
        """The earth's surface BSDF: ``principled`` with the procedural albedo where whitecaps,
        colour or ground are on, under the waves' (and the land's relief's) normals and with
        their roughness where waves or ground are."""
        if not self.earth:
            return principled
        import mitsuba as mi

        from datagen.render.procedural import texture_class

        field_texture = texture_class(mi.variant())
        if self.whitecaps or self.sea_colour or self.ground:
            self._sea_texture = field_texture(pixel_rad=self.pixel_rad, colour=True, slant=True)
            self._sea_texture.shade = _clear_colour
            principled = dict(principled, base_color=self._sea_texture)
        if not (self.waves or self.ground):
            return principled
        normals = field_texture(pixel_rad=self.pixel_rad, colour=True, slant=True)
        roughness = field_texture(pixel_rad=self.pixel_rad, slant=True)
        normals.shade, roughness.shade = _flat_normal, _clear
        self._wave_textures = (normals, roughness)
        return {"type": "normalmap", "normalmap": normals, "bsdf": dict(principled, roughness=roughness)}

    def cloud_shapes(self) -> dict:
        """Scene entries of the cloud layers (none when clouds are off): fixed-topology
        meshes whose cells are collapsed until a frame's clouds give them area.

        A layer is lit in advance rather than path traced: its side facing the camera
        emits ``albedo / pi`` times the sky's horizontal irradiance this frame (tops), or
        the part a cloud of its opacity transmits (bases), premultiplied by the opacity
        texture, over a black BSDF behind the same opacity ``mask``. A path that meets a
        cloud thus takes its light and ends there, or passes a thin edge, and the sun's
        shadow rays carry its transmission (:attr:`integrator`); path traced as white
        diffuse surfaces, the layers would make paths bounce between cloud bases and the
        sea to the maximum depth, at about twice the render time."""
        if not self.clouds:
            return {}
        import mitsuba as mi

        from datagen.render.mitsuba import mitsuba_mesh
        from datagen.render.procedural import mask_class, texture_class

        field_texture = texture_class(mi.variant())
        verts, faces = _cloud_grid()
        entries = {}
        for name in CLOUD_LAYERS:
            opacity = field_texture(pixel_rad=self.pixel_rad)
            radiance = field_texture(pixel_rad=self.pixel_rad, colour=True, front_only=True, slant=True,
                                     varying=CLOUD_EMITTER_WEIGHT > 0.0)
            for texture in (opacity, radiance):
                texture.shade = _clear
            self._cloud_textures[name] = (opacity, radiance)
            # Behind the mask, a black mirror: a delta lobe, so that the path tracer spends no
            # shadow ray on a surface that reflects nothing (a black diffuse one would).
            bsdf = mask_class(mi.variant())(opacity)
            emitter = mi.load_dict({"type": "area", "sampling_weight": CLOUD_EMITTER_WEIGHT,
                                    "radiance": radiance})
            # Built with every cell in place: the acceleration structure then follows the
            # grid, which later frames only collapse cells of (mirroring it measured 2x slower).
            # (Texture coordinates: Mitsuba's surface interactions ask every mesh for them.)
            uv = verts[:, :2] / np.float32(CLOUD_SIZE_M) + np.float32(0.5)
            self.cloud_meshes[name] = mitsuba_mesh(name, verts, faces, bsdf, texcoords=uv, emitter=emitter)
            entries[name] = self.cloud_meshes[name]
        return entries

    def textures(self) -> tuple:
        """Every procedural texture of the world (the clouds', the sea's)."""
        clouds = tuple(t for pair in (self._cloud_textures or {}).values() for t in pair)
        return (*clouds, *(t for t in (self._sea_texture, *(self._wave_textures or ())) if t is not None))

    def cloud_radiances(self) -> tuple:
        """The cloud layers' radiance textures (their emitters') in :data:`CLOUD_LAYERS` order
        (none without clouds)."""
        return tuple(self._cloud_textures[name][1] for name in CLOUD_LAYERS) if self._cloud_textures else ()

    def cloud_opacities(self) -> tuple:
        """The cloud layers' opacity textures in :data:`CLOUD_LAYERS` order (none without
        clouds): what each frame's layer draws, asked at any render-frame point."""
        return tuple(self._cloud_textures[name][0] for name in CLOUD_LAYERS) if self._cloud_textures else ()

    # -- per frame -----------------------------------------------------------------------
    def apply(self, params, look: FrameLook, camera_z_m: float, irradiance=None,
              camera_render=(0.0, 0.0, 0.0), sun_direction=(0.0, 0.0, 1.0)) -> None:
        """Set the frame's clouds and sea (the render frame has its origin at altitude
        ``camera_z_m``, the camera at ``camera_render`` in it; ``irradiance`` is the sun's and
        the sky's RGB irradiance on a horizontal surface, ``sun_direction`` the unit vector to
        the sun: they light the clouds)."""

        if self.clouds:
            from datagen.render.mitsuba import set_buffer

            key = (look.cloud_seed, look.cloud_type, look.cloud_deck_coverage, look.cloud_layer_coverage,
                   look.cloud_opacity, look.cloud_deck_thickness_m, look.cloud_layer_thickness_m)
            fresh = self._cloud_key != key
            drawn = look.cloud_seed is not None  # a look without cloud draws: clear sky
            rng = texture_rng(look.cloud_seed or 0)  # (no seed: clear sky, nothing drawn from it)
            sun, sky = irradiance if irradiance is not None else (np.zeros(3), np.zeros(3))
            light = CloudLight(vec3(sun), vec3(sky),
                               vec3(sun_direction), look.cloud_albedo or 0.0)
            for name, (coverage_key, altitude_key, thickness_key) in CLOUD_LAYERS.items():
                if fresh:  # an approach's weather, drawn once
                    coverage = getattr(look, coverage_key) if drawn else 0.0
                    form = CLOUD_FORMS[(look.cloud_type or "cumulus") if name == "cloud_deck" else "layer"]
                    layer = CloudLayer.drawn(rng, coverage, look.cloud_opacity or 0.0, CLOUD_SIZE_M, form,
                                             getattr(look, thickness_key) or 0.0)
                    self._cloud_layers[name] = layer
                    self._cloudy[name] = _cloudy_cells(layer)
                layer = self._cloud_layers[name]
                height = (getattr(look, altitude_key) if drawn else 0.0) - camera_z_m
                above = height > 0.0  # seen from below: a base, which lets through what its thickness does
                opacity, radiance = self._cloud_textures[name]
                for texture in (opacity, radiance):
                    texture.camera = vec3(camera_render)
                opacity.shade = layer  # CloudLayer(x, y, footprint_m, ops): the opacity
                radiance.shade = functools.partial(_layer_radiance, layer, light, above)
                if fresh or self._cloud_height.get(name) != height:  # the mesh moves only when it must
                    set_buffer(params, f"{name}.vertex_positions",
                               _cloud_cells(self._cloudy[name], height, height + camera_z_m))
                    self._cloud_height[name] = height
                if self._cloud_down.get(name) != above:  # the emitting side faces the camera
                    set_buffer(params, f"{name}.faces", _cloud_faces(above))
                    self._cloud_down[name] = above
            self._cloud_key = key
        sea_textures = [t for t in (self._sea_texture, *(self._wave_textures or ())) if t is not None]
        for texture in sea_textures:
            texture.camera = vec3(camera_render)
        if self._wave_textures is None:
            params[f"{SEA_KEY}.bsdf.roughness.value"] = look.sea_roughness
        if not self.earth:
            return
        sea_key = (look.sea_seed, look.sea_wind_speed_mps, look.sea_wind_direction_deg, look.sea_whitecap_fraction,
               look.sea_colour, look.ground_type, look.ground_seed)
        if sea_key != self._sea_key:  # an approach's sea and ground, made once
            self._sea_key = sea_key
            rng = texture_rng(look.sea_seed or 0)  # (no seed: no wave, whitecap or colour drawn from it)
            wind = look.sea_wind_speed_mps if look.sea_wind_speed_mps is not None else 7.0
            if self.waves:
                self._waves = SeaWaves.drawn(rng, wind, look.sea_wind_direction_deg or 0.0)
            sea = None
            if self.whitecaps or self.sea_colour:
                sea = SeaSurface.drawn(rng, look.sea_colour if look.sea_colour is not None else SEA_COLOUR,
                                       look.sea_whitecap_fraction or 0.0, look.sea_wind_direction_deg or 0.0,
                                       tint=self.sea_colour)
            if self.ground:
                self._ground = Ground.drawn(texture_rng(look.ground_seed or 0), GROUND_TYPES[look.ground_type or "sea"])
            if self._sea_texture is not None:
                self._sea_texture.shade = functools.partial(_earth_albedo, sea, self._ground)
            if self._wave_textures is not None:
                self._wave_textures[0].shade = functools.partial(_earth_normal, self._waves, self._ground)
        if self._wave_textures is not None:  # the frame's roughness (a uniform sea model draws it per frame)
            self._wave_textures[1].shade = functools.partial(_earth_roughness, self._waves, float(look.sea_roughness),
                                                             self._ground)

    def texel_footprint_px(self, depth: NDArray | None, ids: NDArray | None, surface: NDArray | None,
                           fx: float) -> dict[str, float | None]:
        """The largest on-screen size (px) of a texel the frame shows, from its geometry pass
        (z-depth, object ids, surfaces): a texel ``s`` metres across at z-depth ``z`` spans
        at most ``s fx / z`` pixels. ``world_texel_px``: the sea's and the clouds' (0: they
        are procedural, no texel anywhere); ``livery_texel_px``: the liveries' (0 as well:
        :mod:`datagen.assets.liveries`). None where none is seen."""
        out: dict[str, float | None] = {"world_texel_px": None, "livery_texel_px": None}
        if depth is None or surface is None:
            return out
        if np.isin(surface, (SURFACES.index("sea"), SURFACES.index("cloud"))).any():
            out["world_texel_px"] = 0.0
        if self.livery and ids is not None:
            from datagen.core.conventions import object_id
            from datagen.render.paintwork import LIVERY_OBJECTS

            if np.isin(ids, [object_id(obj) for obj in LIVERY_OBJECTS]).any():
                out["livery_texel_px"] = 0.0
        return out

    def cloud_layer(self, name: str) -> CloudLayer | None:
        """Cloud layer ``name`` as this frame draws it (None without clouds)."""
        return self._cloud_layers.get(name)

    def cloud_opacity_at(self, name: str, xy: NDArray, distance_m: NDArray) -> NDArray[np.float32]:
        """The opacity of cloud layer ``name`` this frame at render-frame points ``xy``
        (N, 2) seen from ``distance_m`` (N,) away, as the renderer shades it (evaluated by
        Dr.Jit: the geometry pass classifies hundreds of thousands of pixels a frame)."""
        layer = self.cloud_layer(name)
        if layer is None:
            return np.zeros(len(xy), np.float32)
        from datagen.render.procedural import evaluate

        footprint = np.asarray(distance_m) * self.pixel_rad
        return evaluate(layer, np.asarray(xy)[:, 0], np.asarray(xy)[:, 1], footprint)


def _clear(x, y, footprint_m, ops):
    """A layer without cloud."""
    return x * ops.f32(0.0)


def _clear_colour(x, y, footprint_m, ops):
    import mitsuba as mi

    return mi.Color3f(*(x * ops.f32(0.0) + ops.f32(c) for c in SEA_COLOUR))


def _flat_normal(x, y, footprint_m, ops):
    """A calm sea's normal, encoded as a normal map's colour."""
    import mitsuba as mi

    return mi.Color3f(x * ops.f32(0.0) + ops.f32(0.5), ops.f32(0.5), ops.f32(1.0))


def _earth_normal(waves: SeaWaves | None, ground: Ground | None, x, y, footprint_m, ops):
    """The surface's normal at a footprint, encoded as a normal map's colour (n / 2 + 1/2):
    the waves' (or a calm sea's) where there is sea, the relief's where there is land."""
    import mitsuba as mi

    f = ops.f32

    def sea():
        return waves.normal(x, y, footprint_m, ops) if waves is not None else (x * f(0.0), x * f(0.0),
                                                                               x * f(0.0) + f(1.0))

    if ground is None:
        n = sea()
    else:
        wide = footprint_m.longest(ops)
        n = _with_land(ground, x, y, wide, ops, 3, sea, lambda: ground.normal(x, y, wide, ops))
        norm = ops.sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2])
        n = tuple(c / norm for c in n)
    half = f(0.5)
    return mi.Color3f(*(c * half + half for c in n))


def _earth_roughness(waves: SeaWaves | None, roughness: float, ground: Ground | None, x, y, footprint_m, ops):
    """The sea's roughness (what its waves leave unresolved, or the drawn one), the land's
    :data:`~datagen.assets.ground.LAND_ROUGHNESS`."""
    def sea():
        r = waves.roughness(footprint_m, roughness, ops) if waves is not None else ops.param_f32(roughness)
        return (r + x * ops.f32(0.0),)

    if ground is None:
        return sea()[0]
    return _with_land(ground, x, y, footprint_m.longest(ops), ops, 1, sea,
                      lambda: (x * ops.f32(0.0) + ops.f32(LAND_ROUGHNESS),))[0]


def _earth_albedo(sea: SeaSurface | None, ground: Ground | None, x, y, footprint_m, ops):
    """The surface's albedo: the sea's (filtered to the long axis of a pixel's footprint:
    whitecaps seen edge-on fade to their mean rather than flicker), the land's where there
    is land."""
    import mitsuba as mi

    wide = footprint_m.longest(ops)

    def water():
        if sea is not None:
            return sea.albedo(x, y, wide, ops)
        return tuple(x * ops.f32(0.0) + ops.f32(c) for c in SEA_COLOUR)

    if ground is None:
        return mi.Color3f(*water())
    return mi.Color3f(*_with_land(ground, x, y, wide, ops, 3, water, lambda: ground.albedo(x, y, wide, ops)))


def _with_land(ground: Ground, x, y, footprint_m, ops, size: int, sea, land) -> tuple:
    """``sea()`` (a tuple of ``size`` values at the points) mixed towards ``land()`` (the same for
    the land) by the ground's land weight there. In a kernel each is computed only in lanes
    that show it (:meth:`~datagen.assets.noise.Ops.where`): the weight only where the
    approach's ground has land at all, the sea only where the land does not cover it all,
    the land only where there is some: over open sea the land costs nothing, over a desert
    the sea nothing, over a coast each its own side of the shore."""
    zero = x * ops.f32(0.0)
    has_land = zero + ops.param_f32(ground.threshold) < ops.f32(0.5 * NO_SHORE)  # open sea: NO_SHORE
    m = ops.where(has_land, (zero,), lambda: (ground.land_weight(x, y, footprint_m, ops),))[0]
    one = ops.f32(1.0)
    water = ops.where(m < one, (zero,) * size, sea)
    return ops.where(m > ops.f32(0.0), water,
                     lambda: tuple(a + (b - a) * m for a, b in zip(water, land(), strict=True)))


def _layer_radiance(layer: CloudLayer, light: CloudLight, above: bool, x, y, footprint_m, ops):
    """What a layer's side facing the camera emits (:meth:`CloudLayer.radiance`), its tops
    or, ``above`` the camera, its base (a kernel weight)."""
    import mitsuba as mi

    return mi.Color3f(*layer.radiance(light, ops.param_f32(1.0 if above else 0.0), x, y, footprint_m, ops))


@functools.cache
def _cell_layout() -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """The cells of a cloud layer: lower-left corners ``x0``, ``y0`` and sizes, the
    :data:`CLOUD_CELL_M` grid over :data:`CLOUD_SIZE_M` first (rows along y), then the ring of
    :data:`CLOUD_FAR_CELL_M` cells around it out to :data:`CLOUD_REACH_M`."""
    cells = round(CLOUD_SIZE_M / CLOUD_CELL_M)
    i, j = np.meshgrid(np.arange(cells), np.arange(cells))  # j: rows (y), i: columns (x)
    near_x, near_y = i.reshape(-1) * CLOUD_CELL_M - CLOUD_SIZE_M / 2, j.reshape(-1) * CLOUD_CELL_M - CLOUD_SIZE_M / 2
    assert (CLOUD_SIZE_M / 2) % CLOUD_FAR_CELL_M == 0 and CLOUD_REACH_M % CLOUD_FAR_CELL_M == 0  # no gap, no overlap
    far = round(2 * CLOUD_REACH_M / CLOUD_FAR_CELL_M)
    i, j = np.meshgrid(np.arange(far), np.arange(far))
    far_x, far_y = i.reshape(-1) * CLOUD_FAR_CELL_M - CLOUD_REACH_M, j.reshape(-1) * CLOUD_FAR_CELL_M - CLOUD_REACH_M
    outside = ((far_x >= CLOUD_SIZE_M / 2) | (far_x + CLOUD_FAR_CELL_M <= -CLOUD_SIZE_M / 2)
               | (far_y >= CLOUD_SIZE_M / 2) | (far_y + CLOUD_FAR_CELL_M <= -CLOUD_SIZE_M / 2))
    x0 = np.concatenate([near_x, far_x[outside]])
    y0 = np.concatenate([near_y, far_y[outside]])
    size = np.concatenate([np.full(near_x.size, CLOUD_CELL_M), np.full(int(outside.sum()), CLOUD_FAR_CELL_M)])
    return x0, y0, size


@functools.cache
def _cloud_grid() -> tuple[NDArray[np.float32], NDArray[np.uint32]]:
    """The cell layout of a cloud layer (:func:`_cell_layout`): every cell its own quad (4
    vertices, 2 faces), vertex positions at z = 0."""
    x0, y0, size = _cell_layout()
    corners = np.array([[0, 0], [1, 0], [1, 1], [0, 1]])
    x = x0[:, None] + corners[:, 0] * size[:, None]  # (cells, 4)
    y = y0[:, None] + corners[:, 1] * size[:, None]
    verts = np.stack([x.reshape(-1), y.reshape(-1), np.zeros(x.size)], axis=-1).astype(np.float32)
    base = (np.arange(len(x0)) * 4)[:, None]
    faces = np.concatenate([base + [0, 1, 2], base + [0, 2, 3]], axis=1).reshape(-1, 3).astype(np.uint32)
    return verts, faces


def _cloud_faces(facing_down: bool) -> NDArray[np.uint32]:
    """A cloud layer's faces, wound to face up (+z: tops) or down (bases)."""
    faces = _cloud_grid()[1]
    return faces[:, ::-1].copy() if facing_down else faces


def _cloudy_cells(layer: CloudLayer) -> NDArray[np.bool_]:
    """Which cells of the layer (:func:`_cell_layout`'s order) may hold cloud: the field's
    first :data:`CULL_OCTAVES` octaves at the centres of a square grid of samples per cell
    (:data:`CULL_SAMPLES` a side), whose largest
    value per cell, plus how far those octaves can rise within half a sample's diagonal and
    all the finer octaves can add, reaches the threshold (:func:`_cell_maxima`: 1/16 of the
    22 million points of a layer first, then every point of the cells that leaves undecided)."""
    x0, y0, size = _cell_layout()
    if not math.isfinite(layer.threshold):
        return np.zeros(len(x0), dtype=bool)
    field = layer.field
    kept = np.zeros(len(x0), dtype=bool)
    for cell in (CLOUD_CELL_M, CLOUD_FAR_CELL_M):
        group = np.flatnonzero(size == cell)
        spacing = cell / CULL_SAMPLES
        offsets = (np.arange(CULL_SAMPLES) + 0.5) * spacing
        slack = _cull_slack(field, spacing)
        # A cell kept on a subset of its samples is kept on all of them (their largest value is
        # no smaller): only the cells that subset leaves undecided are sampled in full.
        sure = _cell_maxima(field, x0[group], y0[group], offsets[CULL_SUBSET // 2::CULL_SUBSET]) + slack > \
            layer.threshold
        rest = group[~sure]
        kept[group[sure]] = True
        if len(rest):
            kept[rest] = _cell_maxima(field, x0[rest], y0[rest], offsets) + slack > layer.threshold
    return kept


def _cull_slack(field, spacing_m: float) -> float:
    """How far above its largest sample a cell's field may reach between samples
    ``spacing_m`` apart: the first :data:`CULL_OCTAVES` octaves' rise within half a sample's
    diagonal, and all the finer octaves."""
    rise = sum(NOISE_SLOPE_BOUND * field.amplitude(o) * 2.0**o / field.wavelength_m for o in range(CULL_OCTAVES))
    return rise * spacing_m / math.sqrt(2.0) + field.bound(CULL_OCTAVES)


def _cell_maxima(field, x0: NDArray[np.float64], y0: NDArray[np.float64],
                 offsets: NDArray[np.floating]) -> NDArray[np.float32]:
    """Per cell (lower-left corners ``x0``, ``y0``), the largest value of ``field``'s first
    :data:`CULL_OCTAVES` octaves at the points ``offsets`` x ``offsets`` from its corner
    (each point's float32 coordinates rounded once from the float64 sum). Under a vectorized
    variant the points are made, evaluated and reduced on the render's device, and one value a
    cell comes back (not the points)."""
    import drjit as dr
    import mitsuba as mi

    from datagen.render.mitsuba import aligned
    from datagen.render.procedural import NUMPY, drjit_ops, evaluate

    octaves = functools.partial(field, octaves=CULL_OCTAVES)
    per = len(offsets) ** 2
    if drjit_ops() is NUMPY:
        x = (x0[:, None, None] + offsets[None, None, :]).astype(np.float32)
        y = (y0[:, None, None] + offsets[None, :, None]).astype(np.float32)
        x, y = np.broadcast_arrays(x, y)
        return evaluate(lambda x, y, ops: octaves(x, y, ops=ops), x, y).reshape(len(x0), per).max(axis=1)
    # The counts as data, and two cells at least (a one-cell table would be read as a
    # scalar): one kernel whatever the subset and however few cells it leaves.
    cells = len(x0)
    x0, y0 = np.resize(x0, max(cells, 2)), np.resize(y0, max(cells, 2))
    i = dr.arange(mi.UInt32, len(x0) * per)
    side, count = dr.opaque(mi.UInt32, len(offsets)), dr.opaque(mi.UInt32, per)
    cell, j = i // count, i % count
    corner_x, corner_y, steps = (mi.Float64(aligned(a, np.float64)) for a in (x0, y0, offsets))
    x_dev = mi.Float(dr.gather(mi.Float64, corner_x, cell) + dr.gather(mi.Float64, steps, j % side))
    y_dev = mi.Float(dr.gather(mi.Float64, corner_y, cell) + dr.gather(mi.Float64, steps, j // side))
    maxima = dr.block_reduce(dr.ReduceOp.Max, octaves(x_dev, y_dev, ops=drjit_ops()), per)
    return np.asarray(maxima, dtype=np.float32)[:cells]


def _cloud_cells(cloudy: NDArray[np.bool_], height: float, altitude: float) -> NDArray[np.float32]:
    """Vertex positions of a cloud layer ``height`` over the render frame's origin, at
    ``altitude`` above the sea, on the sphere of that altitude (its top over the origin, as
    the sea's): cells that may hold cloud keep their quad, the others collapse to their
    centre (no area: no ray meets them). The near grid's vertices on its border lie on the
    far ring's edges (straight chords 12 km long, which sag under the sphere by up to 3 m):
    a ray grazing the layer finds no crack between the two.

    Seen from above (``height`` < 0), the layer ends at its horizon, the distance at which
    the camera's ray grazes its sphere: every cell wholly beyond collapses. Past it the
    camera would see the layer's underside (a ray through a gap, down past the sea's
    horizon and up again), whose side facing away emits nothing: dark dots along the
    horizon, where the sky's haze now shows."""
    out = _cloud_grid()[0].reshape(-1, 4, 3).astype(np.float64)
    radius = EARTH_RADIUS_M + max(altitude, 0.0)
    if height < 0.0:
        horizon = math.sqrt((radius - height) ** 2 - radius**2)
        x0, y0, size = _cell_layout()
        nearest = np.hypot(np.clip(0.0, x0, x0 + size), np.clip(0.0, y0, y0 + size))
        cloudy = cloudy & (nearest <= horizon)
    drop = sphere_drop(np.hypot(out[..., 0], out[..., 1]), radius)
    edge = CLOUD_SIZE_M / 2
    for axis in (0, 1):  # border vertices: on x = +-edge (chords along y), on y = +-edge (along x)
        on = np.isclose(np.abs(out[..., axis]), edge)
        along = out[..., 1 - axis][on]
        lo = np.floor(along / CLOUD_FAR_CELL_M) * CLOUD_FAR_CELL_M
        t = (along - lo) / CLOUD_FAR_CELL_M
        side = np.sign(out[..., axis][on]) * edge
        ends = [sphere_drop(np.hypot(side, a), radius) for a in (lo, lo + CLOUD_FAR_CELL_M)]
        drop[on] = (1.0 - t) * ends[0] + t * ends[1]
    out[..., 2] = height - drop
    out[~cloudy] = out[~cloudy].mean(axis=1, keepdims=True)
    return out.astype(np.float32).reshape(-1)
