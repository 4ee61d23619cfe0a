"""Procedural textures, generated from a seed (nothing downloaded, pure numpy + OpenCV).

- :func:`fractal_noise`: a tileable Gaussian field with a power-law spectrum (clouds,
  camouflage blotches, grime).
- :class:`CloudLayer`: a cloud layer's opacity at a coverage: band-limited procedural
  noise (:mod:`datagen.assets.noise`), evaluated where it is seen, no texels.
- :class:`SeaWaves`: a sea's waves, wave trains of a directional Pierson-Moskowitz
  spectrum at a wind, summed where they are seen (no texels); what a pixel cannot
  hold is roughness. :class:`SeaSurface`: its whitecaps and colour.
- :func:`livery`: an aircraft livery (scheme, panel lines, markings, weathering) as
  linear RGB, mapped onto a mesh by :func:`triplanar_uv`.

The bitmap textures (:func:`fractal_noise`, liveries) tile (their spectra live on the FFT
grid); the world's fields are procedural and have no tile.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import Final

import numpy as np
from numpy.typing import NDArray

from datagen.assets.noise import NUMPY, FractalField, Ops, Slant, band_weight, ramp, sample_grid, series
from datagen.core.conventions import GRAVITY_MPS2

__all__ = [
    "CLOUD_CORE",
    "CLOUD_CORE_TOLERANCE",
    "CLOUD_EDGE",
    "CLOUD_GAIN",
    "CLOUD_OCTAVES",
    "CLOUD_WAVELENGTH_M",
    "COVER_MARGIN",
    "FOAM_ALBEDO",
    "LIVERY_TEXELS",
    "WAVE_DIRECTIONS",
    "WAVE_OCTAVES",
    "CloudLayer",
    "SeaSurface",
    "SeaWaves",
    "cox_munk_roughness",
    "cox_munk_slope_variance",
    "fractal_noise",
    "livery",
    "peak_wavelength_m",
    "pierson_moskowitz",
    "triplanar_uv",
    "wave_slope_variance",
]

#: A cloud layer's field: its largest features CLOUD_WAVELENGTH_M across, CLOUD_OCTAVES octaves
#: (the finest 6 km / 2^13, 0.73 m: a pixel of wingcam55 at 1.4 km, of podcam15, the
#: narrowest camera, at 5.7 km), each CLOUD_GAIN of the one before (a fractal edge); its
#: opacity ramps up over CLOUD_EDGE of the field. A fifteenth octave cost a third more
#: path-tracing time on podcam15 (measured: 1.86 s -> 2.30 s at 1024x540, 4 spp).
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
#: The sea's waves (:class:`SeaWaves`): WAVE_OCTAVES octaves of wavelength from twice the
#: spectrum's peak down (240 m to 0.47 m at 12 m/s, 33 m to 0.07 m at 3 m/s), each
#: WAVE_DIRECTIONS wave trains.
WAVE_OCTAVES: Final = 9
WAVE_DIRECTIONS: Final = 4
#: The most of Cox and Munk's slope variance the wave trains carry (the rest, at least the
#: waves shorter than the last octave, is always roughness).
WAVE_SHARE_MAX: Final = 0.8
#: Whitecaps: foam streaks of FOAM_OCTAVES octaves from FOAM_WAVELENGTH_M (down to about
#: 0.4 m), FOAM_STRETCH times longer along the wind than across, ramping in over FOAM_EDGE
#: of their field; foam's effective reflectance is FOAM_ALBEDO (Koepke 1984: 0.22).
FOAM_WAVELENGTH_M: Final = 24.0
FOAM_OCTAVES: Final = 6
FOAM_STRETCH: Final = 3.0
FOAM_EDGE: Final = 0.08
FOAM_ALBEDO: Final = 0.22
#: The sea's tint: a field of features TINT_WAVELENGTH_M across scaling its body colour by
#: up to about TINT_DEPTH either way.
TINT_WAVELENGTH_M: Final = 4_000.0
TINT_DEPTH: Final = 0.6
#: A livery texture's size (it spans the object's bounding box).
LIVERY_TEXELS: Final = 512

FloatArray = NDArray[np.float32]


def fractal_noise(rng: np.random.Generator, size: int, beta: float = 3.0, low_cycles: float = 2.0,
                  stretch: float = 1.0) -> FloatArray:
    """A tileable ``(size, size)`` Gaussian field with power spectrum ~ f^-beta above
    ``low_cycles`` cycles per tile, zero mean and unit standard deviation. ``stretch`` > 1
    elongates features along u (streaks)."""
    fx = np.fft.fftfreq(size) * size / stretch
    fy = np.fft.fftfreq(size) * size
    f = np.hypot(*np.meshgrid(fx, fy))
    amplitude = np.where(f >= low_cycles, np.maximum(f, 1e-9) ** (-beta / 2.0), 0.0)
    spectrum = amplitude * (rng.standard_normal((size, size)) + 1j * rng.standard_normal((size, size)))
    field = np.fft.ifft2(spectrum).real
    field -= field.mean()
    return (field / max(float(field.std()), 1e-12)).astype(np.float32)


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


@dataclass(frozen=True)
class SeaSurface:
    """The sea's albedo over the plane: its body ``colour``, tinted over kilometres by a
    band-limited field where the colour randomizer is on (plankton, depth, the sky's
    patches), and whitecaps: foam streaks a few metres long, stretched along the wind, over
    ``whitecaps`` of the sea. Where a pixel is wider than a whitecap the foam is filtered
    to its mean, the sea's ``(1 - W) colour + W foam`` (:data:`FOAM_ALBEDO`)."""

    colour: tuple[float, float, float]
    whitecaps: float
    foam: FractalField
    foam_threshold: float
    tint: FractalField | None

    @classmethod
    def drawn(cls, rng: np.random.Generator, colour, whitecaps: float, wind_direction_deg: float, *,
              tint: bool) -> SeaSurface:
        foam = FractalField.drawn(rng, FOAM_WAVELENGTH_M, FOAM_OCTAVES, 0.6, stretch=FOAM_STRETCH,
                                  direction_rad=math.radians(wind_direction_deg))
        threshold = math.inf
        if whitecaps > 0.0:
            sample = sample_grid(foam, 40.0 * FOAM_WAVELENGTH_M, 256)
            threshold = float(np.quantile(sample, 1.0 - min(whitecaps, 1.0)))
        tint_field = FractalField.drawn(rng, TINT_WAVELENGTH_M, 4, 0.5) if tint else None
        return cls(tuple(float(c) for c in colour), float(whitecaps), foam, threshold, tint_field)

    def mean_albedo(self) -> tuple[float, float, float]:
        """The albedo a pixel far wider than a whitecap sees (the tint's mean is 1)."""
        w = self.whitecaps
        return tuple(c * (1.0 - w) + FOAM_ALBEDO * w for c in self.colour)

    def albedo(self, x, y, footprint_m, ops: Ops = NUMPY):
        """The albedo ``(r, g, b)`` at ``(x, y)`` metres for a pixel of ``footprint_m`` there."""
        f, p = ops.f32, ops.param_f32
        if math.isfinite(self.foam_threshold):
            value = self.foam(x, y, footprint_m, ops)
            sharp = ramp(value, p(self.foam_threshold), FOAM_EDGE, ops)
            seen = self.foam.weight(1, footprint_m, ops)  # how much of a whitecap's shape a pixel resolves
            foam = p(self.whitecaps) + (sharp - p(self.whitecaps)) * seen
        else:
            foam = x * f(0.0)
        body = f(1.0) - foam
        if self.tint is not None:
            body = body * (f(1.0) + f(TINT_DEPTH) * self.tint(x, y, footprint_m, ops))
        return tuple(body * p(c) + foam * f(FOAM_ALBEDO) for c in self.colour)


