"""The sea: its waves (:class:`SeaWaves`: wave trains of a directional Pierson-Moskowitz
spectrum at a wind, summed where they are seen, no texels; what a pixel cannot hold is
roughness, Cox and Munk's) and its surface (:class:`SeaSurface`: whitecaps and colour)."""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import Final

import numpy as np
from numpy.typing import NDArray

from datagen.assets.noise import NUMPY, FractalField, Ops, Slant, band_weight, ramp, sample_grid, series
from datagen.core.conventions import GRAVITY_MPS2
from datagen.core.transforms import vec3

__all__ = [
    "FOAM_ALBEDO",
    "FOAM_EDGE",
    "FOAM_OCTAVES",
    "FOAM_STRETCH",
    "FOAM_WAVELENGTH_M",
    "TINT_DEPTH",
    "TINT_WAVELENGTH_M",
    "WAVE_DIRECTIONS",
    "WAVE_OCTAVES",
    "WAVE_SHARE_MAX",
    "SeaSurface",
    "SeaWaves",
    "cox_munk_roughness",
    "cox_munk_slope_variance",
    "peak_wavelength_m",
    "pierson_moskowitz",
    "wave_slope_variance",
]

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
        return cls(vec3(colour), float(whitecaps), foam, threshold, tint_field)

    def mean_albedo(self) -> tuple[float, float, float]:
        """The albedo a pixel far wider than a whitecap sees (the tint's mean is 1)."""
        w = self.whitecaps
        return vec3([c * (1.0 - w) + FOAM_ALBEDO * w for c in self.colour])

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
