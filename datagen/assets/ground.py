"""The ground below: land as well as sea. A :class:`Ground` is one approach's kind of
surface (:data:`GROUND_TYPES`), procedural like the sea and the clouds (band-limited
noise evaluated where it is seen, no texels): where its land is (a coastline's field, or
everywhere), the land's albedo (a type's palette over its detail, farmland's field
patchwork, snow and bare rock by height) and its relief, as the normal a surface of that
relief has (shading, not displacement: the horizon stays the sphere's).

Every type is the same kernel with other data: a type is a table of numbers
(:class:`GroundType`), so an approach over desert after one over sea compiles nothing.
Albedos are linear RGB of the surfaces as seen from orbit (MODIS and ASTER spectral
library values, broadband): forest 0.03-0.05, cropland 0.08-0.2, dry sand 0.3-0.45,
fresh snow 0.8-0.9, bare rock 0.1-0.2.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Final

import numpy as np

from datagen.assets.noise import _HX, _HY, NUMPY, FractalField, Ops, _hash, ramp, sample_grid

__all__ = ["GROUND_TYPES", "LAND_ROUGHNESS", "NO_SHORE", "Ground", "GroundType"]

RGB = tuple[float, float, float]

#: A land surface's principled roughness (matte: no glint).
LAND_ROUGHNESS: Final = 0.9
#: The coastline's field: features LAND_WAVELENGTH_M across, LAND_OCTAVES octaves (down to
#: 230 m), the shore ramping over LAND_EDGE of the field (a few tens of metres).
LAND_WAVELENGTH_M: Final = 60_000.0
LAND_OCTAVES: Final = 8
LAND_EDGE: Final = 0.004
#: The land's colour detail and its relief: fields of DETAIL_OCTAVES and RELIEF_OCTAVES octaves.
DETAIL_OCTAVES: Final = 8
RELIEF_OCTAVES: Final = 7
#: Where there is land everywhere or nowhere, the coastline's threshold lies this far
#: beyond anything the field reaches.
NO_SHORE: Final = 1e3


@dataclass(frozen=True)
class GroundType:
    """One kind of ground as numbers: its ``land`` share (0: open sea, 1: land everywhere,
    between: a coast), a palette (``low`` and ``high`` mixed by the detail field, ``peak``
    above ``peak_level`` of the relief field: snow on mountains, rock through snow),
    ``patch`` colours mixed into fields ``patch_m`` across where ``patch_weight`` is 1
    (farmland), the detail's scale ``detail_m`` and stretch (dunes), and the relief:
    ``relief_m`` high over features ``relief_wavelength_m`` across."""

    land: float
    low: RGB = (0.0, 0.0, 0.0)
    high: RGB = (0.0, 0.0, 0.0)
    peak: RGB = (0.0, 0.0, 0.0)
    peak_level: float = NO_SHORE
    patch: RGB = (0.0, 0.0, 0.0)
    patch_weight: float = 0.0
    patch_m: float = 300.0
    detail_m: float = 4_000.0
    detail_stretch: float = 1.0
    relief_m: float = 0.0
    relief_wavelength_m: float = 10_000.0


#: The ground types an approach draws from (``randomization.ground.shares``).
GROUND_TYPES: Final = {
    "sea": GroundType(0.0),
    "coast": GroundType(0.45, low=(0.035, 0.06, 0.025), high=(0.11, 0.10, 0.07), patch=(0.09, 0.12, 0.05),
                        patch_weight=0.35, patch_m=400.0, detail_m=6_000.0, relief_m=250.0,
                        relief_wavelength_m=12_000.0),
    "farmland": GroundType(1.0, low=(0.05, 0.09, 0.03), high=(0.13, 0.10, 0.06), patch=(0.24, 0.19, 0.08),
                           patch_weight=1.0, patch_m=350.0, detail_m=5_000.0, relief_m=80.0,
                           relief_wavelength_m=8_000.0),
    "desert": GroundType(1.0, low=(0.42, 0.31, 0.19), high=(0.26, 0.18, 0.11), peak=(0.14, 0.10, 0.07),
                         peak_level=0.45, detail_m=1_500.0, detail_stretch=3.0, relief_m=150.0,
                         relief_wavelength_m=2_500.0),
    "snow": GroundType(1.0, low=(0.82, 0.84, 0.88), high=(0.70, 0.72, 0.77), peak=(0.10, 0.09, 0.08),
                       peak_level=0.35, detail_m=3_000.0, relief_m=600.0, relief_wavelength_m=9_000.0),
    "mountains": GroundType(1.0, low=(0.03, 0.05, 0.025), high=(0.13, 0.11, 0.09), peak=(0.75, 0.77, 0.81),
                            peak_level=0.3, detail_m=4_000.0, relief_m=2_000.0, relief_wavelength_m=14_000.0),
}


@dataclass(frozen=True)
class Ground:
    """One approach's ground: a :class:`GroundType` with its fields drawn (where the shore
    runs, the land's detail and relief, the farmland's patches)."""

    kind: GroundType
    land: FractalField
    threshold: float
    detail: FractalField
    relief: FractalField
    patch_seed: int
    patch_angle_rad: float

    @classmethod
    def drawn(cls, rng: np.random.Generator, kind: GroundType, span_m: float = 400_000.0) -> Ground:
        """``kind``'s fields from ``rng``: a coast's threshold leaves ``kind.land`` of a
        square ``span_m`` across (centred under the camera) land."""
        land = FractalField.drawn(rng, LAND_WAVELENGTH_M, LAND_OCTAVES, 0.5)
        detail = FractalField.drawn(rng, kind.detail_m, DETAIL_OCTAVES, 0.55, stretch=kind.detail_stretch,
                                    direction_rad=float(rng.uniform(0.0, math.pi)))
        relief = FractalField.drawn(rng, kind.relief_wavelength_m, RELIEF_OCTAVES, 0.5)
        if kind.land <= 0.0:
            threshold = NO_SHORE
        elif kind.land >= 1.0:
            threshold = -NO_SHORE
        else:
            threshold = float(np.quantile(sample_grid(land, span_m, 128, octaves=5), 1.0 - kind.land))
        return cls(kind, land, threshold, detail, relief, int(rng.integers(0, 2**32)),
                   float(rng.uniform(0.0, math.pi / 2)))

    def land_weight(self, x, y, footprint_m, ops: Ops = NUMPY):
        """How much of the point is land (0: sea, 1: land; the shore ramps between), its
        octaves summed only while they can carry the point across the shore."""
        threshold = ops.param_f32(self.threshold)

        def settled(total, row, ops):
            return ops.abs(total[0] - threshold) > row["rest"] + ops.f32(LAND_EDGE)

        value = self.land(x, y, footprint_m, ops, settled=settled)
        return ramp(value, threshold, LAND_EDGE, ops)

    def normal(self, x, y, footprint_m, ops: Ops = NUMPY):
        """The relief's unit normal (local frame: z up): the slope of its field filtered to
        the footprint (:meth:`FractalField.slope`, one pass)."""
        f = ops.f32
        _, dx, dy = self.relief.slope(x, y, footprint_m, ops)
        dx, dy = dx * ops.param_f32(self.kind.relief_m), dy * ops.param_f32(self.kind.relief_m)
        norm = ops.sqrt(dx * dx + dy * dy + f(1.0))
        return -dx / norm, -dy / norm, f(1.0) / norm

    def albedo(self, x, y, footprint_m, ops: Ops = NUMPY):
        """The land's albedo (linear RGB): the palette over the detail field, the farmland's
        patches, the peak colour above the relief's peak level."""
        f, p = ops.f32, ops.param_f32
        k = self.kind
        t = ops.clip(self.detail(x, y, footprint_m, ops) * f(1.2) + f(0.5), 0.0, 1.0)
        peak = ramp(self.relief(x, y, footprint_m, ops), p(k.peak_level), 0.08, ops)
        # Fields: cells patch_m across in a grid turned by the drawn angle, each its own mix.
        c, s = math.cos(self.patch_angle_rad), math.sin(self.patch_angle_rad)
        scale = 1.0 / k.patch_m
        u = ops.floor(x * p(c * scale) + y * p(s * scale))
        v = ops.floor(y * p(c * scale) - x * p(s * scale))
        h = _hash(ops.to_u32(u) * ops.u32(_HX), ops.to_u32(v) * ops.u32(_HY), ops.param_u32(self.patch_seed), ops)
        mix = ops.to_f32(h & ops.u32(0xFFFF)) * f(1.0 / 65535.0)
        shade = ops.to_f32(h >> ops.u32(16)) * f(0.5 / 65535.0) + f(0.75)
        # A pixel much wider than a field sees their mean.
        resolved = ramp(p(k.patch_m) / footprint_m, f(1.0), 2.0, ops) * p(k.patch_weight)
        out = []
        for lo, hi, pk, pa in zip(k.low, k.high, k.peak, k.patch, strict=True):
            base = p(lo) + (p(hi) - p(lo)) * t
            field = (p(lo) + (p(pa) - p(lo)) * mix) * shade
            mean = (p(lo) + p(pa)) * f(0.5)
            patched = base + (mean - base) * p(k.patch_weight) + (field - mean) * resolved
            out.append(patched + (p(pk) - patched) * peak)
        return tuple(out)