def cox_munk_slope_variance(wind_speed_mps: float) -> float:
    """Cox and Munk's (1954) mean square slope of a clean sea under a wind of W m/s:
    0.003 + 5.12e-3 W (both axes together)."""
    return 0.003 + 5.12e-3 * float(wind_speed_mps)


def cox_munk_roughness(wind_speed_mps: float) -> float:
    """The principled-BSDF roughness of a sea under a wind of ``wind_speed_mps``.

    Cox and Munk (1954) measured the mean square slope of the open sea from sun
    glitter as sigma^2 = 0.003 + 5.12e-3 W (W in m/s, clean surface, both axes
    together). A Beckmann-like microfacet lobe of width alpha has mean square slope
    alpha^2, and the principled BSDF's alpha is its roughness squared, so
    roughness = sigma^2 ** (1/4): 0.37 at 3 m/s, 0.50 at 12 m/s. The lobe stands
    for wave facets smaller than a pixel; the sun's glint then spreads over the
    area of the sea whose slopes reflect it, as it does in photographs. With waves on,
    the waves a pixel resolves are taken out of the lobe there
    (:meth:`SeaWaves.roughness`)."""
    return float(cox_munk_slope_variance(wind_speed_mps) ** 0.25)


def pierson_moskowitz(k: NDArray, wind_mps: float) -> NDArray[np.float64]:
    """The height spectrum of a fully developed sea per unit wavenumber (m^3) at wavenumbers
    ``k`` (rad/m) under a wind of ``wind_mps``: S(omega) = alpha g^2 omega^-5
    exp(-0.74 (omega_0 / omega)^4), alpha = 8.1e-3, omega_0 = g / W, deep water
    omega^2 = g k, S(k) = S(omega) d omega / dk."""
    g = GRAVITY_MPS2
    omega = np.sqrt(g * np.asarray(k, dtype=np.float64))
    omega0 = g / max(float(wind_mps), 0.5)
    s = 8.1e-3 * g**2 * omega**-5.0 * np.exp(-0.74 * (omega0 / omega) ** 4)
    return s * g / (2.0 * omega)


