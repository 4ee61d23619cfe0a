"""Procedural noise evaluated where it is seen: band-limited fractal gradient noise on the
plane, written once for two array kinds, numpy's on the CPU and Dr.Jit's inside a
Mitsuba kernel (:mod:`datagen.render.procedural`), so that what the renderer shades and
what the geometry pass classifies are the same field.

A field is a sum of octaves of gradient noise, each half the wavelength of the one
before, rotated and offset so that no lattice lines up. An octave whose wavelength is
under a few pixels at the point where it is evaluated fades to its mean (zero): far away
the field is filtered instead of aliased, close up it carries detail down to about a
pixel. There is no texel anywhere: nothing to magnify into blocks.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Final

import numpy as np
from numpy.typing import NDArray

__all__ = ["NOISE_BOUND", "NUMPY", "FractalField", "Ops", "Slant", "band_weight", "cell_value", "gradient_noise",
           "gradient_noise_slope", "ramp", "row_params", "series"]

#: |gradient_noise| never exceeds this: Perlin's noise with unit gradients peaks at sqrt(1/2)
#: in two dimensions, and a corner gradient here is at most sqrt(2) long ([-1, 1]^2).
NOISE_BOUND: Final = 1.0
#: An octave is whole while its wavelength spans at least FADE_HI pixel footprints, and gone
#: (at its mean) below FADE_LO: a wavelength of two pixels is the finest a pixel grid holds.
FADE_LO: Final = 2.0
FADE_HI: Final = 4.0
# Rotation between successive octaves (radians): an irrational share of a turn, so that no two
# octaves' lattices share an axis.
_TURN: Final = 2.3999632297286533  # the golden angle


@dataclass(frozen=True)
class Ops:
    """The few operations the noise needs that numpy and Dr.Jit spell differently.

    ``f32``/``u32`` make a constant of the build (a literal in a kernel); ``param_f32``/
    ``param_u32`` a value that changes between frames or approaches (an opaque input of a
    kernel, so that a new value compiles no new kernel; one already on the device passes
    as it is)."""

    floor: Callable[..., Any]
    to_u32: Callable[..., Any]  # float (already floored) -> uint32, wrapping negatives
    to_f32: Callable[..., Any]  # uint32 -> float
    clip: Callable[..., Any]
    f32: Callable[..., Any]
    u32: Callable[..., Any]
    param_f32: Callable[..., Any]
    param_u32: Callable[..., Any]
    sin: Callable[..., Any]
    sqrt: Callable[..., Any]
    exp: Callable[..., Any] = np.exp
    log: Callable[..., Any] = np.log
    abs: Callable[..., Any] = np.abs
    select: Callable[..., Any] = np.where  # (condition, then, else)
    #: Sums a :func:`series` at a footprint, term by term until the rest are filtered away
    #: in every lane (None: every term, in a Python loop).
    series_loop: Callable[..., Any] | None = None
    #: ``only_where(active, initial, fn)``: the tuple ``fn()`` where ``active``, ``initial``
    #: elsewhere, ``fn`` evaluated only where needed (None: everywhere, then selected).
    only_where: Callable[..., Any] | None = None

    def where(self, active, initial: tuple, fn) -> tuple:
        """``fn()`` (a tuple of arrays) where ``active``, ``initial`` elsewhere; a kernel
        skips ``fn``'s work in packets of lanes none of which is active."""
        if self.only_where is not None:
            return self.only_where(active, initial, fn)
        return tuple(self.select(active, a, b) for a, b in zip(fn(), initial, strict=True))


#: numpy's spelling (float32 and uint32 arrays; uint32 products wrap, as in a kernel).
NUMPY: Final = Ops(
    floor=np.floor,
    to_u32=lambda f: np.asarray(f, dtype=np.float32).astype(np.int32).view(np.uint32),
    to_f32=lambda u: np.asarray(u).astype(np.float32),
    clip=lambda x, lo, hi: np.clip(x, np.float32(lo), np.float32(hi)),
    f32=np.float32,
    u32=np.uint32,
    param_f32=np.float32,
    param_u32=np.uint32,
    sin=np.sin,
    sqrt=np.sqrt,
)


def _hash(hx, hy, seed, ops: Ops):
    """A 32-bit hash of a lattice corner from its coordinates already multiplied by
    :data:`_HX` and :data:`_HY` (uint32 arrays; ``seed`` a uint32 scalar or array): two
    xor-shift-multiply rounds, enough for the 16-bit halves a gradient takes."""
    u = ops.u32
    h = hx ^ hy ^ seed
    h = (h ^ (h >> u(15))) * u(0x2C1B3C6D)
    return h ^ (h >> u(13))


