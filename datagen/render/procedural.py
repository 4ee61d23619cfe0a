"""Procedural textures inside Mitsuba's kernels: the fields of :mod:`datagen.assets.noise`
evaluated at each shading point, band-limited by the footprint of a pixel there.

A texture here is a Python :class:`mitsuba.Texture`: Dr.Jit traces its ``eval`` into the
render kernel like any other texture. What changes between frames (the field's offsets and
seeds, a layer's threshold, the camera's position, a colour) enters the kernel as opaque
values, so that a new frame reuses the compiled kernel.

The footprint of a pixel at a point is its distance from the camera times the angle a
pixel subtends (``1 / fx``): exact for what the camera sees directly, and a lower bound
for what it sees through a reflection.
"""

from __future__ import annotations

import dataclasses
import functools
from typing import Final

import numpy as np

from datagen.assets.noise import FADE_LO, NUMPY, FractalField, Ops, gradient_noise

__all__ = ["drjit_ops", "evaluate", "texture_class"]

#: The area a texture's field is evaluated on: its surface's render-frame x and y (metres).
PLANE_AXES: Final = (0, 1)


def drjit_ops() -> Ops:
    """:class:`datagen.assets.noise.Ops` for the current Mitsuba variant's Dr.Jit arrays
    (a scalar variant's are Python numbers: numpy's float32 and uint32 scalars then)."""
    import mitsuba as mi

    return _ops(mi.variant())


@functools.cache
def _ops(variant: str) -> Ops:
    import drjit as dr
    import mitsuba as mi

    if variant.startswith("scalar"):
        return NUMPY

    ops = Ops(
        floor=dr.floor,
        to_u32=lambda f: mi.UInt32(mi.Int32(f)),
        to_f32=mi.Float,
        clip=dr.clip,
        f32=float,
        u32=int,
        param_f32=lambda v: dr.opaque(mi.Float, float(v)),
        param_u32=lambda v: dr.opaque(mi.UInt32, int(v)),
    )
    return dataclasses.replace(ops, octave_loop=functools.partial(_octave_loop, ops))


def evaluate(fn, *arrays: np.ndarray) -> np.ndarray:
    """``fn(*arrays, ops)`` over numpy float32 arrays, evaluated by the current variant's
    Dr.Jit (by numpy under a scalar variant); the result as a numpy array of their shape."""
    import drjit as dr
    import mitsuba as mi

    ops = drjit_ops()
    flat = [np.ascontiguousarray(a, dtype=np.float32).reshape(-1) for a in arrays]
    if ops is NUMPY:
        out = fn(*flat, ops)
    else:
        out = fn(*(mi.Float(a) for a in flat), ops)
        dr.eval(out)
    return np.asarray(out, dtype=np.float32).reshape(np.shape(arrays[0]))


def _octave_loop(ops: Ops, field: FractalField, x, y, footprint_m):
    """``field`` at a footprint as a loop over octaves that each lane leaves at its first
    octave a pixel cannot hold (every later one is finer): far away, few octaves cost
    anything. The octaves' maps, offsets and seeds are opaque arrays gathered per step; the
    sum is the same, term by term, as :meth:`FractalField.__call__`'s."""
    import drjit as dr
    import mitsuba as mi

    frames = field.octave_frames()
    table = {name: mi.Float(np.asarray(values, dtype=np.float32))
             for name, values in (("a", [f[0] for f in frames]), ("b", [f[1] for f in frames]),
                                  ("c", [f[2] for f in frames]), ("d", [f[3] for f in frames]),
                                  ("ox", [o[0] for o in field.offsets]), ("oy", [o[1] for o in field.offsets]),
                                  ("amplitude", [field.amplitude(o) for o in range(field.octaves)]),
                                  ("wavelength", [field.shortest_wavelength_m(o) for o in range(field.octaves)]))}
    seeds = mi.UInt32(np.array([(field.seed + o) % 2**32 for o in range(field.octaves)], dtype=np.uint32))
    dr.make_opaque(seeds, *table.values())  # device arrays, not literals: a new draw compiles no kernel
    limit = footprint_m * FADE_LO  # an octave whose wavelength is at most this adds nothing

    def cond(o, total):
        wavelength = dr.gather(mi.Float, table["wavelength"], dr.minimum(o, field.octaves - 1))
        return (o < field.octaves) & (wavelength > limit)

    def body(o, total):
        g = {name: dr.gather(mi.Float, values, o) for name, values in table.items()}
        lx = x * g["a"] + y * g["b"] + g["ox"]
        ly = x * g["c"] + y * g["d"] + g["oy"]
        term = gradient_noise(lx, ly, dr.gather(mi.UInt32, seeds, o), ops) * g["amplitude"]
        return o + 1, total + term * field.weight(0, footprint_m, ops, wavelength_m=g["wavelength"])

    _, total = dr.while_loop(state=(mi.UInt32(0), dr.zeros(mi.Float, dr.width(x))), cond=cond, body=body)
    return total


@functools.cache
def texture_class(variant: str):
    """A :class:`mitsuba.Texture` whose value is ``shade(x, y, footprint_m, ops)``, a
    callable the owner sets (and replaces per frame) on the instance's ``shade``; the
    camera's render-frame position goes in ``camera`` and a pixel's angle in
    ``pixel_rad``. ``eval`` returns what ``shade`` does (a colour or a value)."""
    import drjit as dr
    import mitsuba as mi

    class FieldTexture(mi.Texture):
        def __init__(self, props=None, *, pixel_rad: float = 1e-3, colour: bool = False):
            super().__init__(props if props is not None else mi.Properties())
            self.pixel_rad = float(pixel_rad)
            self.colour = colour
            self.camera = (0.0, 0.0, 0.0)
            self.shade = None  # (x, y, footprint_m, ops) -> value (Float, or Color3f when colour)

        def _value(self, si):
            ops = drjit_ops()
            if ops is NUMPY:  # a scalar variant: one point, numpy's wrapping uint32 arithmetic
                p = np.array([si.p.x, si.p.y, si.p.z], dtype=np.float64)
                footprint = np.float32(np.linalg.norm(p - np.asarray(self.camera)) * self.pixel_rad)
                with np.errstate(over="ignore"):
                    return self.shade(np.float32(p[0]), np.float32(p[1]), footprint, ops)
            camera = mi.Point3f(*(dr.opaque(mi.Float, float(c)) for c in self.camera))
            footprint = dr.norm(si.p - camera) * self.pixel_rad
            return self.shade(si.p.x, si.p.y, footprint, ops)

        def eval(self, si, active=True):
            v = self._value(si)
            return v if self.colour else mi.Color3f(v)

        def eval_1(self, si, active=True):
            v = self._value(si)
            return mi.luminance(v) if self.colour else v

        def eval_3(self, si, active=True):
            return self.eval(si, active)

        def mean(self):
            return 0.5

        def is_spatially_varying(self):
            return True

        def to_string(self):
            return "FieldTexture[]"

    assert mi.variant() == variant
    return FieldTexture
