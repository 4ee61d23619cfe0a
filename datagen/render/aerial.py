"""Aerial perspective inside the render: every camera sample seen through the air.

:func:`aerial_class` wraps the scene's path tracer in a Python
:class:`mitsuba.SamplingIntegrator` that takes each camera sample's radiance ``L`` and
returns :func:`~datagen.render.atmosphere.through_air` of it, along the sample's own first
hit: a pixel across the horizon or a silhouette mixes samples each seen through its own
path, before the denoiser sees them (a post-process on the finished image would dim the
sea's samples of a horizon pixel by its centre's path, or not at all). Per sample:

- the path's transmittance, looked up bilinearly in the frame's
  :func:`~datagen.render.atmosphere.transmittance_table` by the ray's elevation and the
  hit's distance;
- its airlight and the column's transmittance, interpolated from a grid of the sky's own
  radiance every :data:`AIRLIGHT_STEP_PX` pixels (:meth:`~datagen.render.sky.sky_class`'s
  ``radiance``);
- a sample that meets cloud layers weighs its path to each layer and the one past it
  (more rays, up to two layers) by that layer's opacity where the sample meets it (the
  share of the sample's light the layer itself sends; the rest comes from behind it). A
  pixel's or a block's opacity instead (a geometry pass's) gave every sample of a block
  whose centre met a wisp of cloud the wisp's short path: rows of dark dots where the
  sample saw the far sea.

Everything that changes per frame is a kernel input (arrays, opaque scalars): the render
kernel compiles once. Samples that meet nothing (the sky) are returned as they are.
"""

from __future__ import annotations

import functools
from typing import Final

import numpy as np
from numpy.typing import NDArray

from datagen.core.camera import Intrinsics
from datagen.render.atmosphere import (
    TABLE_MU,
    TABLE_S,
    Atmosphere,
    table_coordinates,
    table_paths,
    through_air,
    transmittance_table,
)
from datagen.render.raycast import hit_key

__all__ = ["AIRLIGHT_STEP_PX", "aerial_class", "airlight_grid"]

#: The airlight (the sky's radiance in each pixel's direction) and its column's transmittance
#: are looked up every AIRLIGHT_STEP_PX pixels and interpolated (the sky varies over degrees).
AIRLIGHT_STEP_PX: Final = 16


