"""The sun and the sky as one environment emitter whose per-frame scales are kernel inputs.

Mitsuba's ``sunsky`` holds ``sun_scale`` and ``sky_scale`` as C++ scalars, which Dr.Jit
bakes into the render kernel as literals: each new pair compiled a new path-tracing kernel
(seconds each). :func:`sky_class` wraps one ``sunsky`` made with both scales at 1 in a
Python emitter that multiplies what it emits by the frame's scale, the sun's inside the
sun's disk and the sky's outside it, both held as opaque values. Radiance is linear in
each scale and the two terms are apart on the sphere, except for the sky inside the
disk, which the sun outshines some 10^5 times: the sky's share there takes the sun's scale
instead of its own (the images of both ways agree within their sampling noise for
scales 0 to 1.2: CHANGELOG.md). Sampling is ``sunsky``'s own; a sample's weight takes its
direction's scale. Turbidity and the sun's direction go to the wrapped ``sunsky`` through
``mi.traverse`` (kernel inputs already).

The earth is round (:mod:`datagen.core.conventions`): from altitude the sea's horizon lies
below the horizontal, and a ray between the two sees the sky just above the horizon
(``sunsky``, made for an observer on the ground, is black below it):
:meth:`SunSky.eval` lifts such directions to :data:`~datagen.render.atmosphere.HORIZON_ELEVATION_DEG`.
:meth:`SunSky.radiance` looks the sky up for the aerial perspective.
"""

from __future__ import annotations

import functools
import math
from typing import Final

import numpy as np
from numpy.typing import ArrayLike

from datagen.core.transforms import vec3

__all__ = ["SUN_APERTURE_DEG", "sky_class"]

#: The sun's angular diameter, degrees (``sunsky``'s default, passed to it explicitly).
SUN_APERTURE_DEG: Final = 0.5338
#: Where the sun is until the first frame sets it (a unit vector, world frame).
_FIRST_SUN: Final = (0.0, 0.5, math.sqrt(0.75))


@functools.cache
def sky_class(variant: str):
    """The sun-and-sky :class:`mitsuba.Emitter` of ``variant`` (the current one): construct
    it with no argument and set each frame's sky with :meth:`set`."""
    import drjit as dr
    import mitsuba as mi

    from datagen.render.atmosphere import HORIZON_ELEVATION_DEG, airlight_directions

    scalar = variant.startswith("scalar")
    cos_half = math.cos(math.radians(SUN_APERTURE_DEG / 2.0))
    low = math.sin(math.radians(HORIZON_ELEVATION_DEG))
    low_horizontal = math.sqrt(1.0 - low * low)

    def lifted(d):
        """``d`` (towards the sky), or below the horizon the direction of its azimuth at
        :data:`HORIZON_ELEVATION_DEG` (:func:`~datagen.render.atmosphere.airlight_directions`'
        rule)."""
        level = d.x * d.x + d.y * d.y > 1e-18  # straight down: the horizon along +x
        x, y = dr.select(level, d.x, 1.0), dr.select(level, d.y, 0.0)
        k = low_horizontal / dr.sqrt(x * x + y * y)
        below = d.z < low
        return mi.Vector3f(dr.select(below, x * k, d.x), dr.select(below, y * k, d.y), dr.select(below, low, d.z))

    def opaque(value: float):
        return float(value) if scalar else dr.opaque(mi.Float, float(value))

    class SunSky(mi.Emitter):
        def __init__(self, props=None):
            super().__init__(props if props is not None else mi.Properties())
            self.inner = mi.load_dict({"type": "sunsky", "sun_direction": list(_FIRST_SUN),
                                       "sun_aperture": SUN_APERTURE_DEG})
            self._params = mi.traverse(self.inner)
            self.m_flags = mi.EmitterFlags.Infinite | mi.EmitterFlags.SpatiallyVarying
            self.sun = mi.Vector3f(*_FIRST_SUN)
            self.sun_direction = np.array(_FIRST_SUN)  # the same, on the host
            self.sun_scale = self.sky_scale = opaque(1.0)

        def set(self, sun_direction: ArrayLike, turbidity: float, sun_scale: float, sky_scale: float) -> None:
            """The frame's sky: the unit vector towards the sun (world frame), the
            atmosphere's turbidity and the two scales."""
            d = np.asarray(sun_direction, dtype=np.float64)
            self._params["sun_direction"] = mi.Vector3f(*vec3(d / np.linalg.norm(d)))
            self._params["turbidity"] = float(turbidity)
            self._params.update()
            self.sun = mi.Vector3f(*(opaque(c) for c in d))
            self.sun_direction = np.array(d)
            self.sun_scale, self.sky_scale = opaque(sun_scale), opaque(sky_scale)

        def _scale(self, d):
            """The scale of what arrives from direction ``d`` (towards the sky)."""
            return dr.select(dr.dot(d, self.sun) >= cos_half, self.sun_scale, self.sky_scale)

        def eval(self, si, active=True):
            d = lifted(-si.wi)
            si = mi.SurfaceInteraction3f(si)
            si.wi = -d
            return self.inner.eval(si, active) * self._scale(d)

        def radiance(self, directions) -> np.ndarray:
            """(N, 3) linear RGB of the sky (the sun's disc excluded: the sky just outside
            it) in ``directions`` (N, 3), world frame, lifted above the horizon as
            :meth:`eval` does: the airlight of :mod:`datagen.render.atmosphere`."""
            d = airlight_directions(directions, self.sun_direction, SUN_APERTURE_DEG)
            if scalar:
                out = np.zeros((len(d), 3))
                for i, v in enumerate(d):
                    si = dr.zeros(mi.SurfaceInteraction3f)
                    si.wi = mi.Vector3f(*(-float(c) for c in v))
                    value = self.inner.eval(si)
                    out[i] = [float(value[c]) for c in range(3)]
                return out * float(self.sky_scale)
            from datagen.render.mitsuba import jit_vectors

            si = dr.zeros(mi.SurfaceInteraction3f, max(len(d), 2))
            si.wi = -jit_vectors(mi.Vector3f, np.resize(d.astype(np.float32), (max(len(d), 2), 3)))
            value = self.inner.eval(si) * self.sky_scale
            return np.stack([np.asarray(value[c], dtype=np.float64) for c in range(3)], axis=-1)[: len(d)]

        def sample_direction(self, it, sample, active=True):
            ds, weight = self.inner.sample_direction(it, sample, active)
            return ds, weight * self._scale(ds.d)

        def pdf_direction(self, it, ds, active=True):
            return self.inner.pdf_direction(it, ds, active)

        def eval_direction(self, it, ds, active=True):
            return self.inner.eval_direction(it, ds, active) * self._scale(ds.d)

        def sample_wavelengths(self, si, sample, active=True):
            return self.inner.sample_wavelengths(si, sample, active)

        def set_scene(self, scene):
            self.inner.set_scene(scene)

        def bbox(self):
            return self.inner.bbox()

        def traverse(self, callback):
            pass  # set() updates the sky: mi.traverse of a scene shows none of it

        def parameters_changed(self, keys=None):
            pass

        def to_string(self):
            return "SunSky[]"

    assert mi.variant() == variant
    return SunSky