_HX: Final = 0x8DA6B343
_HY: Final = 0xD8163841


def _gradient(h, ops: Ops):
    """A corner's random gradient: two 16-bit halves of its hash, each in [-1, 1]."""
    scale, one = ops.f32(2.0 / 65535.0), ops.f32(1.0)
    return ops.to_f32(h & ops.u32(0xFFFF)) * scale - one, ops.to_f32(h >> ops.u32(16)) * scale - one


def cell_value(i, j, seed, ops: Ops = NUMPY):
    """A value in [-1, 1] per cell ``(i, j)`` of an integer lattice (``i``, ``j`` already
    floored float32 arrays; ``seed`` a uint32 made by ``ops``): the same hash as the noise's corners."""
    h = _hash(ops.to_u32(i) * ops.u32(_HX), ops.to_u32(j) * ops.u32(_HY), seed, ops)
    return _gradient(h, ops)[0]


def ramp(value, start, width: float, ops: Ops = NUMPY):
    """0 up to ``start``, 1 from ``start + width``, smoothstep between (``start`` a constant
    or a kernel parameter already made by ``ops``)."""
    f = ops.f32
    t = ops.clip((value - start) * f(1.0 / width), 0.0, 1.0)
    return t * t * (f(3.0) - f(2.0) * t)


@dataclass(frozen=True)
class Slant:
    """A pixel's footprint on a horizontal plane seen at a slant: an ellipse ``across``
    metres wide across the view and longer along the view's horizontal direction, by the
    factor ``sqrt(1 + s^2)`` with ``s = (sx, sy)``, the view's horizontal part over its
    vertical part (the tangent of its angle from the vertical)."""

    across: Any
    sx: Any
    sy: Any

    def along(self, dx, dy, ops: Ops = NUMPY):
        """The footprint's extent along the unit direction ``(dx, dy)``."""
        t = self.sx * dx + self.sy * dy
        return self.across * ops.sqrt(ops.f32(1.0) + t * t)

    def longest(self, ops: Ops = NUMPY):
        return self.across * ops.sqrt(ops.f32(1.0) + self.sx * self.sx + self.sy * self.sy)


def band_weight(wavelength_m, footprint_m, ops: Ops = NUMPY):
    """How much of a wave of ``wavelength_m`` a pixel of ``footprint_m`` metres holds: 1
    while it spans :data:`FADE_HI` footprints, 0 under :data:`FADE_LO`, smooth between
    (``wavelength_m`` a kernel value made by ``ops``)."""
    return ramp(wavelength_m / footprint_m, ops.f32(FADE_LO), FADE_HI - FADE_LO, ops)


def series(rows: dict[str, NDArray], term, outputs: int, footprint_m=None, ops: Ops = NUMPY,
           count: int | None = None, settled=None):
    """The sum over the rows of a table of ``term(row, footprint_m, ops)`` (each a tuple of
    ``outputs`` arrays, summed element-wise): ``rows`` maps a column name to its values per row
    (float32 or uint32), with a ``wavelength`` column in decreasing order. At a footprint,
    a term whose wavelength is at most :data:`FADE_LO` footprints is taken to add nothing,
    so a kernel stops at the first such row (``ops.series_loop``); ``count``: only the
    first that many rows. A row's values enter a kernel as parameters (a new table
    compiles nothing). A :class:`Slant` footprint stops the kernel at its narrowest axis.
    ``settled(total, row, ops)``: true where the rows from ``row`` on can no longer change
    what the caller makes of the sum (a kernel's lane stops there; the numpy loop sums on)."""
    if footprint_m is not None and ops.series_loop is not None and count is None:
        return ops.series_loop(rows, term, footprint_m, outputs, settled)
    total = None
    n = len(rows["wavelength"]) if count is None else count
    for i in range(n):
        t = term(row_params(rows, i, ops), footprint_m, ops)
        total = t if total is None else tuple(a + b for a, b in zip(total, t, strict=True))
    return total


def row_params(rows: dict[str, NDArray], i: int, ops: Ops = NUMPY) -> dict:
    """Row ``i`` of a :func:`series` table as kernel parameters made by ``ops`` (opaque
    values: a new table compiles nothing)."""
    return {name: (ops.param_u32 if values.dtype == np.uint32 else ops.param_f32)(values[i])
            for name, values in rows.items()}


def _fade(t, ops: Ops):
    f = ops.f32
    return t * t * t * (t * (t * f(6.0) - f(15.0)) + f(10.0))


