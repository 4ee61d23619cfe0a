"""The world's Mitsuba side: cloud layers, the sea's waves, whitecaps and colour, and the
aircraft liveries, built into the scene once and re-dressed per frame through
``mi.traverse`` from a frame's :class:`~datagen.scene.look.FrameLook`.

Each piece exists in the scene only when its randomizer is on: with it off, the scene
holds nothing of it (no mesh, texture or kernel). Texture contents change per frame
(data updates, no new kernel); texture tilings are fixed per build (Mitsuba bakes
``to_uv`` into its kernels).

- Clouds: two horizontal sheets of cells (deck and scattered layer) whose ``mask`` opacity
  is :func:`datagen.assets.textures.cloud_opacity` (bilinear), each emitting the light its
  tops or bases send back (:meth:`World.cloud_shapes`).
- Sea: the principled BSDF under a ``normalmap`` of :func:`~datagen.assets.textures.wave_field`;
  its base colour is the drawn body colour lifted by the whitecaps: at 4-8 km a whitecap
  (metres across) is smaller than a pixel, so what a camera sees of them is the sea's
  mean albedo, ``(1 - W) colour + W foam`` with foam's effective reflectance
  (:data:`FOAM_ALBEDO`) over the whitecap fraction ``W``.
- Liveries: the painted parts of the receiver and the tanker get texture coordinates
  (:func:`~datagen.assets.textures.triplanar_uv`) and a base-colour texture per object.
"""

from __future__ import annotations

import functools
from typing import TYPE_CHECKING, Final

import numpy as np
from numpy.typing import NDArray

from datagen.assets import textures
from datagen.core.conventions import texture_rng
from datagen.scene.look import FrameLook

if TYPE_CHECKING:
    from datagen.config.schema import Config

__all__ = ["CLOUD_LAYERS", "CLOUD_SIZE_M", "FOAM_ALBEDO", "LIVERY_OBJECTS", "SEA_COLOUR", "SURFACES", "World"]

#: The cloud layers' shape names (in the scene) and the FrameLook fields that place them.
CLOUD_LAYERS: Final = {"cloud_deck": ("cloud_deck_coverage", "cloud_deck_altitude_m"),
                       "cloud_layer": ("cloud_layer_coverage", "cloud_layer_altitude_m")}
#: A cloud layer spans CLOUD_TILES x CLOUD_TILES texture tiles (168 km) centred under or over
#: the camera, as a mesh of CLOUD_CELLS cells per tile side: a cell exists (has area) only
#: where its texture has cloud, so that rays through clear sky meet nothing (a plane with
#: a mask would cost every ray that crosses it an extra path vertex and shadow ray). 16 cells
#: (1.5 km): the layers' 25,000 triangles rebuild with the scene's top level in 0.02 s when an
#: aircraft moves; at 64 cells (400,000 triangles) that took 0.24 s a frame, and the finer
#: cells saved no measurable path-tracing time.
CLOUD_TILES: Final = 7
CLOUD_CELLS: Final = 16
CLOUD_SIZE_M: Final = CLOUD_TILES * textures.CLOUD_TILE_M
#: The objects that wear a livery (on their painted parts).
LIVERY_OBJECTS: Final = ("receiver", "tanker")
#: What a pixel's ray meets first, as the geometry pass classifies it (index = code).
SURFACES: Final = ("sky", "sea", "cloud", "object")
#: Effective reflectance of whitecap foam (Koepke 1984: 0.22).
FOAM_ALBEDO: Final = 0.22
#: The sea's body colour when it is not drawn (linear RGB).
SEA_COLOUR: Final = (0.01, 0.03, 0.05)


def _bitmap(data: NDArray, repeats: float, filter_type: str = "nearest") -> dict:
    """A repeating raw bitmap; the clouds filter bilinearly (a 47 m texel seen from a few
    hundred metres would show as a block), the wave normals by nearest texel."""
    import mitsuba as mi

    return {"type": "bitmap", "data": mi.TensorXf(np.ascontiguousarray(data, dtype=np.float32)), "raw": True,
            "wrap_mode": "repeat", "filter_type": filter_type,
            "to_uv": mi.ScalarTransform4f().scale([repeats, repeats, 1.0])}


