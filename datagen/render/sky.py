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
"""

from __future__ import annotations

import functools
import math
from typing import Final

import numpy as np
from numpy.typing import ArrayLike

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

    scalar = variant.startswith("scalar")
    cos_half = math.cos(math.radians(SUN_APERTURE_DEG / 2.0))

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
            self.sun_scale = self.sky_scale = opaque(1.0)

        def set(self, sun_direction: ArrayLike, turbidity: float, sun_scale: float, sky_scale: float) -> None:
            """The frame's sky: the unit vector towards the sun (world frame), the
            atmosphere's turbidity and the two scales."""
            d = np.asarray(sun_direction, dtype=np.float64)
            d = [float(c) for c in d / np.linalg.norm(d)]
            self._params["sun_direction"] = mi.Vector3f(*d)
            self._params["turbidity"] = float(turbidity)
            self._params.update()
            self.sun = mi.Vector3f(*(opaque(c) for c in d))
            self.sun_scale, self.sky_scale = opaque(sun_scale), opaque(sky_scale)

        def _scale(self, d):
            """The scale of what arrives from direction ``d`` (towards the sky)."""
            return dr.select(dr.dot(d, self.sun) >= cos_half, self.sun_scale, self.sky_scale)

        def eval(self, si, active=True):
            return self.inner.eval(si, active) * self._scale(-si.wi)

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
