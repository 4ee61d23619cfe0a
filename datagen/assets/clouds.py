"""Clouds: a cloud layer's opacity at a coverage (:class:`CloudLayer`), band-limited
procedural noise (:mod:`datagen.assets.noise`) evaluated where it is seen, no texels."""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import Final

import numpy as np

from datagen.assets.noise import NUMPY, FractalField, Ops, ramp, sample_grid

__all__ = [
    "CLOUD_CORE",
    "CLOUD_CORE_TOLERANCE",
    "CLOUD_EDGE",
    "CLOUD_GAIN",
    "CLOUD_OCTAVES",
    "CLOUD_WAVELENGTH_M",
    "COVER_MARGIN",
    "CloudLayer",
]

#: A cloud layer's field: its largest features CLOUD_WAVELENGTH_M across, CLOUD_OCTAVES octaves
#: (the finest 6 km / 2^13, 0.73 m: a pixel of wingcam55 at 1.4 km, of podcam15, the
#: narrowest camera, at 5.7 km), each CLOUD_GAIN of the one before (a fractal edge); its
#: opacity ramps up over CLOUD_EDGE of the field. A further octave would add detail under
#: every camera's pixel and about a third to podcam15's path-tracing time.
CLOUD_WAVELENGTH_M: Final = 6_000.0
CLOUD_OCTAVES: Final = 14
CLOUD_GAIN: Final = 0.55
CLOUD_EDGE: Final = 0.06
#: What float rounding can add to a field's value beyond the provable bound of the octaves
#: still to come (float32 sums of 14 terms, under 2.3 in all: under 2e-6).
COVER_MARGIN: Final = 1e-5
#: How far above its threshold the field reaches a layer's thickest core (which shades the
#: tops brighter and the bases darker than the thin parts).
CLOUD_CORE: Final = 0.35
#: Inside a cloud at full opacity, the octaves still to come are left out of its core once
#: they can move the field by at most this: the shading then errs by at most 1.5 / CLOUD_CORE
#: x 0.45 x this (under 4% at the worst alignment of every later octave, typically a tenth
#: of it), detail under about 50 m inside thick cloud that 4 spp and the denoiser do not
#: resolve. The edges keep every octave.
CLOUD_CORE_TOLERANCE: Final = 0.02


@dataclass(frozen=True)
class CloudLayer:
    """One cloud layer's opacity over the plane: a band-limited fractal field
    (:class:`datagen.assets.noise.FractalField`, :data:`CLOUD_OCTAVES` octaves from
    :data:`CLOUD_WAVELENGTH_M` down to about a metre) above the level that leaves
    ``coverage`` of the layer clear, ramping to ``opacity`` over :data:`CLOUD_EDGE` of
    the field: thin, ragged edges, thick cores, and the field's own variation inside."""

    field: FractalField
    threshold: float
    opacity: float

    @classmethod
    def drawn(cls, rng: np.random.Generator, coverage: float, opacity: float, span_m: float) -> CloudLayer:
        """A layer whose cloud covers ``coverage`` of a square ``span_m`` across (the
        threshold is the field's quantile there; no cloud at all for coverage 0)."""
        field = FractalField.drawn(rng, CLOUD_WAVELENGTH_M, CLOUD_OCTAVES, CLOUD_GAIN)
        if coverage <= 0.0:
            return cls(field, math.inf, 0.0)
        sample = sample_grid(field, span_m, 256, octaves=6)
        return cls(field, float(np.quantile(sample, 1.0 - min(coverage, 1.0))), float(opacity))

    def opacity_of(self, value, ops: Ops = NUMPY):
        """Opacity where the field is ``value``."""
        if not math.isfinite(self.threshold):
            return value * ops.f32(0.0)
        return ramp(value, ops.param_f32(self.threshold), CLOUD_EDGE, ops) * ops.param_f32(self.opacity)

    def core_of(self, value, ops: Ops = NUMPY):
        """How deep in a core (0 at the edge, 1 from :data:`CLOUD_CORE` above the threshold)
        the field's ``value`` is."""
        if not math.isfinite(self.threshold):
            return value * ops.f32(0.0)
        return ramp(value, ops.param_f32(self.threshold), CLOUD_CORE, ops)

    def settled(self, total, row, ops: Ops = NUMPY, *, core: bool = True):
        """Where octaves still to come (at most ``row["rest"]`` in all) can change neither
        opacity nor, with ``core``, the core beyond :data:`CLOUD_CORE_TOLERANCE`: the field
        so far ``total`` lies that far below the threshold or above full opacity
        (:data:`CLOUD_EDGE`), and with ``core`` above the thickest core (:data:`CLOUD_CORE`)
        or with at most the tolerance to come."""
        value, rest = total[0], row["rest"]
        threshold = ops.param_f32(self.threshold)
        clear, opaque = value + rest < threshold, value - rest > threshold + ops.f32(CLOUD_EDGE)
        if not core:
            return clear | opaque
        top = ops.f32(max(CLOUD_EDGE, CLOUD_CORE))
        return clear | (opaque & ((rest <= ops.f32(CLOUD_CORE_TOLERANCE)) | (value - rest > threshold + top)))

    def value(self, x, y, footprint_m=None, ops: Ops = NUMPY, *, core: bool = True):
        """The field at ``(x, y)``, its octaves summed only while they can matter to
        :meth:`opacity_of` and, with ``core``, :meth:`core_of` (a kernel stops a lane where
        they no longer can)."""
        if not math.isfinite(self.threshold):
            return self.field(x, y, footprint_m, ops)
        return self.field(x, y, footprint_m, ops, settled=functools.partial(self.settled, core=core))

    def __call__(self, x, y, footprint_m=None, ops: Ops = NUMPY):
        """Opacity at ``(x, y)`` metres, filtered to a pixel of ``footprint_m`` metres there."""
        return self.opacity_of(self.value(x, y, footprint_m, ops, core=False), ops)

    def decided(self, total, row, ops: Ops = NUMPY, *, u):
        """Where octaves still to come (at most ``row["rest"]``, plus :data:`COVER_MARGIN`
        for float rounding) cannot carry the opacity of the field so far ``total`` across
        ``u``, and wherever :meth:`settled` without core holds (the opacity is then known)."""
        value, rest = total[0], row["rest"] + ops.f32(COVER_MARGIN)
        return (self.settled(total, row, ops, core=False) | (u < self.opacity_of(value - rest, ops))
                | (u >= self.opacity_of(value + rest, ops)))

    def covers(self, x, y, footprint_m, u, ops: Ops = NUMPY):
        """Whether the opacity at ``(x, y)`` (:meth:`__call__`, clipped to [0, 1]) exceeds
        ``u``, the octaves summed only until the answer is :meth:`decided` (a kernel's lane
        stops there)."""
        if not math.isfinite(self.threshold):
            return u < x * ops.f32(0.0)
        value = self.field(x, y, footprint_m, ops, settled=functools.partial(self.decided, u=u))
        return u < ops.clip(self.opacity_of(value, ops), 0.0, 1.0)
