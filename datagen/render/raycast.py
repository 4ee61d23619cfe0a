"""Ray casting in the posed scene of a :class:`~datagen.render.renderer.Renderer`: the
geometry pass (a ray through each pixel centre, continuous convention: pixel (i, j) has its
centre at (i + 0.5, j + 0.5)) for the camera z-depth ``Z``, the
:func:`~datagen.core.conventions.object_id` of each object (0 where the ray hits the sea or
nothing) and the surface it meets, on the variant's device; and feature visibility, a ray
from the camera to each feature point: a point is visible when it is in front of the camera
and nothing is hit before it, up to :func:`visibility_tolerance_m`."""

from __future__ import annotations

import functools
from typing import TYPE_CHECKING, Any, Final

import numpy as np
from numpy.typing import NDArray

from datagen.core.conventions import OBJECT_NAMES, OTHER_AIRCRAFT_ID, object_id, pixel_centres
from datagen.render.mitsuba import jit_array, jit_vectors, scene_array, visible
from datagen.render.procedural import only_where
from datagen.render.world import CLOUD_LAYERS, SURFACES, World

if TYPE_CHECKING:
    from datagen.core.camera import Intrinsics
    from datagen.core.features import FeatureTable
    from datagen.render.frozen import Frozen
    from datagen.scene.approach import FrameState

__all__ = ["CLOUD_PASS_OPACITY", "RayCasting", "cast_kernel", "hit_key", "visibility_tolerance_m"]

#: The geometry pass's cast carries a frame's other rays from the camera (the sun's, the lights')
#: in blocks of this many.
EXTRA_RAYS: Final = 16
#: A ray cast by the geometry pass passes a cloud layer where the layer's opacity is below this.
CLOUD_PASS_OPACITY: Final = 0.5


def visibility_tolerance_m(distance_m: NDArray[np.float64]) -> NDArray[np.float64]:
    """How far before a feature point a hit still counts as the point itself: 1 cm
    plus 1e-4 of the distance (float32 intersection error and mesh rounding)."""
    return 0.01 + 1e-4 * np.asarray(distance_m)


def _appended(mi, dr, a, b):
    """Dr.Jit vectors ``b`` after ``a`` in one array (on their device, in Dr.Jit's memory)."""
    n, m = dr.width(a), dr.width(b)
    out = dr.zeros(type(a), n + m)
    dr.scatter(out, a, dr.arange(mi.UInt32, n))
    dr.scatter(out, b, dr.arange(mi.UInt32, m) + dr.opaque(mi.UInt32, n))
    return out