def airlight_grid(sky, air: Atmosphere, k: Intrinsics, world_from_cam: NDArray[np.float64],
                  step: int = AIRLIGHT_STEP_PX) -> NDArray[np.float32]:
    """(gh, gw, 6): the airlight (RGB) and the column transmittance (RGB) at pixel centres
    spread evenly from the first pixel's to the last's, about ``step`` pixels apart
    (``sky``: the frame's :func:`~datagen.render.sky.sky_class` emitter)."""
    gu = np.linspace(0.5, k.width - 0.5, max(2, -(-k.width // step) + 1))
    gv = np.linspace(0.5, k.height - 0.5, max(2, -(-k.height // step) + 1))
    u, v = np.meshgrid(gu, gv)
    rays = np.stack([(u - k.cx) / k.fx, (v - k.cy) / k.fy, np.ones_like(u)], axis=-1) @ world_from_cam[:3, :3].T
    rays /= np.linalg.norm(rays, axis=-1, keepdims=True)
    airlight = sky.radiance(rays.reshape(-1, 3)).reshape(*rays.shape[:2], 3)
    return np.concatenate([airlight, air.column_transmittance(rays[..., 2])], axis=-1).astype(np.float32)


@functools.cache
def aerial_class(variant: str):
    """The aerial-perspective :class:`mitsuba.SamplingIntegrator` of ``variant`` (a JIT
    one): construct it around the scene's integrator; :meth:`set_frame` each frame."""
    import drjit as dr
    import mitsuba as mi

    from datagen.render.mitsuba import scene_array
    from datagen.render.procedural import drjit_ops
    from datagen.render.raycast import _past

    ops = drjit_ops()

    def opaque(value: float):
        return dr.opaque(mi.Float, float(value))

    class AerialPerspective(mi.SamplingIntegrator):
        def __init__(self, inner) -> None:
            super().__init__(mi.Properties())
            self.inner = inner
            self._frame: dict | None = None  # (set_frame; None: the air dims nothing)
            self._paths: tuple | None = None

        def set_frame(self, *, air: Atmosphere, grid: NDArray[np.float32], intrinsics: Intrinsics,
                      cam_from_render: NDArray[np.float64], codes, opacities: tuple = ()) -> None:
            """The frame's air (``grid``: :func:`airlight_grid`; ``cam_from_render``: the
            camera's rotation; ``codes``: per :func:`~datagen.render.raycast.hit_key` + 1 its
            index in ``("sea", *CLOUD_LAYERS)``; ``opacities``: the layers' opacity textures, in that
            order, asked where a sample meets a layer)."""
            k = intrinsics
            gh, gw = grid.shape[:2]
            if self._paths is None:  # the table's entries, made once
                self._paths = tuple(scene_array(mi.Float, a.reshape(-1).astype(np.float32)) for a in table_paths())
                dr.make_opaque(*self._paths)
            table = dr.ravel(mi.Vector3f(*transmittance_table(air, ops, self._paths)))  # RGB interleaved
            self._frame = {
                "table": table,
                "grid": scene_array(mi.Float, np.ascontiguousarray(grid).reshape(-1)), "gw": gw, "gh": gh,
                "k": [opaque(x) for x in (k.fx, k.fy, k.cx, k.cy)], "size": (k.width, k.height),
                "rotation": [[opaque(cam_from_render[i, j]) for j in range(3)] for i in range(3)],
                "codes": codes, "opacities": tuple(opacities),
            }
            dr.make_opaque(self._frame["table"], self._frame["grid"])

        def sample(self, scene, sampler, ray, medium=None, active=True):
            L, valid, aovs = self.inner.sample(scene, sampler, ray, medium, active)
            f = self._frame
            if f is None:
                return L, valid, aovs
            d = ray.d
            codes = f["codes"]

            def cast(origin, active):
                """(distance, 0 where nothing is met; the cloud layer met: its index in
                ``("sea", *CLOUD_LAYERS)``, 0 or -1 for anything else) along ``d``."""
                # The preliminary intersection: the distance and what was met (keyed as the
                # geometry pass keys it), without the surface interaction (a call per shape a
                # frozen render cannot record).
                si = scene.ray_intersect_preliminary(mi.Ray3f(origin, d), coherent=True, active=active)
                hit = active & si.is_valid()
                shape = hit_key(mi, dr, si)
                known = hit & (shape + 1 < dr.width(codes))
                return dr.select(hit, si.t, 0.0), dr.select(known, dr.gather(mi.Int32, codes, shape + 1, known), -1)

            # The sample's first hit, and past up to two cloud layers what lies behind each
            # (the sky: 0).
            t1, layer1 = cast(ray.o, active)
            cloud1 = layer1 > 0
            start = _past(t1, dr.maximum)
            t2, layer2 = cast(ray.o + d * start, cloud1)
            t2 = dr.select(cloud1 & (t2 > 0.0), start + t2, 0.0)
            cloud2 = cloud1 & (layer2 > 0)
            start = _past(t2, dr.maximum)
            t3, _ = cast(ray.o + d * start, cloud2)
            t3 = dr.select(cloud2 & (t3 > 0.0), start + t3, 0.0)
            # The sample's pixel (continuous), from its direction in the camera frame.
            r = f["rotation"]
            x, y, z = (r[i][0] * d.x + r[i][1] * d.y + r[i][2] * d.z for i in range(3))
            fx, fy, cx, cy = f["k"]
            width, height = f["size"]
            u = dr.clip(fx * x / z + cx, 0.0, width - 1e-3)
            v = dr.clip(fy * y / z + cy, 0.0, height - 1e-3)
            # How much of the sample each path carries: the layers' opacities where it meets them.
            w1 = self._opacity(cloud1, layer1, ray.o + d * t1)
            w2 = self._opacity(cloud2, layer2, ray.o + d * t2)
            weights = (w1, (1.0 - w1) * w2, (1.0 - w1) * (1.0 - w2))
            airlight, column = self._grid(u, v, width, height)
            paths = [self._transmittance(d.z, t) for t in (t1, t2, t3)]
            out = []
            for c in range(3):
                seen = sum(w * through_air(L[c], airlight[c], column[c], tt[c], ops)
                           for w, tt in zip(weights, paths, strict=True))
                out.append(dr.select(t1 > 0.0, seen, L[c]))
            return mi.Spectrum(*out), valid, aovs

        def _opacity(self, met, layer, p):
            """The opacity of the cloud layer a sample met (``layer``: its index in
            ``("sea", *CLOUD_LAYERS)``) at the sample's hit ``p``, 1 where it met none or no
            opacity is known (the path ends there); a texture is evaluated only in its
            layer's lanes (packets without one skip it)."""
            w = dr.full(mi.Float, 1.0, dr.width(p))
            si = dr.zeros(mi.SurfaceInteraction3f)
            si.p = p
            for k, texture in enumerate(self._frame["opacities"], start=1):
                def own(texture=texture):
                    return (dr.clip(texture.eval_1(si), 0.0, 1.0),)

                w = ops.where(met & (layer == k), (w,), own)[0]
            return w

        def _transmittance(self, mu, s):
            """The table's transmittance (RGB) of paths of elevation ``asin(mu)`` and length ``s``."""
            row, column = table_coordinates(mu, s, ops)
            i = dr.minimum(mi.UInt32(row), TABLE_MU - 2)
            j = dr.minimum(mi.UInt32(column), TABLE_S - 2)
            a, b = row - mi.Float(i), column - mi.Float(j)
            table = self._frame["table"]
            first = i * TABLE_S + j  # entries of three floats

            def at(offset):
                return dr.gather(mi.Vector3f, table, first + offset)

            top = at(0) * (1.0 - b) + at(1) * b
            bottom = at(TABLE_S) * (1.0 - b) + at(TABLE_S + 1) * b
            return top * (1.0 - a) + bottom * a

        def _grid(self, u, v, width: int, height: int):
            """The airlight and the column transmittance at continuous pixel ``(u, v)``."""
            f = self._frame
            assert f is not None  # (read only where a frame set it: sample)
            gw, gh = f["gw"], f["gh"]
            gx = dr.clip((u - 0.5) * ((gw - 1) / max(width - 1, 1)), 0.0, gw - 1.0)
            gy = dr.clip((v - 0.5) * ((gh - 1) / max(height - 1, 1)), 0.0, gh - 1.0)
            i = dr.minimum(mi.UInt32(gy), gh - 2)
            j = dr.minimum(mi.UInt32(gx), gw - 2)
            a, b = gy - mi.Float(i), gx - mi.Float(j)
            grid = f["grid"]

            def at(di, dj, half):
                return dr.gather(mi.Vector3f, grid, ((i + di) * gw + j + dj) * 2 + half)

            def lerp(half):
                top = at(0, 0, half) * (1.0 - b) + at(0, 1, half) * b
                bottom = at(1, 0, half) * (1.0 - b) + at(1, 1, half) * b
                return top * (1.0 - a) + bottom * a

            return lerp(0), lerp(1)

        def aov_names(self):
            return self.inner.aov_names()

        def to_string(self):
            return "AerialPerspective[]"

    assert mi.variant() == variant
    return AerialPerspective