def peak_wavelength_m(wind_mps: float) -> float:
    """Pierson-Moskowitz's peak wavelength: omega_p = 0.877 g / W, lambda = 2 pi g / omega_p^2."""
    omega_p = 0.877 * GRAVITY_MPS2 / max(float(wind_mps), 0.5)
    return 2.0 * math.pi * GRAVITY_MPS2 / omega_p**2


def _longest_wavenumber(wind_mps: float) -> float:
    """The wavenumber (rad/m) at which :class:`SeaWaves`' first octave starts: twice the
    spectrum's peak wavelength; octave ``o`` spans ``2^o`` to ``2^(o + 1)`` times it."""
    return 2.0 * math.pi / (2.0 * peak_wavelength_m(wind_mps))


def _sector_spread(lo: float, hi: float) -> float:
    """The share of a cos^2 spreading (2/pi cos^2 of the angle to the wind, waves running
    with it) between angles ``lo`` and ``hi`` (radians from the wind, within +-pi/2)."""
    def primitive(t: float) -> float:
        return 2.0 / math.pi * (t / 2.0 + math.sin(2.0 * t) / 4.0)

    return primitive(hi) - primitive(lo)


@functools.lru_cache(maxsize=256)
def _octave_slope_variance(wind_mps: float) -> tuple[float, ...]:
    """Per octave of :class:`SeaWaves` (longest first), the mean square slope its trains
    carry, all directions together: the integral of k^2 S(k) over the octave (log-spaced
    trapezoids), scaled down where the octaves would carry more than
    :data:`WAVE_SHARE_MAX` of Cox and Munk's total (light winds: Pierson-Moskowitz's
    k^-3 tail overstates short waves that Cox and Munk's glitter measured)."""
    top = _longest_wavenumber(wind_mps)
    out = []
    for o in range(WAVE_OCTAVES):
        k = top * 2.0 ** (o + np.linspace(0.0, 1.0, 257))
        density = k**2 * pierson_moskowitz(k, wind_mps)
        out.append(float(np.sum((density[1:] + density[:-1]) / 2.0 * np.diff(k))))
    scale = min(1.0, WAVE_SHARE_MAX * cox_munk_slope_variance(wind_mps) / sum(out))
    return tuple(v * scale for v in out)