class World:
    """Which world pieces a config renders, their scene entries and their per-frame updates."""

    def __init__(self, config: Config, sea_size_m: float) -> None:
        r = config.randomization
        self.config = config
        self.clouds = r.clouds.enabled
        self.waves = r.sea.waves
        self.whitecaps = r.sea.whitecaps
        self.sea_colour = r.sea.colour
        self.livery = r.livery.enabled
        self.sea_size_m = sea_size_m
        #: Any world piece on (the renderer then classifies every pixel's surface).
        self.any = self.clouds or self.waves or self.whitecaps or self.sea_colour or self.livery
        self._livery_bbox: dict[str, tuple[NDArray, NDArray]] = {}
        self._cloud_opacity: dict[str, NDArray[np.float32]] = {}
        self._cloud_key: tuple | None = None
        self._livery_key: tuple | None = None
        self._liveries: dict = {}
        self._sea_key: tuple | None = None
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

    def sea_bsdf(self, principled: dict) -> tuple[dict, str]:
        """The sea's BSDF and the parameter prefix of its principled BSDF."""
        repeats = self.sea_size_m / textures.WAVE_TILE_M
        if not self.waves:
            return principled, "sea.bsdf"
        flat = np.zeros((textures.WAVE_TEXELS, textures.WAVE_TEXELS, 3), np.float32)
        flat[..., 2] = 1.0
        return {"type": "normalmap", "normalmap": _bitmap(flat, repeats), "bsdf": principled}, "sea.bsdf.nested_bsdf"

    def cloud_shapes(self) -> dict:
        """Scene entries of the cloud layers (none when clouds are off): fixed-topology
        meshes whose cells are collapsed until a frame's clouds give them area.

        A layer is lit in advance rather than path traced: its side facing the camera
        emits ``albedo / pi`` times the sky's horizontal irradiance this frame (tops), or
        the part a cloud of its opacity transmits (bases), premultiplied by the opacity
        texture, over a black BSDF behind the same opacity ``mask``. A path that meets a
        cloud thus takes its light and ends there, or passes a thin edge, and the sun's
        shadow rays carry its transmission (:attr:`integrator`); path tracing the layers as white diffuse surfaces made
        paths bounce between cloud bases and the sea to the maximum depth and doubled
        the render time (measured)."""
        if not self.clouds:
            return {}
        import mitsuba as mi

        from datagen.render.mitsuba import mitsuba_mesh

        verts, faces, uv = _cloud_grid()
        empty = np.zeros((textures.CLOUD_TEXELS, textures.CLOUD_TEXELS, 1), np.float32)
        entries = {}
        for name in CLOUD_LAYERS:
            # Behind the mask, a black mirror: a delta lobe, so that the path tracer spends no
            # shadow ray on a surface that reflects nothing (a black diffuse one would).
            bsdf = mi.load_dict({"type": "mask", "opacity": _bitmap(empty, 1.0, "bilinear"), "bsdf": {
                "type": "conductor", "specular_reflectance": {"type": "rgb", "value": 0.0}}})
            emitter = mi.load_dict({"type": "area", "sampling_weight": 0.0,  # found by paths, never sampled
                                    "radiance": _bitmap(np.zeros(empty.shape[:2] + (3,)), 1.0, "bilinear")})
            # Built with every cell in place: the acceleration structure then follows the
            # grid, which later frames only collapse cells of (mirroring it measured 2x slower).
            self.cloud_meshes[name] = mitsuba_mesh(name, verts, faces, bsdf, texcoords=uv, emitter=emitter)
            entries[name] = self.cloud_meshes[name]
        return entries

    def wears_livery(self, obj: str, material_class: str) -> bool:
        return self.livery and obj in LIVERY_OBJECTS and material_class == "paint"

    def livery_part(self, obj: str, mesh, tm) -> tuple[NDArray, NDArray, NDArray]:
        """Unwelded vertices, faces and texture coordinates of a painted part of ``obj``
        (``mesh``: the whole object, whose bounding box the texture spans)."""
        if obj not in self._livery_bbox:
            vertices = np.concatenate([np.asarray(p.vertices) for p in mesh.parts.values()])
            self._livery_bbox[obj] = (vertices.min(axis=0), vertices.max(axis=0))
        lo, hi = self._livery_bbox[obj]
        return textures.triplanar_uv(tm.vertices, tm.faces, lo, hi)

    @staticmethod
    def livery_base_color() -> dict:
        import mitsuba as mi

        return {"type": "bitmap", "data": mi.TensorXf(np.full((textures.LIVERY_TEXELS,) * 2 + (3,), 0.5, np.float32)),
                "raw": True, "wrap_mode": "clamp", "filter_type": "bilinear"}

    # -- per frame -----------------------------------------------------------------------
    def livery_textures(self, look: FrameLook):
        """``{object: TensorXf}`` of the frame's liveries (empty when liveries are off)."""
        import mitsuba as mi

        if not self.livery or look.livery_seed is None:
            return {}
        key = (look.livery_seed, look.receiver_livery, look.tanker_livery, look.livery_weathering)
        if key == self._livery_key:
            return self._liveries  # an approach's aircraft, painted once
        lv = self.config.randomization.livery
        rng = texture_rng(look.livery_seed)
        out = {}
        for obj in LIVERY_OBJECTS:
            lo, hi = self._livery_bbox.get(obj, (np.zeros(3), np.ones(3)))
            scheme = getattr(look, f"{obj}_livery")
            out[obj] = mi.TensorXf(textures.livery(rng, scheme, look.livery_weathering, hi - lo,
                                                   panel_lines=lv.panel_lines, markings=lv.markings))
        self._livery_key, self._liveries = key, out
        return out

    def apply(self, params, look: FrameLook, camera_z_m: float, sea_prefix: str, sky_irradiance=None) -> None:
        """Set the frame's clouds and sea textures (the render frame has the camera at
        the origin; ``camera_z_m`` is its altitude; ``sky_irradiance`` the sun and sky's
        RGB irradiance on a horizontal surface, which lights the clouds)."""
        import mitsuba as mi

        if self.clouds:
            from datagen.render.mitsuba import set_buffer

            key = (look.cloud_seed, look.cloud_deck_coverage, look.cloud_layer_coverage, look.cloud_opacity)
            fresh = self._cloud_key != key
            drawn = look.cloud_seed is not None  # a look without cloud draws: clear sky
            rng = texture_rng(look.cloud_seed)
            albedo = look.cloud_albedo if drawn else 0.0
            light = np.asarray(sky_irradiance, dtype=np.float32) / np.float32(np.pi) * np.float32(albedo)
            for name, (coverage_key, altitude_key) in CLOUD_LAYERS.items():
                if fresh:  # the opacity of an approach's weather, made once
                    opacity = (textures.cloud_opacity(rng, getattr(look, coverage_key), look.cloud_opacity) if drawn
                               else np.zeros((textures.CLOUD_TEXELS, textures.CLOUD_TEXELS, 1), np.float32))
                    self._cloud_opacity[name] = opacity[..., 0]
                    params[f"{name}.bsdf.opacity.data"] = mi.TensorXf(opacity)
                opacity = self._cloud_opacity[name][..., None]
                height = (getattr(look, altitude_key) if drawn else 0.0) - camera_z_m
                above = height > 0.0  # seen from below: a base, which lets through what its thickness does
                radiance = light * (np.float32(1.0) - np.float32(0.7) * opacity if above else np.float32(1.0))
                params[f"{name}.emitter.radiance.data"] = mi.TensorXf(radiance * opacity)
                if fresh or self._cloud_height.get(name) != height:  # the mesh moves only when it must
                    set_buffer(params, f"{name}.vertex_positions", _cloud_cells(self._cloud_opacity[name], height))
                    self._cloud_height[name] = height
                if self._cloud_down.get(name) != above:  # the emitting side faces the camera
                    set_buffer(params, f"{name}.faces", _cloud_faces(above))
                    self._cloud_down[name] = above
            self._cloud_key = key
        if not (self.waves or self.whitecaps or self.sea_colour):
            return
        key = (look.sea_seed, look.sea_wind_speed_mps, look.sea_wind_direction_deg, look.sea_whitecap_fraction,
               look.sea_colour)
        if key == self._sea_key:
            return  # an approach's sea, made once
        self._sea_key = key
        rng = texture_rng(look.sea_seed)
        colour = np.asarray(look.sea_colour if look.sea_colour is not None else SEA_COLOUR, dtype=np.float32)
        wind = look.sea_wind_speed_mps if look.sea_wind_speed_mps is not None else 7.0
        if self.waves:
            normals = textures.wave_field(rng, wind, look.sea_wind_direction_deg or 0.0)
            params["sea.bsdf.normalmap.data"] = mi.TensorXf(normals * 0.5 + 0.5)
        caps = np.float32(look.sea_whitecap_fraction or 0.0)
        albedo = colour * (np.float32(1.0) - caps) + np.float32(FOAM_ALBEDO) * caps
        params[f"{sea_prefix}.base_color.value"] = mi.Color3f(*(float(c) for c in albedo))

    def cloud_opacity_at(self, name: str, uv: NDArray) -> NDArray[np.float32]:
        """The opacity of cloud layer ``name`` this frame at its texture coordinates ``uv`` (N, 2)."""
        tex = self._cloud_opacity.get(name)
        if tex is None:
            return np.zeros(len(uv), np.float32)
        n = tex.shape[0]
        # Mitsuba's bilinear filter with repeat: texel centres at (i + 0.5) / n.
        xy = np.mod(np.asarray(uv, dtype=np.float64), 1.0) * n - 0.5
        i0 = np.floor(xy).astype(np.int64)
        f = (xy - i0).astype(np.float32)
        x0, y0 = i0[:, 0] % n, i0[:, 1] % n
        x1, y1 = (x0 + 1) % n, (y0 + 1) % n
        top = tex[y0, x0] * (1 - f[:, 0]) + tex[y0, x1] * f[:, 0]
        bottom = tex[y1, x0] * (1 - f[:, 0]) + tex[y1, x1] * f[:, 0]
        return top * (1 - f[:, 1]) + bottom * f[:, 1]