def _lattice(x, y, seed, ops: Ops):
    """The lattice cell of ``(x, y)``: the offsets from its lower corner (``fx, fy``) and
    from its upper one (``fx - 1, fy - 1``), and its four corners' gradients (:func:`_gradient`)
    in the order (0, 0), (1, 0), (0, 1), (1, 1)."""
    xf, yf = ops.floor(x), ops.floor(y)
    fx, fy = x - xf, y - yf
    hx0, hy0 = ops.to_u32(xf) * ops.u32(_HX), ops.to_u32(yf) * ops.u32(_HY)
    hx1, hy1 = hx0 + ops.u32(_HX), hy0 + ops.u32(_HY)  # the next corners': (i + 1) * H wraps as i * H + H
    one = ops.f32(1.0)
    corners = tuple(_gradient(_hash(hx, hy, seed, ops), ops) for hx, hy in ((hx0, hy0), (hx1, hy0), (hx0, hy1),
                                                                             (hx1, hy1)))
    return fx, fy, fx - one, fy - one, corners


def gradient_noise(x, y, seed, ops: Ops = NUMPY):
    """Gradient noise at ``(x, y)`` (lattice units, float32 arrays), in about [-0.7, 0.7]
    and never beyond :data:`NOISE_BOUND`; zero at every lattice corner."""
    fx, fy, fx1, fy1, (g00, g10, g01, g11) = _lattice(x, y, seed, ops)
    n00, n10 = g00[0] * fx + g00[1] * fy, g10[0] * fx1 + g10[1] * fy
    n01, n11 = g01[0] * fx + g01[1] * fy1, g11[0] * fx1 + g11[1] * fy1
    u, v = _fade(fx, ops), _fade(fy, ops)
    bottom = n00 + (n10 - n00) * u
    top = n01 + (n11 - n01) * u
    return bottom + (top - bottom) * v


def _fade_slope(t, ops: Ops):
    """The derivative of :func:`_fade`."""
    s = t * (t - ops.f32(1.0))
    return ops.f32(30.0) * s * s


def gradient_noise_slope(x, y, seed, ops: Ops = NUMPY):
    """:func:`gradient_noise` at ``(x, y)`` with its partial derivatives: ``(value, d/dx,
    d/dy)``, exact (the same lattice, hashes and fade; one pass instead of three)."""
    fx, fy, fx1, fy1, (g00, g10, g01, g11) = _lattice(x, y, seed, ops)
    n00, n10 = g00[0] * fx + g00[1] * fy, g10[0] * fx1 + g10[1] * fy
    n01, n11 = g01[0] * fx + g01[1] * fy1, g11[0] * fx1 + g11[1] * fy1
    u, v = _fade(fx, ops), _fade(fy, ops)
    du, dv = _fade_slope(fx, ops), _fade_slope(fy, ops)
    bottom, top = n00 + (n10 - n00) * u, n01 + (n11 - n01) * u
    # d/dx of a corner's dot is its gradient's x; the fade's slope carries the blend.
    bottom_x = g00[0] + (g10[0] - g00[0]) * u + (n10 - n00) * du
    top_x = g01[0] + (g11[0] - g01[0]) * u + (n11 - n01) * du
    bottom_y = g00[1] + (g10[1] - g00[1]) * u
    top_y = g01[1] + (g11[1] - g01[1]) * u
    return (bottom + (top - bottom) * v, bottom_x + (top_x - bottom_x) * v,
            bottom_y + (top_y - bottom_y) * v + (top - bottom) * dv)