def wave_slope_variance(wind_mps: float) -> float:
    """The mean square slope (both axes) the sea's wave trains (:class:`SeaWaves`) carry at
    ``wind_mps``: what a pixel that resolves every one of them sees as waves rather than as
    the BSDF's roughness."""
    return float(sum(_octave_slope_variance(float(wind_mps))))


@dataclass(frozen=True)
class SeaWaves:
    """The sea's waves as :data:`WAVE_OCTAVES` x :data:`WAVE_DIRECTIONS` wave trains of a
    directional Pierson-Moskowitz sea, summed where the sea is seen: no texels and no tile.

    The octaves run from twice the spectrum's peak wavelength down; each octave's trains
    cover sectors of the half-plane the wind drives (cos^2 spreading), with a wavenumber
    drawn log-uniformly in the octave, a direction in the sector and a phase. A train's
    amplitude gives it its cell's mean square slope, so the trains together carry the
    spectrum's slope variance over their octaves (:func:`wave_slope_variance`). A pixel
    holds a train while its wavelength spans a few footprints (:func:`band_weight`); the
    slope variance it cannot hold, and that of every wave shorter than the last octave
    (Cox and Munk's total minus what is resolved), is the BSDF's roughness there
    (:meth:`roughness`): one sea, whether a pixel sees its waves or their glitter."""

    kx: tuple[float, ...]
    ky: tuple[float, ...]
    phase: tuple[float, ...]
    amplitude: tuple[float, ...]
    slope_variance: tuple[float, ...]  # each train's mean square slope

    @classmethod
    def drawn(cls, rng: np.random.Generator, wind_mps: float, direction_deg: float) -> SeaWaves:
        top = _longest_wavenumber(wind_mps)
        sector = math.pi / WAVE_DIRECTIONS
        trains = []
        for o, octave_variance in enumerate(_octave_slope_variance(float(wind_mps))):
            for d in range(WAVE_DIRECTIONS):
                lo = -math.pi / 2.0 + d * sector
                variance = octave_variance * _sector_spread(lo, lo + sector)
                k = top * 2.0 ** (o + rng.random())
                angle = math.radians(direction_deg) + lo + sector * rng.random()
                phase = 2.0 * math.pi * rng.random()
                trains.append((k, angle, phase, math.sqrt(2.0 * variance) / k, variance))
        trains.sort(key=lambda t: t[0])  # longest first: a kernel stops at the first a pixel cannot hold
        return cls(tuple(t[0] * math.cos(t[1]) for t in trains), tuple(t[0] * math.sin(t[1]) for t in trains),
                   tuple(t[2] for t in trains), tuple(t[3] for t in trains), tuple(t[4] for t in trains))

    def rows(self) -> dict[str, NDArray]:
        """The trains as a :func:`datagen.assets.noise.series` table."""
        k = np.hypot(self.kx, self.ky)
        return {"kx": np.asarray(self.kx, np.float32), "ky": np.asarray(self.ky, np.float32),
                "dx": (np.asarray(self.kx) / k).astype(np.float32), "dy": (np.asarray(self.ky) / k).astype(np.float32),
                "phase": np.asarray(self.phase, np.float32), "amplitude": np.asarray(self.amplitude, np.float32),
                "slope_variance": np.asarray(self.slope_variance, np.float32),
                "wavelength": (2.0 * np.pi / k).astype(np.float32)}

    @staticmethod
    def _weight(row, footprint_m, ops: Ops):
        """How much of a train a pixel holds: by its footprint along the train's direction
        where the footprint is a :class:`~datagen.assets.noise.Slant`."""
        if isinstance(footprint_m, Slant):
            footprint_m = footprint_m.along(row["dx"], row["dy"], ops)
        return band_weight(row["wavelength"], footprint_m, ops)

    def slope(self, x, y, footprint_m, ops: Ops = NUMPY):
        """The sea surface's slope ``(dh/dx, dh/dy)`` at ``(x, y)`` metres, holding the
        trains a pixel of ``footprint_m`` (metres, or a Slant) there resolves."""
        def train(row, footprint_m, ops):
            sin = ops.sin(x * row["kx"] + y * row["ky"] + row["phase"])
            s = sin * row["amplitude"] * self._weight(row, footprint_m, ops)
            return -s * row["kx"], -s * row["ky"]  # h = a cos(k.x + phase)

        return series(self.rows(), train, 2, footprint_m, ops)

    def normal(self, x, y, footprint_m, ops: Ops = NUMPY):
        """The surface normal ``(x, y, z)`` (unit, z up) at a footprint."""
        sx, sy = self.slope(x, y, footprint_m, ops)
        norm = ops.sqrt(sx * sx + sy * sy + ops.f32(1.0))
        return -sx / norm, -sy / norm, ops.f32(1.0) / norm

    def roughness(self, footprint_m, roughness: float, ops: Ops = NUMPY):
        """The principled BSDF's roughness for a pixel of ``footprint_m`` on a sea whose
        roughness without waves is ``roughness`` (its slope variance ``roughness ** 4``,
        :func:`cox_munk_roughness`): that slope variance less what the
        pixel resolves of the trains, and at least ``1 - WAVE_SHARE_MAX`` of it, ** (1/4).
        A :class:`~datagen.assets.noise.Slant` footprint counts by its long axis: a train
        seen across the view's width but not along it stays in the roughness too (the lobe
        errs wide, never sharp: a sharp lobe under resolved waves makes fireflies)."""
        def resolved(row, footprint_m, ops):
            w = band_weight(row["wavelength"], footprint_m, ops)
            return (w * w * row["slope_variance"],)

        if isinstance(footprint_m, Slant):
            footprint_m = footprint_m.longest(ops)

        total = ops.param_f32(roughness**4)
        unresolved = total - series(self.rows(), resolved, 1, footprint_m, ops)[0]
        unresolved = ops.clip(unresolved, total * ops.f32(1.0 - WAVE_SHARE_MAX), np.inf)
        return ops.sqrt(ops.sqrt(unresolved))