@functools.cache
def _cloud_grid() -> tuple[NDArray[np.float32], NDArray[np.uint32], NDArray[np.float32]]:
    """The cell layout of a cloud layer: every cell its own quad (4 vertices, 2 faces),
    texture coordinates in tiles (the bitmap repeats), vertex positions at z = 0."""
    cells = CLOUD_TILES * CLOUD_CELLS
    i, j = np.meshgrid(np.arange(cells), np.arange(cells))  # j: rows (v), i: columns (u)
    corners = np.array([[0, 0], [1, 0], [1, 1], [0, 1]])
    u = (i.reshape(-1, 1) + corners[:, 0]) / CLOUD_CELLS  # (cells^2, 4), in tiles
    v = (j.reshape(-1, 1) + corners[:, 1]) / CLOUD_CELLS
    uv = np.stack([u, v], axis=-1).reshape(-1, 2).astype(np.float32)
    x = (uv[:, 0] - CLOUD_TILES / 2) * textures.CLOUD_TILE_M
    y = (uv[:, 1] - CLOUD_TILES / 2) * textures.CLOUD_TILE_M
    verts = np.stack([x, y, np.zeros_like(x)], axis=-1).astype(np.float32)
    base = (np.arange(cells * cells) * 4)[:, None]
    faces = np.concatenate([base + [0, 1, 2], base + [0, 2, 3]], axis=1).reshape(-1, 3).astype(np.uint32)
    return verts, faces, uv


