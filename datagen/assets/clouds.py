"""Clouds: a cloud layer's opacity at a coverage (:class:`CloudLayer`), band-limited
procedural noise (:mod:`datagen.assets.noise`) evaluated where it is seen, no texels;
the forms a pilot meets (:data:`CLOUD_FORMS`: cumulus fields, stratocumulus rolls, an
overcast, a thin layer above) and their body: a layer is a shaded height field of its
drawn thickness (:meth:`CloudLayer.radiance`: sunlit slopes and tops, self-shadowed lee
sides, bases darkening with the thickness above them)."""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import Final

import numpy as np

from datagen.assets.noise import NUMPY, FractalField, Ops, Slant, ramp, sample_grid
from datagen.core.transforms import vec3

__all__ = [
    "CLOUD_CORE",
    "CLOUD_CORE_TOLERANCE",
    "CLOUD_EDGE",
    "CLOUD_FORMS",
    "CLOUD_GAIN",
    "CLOUD_OCTAVES",
    "CLOUD_WAVELENGTH_M",
    "CloudForm",
    "CloudLayer",
    "CloudLight",
    "forward_scattered",
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
#: How far above its threshold the field reaches a layer's thickest core (which shades the
#: tops brighter and the bases darker than the thin parts).
CLOUD_CORE: Final = 0.35
#: Inside a cloud at full opacity, the octaves still to come are left out of its core once
#: they can move the field by at most this: the shading then errs by at most 1.5 / CLOUD_CORE
#: x 0.45 x this (under 4% at the worst alignment of every later octave, typically a tenth
#: of it), detail under about 50 m inside thick cloud that 4 spp and the denoiser do not
#: resolve. The edges keep every octave.
CLOUD_CORE_TOLERANCE: Final = 0.02
#: The height field that gives a layer its body is the field's first SHAPE_OCTAVES octaves
#: (down to 1/16 of the form's wavelength: 125-375 m) with its slope towards the sun at the
#: shading point, and its first SHADOW_OCTAVES at SHADOW_STEPS of the wavelength towards the
#: sun (whether the cloud rises above the sun's ray there: self-shadowing; detail finer than
#: an eighth of the wavelength hardly moves a shadow cast from that far).
SHAPE_OCTAVES: Final = 5
SHADOW_OCTAVES: Final = 4
SHADOW_STEPS: Final = (1.0 / 12.0, 1.0 / 5.0)
#: Multiple scattering inside a cloud lights its slopes beyond the terminator: the sun's
#: cosine is wrapped by WRAP (0: a Lambertian surface), and a self-shadowed point keeps
#: SHADOW_FLOOR of the sun's light.
WRAP: Final = 0.4
SHADOW_FLOOR: Final = 0.25
#: A droplet cloud's extinction (per metre) and the asymmetry of its phase function
#: (Henyey-Greenstein's g).
EXTINCTION_PER_M: Final = 0.05
ASYMMETRY: Final = 0.85
#: A base transmits the sun and sky through a thickness h as a thick scattering slab does,
#: 1 / (1 + h / BASE_DEPTH_M) (Bohren 1987's diffuse transmittance, 1 / (1 + 3/4 (1 - g)
#: tau): half the light through 180 m, a sixth through 1 km); its thin parts also send the
#: sun's light on forwards, scattered once (:func:`forward_scattered`): a silver lining
#: round a cloud seen towards the sun from below.
BASE_DEPTH_M: Final = 1.0 / (0.75 * (1.0 - ASYMMETRY) * EXTINCTION_PER_M)


def forward_scattered(tau, cos_angle, ops: Ops = NUMPY):
    """The radiance a bit of cloud of optical depth ``tau`` along both the sun's ray and the
    view (a lump as deep as it is wide: a cloud's edges are lit from the side, not through a
    slab) sends towards the camera per unit of the sun's normal irradiance, scattered once
    with albedo 1: the Henyey-Greenstein phase (:data:`ASYMMETRY`) at the scattering angle's
    cosine ``cos_angle`` times ``tau exp(-tau)``. Largest at an optical depth of 1, nothing
    through a thick core: it lights a cloud's thin edges towards the sun."""
    f = ops.f32
    g = ASYMMETRY
    spread = f(1.0 + g * g) - f(2.0 * g) * cos_angle
    phase = f((1.0 - g * g) / (4.0 * math.pi)) / (spread * ops.sqrt(spread))
    return phase * tau * ops.exp(-tau)


@dataclass(frozen=True)
class CloudForm:
    """One kind of cloud: its field's largest features ``wavelength_m`` across, elongated
    ``stretch`` times along a drawn direction (rolls), the share of a layer it covers
    (``coverage``) and how thick it is (``thickness_m``), both drawn per approach."""

    wavelength_m: float
    stretch: float
    coverage: tuple[float, float]
    thickness_m: tuple[float, float]


#: The deck's forms (:class:`CloudForm`), drawn per approach by the config's shares; the
#: scattered layer is always a ``layer`` (altocumulus: thin, small cells, above or below).
#: Coverage and thickness from the WMO cloud atlas's descriptions: cumulus fields of
#: separate heaps 0.5-2.5 km deep, stratocumulus rolls mostly covering the sky, 200-800 m
#: deep, an overcast (stratus, nimbostratus) over all of it.
CLOUD_FORMS: Final = {
    "cumulus": CloudForm(3_000.0, 1.0, (0.1, 0.45), (600.0, 2_500.0)),
    "stratocumulus": CloudForm(2_500.0, 2.2, (0.5, 0.85), (200.0, 800.0)),
    "overcast": CloudForm(CLOUD_WAVELENGTH_M, 1.0, (0.93, 1.0), (400.0, 1_500.0)),
    "layer": CloudForm(2_000.0, 1.5, (0.0, 1.0), (100.0, 600.0)),
}
#: A layer of no form drawn (the forms' fields as they were before they had forms).
FLAT: Final = CloudForm(CLOUD_WAVELENGTH_M, 1.0, (0.0, 1.0), (0.0, 0.0))


@dataclass(frozen=True)
class CloudLight:
    """What lights a layer this frame: the sun's and the sky's RGB irradiance on a
    horizontal surface (no occluders), the sun's direction (unit, render frame: z up) and
    the clouds' albedo."""

    sun: tuple[float, float, float]
    sky: tuple[float, float, float]
    sun_direction: tuple[float, float, float]
    albedo: float

    @property
    def sun_normal(self) -> tuple[float, float, float]:
        """The sun's irradiance on a surface facing it."""
        sin_el = max(self.sun_direction[2], 0.05)
        return vec3([c / sin_el for c in self.sun])


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
    thickness_m: float = 0.0
    #: How far above the threshold the height field reaches its full thickness (the field's
    #: 99.5th percentile there: a layer's thickest cells).
    crest: float = CLOUD_CORE

    @classmethod
    def drawn(cls, rng: np.random.Generator, coverage: float, opacity: float, span_m: float,
              form: CloudForm = FLAT, thickness_m: float = 0.0) -> CloudLayer:
        """A layer of ``form`` whose cloud covers ``coverage`` of a square ``span_m``
        across (the threshold is the field's quantile there; no cloud at all for coverage
        0), ``thickness_m`` deep at its thickest."""
        direction = float(rng.uniform(0.0, 2.0 * math.pi)) if form.stretch != 1.0 else 0.0
        field = FractalField.drawn(rng, form.wavelength_m, CLOUD_OCTAVES, CLOUD_GAIN, stretch=form.stretch,
                                   direction_rad=direction)
        if coverage <= 0.0:
            return cls(field, math.inf, 0.0, float(thickness_m))
        sample = sample_grid(field, span_m, 256, octaves=SHAPE_OCTAVES)
        threshold = float(np.quantile(sample, 1.0 - min(coverage, 1.0)))
        crest = max(float(np.quantile(sample, 0.995)) - threshold, CLOUD_EDGE)
        return cls(field, threshold, float(opacity), float(thickness_m), crest)

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

    def _rise(self, value, ops: Ops):
        return ops.clip((value - ops.param_f32(self.threshold)) * ops.param_f32(1.0 / self.crest), 0.0, 1.0)

    def _dome(self, rise, ops: Ops):
        return rise * (ops.f32(2.0) - rise) * ops.param_f32(self.thickness_m)

    def height(self, x, y, ops: Ops = NUMPY, octaves: int = SHAPE_OCTAVES, footprint_m=None):
        """The layer's height field at ``(x, y)``: its thickness where the field's first
        ``octaves`` octaves reach the crest, rounding down to 0 at the threshold (a heap's
        dome, ``r (2 - r)`` of the field's rise ``r``: flat on top, a finite slope at its
        foot); with ``footprint_m``, octaves finer than a pixel there fade to their mean
        (far away a heap's shading is filtered, not aliased into speckle)."""
        return self._dome(self._rise(self.field(x, y, footprint_m, ops, octaves=octaves), ops), ops)

    def height_slope(self, x, y, ux, uy, ops: Ops = NUMPY, footprint_m=None):
        """:meth:`height` at ``(x, y)`` and its slope along the unit direction ``(ux, uy)``
        (kernel values), from one pass over the field's octaves with their derivatives."""
        value, dx, dy = self.field.slope(x, y, footprint_m, ops, octaves=SHAPE_OCTAVES)
        rise = self._rise(value, ops)
        inside = (rise > ops.f32(0.0)) & (rise < ops.f32(1.0))
        per_rise = ops.select(inside, (ops.f32(2.0) - ops.f32(2.0) * rise) * ops.param_f32(
            self.thickness_m / self.crest), ops.f32(0.0))
        return self._dome(rise, ops), per_rise * (dx * ux + dy * uy)

    def radiance(self, light: CloudLight, above, x, y, footprint_m=None, ops: Ops = NUMPY):
        """What the layer's side facing the camera sends back at ``(x, y)``, RGB,
        premultiplied by its opacity: from above, its tops and slopes, the sun's light by the
        height field's slope towards it (wrapped by :data:`WRAP`) where no higher part of the
        cloud stands in the sun's ray (:data:`SHADOW_STEPS`), and the sky's, thin parts
        reflecting a little over half what thick cores do; from below (``above``, a kernel
        weight: 1 or 0), its base, the sun and sky transmitted through the thickness there
        (:data:`BASE_DEPTH_M`), and where ``footprint_m`` is a :class:`Slant` (it gives the
        view's direction) the sun's light its thin parts scatter forwards towards the camera
        (:func:`forward_scattered`). Both are traced: a layer passing from below the camera
        to above it compiles no new kernel."""
        f, p = ops.f32, ops.param_f32
        # A pixel's footprint on the layer: across the view (the opacity's, as the mask's) and,
        # seen at a slant, along it (the body's shading filtered to the longest axis).
        wide, view = footprint_m, None
        if isinstance(footprint_m, Slant):
            view = (footprint_m.sx, footprint_m.sy)  # the view's horizontal part over its vertical part
            footprint_m, wide = footprint_m.across, footprint_m.longest(ops)
        value = self.value(x, y, footprint_m, ops)
        opacity, core = self.opacity_of(value, ops), self.core_of(value, ops)
        if not math.isfinite(self.threshold):
            return tuple(opacity for _ in range(3))
        sx, sy, sz = light.sun_direction
        horizontal = math.hypot(sx, sy) or 1.0
        ux, uy = p(sx / horizontal), p(sy / horizontal)
        sin_el, cos_el = max(sz, 0.05), horizontal
        wavelength = self.field.wavelength_m
        sun_n, sun, sky = light.sun_normal, light.sun, light.sky
        albedo = light.albedo / math.pi

        def shaded():
            h, slope = self.height_slope(x, y, ux, uy, ops, wide)
            facing = (p(sin_el) - p(cos_el) * slope) / ops.sqrt(f(1.0) + slope * slope)
            lit = ops.clip((facing + f(WRAP)) * f(1.0 / (1.0 + WRAP)), 0.0, 1.0)
            for fraction in SHADOW_STEPS:
                reach = fraction * wavelength
                climb = reach * sin_el / max(cos_el, 1e-6)  # how far the sun's ray has risen there
                over = self.height(x + ux * p(reach), y + uy * p(reach), ops, SHADOW_OCTAVES, wide) - h - p(climb)
                lit = lit * (f(1.0) - f(1.0 - SHADOW_FLOOR) * ops.clip(
                    over * p(1.0 / max(0.25 * self.thickness_m, 1.0)), 0.0, 1.0))
            # Thin parts reflect a little over half what the thickest do, by the height field's
            # share of the thickness (the large shapes: the whole field's crisp valleys drew
            # grey contour lines over an overcast); a layer of no thickness by its core.
            deep = h * p(1.0 / self.thickness_m) if self.thickness_m > 0.0 else core
            reflect = f(0.55) + f(0.45) * deep
            through = f(1.0) / (f(1.0) + h * f(1.0 / BASE_DEPTH_M))
            forward = f(0.0)
            if view is not None:  # seen from below: the camera looks up along (sx, sy, 1)
                mu_view = f(1.0) / ops.sqrt(f(1.0) + view[0] * view[0] + view[1] * view[1])
                cos_angle = mu_view * (view[0] * p(sx) + view[1] * p(sy) + p(sz))
                forward = forward_scattered(h * f(EXTINCTION_PER_M), cos_angle, ops)
            out = []
            for c in range(3):
                top = (lit * p(sun_n[c] * albedo) + p(sky[c] * albedo)) * reflect
                base = through * p((sun[c] + sky[c]) * albedo) + forward * p(sun_n[c] * light.albedo)
                out.append(opacity * (above * base + (f(1.0) - above) * top))
            return tuple(out)

        # Only where there is cloud and the camera's side of the layer is seen (an emitter
        # seen from behind gets an infinite footprint: it shows nothing).
        seen = opacity > f(0.0)
        if footprint_m is not None:
            seen = seen & (footprint_m < f(1e30))
        return ops.where(seen, tuple(opacity * f(0.0) for _ in range(3)), shaded)