# --- liveries ------------------------------------------------------------------------
def triplanar_uv(vertices: NDArray, faces: NDArray, lo: NDArray, hi: NDArray
                 ) -> tuple[NDArray[np.float32], NDArray[np.uint32], NDArray[np.float32]]:
    """Unwelded vertices, faces and texture coordinates of a mesh: each face is projected
    onto the bounding-box plane most facing it (x-y from above and below, x-z from the
    sides, y-z from the front), coordinates normalized by the box ``lo``..``hi``, so one
    texture covers the object with at most a 2x stretch on sloped faces. Faces keep flat
    normals, so the unwelded mesh renders the same shape."""
    v = np.asarray(vertices, dtype=np.float64)[np.asarray(faces).reshape(-1)].reshape(-1, 3, 3)
    n = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
    axis = np.argmax(np.abs(n), axis=1)  # 0: faces front/back, 1: sides, 2: top/bottom
    span = np.maximum(np.asarray(hi, dtype=np.float64) - np.asarray(lo, dtype=np.float64), 1e-9)
    t = (v - np.asarray(lo, dtype=np.float64)) / span  # (F, 3, 3) in [0, 1]
    planes = np.array([[1, 2], [0, 2], [0, 1]])[axis]  # the two axes of each face's plane
    uv = np.take_along_axis(t, planes[:, None, :].repeat(3, axis=1), axis=2)
    verts = v.reshape(-1, 3).astype(np.float32)
    out_faces = np.arange(len(verts), dtype=np.uint32).reshape(-1, 3)
    return verts, out_faces, uv.reshape(-1, 2).astype(np.float32)