def _cloud_faces(facing_down: bool) -> NDArray[np.uint32]:
    """A cloud layer's faces, wound to face up (+z: tops) or down (bases)."""
    faces = _cloud_grid()[1]
    return faces[:, ::-1].copy() if facing_down else faces


def _cloud_cells(opacity: NDArray[np.float32], height: float) -> NDArray[np.float32]:
    """Vertex positions of a cloud layer at ``height`` over the camera: cells that hold
    cloud anywhere keep their quad, the others collapse to their centre (no area: no ray
    meets them)."""
    verts = _cloud_grid()[0]
    n = opacity.shape[0]
    per_cell = n // CLOUD_CELLS
    # A texel's cloud reaches half a texel into its neighbours through the bilinear filter.
    grown = opacity
    for axis in (0, 1):
        grown = np.maximum(grown, np.maximum(np.roll(grown, 1, axis), np.roll(grown, -1, axis)))
    cloudy = grown.reshape(CLOUD_CELLS, per_cell, CLOUD_CELLS, per_cell).max(axis=(1, 3)) > 0.0
    cloudy = np.tile(cloudy, (CLOUD_TILES, CLOUD_TILES)).reshape(-1)
    out = verts.reshape(-1, 4, 3).copy()
    out[~cloudy] = out[~cloudy].mean(axis=1, keepdims=True)
    out[..., 2] = height
    return out.reshape(-1)