@dataclass(frozen=True)
class FractalField:
    """A band-limited fractal field on the plane (metres): ``octaves`` of gradient noise
    from ``wavelength_m`` down, each ``gain`` times the amplitude of the one before,
    ``stretch`` > 1 elongating features along ``direction_rad`` (streaks, wave crests).

    ``offsets`` ``(octaves, 2)`` (lattice units) and ``seed`` make one realization; they
    come from a generator through :meth:`drawn`."""

    wavelength_m: float
    octaves: int
    gain: float
    offsets: tuple[tuple[float, float], ...]
    seed: int
    stretch: float = 1.0
    direction_rad: float = 0.0

    @classmethod
    def drawn(cls, rng: np.random.Generator, wavelength_m: float, octaves: int, gain: float, *,
              stretch: float = 1.0, direction_rad: float = 0.0) -> FractalField:
        offsets = tuple((float(a), float(b)) for a, b in rng.uniform(0.0, 4096.0, size=(octaves, 2)))
        return cls(wavelength_m, octaves, gain, offsets, int(rng.integers(0, 2**32)), stretch, direction_rad)

    def amplitude(self, octave: int) -> float:
        return self.gain**octave

    def bound(self, first: int = 0) -> float:
        """The most the octaves from ``first`` on can add, in absolute value."""
        return NOISE_BOUND * sum(self.amplitude(o) for o in range(first, self.octaves))

    def octave_frames(self) -> list[tuple[float, float, float, float]]:
        """Per octave, the linear map from metres to lattice units: ``(a, b, c, d)`` with
        lattice ``(a x + b y, c x + d y)``: rotated by the golden angle per octave on top of
        the field's direction, squeezed across it by ``stretch``, scaled by the wavelength."""
        out = []
        for o in range(self.octaves):
            k = 2.0**o / self.wavelength_m
            angle = self.direction_rad + (_TURN * o if self.stretch == 1.0 else 0.0)
            c, s = math.cos(angle), math.sin(angle)
            along, across = k / self.stretch, k
            out.append((along * c, along * s, -across * s, across * c))
        return out

    def shortest_wavelength_m(self, octave: int) -> float:
        """An octave's wavelength across the stretch (its finest detail)."""
        return self.wavelength_m / 2.0**octave / self.stretch

    def weight(self, octave: int, footprint_m, ops: Ops = NUMPY):
        """How much of ``octave`` a pixel of ``footprint_m`` metres holds (:func:`band_weight`
        of its wavelength across the stretch)."""
        return band_weight(ops.f32(self.shortest_wavelength_m(octave)), footprint_m, ops)

    def rows(self) -> dict[str, NDArray]:
        """The octaves as a :func:`series` table: lattice map, offsets, seed, amplitude and
        wavelength per octave."""
        frames = np.asarray(self.octave_frames(), dtype=np.float32).reshape(-1, 4)
        offsets = np.asarray(self.offsets, dtype=np.float32).reshape(-1, 2)
        return {"a": frames[:, 0], "b": frames[:, 1], "c": frames[:, 2], "d": frames[:, 3],
                "ox": offsets[:, 0], "oy": offsets[:, 1],
                "seed": np.array([(self.seed + o) % 2**32 for o in range(self.octaves)], dtype=np.uint32),
                "amplitude": np.array([self.amplitude(o) for o in range(self.octaves)], dtype=np.float32),
                "rest": np.array([self.bound(o) for o in range(self.octaves)], dtype=np.float32),
                "wavelength": np.array([self.shortest_wavelength_m(o) for o in range(self.octaves)],
                                       dtype=np.float32)}

    def __call__(self, x, y, footprint_m=None, ops: Ops = NUMPY, octaves: int | None = None, settled=None):
        """The field at ``(x, y)`` metres (float32 arrays): every octave (``footprint_m``
        None) or each weighted by :meth:`weight` at that pixel footprint; ``octaves``: only
        the first that many."""
        def octave(row, footprint_m, ops):
            lx = x * row["a"] + y * row["b"] + row["ox"]
            ly = x * row["c"] + y * row["d"] + row["oy"]
            term = gradient_noise(lx, ly, row["seed"], ops) * row["amplitude"]
            if footprint_m is not None:
                term = term * band_weight(row["wavelength"], footprint_m, ops)
            return (term,)

        return series(self.rows(), octave, 1, footprint_m, ops, count=octaves, settled=settled)[0]

    def slope(self, x, y, footprint_m=None, ops: Ops = NUMPY, octaves: int | None = None):
        """The field at ``(x, y)`` as :meth:`__call__` makes it, with its partial derivatives
        in x and y (per metre): ``(value, d/dx, d/dy)`` in one pass over the octaves."""
        def octave(row, footprint_m, ops):
            lx = x * row["a"] + y * row["b"] + row["ox"]
            ly = x * row["c"] + y * row["d"] + row["oy"]
            value, d_lx, d_ly = gradient_noise_slope(lx, ly, row["seed"], ops)
            amplitude = row["amplitude"]
            if footprint_m is not None:
                amplitude = amplitude * band_weight(row["wavelength"], footprint_m, ops)
            # The lattice is (x, y) mapped by [[a, b], [c, d]]: the chain rule through it.
            return (value * amplitude, (d_lx * row["a"] + d_ly * row["c"]) * amplitude,
                    (d_lx * row["b"] + d_ly * row["d"]) * amplitude)

        return series(self.rows(), octave, 3, footprint_m, ops, count=octaves)


def sample_grid(field: FractalField, span_m: float, n: int, octaves: int | None = None) -> NDArray[np.float32]:
    """``field`` on an ``n`` x ``n`` grid of cell centres spanning ``span_m`` about the origin
    (rows along y)."""
    c = ((np.arange(n, dtype=np.float64) + 0.5) / n - 0.5) * span_m
    x, y = np.meshgrid(c.astype(np.float32), c.astype(np.float32))
    return field(x, y, octaves=octaves)