def _mix(a: NDArray, b: NDArray, t: NDArray) -> NDArray:
    return a * (1.0 - t[..., None]) + b * t[..., None]


def _srgb_to_linear(c) -> NDArray[np.float64]:
    c = np.asarray(c, dtype=np.float64)
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def _scheme(rng: np.random.Generator, scheme: str, size: int) -> NDArray[np.float64]:
    """The base paint of a scheme, linear RGB ``(size, size, 3)``."""
    def grey(lo: float, hi: float) -> NDArray:
        value = rng.uniform(lo, hi)
        tint = rng.normal(0.0, 0.015, 3)
        return _srgb_to_linear(np.clip(value + tint + np.array([0.0, 0.005, 0.02]), 0, 1))

    if scheme == "grey_camouflage":
        colours = [grey(0.35, 0.5), grey(0.5, 0.62), grey(0.62, 0.75)]
        field = fractal_noise(rng, size, beta=3.4, low_cycles=2.0)
        img = np.broadcast_to(colours[0], (size, size, 3)).copy()
        img[field > -0.4] = colours[1]
        img[field > 0.5] = colours[2]
        return img
    if scheme == "two_tone":
        dark, light = grey(0.3, 0.45), grey(0.6, 0.8)
        field = fractal_noise(rng, size, beta=4.0, low_cycles=1.0)
        return _mix(np.broadcast_to(dark, (size, size, 3)), np.broadcast_to(light, (size, size, 3)),
                    (field > 0.0).astype(np.float64))
    if scheme == "high_visibility":
        base = _srgb_to_linear(np.clip([0.88, 0.88, 0.86] + rng.normal(0, 0.02, 3), 0, 1))
        band = _srgb_to_linear([rng.uniform(0.85, 1.0), rng.uniform(0.15, 0.4), rng.uniform(0.0, 0.1)])
        img = np.broadcast_to(base, (size, size, 3)).copy()
        u = np.arange(size) / size  # along the body's x (the first texture axis for most faces)
        for centre in rng.uniform(0.05, 0.95, int(rng.integers(2, 5))):
            width = rng.uniform(0.04, 0.12)
            img[:, np.abs(u - centre) < width / 2] = band
        return img
    if scheme == "bare_metal":
        value = rng.uniform(0.55, 0.8)
        tone = fractal_noise(rng, size, beta=2.0, low_cycles=8.0)
        return np.broadcast_to(_srgb_to_linear([value] * 3), (size, size, 3)) * (1.0 + 0.05 * tone[..., None])
    raise ValueError(f"unknown livery scheme {scheme!r}")


def _panel_lines(rng: np.random.Generator, img: NDArray, span_m: NDArray) -> None:
    """Darken panel seams every ~1-2 m (bricked rows) and rivet rows beside them."""
    import cv2

    size = img.shape[0]
    mask = np.zeros((size, size), np.uint8)
    pitch_u = rng.uniform(1.0, 2.0) / max(span_m[0], 1e-3) * size
    pitch_v = rng.uniform(0.7, 1.4) / max(span_m[1], 1e-3) * size
    rows = np.arange(0.0, size, max(pitch_v, 3.0))
    for r, y in enumerate(rows):
        cv2.line(mask, (0, int(y)), (size - 1, int(y)), 255, 1)
        offset = (r % 2) * pitch_u / 2
        for x in np.arange(offset, size, max(pitch_u, 3.0)):
            cv2.line(mask, (int(x), int(y)), (int(x), int(min(y + pitch_v, size - 1))), 255, 1)
    seams = mask.astype(np.float64) / 255.0
    img *= (1.0 - rng.uniform(0.25, 0.5) * seams)[..., None]