def _ray_block(mi, directions: NDArray):
    """``(N, 3)`` directions padded to a whole number of :data:`EXTRA_RAYS` blocks (one at
    least; padding repeats them, or looks straight ahead) as a ``mi.Vector3f`` in Dr.Jit's
    memory: a frozen cast takes it as an input (:func:`datagen.render.mitsuba.scene_array`),
    and the same count of rays gives the same recording."""
    rays = np.asarray(directions, dtype=np.float32).reshape(-1, 3)
    rays = np.resize(rays if len(rays) else np.array([[0.0, 0.0, 1.0]], np.float32),
                     (max(1, -(-len(rays) // EXTRA_RAYS)) * EXTRA_RAYS, 3))
    return mi.Vector3f(*(scene_array(mi.Float, rays[:, i]) for i in range(3)))


def _past(t, maximum):
    """How far a ray that passes a cloud layer at distance ``t`` goes on before it is cast
    again: just past the layer (``maximum``: numpy's or Dr.Jit's)."""
    return t + 1e-3 * maximum(t, 1.0)


class RayCasting:
    """The renderer's ray casts, after it is posed: its Mitsuba ``scene``, ``world``,
    ``variant``, ``intrinsics``, the posed camera (``_world_from_cam``, ``_camera_render``),
    the device tables its build made (``_id_table``, ``_background_codes``, keyed by
    :func:`hit_key`), its Mitsuba and Dr.Jit modules (``_mi``, ``_dr``), and the frozen cast
    (``_frozen_cast``, a :class:`~datagen.render.frozen.Frozen` of :func:`cast_kernel`; None: traced)."""

    intrinsics: Intrinsics
    variant: str
    scene: Any  # mi.Scene (of the variant)
    world: World
    _world_from_cam: NDArray[np.float64]
    _camera_render: NDArray[np.float64]
    _id_table: Any
    _background_codes: Any
    _mi: Any
    _dr: Any
    _frozen_cast: Frozen | None

    @functools.cache  # noqa: B019 (one renderer per process; two strides at most)
    def _pixel_rays(self, stride: int = 1) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
        """Unit directions (camera frame) through every pixel centre (``stride`` 1) or
        through the centre of every ``stride`` x ``stride`` block, and their z components
        (z-depth per unit of ray length); computed once."""
        k = self.intrinsics
        uu, vv = pixel_centres(k.width, k.height, stride)
        d_cam = np.stack([(uu - k.cx) / k.fx, (vv - k.cy) / k.fy, np.ones_like(uu)], axis=-1).reshape(-1, 3)
        norm = np.linalg.norm(d_cam, axis=1)
        return (d_cam / norm[:, None]).astype(np.float32), (1.0 / norm).astype(np.float32)

    def cast(self, origin_render: NDArray, directions_render: NDArray):
        """Intersect rays (render frame); returns (t, object id, surface) as numpy arrays,
        ``surface`` indexing :data:`datagen.render.world.SURFACES`. A ray passes through a
        cloud layer where the layer's opacity is below :data:`CLOUD_PASS_OPACITY` (Mitsuba's
        intersection sees the layer's cells; the mask is a texture). Vectorized variants
        cast on their device (:meth:`_cast_on_device`, from the posed camera), a scalar one
        here, one ray at a time."""
        n = len(directions_render)
        directions = np.asarray(directions_render, dtype=np.float32)
        if not self.variant.startswith("scalar"):  # on the variant's device
            t, ids, surface = self._cast_on_device(_ray_block(self._mi, directions))[:3]
            return tuple(np.asarray(a)[:n] for a in (t, ids, surface))
        origins = np.broadcast_to(np.asarray(origin_render, dtype=np.float32), (n, 3)).copy()
        t = np.full(n, np.inf)
        ids = np.zeros(n, dtype=np.uint32)
        surface = np.zeros(n, dtype=np.uint8)
        travelled = np.zeros(n)
        todo = np.arange(n)
        backgrounds = ("sea", *CLOUD_LAYERS)
        for _ in range(len(CLOUD_LAYERS) + 1):
            valid, hit_t, hit_ids, background = self._intersect(origins[todo], directions[todo])
            surface_now = np.where(valid, SURFACES.index("object"), SURFACES.index("sky")).astype(np.uint8)
            surface_now[background == 0] = SURFACES.index("sea")
            passing = np.zeros(len(todo), dtype=bool)
            for code, name in enumerate(backgrounds[1:], start=1):
                on = background == code
                if on.any():
                    surface_now[on] = SURFACES.index("cloud")
                    at = origins[todo[on]] + directions[todo[on]] * hit_t[on, None].astype(np.float32)
                    opacity = self.world.cloud_opacity_at(name, at[:, :2], travelled[todo[on]] + hit_t[on])
                    passing[np.flatnonzero(on)[opacity < CLOUD_PASS_OPACITY]] = True
            done = ~passing
            idx = todo[done]
            t[idx] = travelled[idx] + hit_t[done]
            ids[idx] = hit_ids[done]
            surface[idx] = surface_now[done]
            if not passing.any():
                break
            go = todo[passing]
            step = _past(hit_t[passing], np.maximum)
            travelled[go] += step
            origins[go] += directions[go] * step[:, None].astype(np.float32)
            todo = go
        return t, ids, surface

    def _intersect(self, origins: NDArray[np.float32], directions: NDArray[np.float32]):
        """First hits of rays under a scalar variant, one ray at a time (slow; shapes go by
        their names): (valid, t (inf on a miss), object id, background code (index into
        ``("sea", *CLOUD_LAYERS)``, -1 for none))."""
        mi = self._mi
        n = len(origins)
        valid, hit_t = np.zeros(n, dtype=bool), np.full(n, np.inf)
        ids, background = np.zeros(n, np.uint32), np.full(n, -1)
        codes = {name: c for c, name in enumerate(("sea", *CLOUD_LAYERS))}
        for i in range(n):
            ray = mi.Ray3f(mi.Point3f(*(float(v) for v in origins[i])), mi.Vector3f(*(float(v) for v in directions[i])))
            si = self.scene.ray_intersect(ray)
            if si.is_valid():
                valid[i], hit_t[i] = True, si.t
                shape = str(si.shape.id())
                name = shape.split("_")[0]  # shape ids are object_pN or hose
                ids[i] = object_id(name) if name in OBJECT_NAMES else 0
                if si.instance is not None and str(si.instance.id()).startswith("other_"):
                    ids[i] = OTHER_AIRCRAFT_ID  # another aircraft (datagen.scene.traffic)
                background[i] = codes.get(shape, -1)
        return valid, hit_t, ids, background

    def geometry_pass(self, stride: int = 1, *, opacity: bool = False) -> tuple[NDArray, ...]:
        """Camera z-depth, object id and surface (:data:`~datagen.render.world.SURFACES`)
        at every pixel centre; with ``stride`` 2, one ray per 2 x 2 block (at its centre),
        repeated over the block (what the camera model and the image statistics need).

        ``opacity``: also (h, w, 2) the opacity of each cloud layer (in
        :data:`~datagen.render.world.CLOUD_LAYERS`' order) where the pixel's ray meets it (-1
        where it does not: it meets none, or stops before; a scalar variant gives -1
        everywhere), copied to the host only when asked for (the aerial perspective weighs each
        sample by the layers' opacity where the sample meets them, not by this)."""
        return self.geometry_and_cast(stride, np.zeros((0, 3), np.float32), opacity=opacity)[0]

    def geometry_and_cast(self, stride: int, directions_render: NDArray, *, opacity: bool = False, grid: int = 0
                          ) -> tuple[tuple[NDArray, ...], NDArray, NDArray | None]:
        """:meth:`geometry_pass` and, in the same cast, the distance (inf: nothing) along each
        of ``directions_render`` ((N, 3), render frame) from the posed camera, as
        :meth:`cast` gives it: a frame's few other rays from the camera (the sun's, its
        lights') ride with the pixels' rays, so that the frame traces one cast, not three.
        With ``grid``, also the object ids at the centres of ``grid`` x ``grid`` blocks (as
        :meth:`geometry_pass` at that stride, not repeated; None without), the same whatever
        ``stride`` is."""
        k = self.intrinsics
        d_cam, z_per_t = self._pixel_rays(stride)
        w, h = -(-k.width // stride), -(-k.height // stride)
        n, extra = len(d_cam), np.asarray(directions_render, dtype=np.float32).reshape(-1, 3)
        g = len(self._pixel_rays(grid)[0]) if grid else 0
        r = self._world_from_cam[:3, :3].astype(np.float32)  # the render frame shares the world's axes
        if self.variant.startswith("scalar"):
            grid_rays = [self._pixel_rays(grid)[0] @ r.T] if grid else []
            t, ids, surface = self.cast(self._camera_render, np.concatenate([d_cam @ r.T, *grid_rays, extra]))
            depth = t[:n] * z_per_t
            alpha = [np.full(n, -1.0, np.float32)] * len(CLOUD_LAYERS)
        else:  # the rays made and rotated on the device
            mi, dr = self._mi, self._dr
            d_dev, z_dev = self._device_rays(stride, grid)
            m = [[dr.opaque(mi.Float, float(r[i, j])) for j in range(3)] for i in range(3)]
            d = mi.Vector3f(*(m[i][0] * d_dev.x + m[i][1] * d_dev.y + m[i][2] * d_dev.z for i in range(3)))
            # The rays the frame asks for in blocks of EXTRA_RAYS (one at least): the same
            # kernels, and the same recording of them, every frame.
            d = _appended(mi, dr, d, _ray_block(mi, extra))
            t, ids, surface, *alpha = self._cast_on_device(d)
            dr.eval(t, ids, surface)
            t, ids, surface = (np.asarray(a) for a in (t, ids, surface))
            depth = t[:n] * np.asarray(z_dev)  # float32 products, as on the device
        out: tuple[NDArray, ...] = (depth.reshape(h, w).astype(np.float32), ids[:n].reshape(h, w).astype(np.uint32),
               surface[:n].reshape(h, w).astype(np.uint8))
        if opacity:
            layers = np.stack([np.asarray(a)[:n] for a in alpha], axis=-1)  # one per layer: a copy from the device
            out += (layers.reshape(h, w, len(CLOUD_LAYERS)).astype(np.float32),)
        cast = np.asarray(t[n + g:n + g + len(extra)], dtype=np.float32)
        grid_ids = np.asarray(ids[n:n + g]).reshape(-(-k.height // grid), -(-k.width // grid)).astype(np.uint32) \
            if grid else None
        if stride == 1:
            return out, cast, grid_ids
        return (tuple(np.repeat(np.repeat(a, stride, axis=0), stride, axis=1)[:k.height, :k.width] for a in out),
                cast, grid_ids)

    @functools.cache  # noqa: B019 (one renderer per process; two strides at most)
    def _device_rays(self, stride: int, grid: int = 0):
        """:meth:`_pixel_rays` as Dr.Jit arrays on the variant's device (made once, opaque);
        with ``grid``, the rays through the centres of ``grid`` x ``grid`` blocks after the
        pixels' (their z components are the pixels' alone)."""
        mi, dr = self._mi, self._dr
        d_cam, z_per_t = self._pixel_rays(stride)
        if grid:
            d_cam = np.concatenate([d_cam, self._pixel_rays(grid)[0]])
        rays = jit_vectors(mi.Vector3f, d_cam), jit_array(mi.Float, z_per_t)
        dr.make_opaque(*rays)
        return rays

    def _cast_on_device(self, d):
        """:meth:`cast` of rays ``d`` (``mi.Vector3f``, render frame) from the posed camera, as
        Dr.Jit work on the variant's device: (t, object id, surface, and per cloud layer its
        opacity where the ray meets it (-1 where it does not)), evaluated there
        (:func:`cast_kernel`, frozen with the render where the render is: ``_frozen_cast``).
        The same as the scalar loop but for float32 rounding of the distance travelled
        through cloud layers (a pixel or two of 2 million at a cloud's edge)."""
        mi, dr = self._mi, self._dr
        n = dr.width(d)
        opaque = functools.partial(dr.opaque, shape=n)
        start = {"o": mi.Point3f(*(opaque(mi.Float, float(c)) for c in self._camera_render)),
                 "travelled": opaque(mi.Float, 0.0), "t": opaque(mi.Float, dr.inf), "ids": opaque(mi.UInt32, 0),
                 "surface": opaque(mi.UInt32, 0), "alpha": [opaque(mi.Float, -1.0) for _ in CLOUD_LAYERS],
                 "active": opaque(mi.Bool, True)}
        dr.make_opaque(d)
        present = tuple(c for c, name in enumerate(CLOUD_LAYERS, start=1) if self.world.cloud_layer(name) is not None)
        opacities = self.world.cloud_opacities()
        textures = tuple(opacities[c - 1] for c in present)
        # What the kernel bakes in (the rays' count too: loops size their state by it), so that
        # a change of any of it records anew.
        key = (present, dr.width(self._id_table), dr.width(self._background_codes),
               float(self.world.pixel_rad), n)
        args = (self.scene, d, start, self._id_table, self._background_codes, textures, key,
                tuple(t.inputs() for t in textures))
        frozen = getattr(self, "_frozen_cast", None)
        return cast_kernel(*args) if frozen is None else frozen(cast_kernel, *args)  # traced where refused

    def feature_visibility(self, state: FrameState, features: FeatureTable
                           ) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
        """Per feature: the fraction of its points visible from the camera and whether
        its centre is. Call after :meth:`pose` (or :meth:`render`) for the same state."""
        cam_pos = state.world_from_cam[:3, 3]
        world_from_obj = np.stack([state.world_from(o) for o in features.objects])[features.object_index]
        pts = np.concatenate([features.points_model, features.center_model[:, None]], axis=1)  # (F, P+1, 3)
        world = np.einsum("fij,fpj->fpi", world_from_obj[:, :3, :3], pts) + world_from_obj[:, None, :3, 3]
        rel = world.reshape(-1, 3) - cam_pos  # from the camera
        tolerance = visibility_tolerance_m(np.linalg.norm(rel, axis=1))
        in_front = rel @ state.world_from_cam[:3, 2] > 0
        origin = self._camera_render  # the camera in the render frame
        seen = (visible(self.scene, origin, rel + origin, tolerance) & in_front).reshape(world.shape[:2])
        p = features.points_model.shape[1]
        mask = np.arange(p)[None, :] < features.n_points[:, None]
        fraction = (seen[:, :p] & mask).sum(axis=1) / features.n_points
        return fraction, seen[:, p]


def hit_key(mi, dr, si):
    """What a preliminary intersection ``si`` met, as the registry id its tables are keyed by:
    the instance's where the hit is on one (an object, the earth, another aircraft), else the
    shape's (the hose, a cloud layer). (Embree leaves ``si.shape`` null on an instance's hit,
    OptiX names the instanced mesh: the instance decides on both.)"""
    instance = dr.reinterpret_array(mi.UInt32, si.instance)
    return dr.select(instance != 0, instance, dr.reinterpret_array(mi.UInt32, si.shape))


def cast_kernel(scene, d, start: dict, id_table, codes, textures: tuple, key: tuple, inputs: tuple = ()):
    """The rays ``d`` (render frame) cast from ``start["o"]`` through ``scene``, passing each
    cloud layer where its opacity is below :data:`CLOUD_PASS_OPACITY`, up to
    ``len(CLOUD_LAYERS) + 1`` times: (t, object id, surface code, and per cloud layer its
    opacity where the ray meets it, -1 where it does not). ``start`` holds the state's first
    values (all ``d``'s width); ``id_table`` maps a hit's :func:`hit_key` to its object id
    (:data:`~datagen.core.conventions.OTHER_AIRCRAFT_ID` for another aircraft's instance),
    ``codes`` a hit's key + 1 to its background code (0 sea, c the c-th cloud layer);
    ``textures`` are the opacity textures of the layers ``key[0]`` names (their codes);
    ``key`` also holds the tables' widths, the pixel's angle and the rays' count; ``inputs``,
    the textures' device values (their ``inputs``: a frozen cast finds its inputs among its
    arguments, not inside the textures).

    Everything a frame changes comes in as device data and every pass runs whatever the rays
    met, so that a recording (``dr.freeze``, :func:`datagen.render.frozen.frozen_cast`)
    replays any frame: a layer's opacity is evaluated on the lanes that meet it, inside a
    loop the others leave at once (no ``dr.compress``, whose width a recording would fix),
    and nothing is read back to the host."""
    import drjit as dr
    import mitsuba as mi

    present, _, _, pixel_rad, _ = key
    o = start["o"]
    travelled, t_out, ids_out, surface_out = start["travelled"], start["t"], start["ids"], start["surface"]
    alpha_out, active = list(start["alpha"]), start["active"]
    # Each step is evaluated on its own, so that every kernel is the same whichever
    # layers a frame's rays meet, and how many passes they take.
    for _ in range(len(CLOUD_LAYERS) + 1):
        # The preliminary intersection: the distance and what was met, without the surface
        # interaction, whose call per shape runs over every lane, the inactive ones too.
        si = scene.ray_intersect_preliminary(mi.Ray3f(o, d), coherent=True, active=active)
        shape: Any = hit_key(mi, dr, si)
        valid = active & si.is_valid()
        known = valid & (shape + 1 < dr.width(codes))
        ids = dr.gather(mi.UInt32, id_table, shape, valid & (shape < dr.width(id_table)))
        code = dr.select(known, dr.gather(mi.Int32, codes, shape + 1, known), -1)
        surface = mi.UInt32(dr.select(valid, SURFACES.index("object"), SURFACES.index("sky")))
        surface = dr.select(code == 0, SURFACES.index("sea"), surface)
        surface = dr.select(code > 0, SURFACES.index("cloud"), surface)
        hit_t = si.t
        dr.eval(hit_t, ids, code, surface)
        passing = dr.zeros(mi.Bool, dr.width(d))
        alpha = mi.Float(1.0)  # (read only where a layer set it)
        p = o + d * hit_t
        footprint = (travelled + hit_t) * pixel_rad
        for c, texture in zip(present, textures, strict=True):
            on = active & (code == c)  # the rays that met this layer
            (opacity,) = only_where(on, (mi.Float(1.0),), lambda p=p, footprint=footprint, texture=texture:
                                     (texture.value_at(p.x, p.y, footprint),))
            passing = dr.select(on, opacity < CLOUD_PASS_OPACITY, passing)
            alpha = dr.select(on, opacity, alpha)
            dr.eval(passing, alpha)
        done = active & ~passing
        t_out = dr.select(done, travelled + hit_t, t_out)
        ids_out = dr.select(done, ids, ids_out)
        surface_out = dr.select(done, surface, surface_out)
        for c in range(1, len(CLOUD_LAYERS) + 1):
            alpha_out[c - 1] = dr.select(active & (code == c), alpha, alpha_out[c - 1])
        active = passing
        step = _past(hit_t, dr.maximum)
        travelled = dr.select(passing, travelled + step, travelled)
        o = dr.select(passing, o + d * step, o)
        dr.eval(t_out, ids_out, surface_out, *alpha_out, active, travelled, o)
    return t_out, ids_out, surface_out, *alpha_out