def _markings(rng: np.random.Generator, img: NDArray, low_vis: bool) -> None:
    """Roundels (national markings) and an aircraft number at random spots."""
    import cv2

    size = img.shape[0]
    canvas = np.ascontiguousarray(img[..., ::-1])  # OpenCV draws BGR
    if low_vis:
        rings = [_srgb_to_linear([g] * 3) for g in (rng.uniform(0.2, 0.3), rng.uniform(0.45, 0.55))]
    else:
        rings = [_srgb_to_linear(c) for c in ([0.05, 0.15, 0.45], [0.95, 0.95, 0.95], [0.75, 0.05, 0.08])]
    for _ in range(int(rng.integers(2, 5))):
        centre = (int(rng.uniform(0.1, 0.9) * size), int(rng.uniform(0.1, 0.9) * size))
        radius = int(rng.uniform(0.015, 0.04) * size)
        for j, colour in enumerate(rings):
            cv2.circle(canvas, centre, max(1, radius * (len(rings) - j) // len(rings)),
                       tuple(float(c) for c in colour[::-1]), -1, cv2.LINE_AA)
    ink = _srgb_to_linear([0.04] * 3) if not low_vis else _srgb_to_linear([0.25] * 3)
    text_mask = np.zeros((size, size), np.uint8)  # (OpenCV writes text on 8-bit images only)
    for _ in range(int(rng.integers(1, 3))):
        text = f"{int(rng.integers(10, 1000))}"
        origin = (int(rng.uniform(0.05, 0.75) * size), int(rng.uniform(0.15, 0.95) * size))
        cv2.putText(text_mask, text, origin, cv2.FONT_HERSHEY_SIMPLEX, rng.uniform(1.2, 3.0) * size / 1024,
                    255, max(1, size // 300), cv2.LINE_AA)
    img[...] = _mix(canvas[..., ::-1], np.broadcast_to(ink, img.shape), text_mask.astype(np.float64) / 255.0)


def _weathering(rng: np.random.Generator, img: NDArray, strength: float) -> None:
    """Grime (dark, low-frequency) and streaks along the airflow (u), plus fading."""
    size = img.shape[0]
    grime = np.clip(0.5 + 0.35 * fractal_noise(rng, size, beta=2.6, low_cycles=3.0), 0.0, 1.0)
    streaks = np.clip(0.5 + 0.35 * fractal_noise(rng, size, beta=2.2, low_cycles=4.0, stretch=12.0), 0.0, 1.0)
    dirt = strength * (0.45 * grime + 0.35 * streaks)
    img *= (1.0 - dirt)[..., None]
    img[...] = _mix(img, np.broadcast_to(img.mean(axis=(0, 1)), img.shape), np.full(img.shape[:2], 0.3 * strength))


def livery(rng: np.random.Generator, scheme: str, weathering: float, span_m, *, panel_lines: bool = True,
           markings: bool = True, size: int = LIVERY_TEXELS) -> FloatArray:
    """A livery texture ``(size, size, 3)``, linear RGB in [0, 1], for an object whose
    bounding box spans ``span_m`` (its first two extents set the panel pitch in texels)."""
    img = _scheme(rng, scheme, size)
    span = np.asarray(span_m, dtype=np.float64)
    if panel_lines:
        _panel_lines(rng, img, span)
    if markings:
        _markings(rng, img, low_vis=scheme in ("grey_camouflage", "two_tone"))
    if weathering > 0.0:
        _weathering(rng, img, float(weathering))
    return np.clip(img, 0.0, 1.0).astype(np.float32)
