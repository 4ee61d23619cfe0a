"""Aircraft liveries evaluated where they are seen: a scheme's paint, panels along the
structure with their seams and rivet rows, the skin's ripple, grime, streaks and exhaust
soot, and the markings' roundels and numbers, written once over :class:`~datagen.assets.noise.Ops`
(numpy on the CPU, Dr.Jit inside a Mitsuba kernel: :mod:`datagen.render.procedural`).

Like the sea and the clouds there is no texel: every pattern is band-limited by the
footprint of a pixel where it is evaluated (a seam narrower than a pixel darkens it by the
share it covers; rivet rows and panels a pixel cannot hold fade to their mean).

A painted point is known by a :class:`PaintPoint`: its *structural* coordinates ``(s, t)``
in metres (:func:`structure_uv`: each connected piece of a mesh is mapped along its own
principal axes, so a fuselage's panels run along and around it and a swept wing's along
its span), its position and outward normal in the object's body frame (for what belongs
to the aircraft as a whole: the scheme's pattern, streaks along the airflow, soot behind
the exhausts), and the pixel's footprint there.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any, Final

import numpy as np
from numpy.typing import NDArray

from datagen.assets.noise import NUMPY, FractalField, Ops, band_weight, cell_value
from datagen.core.conventions import SEALANT_PART, texture_part_rng
from datagen.core.transforms import vec3

__all__ = [
    "DIGIT_SEGMENTS",
    "MAX_BANDS",
    "MAX_DIGITS",
    "MAX_EXHAUSTS",
    "PATTERN_OCTAVES",
    "Livery",
    "Markings",
    "PaintPoint",
    "decal_uv",
    "exhaust_sites",
    "light_sites",
    "structure_uv",
]

#: High-visibility bands across the fuselage at most (the kernel's loop is unrolled).
MAX_BANDS: Final = 4
#: Octaves of every scheme's pattern field (one count: the kernel is the same for every scheme).
PATTERN_OCTAVES: Final = 4
#: Digits of an aircraft number at most (a shorter number leaves its first cells blank).
MAX_DIGITS: Final = 3
#: Exhausts whose soot a livery carries at most.
MAX_EXHAUSTS: Final = 4
#: A digit's lit segments (bit k: segment k of a, b, c, d, e, f, g in the usual seven-segment order).
DIGIT_SEGMENTS: Final = (0x3F, 0x06, 0x5B, 0x4F, 0x66, 0x6D, 0x7D, 0x07, 0x7F, 0x6F)
#: The cosine under which a pixel's footprint on a surface stops growing (grazing views).
MIN_COSINE: Final = 0.2
#: A decal's texture coordinate u carries its kind: u in [-1, 1] a roundel, u - NUMBER_U in [-1, 1] a number.
NUMBER_U: Final = 4.0


@dataclass(frozen=True)
class PaintPoint:
    """Where a livery is evaluated (arrays of one shape, float32)."""

    s: Any  # structural coordinates (metres)
    t: Any
    x: Any  # body-frame position (metres)
    y: Any
    z: Any
    nz: Any  # body-frame outward normal's z
    footprint: Any  # a pixel's width on the surface there across the view (metres)
    along_s: Any = None  # its extent along s and along t (foreshortened; None: as ``footprint``)
    along_t: Any = None

    def extent(self, axis: str):
        """The footprint's extent along ``s`` or ``t``."""
        value = self.along_s if axis == "s" else self.along_t
        return self.footprint if value is None else value

    def longest(self, ops: Ops):
        """The footprint's longest extent of the two (what a pattern in any direction must be filtered to)."""
        if self.along_s is None:
            return self.footprint
        return ops.select(self.along_s > self.along_t, self.along_s, self.along_t)


def _linear(srgb) -> tuple[float, float, float]:
    c = np.clip(np.asarray(srgb, dtype=np.float64), 0.0, 1.0)
    return vec3(np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4))


def _grey(rng: np.random.Generator, lo: float, hi: float) -> tuple[float, float, float]:
    """A military grey (sRGB ``lo``..``hi``), a little blue and tinted at random."""
    return _linear(rng.uniform(lo, hi) + rng.normal(0.0, 0.015, 3) + np.array([0.0, 0.005, 0.02]))


@dataclass(frozen=True)
class Livery:
    """One aircraft's paint for an approach (:meth:`drawn`); :meth:`albedo`, :meth:`roughness`
    and :meth:`normal` evaluate it at a :class:`PaintPoint`."""

    scheme: str
    colours: tuple[tuple[float, float, float], ...]  # three linear RGB colours (their use: the scheme's)
    pattern: FractalField  # camouflage blotches, the two-tone demarcation's wander (PATTERN_OCTAVES)
    pattern_gain: float  # the pattern's weight in the field cut into colours
    shading: float  # the surface's downward facing's weight in it (counter-shading)
    cuts: tuple[float, float]  # the field's thresholds between the colours
    bands: tuple[float, ...]  # high-visibility bands' body x (metres; far away where unused)
    band_width_m: float
    tip_m: float  # |y - centre| beyond which a high-visibility wingtip is painted (large: none)
    centre_y_m: float
    panel_m: tuple[float, float]  # panel pitch along s and t
    seam_m: float  # a seam's width
    seam_dark: float  # how much a seam darkens the paint
    sealant_m: float  # the band of sealant and grime along a seam, wider than its gap
    sealant_dark: float  # how much that band darkens the paint
    rivet_pitch_m: float
    rivet_radius_m: float
    rivet_offset_m: float  # a rivet row's distance from its seam
    tone: float  # panel-to-panel tone variation (relative)
    gloss: float  # panel-to-panel roughness variation (relative; the same panels as the tone's)
    seed: int
    grime: FractalField
    streaks: FractalField  # along the airflow (body x)
    weathering: float
    exhausts: tuple[tuple[float, float, float, float], ...]  # (x, y, z, radius), MAX_EXHAUSTS of them
    soot: float
    ripple: FractalField  # the skin's waviness (its slope tilts the normal)
    ripple_rad: float
    groove: float  # a seam's and a rivet head's slope
    panel_lines: bool = True

    @classmethod
    def drawn(cls, rng: np.random.Generator, scheme: str, weathering: float, *, length_m: float,
              span_m: float, centre_y_m: float = 0.0, nose_x_m: float = 0.0,
              exhausts: tuple[tuple[float, float, float, float], ...] = (), panel_lines: bool = True) -> Livery:
        """A livery of ``scheme`` for an aircraft ``length_m`` long (its nose at body x
        ``nose_x_m``) and ``span_m`` across (centreline at ``centre_y_m``), weathered by
        ``weathering`` (0 clean .. 1), with soot behind ``exhausts`` (x, y, z, radius)."""
        gain, shading, never = 1.0, 0.0, 9.0  # a cut at ``never`` is beyond the field's reach
        if scheme == "grey_camouflage":
            colours = (_grey(rng, 0.35, 0.5), _grey(rng, 0.5, 0.62), _grey(rng, 0.62, 0.75))
            pattern = FractalField.drawn(rng, rng.uniform(3.0, 6.0), PATTERN_OCTAVES, 0.5)
            cuts = (float(rng.uniform(-0.25, -0.05)), float(rng.uniform(0.1, 0.3)))
        elif scheme == "two_tone":  # counter-shading: dark above, light below, a wandering line between
            colours = (_grey(rng, 0.3, 0.45), _grey(rng, 0.6, 0.8), _grey(rng, 0.6, 0.8))
            pattern = FractalField.drawn(rng, rng.uniform(6.0, 12.0), PATTERN_OCTAVES, 0.5)
            gain, shading = 0.35, 1.0
            cuts = (float(rng.uniform(-0.3, 0.2)), never)
        elif scheme == "high_visibility":
            base = _linear(0.88 + rng.normal(0.0, 0.02, 3))
            band = _linear([rng.uniform(0.85, 1.0), rng.uniform(0.15, 0.4), rng.uniform(0.0, 0.1)])
            colours = (base, band, base)
            pattern = FractalField.drawn(rng, 8.0, PATTERN_OCTAVES, 0.5)
            cuts = (never, never)
        elif scheme == "bare_metal":
            value = _linear([rng.uniform(0.55, 0.8)] * 3)
            colours = (value, value, value)
            pattern = FractalField.drawn(rng, 8.0, PATTERN_OCTAVES, 0.5)
            cuts = (never, never)
        else:
            raise ValueError(f"unknown livery scheme {scheme!r}")
        bands: list[float] = []
        tip = 1e4
        if scheme == "high_visibility":
            n = int(rng.integers(1, MAX_BANDS + 1))
            bands = [float(nose_x_m - length_m * f) for f in np.sort(rng.uniform(0.2, 0.85, n))]
            tip = float(span_m / 2.0 * rng.uniform(0.75, 0.9)) if rng.uniform() < 0.7 else 1e4
        bands += [1e6] * (MAX_BANDS - len(bands))
        sites = tuple(exhausts[:MAX_EXHAUSTS]) + ((1e6, 0.0, 0.0, 0.1),) * (MAX_EXHAUSTS - len(exhausts[:MAX_EXHAUSTS]))
        w = float(weathering)
        livery = cls(
            scheme=scheme, colours=colours, pattern=pattern, pattern_gain=gain, shading=shading, cuts=cuts,
            bands=tuple(bands),
            band_width_m=float(rng.uniform(0.04, 0.1) * length_m), tip_m=tip, centre_y_m=float(centre_y_m),
            panel_m=(float(rng.uniform(0.6, 1.5)), float(rng.uniform(0.4, 1.0))),
            seam_m=float(rng.uniform(0.004, 0.01)), seam_dark=float(rng.uniform(0.35, 0.65)),
            rivet_pitch_m=float(rng.uniform(0.025, 0.045)), rivet_radius_m=float(rng.uniform(0.0025, 0.004)),
            rivet_offset_m=float(rng.uniform(0.012, 0.02)),
            tone=float(rng.uniform(0.05, 0.1) if scheme == "bare_metal" else rng.uniform(0.015, 0.04)),
            gloss=float(rng.uniform(0.05, 0.15)),
            seed=int(rng.integers(0, 2**32)),
            grime=FractalField.drawn(rng, rng.uniform(1.5, 3.5), 4, 0.55),
            streaks=FractalField.drawn(rng, rng.uniform(2.0, 4.0), 4, 0.6, stretch=8.0),
            weathering=w, exhausts=sites, soot=float(np.clip(w + rng.uniform(0.1, 0.5), 0.0, 1.0)),
            ripple=FractalField.drawn(rng, rng.uniform(0.5, 1.5), 3, 0.5),
            ripple_rad=float(rng.uniform(0.004, 0.015)), groove=float(rng.uniform(0.2, 0.5)),
            panel_lines=panel_lines, sealant_m=0.0, sealant_dark=0.0,
        )
        # The sealant's draws come from the livery's own seed, not ``rng``: every draw here and
        # after (the markings, the other aircraft's livery) stays what it was without them.
        own = texture_part_rng(livery.seed, SEALANT_PART)
        return replace(livery, sealant_m=float(own.uniform(0.02, 0.04)),
                       sealant_dark=float(own.uniform(0.12, 0.25) + 0.15 * w))

    # -- the pieces -----------------------------------------------------------------------
    def _pattern(self, p: PaintPoint, ops: Ops):
        """The scheme's colour weights ``(w1, w2)`` (the second and third colour's shares).

        One expression for every scheme, the scheme's draws its data (a kernel compiled for
        one scheme paints them all): a field ``pattern_gain * pattern - shading * nz`` cut at
        two thresholds (camouflage: three greys in blotches; two-tone: light where the surface
        faces down, the line between wandering; the others cut beyond reach), plus the
        high-visibility bands and wingtips (the others' far away)."""
        f = ops.f32
        wide = p.longest(ops)
        field = self.pattern(p.x, p.y + p.z, wide, ops) * ops.param_f32(self.pattern_gain) \
            - p.nz * ops.param_f32(self.shading)
        # An edge as sharp as a pixel allows: its width in field units grows with the footprint.
        soft = f(0.02) + wide * ops.param_f32(4.0 / self.pattern.wavelength_m)
        w1 = _soft_step(field, ops.param_f32(self.cuts[0]), soft, ops)
        w2 = _soft_step(field, ops.param_f32(self.cuts[1]), soft, ops)
        width = ops.param_f32(self.band_width_m)
        for centre in self.bands:
            w1 = w1 + _line(ops.abs(p.x - ops.param_f32(centre)), width, wide, ops)
        lateral = ops.abs(p.y - ops.param_f32(self.centre_y_m))
        w1 = w1 + _soft_step(lateral, ops.param_f32(self.tip_m), wide, ops)
        return ops.clip(w1, 0.0, 1.0), w2

    def _bricks(self, p: PaintPoint, ops: Ops):
        """``(s, row)``: ``p.s`` shifted by half a panel in every other row of panels (brick
        rows), and the row's index."""
        f = ops.f32
        ps, pt = (ops.param_f32(v) for v in self.panel_m)
        row = ops.floor(p.t / pt)
        half = ops.floor(row * f(0.5))
        return p.s + (row - half * f(2.0)) * ps * f(0.5), row

    def _panel_value(self, p: PaintPoint, ops: Ops):
        """A value in [-1, 1] per panel (a panel's own tone and gloss), faded to 0 where a
        pixel spans panels."""
        ps, pt = self.panel_m
        s, row = self._bricks(p, ops)
        value = cell_value(ops.floor(s / ops.param_f32(ps)), row, ops.param_u32(self.seed), ops)
        return value * band_weight(ops.param_f32(min(ps, pt)), p.longest(ops), ops)

    def _panels(self, p: PaintPoint, ops: Ops):
        """``(seam, rivet, s_signed, t_signed)``: a pixel's coverage by seams and by rivet heads
        (mean-filtered where it cannot hold them), and the offsets from the nearest seams."""
        f = ops.f32
        ps, pt = (ops.param_f32(v) for v in self.panel_m)
        s, _ = self._bricks(p, ops)
        ds = s - ps * ops.floor(s / ps + f(0.5))
        dt = p.t - pt * ops.floor(p.t / pt + f(0.5))
        fs, ft = p.extent("s"), p.extent("t")
        seam = self._seam_lines(ds, dt, ops.param_f32(self.seam_m), p, ops)
        pitch, radius, offset = (ops.param_f32(v) for v in (self.rivet_pitch_m, self.rivet_radius_m,
                                                             self.rivet_offset_m))
        rivet = p.x * f(0.0)
        wide = p.longest(ops)
        for across, along in ((ds, p.t), (dt, s)):  # a row beside each seam, along it
            a = ops.abs(across) - offset
            b = along - pitch * ops.floor(along / pitch + f(0.5))
            distance = ops.sqrt(a * a + b * b)
            disc = ops.clip((radius + wide * f(0.5) - distance) / wide, 0.0, 1.0)
            share = ops.clip(radius * radius * f(4.0) / (fs * ft), 0.0, 1.0)
            rivet = rivet + disc * share
        rivet = rivet * band_weight(pitch, wide, ops)
        return seam, rivet, ds, dt

    def _seam_lines(self, ds, dt, width, p: PaintPoint, ops: Ops):
        """A pixel's coverage by lines ``width`` wide centred on the seams (``ds``, ``dt``: the
        offsets from the nearest seams of :meth:`_panels`), mean-filtered where it cannot hold them."""
        ps, pt = (ops.param_f32(v) for v in self.panel_m)
        along_s = _line(ops.abs(ds), width, p.extent("s"), ops, pitch=ps)
        along_t = _line(ops.abs(dt), width, p.extent("t"), ops, pitch=pt)
        return along_s + along_t - along_s * along_t

    def _weather(self, p: PaintPoint, ops: Ops, streaks: bool = True):
        """``(dirt, soot)`` in [0, 1]: grime and (``streaks``) streaks along the airflow, soot
        behind the exhausts."""
        f = ops.f32
        wide = p.longest(ops)
        grime = ops.clip(f(0.5) + f(0.35) * self.grime(p.s, p.t, wide, ops), 0.0, 1.0)
        w = ops.param_f32(self.weathering)
        if streaks:
            streak = ops.clip(f(0.5) + f(0.4) * self.streaks(p.x, p.y + p.z, wide, ops), 0.0, 1.0)
            dirt = w * (f(0.45) * grime + f(0.35) * streak)
        else:
            streak, dirt = f(0.5), w * f(0.8) * grime
        soot = p.x * f(0.0)
        for x, y, z, r in self.exhausts:
            aft = ops.param_f32(x) - p.x  # behind the exhaust's plane (body x is forward)
            dy, dz = p.y - ops.param_f32(y), p.z - ops.param_f32(z)
            spread = ops.param_f32(r) + ops.clip(aft, 0.0, 1e3) * f(0.12)
            lateral = ops.sqrt(dy * dy + dz * dz) / spread
            near = ops.clip(f(1.0) - aft * f(1.0 / 6.0), 0.0, 1.0) * ops.clip((aft + f(0.8)) * f(2.0), 0.0, 1.0)
            soot = soot + near * ops.exp(-(lateral * lateral))
        soot = ops.clip(soot * ops.param_f32(self.soot), 0.0, 1.0) * (f(0.6) + f(0.4) * streak)
        return ops.clip(dirt, 0.0, 1.0), soot

    # -- what the renderer asks ----------------------------------------------------------
    def paint(self, p: PaintPoint, ops: Ops = NUMPY) -> tuple:
        """The scheme's colour at ``p`` (linear RGB), clean: no panels, no weather."""
        w1, w2 = self._pattern(p, ops)
        c0, c1, c2 = ([ops.param_f32(v) for v in c] for c in self.colours)
        colour = [a + (b - a) * w1 for a, b in zip(c0, c1, strict=True)]
        return tuple(a + (b - a) * w2 for a, b in zip(colour, c2, strict=True))

    def albedo(self, p: PaintPoint, ops: Ops = NUMPY) -> tuple:
        """Linear RGB base colour at ``p``: the scheme's paint, its panels' seams, rivets and
        tones, grime, streaks and soot, faded with the weathering."""
        f = ops.f32
        colour = self.paint(p, ops)
        shade = f(1.0) + p.x * f(0.0)
        if self.panel_lines:
            seam, rivet, ds, dt = self._panels(p, ops)
            sealant = self._seam_lines(ds, dt, ops.param_f32(self.sealant_m), p, ops)
            tone = self._panel_value(p, ops) * ops.param_f32(self.tone)
            shade = (shade + tone) * (f(1.0) - ops.param_f32(self.seam_dark) * seam) * (f(1.0) + f(0.08) * rivet) \
                * (f(1.0) - ops.param_f32(self.sealant_dark) * sealant)
        dirt, soot = self._weather(p, ops)
        shade = shade * (f(1.0) - f(0.55) * dirt) * (f(1.0) - f(0.85) * soot)
        fade = f(0.3) * ops.param_f32(self.weathering)  # faded paint drifts to grey
        grey = (colour[0] + colour[1] + colour[2]) * f(1.0 / 3.0)
        return tuple(ops.clip((c + (grey - c) * fade) * shade, 0.0, 1.0) for c in colour)

    def roughness(self, base: float, p: PaintPoint, ops: Ops = NUMPY):
        """The paint's roughness at ``p``: the drawn ``base``, varied from panel to panel,
        rougher where grimy or sooty and in the seams (the grime without its streaks: one field
        less in the kernel)."""
        f = ops.f32
        grime, soot = self._weather(p, ops, streaks=False)
        r = ops.param_f32(base) * (f(1.0) + f(0.6) * grime) + f(0.35) * soot
        if self.panel_lines:
            seam = self._panels(p, ops)[0]
            r = r * (f(1.0) + ops.param_f32(self.gloss) * self._panel_value(p, ops)) + f(0.2) * seam
        return ops.clip(r, 0.02, 1.0)

    def normal(self, p: PaintPoint, ops: Ops = NUMPY) -> tuple:
        """The tangent-space normal at ``p`` (along s, along t, out): the skin's ripple, the
        seams' grooves and the rivets' heads, each only where a pixel resolves it."""
        f = ops.f32
        _, ds_ripple, dt_ripple = self.ripple.slope(p.s, p.t, p.longest(ops), ops)
        k = ops.param_f32(self.ripple_rad * self.ripple.wavelength_m / (2.0 * math.pi))
        gs, gt = ds_ripple * k, dt_ripple * k
        if self.panel_lines:
            _, _, ds, dt = self._panels(p, ops)
            groove = ops.param_f32(self.groove)
            width = ops.param_f32(self.seam_m)
            for d, axis in ((ds, 0), (dt, 1)):  # a groove's walls: slope across it, where a pixel resolves it
                inside = ops.clip(f(1.0) - ops.abs(d) / (width * f(0.5)), 0.0, 1.0)
                slope = ops.select(d > f(0.0), -groove, groove) * ops.select(inside > f(0.0), f(1.0), f(0.0))
                slope = slope * band_weight(width * f(2.0), p.extent("s" if axis == 0 else "t"), ops)
                if axis == 0:
                    gs = gs + slope
                else:
                    gt = gt + slope
        norm = ops.sqrt(gs * gs + gt * gt + f(1.0))
        return -gs / norm, -gt / norm, f(1.0) / norm


@dataclass(frozen=True)
class Markings:
    """An aircraft's roundels and number for an approach: roundels of three rings, the
    number in stencil seven-segment digits on the decals that are not round."""

    rings: tuple[tuple[float, float, float], ...]  # outer, middle, inner (linear RGB)
    ink: tuple[float, float, float]
    digits: tuple[int, ...]

    @classmethod
    def drawn(cls, rng: np.random.Generator, low_visibility: bool) -> Markings:
        if low_visibility:
            light, dark = rng.uniform(0.45, 0.55), rng.uniform(0.2, 0.3)
            rings = (_linear([light] * 3), _linear([dark] * 3), _linear([light] * 3))
            ink = _linear([rng.uniform(0.15, 0.3)] * 3)
        else:
            palettes = (([0.05, 0.15, 0.45], [0.95, 0.95, 0.95], [0.75, 0.05, 0.08]),
                        ([0.75, 0.05, 0.08], [0.95, 0.95, 0.95], [0.05, 0.15, 0.45]),
                        ([0.1, 0.4, 0.75], [0.95, 0.95, 0.95], [0.05, 0.12, 0.35]),
                        ([0.05, 0.3, 0.12], [0.95, 0.85, 0.1], [0.05, 0.3, 0.12]))
            outer, middle, inner = palettes[int(rng.integers(len(palettes)))]
            rings = (_linear(outer), _linear(middle), _linear(inner))
            ink = _linear([rng.uniform(0.02, 0.08)] * 3)
        digits = tuple(int(d) for d in rng.integers(0, 10, int(rng.integers(2, MAX_DIGITS + 1))))
        return cls(rings, ink, digits)

    def colour(self, u, v, footprint, background: tuple, ops: Ops = NUMPY) -> tuple:
        """A decal's colour at its coordinates ``(u, v)`` (:func:`decal_uv`; ``footprint``
        in the same units: a pixel's width over the decal's half-size) over ``background``."""
        f = ops.f32
        number = u > f(NUMBER_U / 2.0)
        r = ops.sqrt(u * u + v * v)
        outer, middle, inner = ([ops.param_f32(c) for c in ring] for ring in self.rings)
        to_middle = _soft_step(f(2.0 / 3.0) - r, f(0.0), footprint, ops)
        to_inner = _soft_step(f(1.0 / 3.0) - r, f(0.0), footprint, ops)
        roundel = [a + (b - a) * to_middle for a, b in zip(outer, middle, strict=True)]
        roundel = [a + (b - a) * to_inner for a, b in zip(roundel, inner, strict=True)]
        ink = _number(self.digits, u - f(NUMBER_U), v, footprint, ops)
        text = [b + (ops.param_f32(c) - b) * ink for b, c in zip(background, self.ink, strict=True)]
        return tuple(ops.select(number, a, b) for a, b in zip(text, roundel, strict=True))


# -- band-limited primitives ----------------------------------------------------------------
def _soft_step(value, edge, width, ops: Ops):
    """0 below ``edge``, 1 above, linear over ``width`` around it (a pixel's box filter of a step)."""
    return ops.clip((value - edge) / width + ops.f32(0.5), 0.0, 1.0)


def _line(distance, width, footprint, ops: Ops, pitch=None):
    """The share of a pixel ``footprint`` wide that a line ``width`` wide covers, its centre
    ``distance`` away (a box filter, exact); lines repeating every ``pitch`` fade to their
    mean ``width / pitch`` where a pixel cannot hold the pitch."""
    f = ops.f32
    half_f, half_w = footprint * f(0.5), width * f(0.5)
    # The pixel's interval [d - f/2, d + f/2] less what lies beyond either edge of the line
    # (differences of nearby numbers: a wide line under a narrow pixel covers it exactly).
    right = ops.clip(distance + half_f - half_w, 0.0, 3e38)
    left = ops.clip(half_f - distance - half_w, 0.0, 3e38)
    cover = ops.clip(f(1.0) - (right + left) / footprint, 0.0, 1.0)
    if pitch is None:
        return cover
    mean = width / pitch
    return mean + (cover - mean) * band_weight(pitch, footprint, ops)


def _segment_box(u, v, cx: float, cy: float, hx: float, hy: float, footprint, ops: Ops):
    """The share of a pixel covered by the box centred ``(cx, cy)`` with half-sizes ``(hx, hy)``."""
    f = ops.f32
    bx = _soft_step(f(hx) - ops.abs(u - f(cx)), f(0.0), footprint, ops)
    by = _soft_step(f(hy) - ops.abs(v - f(cy)), f(0.0), footprint, ops)
    return bx * by


#: Seven segments of a digit cell [-1, 1] x [-1, 1] (wide, tall): centre and half-sizes, in a..g order.
_SEGMENTS: Final = ((0.0, 0.85, 0.5, 0.12), (0.62, 0.42, 0.12, 0.36), (0.62, -0.42, 0.12, 0.36),
                    (0.0, -0.85, 0.5, 0.12), (-0.62, -0.42, 0.12, 0.36), (-0.62, 0.42, 0.12, 0.36),
                    (0.0, 0.0, 0.5, 0.12))


def _number(digits: tuple[int, ...], u, v, footprint, ops: Ops):
    """Ink coverage of ``digits`` written across the decal (``u`` left to right in [-1, 1],
    ``v`` up) in :data:`MAX_DIGITS` cells, right-aligned (a shorter number leaves the first
    cells blank: the kernel is the same for every number), each digit as tall as the decal
    with a stencil's gaps between segments."""
    f = ops.f32
    ink = u * f(0.0)
    cell_w = 2.0 / MAX_DIGITS
    aspect = 0.6  # a digit's width over its height, in the decal's units (v spans 2)
    blank = MAX_DIGITS - len(digits)
    for k in range(MAX_DIGITS):
        centre = -1.0 + cell_w * (k + 0.5)
        sx = min(cell_w * 0.4, aspect * 0.8)  # the digit's half-width in decal units
        lu, lv = (u - f(centre)) * f(1.0 / sx), v * f(1.0 / 0.8)
        scale = f(1.0 / min(sx, 0.8))
        bits = ops.param_u32(DIGIT_SEGMENTS[digits[k - blank]] if k >= blank else 0)
        for j, (cx, cy, hx, hy) in enumerate(_SEGMENTS):
            lit = ops.select(((bits >> ops.u32(j)) & ops.u32(1)) == ops.u32(1), f(1.0), f(0.0))
            ink = ink + lit * _segment_box(lu, lv, cx, cy, hx, hy, footprint * scale, ops)
    return ops.clip(ink, 0.0, 1.0)


# -- geometry, on the host ------------------------------------------------------------------
def _components(faces: NDArray) -> NDArray[np.int64]:
    """Per face, the index of its connected piece (faces sharing a vertex)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    f = np.asarray(faces, dtype=np.int64)
    n_v = int(f.max()) + 1 if len(f) else 0
    rows = np.repeat(np.arange(len(f)), 3)
    graph = coo_matrix((np.ones(len(rows)), (rows, f.reshape(-1))), shape=(len(f), n_v)).tocsr()
    # faces are linked through their vertices: the face-vertex graph's components, faces' labels
    from scipy.sparse import bmat

    both = bmat([[None, graph], [graph.T, None]])
    _, labels = connected_components(both, directed=False)
    return labels[: len(f)]


def _principal_axes(points: NDArray) -> NDArray[np.float64]:
    """Rows: the principal axes of ``points``, longest first, right-handed."""
    centred = points - points.mean(axis=0)
    _, _, vt = np.linalg.svd(centred, full_matrices=False)
    axes = vt.copy()
    if np.linalg.det(axes) < 0:
        axes[2] *= -1.0
    return axes


def _unwelded(tri: NDArray, uv: NDArray) -> tuple[NDArray[np.float32], NDArray[np.uint32], NDArray[np.float32]]:
    """Vertices, faces and texture coordinates of triangles ``tri`` (F, 3, 3) with per-corner ``uv`` (F, 3, 2)."""
    verts = tri.reshape(-1, 3).astype(np.float32)
    return verts, np.arange(len(verts), dtype=np.uint32).reshape(-1, 3), uv.reshape(-1, 2).astype(np.float32)


def structure_uv(vertices: NDArray, faces: NDArray) -> tuple[NDArray[np.float32], NDArray[np.uint32],
                                                                NDArray[np.float32]]:
    """Unwelded vertices, faces and structural coordinates ``(s, t)`` in metres of a mesh.

    Each connected piece (a fuselage, a wing, a fin, a pod) is mapped in its own principal
    frame, longest axis first: a face takes the two axes of the principal plane it faces
    most, the longest always first when it is one of them. A fuselage's panels thus run
    along it and around it, a swept wing's along its span and its chord. Each face's
    coordinates are oriented so that ``(ds, dt, n)`` is right-handed (a normal map's
    tangent frame follows ``s``)."""
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    tri = v[f]  # (F, 3, 3)
    uv = np.zeros((len(f), 3, 2))
    labels = _components(f)
    for piece in np.unique(labels):
        sel = labels == piece
        axes = _principal_axes(v[np.unique(f[sel])])
        local = (tri[sel] - v[np.unique(f[sel])].mean(axis=0)) @ axes.T  # (n, 3, 3) in the piece's frame
        n = np.cross(local[:, 1] - local[:, 0], local[:, 2] - local[:, 0])
        facing = np.argmax(np.abs(n), axis=1)  # the principal axis the face looks along
        planes = np.array([[1, 2], [0, 2], [0, 1]])[facing]
        uv[sel] = np.take_along_axis(local, planes[:, None, :].repeat(3, axis=1), axis=2)
    e1, e2 = uv[:, 1] - uv[:, 0], uv[:, 2] - uv[:, 0]
    flip = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0] < 0.0
    uv[flip, :, 1] *= -1.0
    return _unwelded(tri, uv)


def decal_uv(vertices: NDArray, faces: NDArray, body_centre: NDArray) -> tuple[
        NDArray[np.float32], NDArray[np.uint32], NDArray[np.float32]]:
    """Unwelded vertices, faces and decal coordinates of a mesh of flat decals: each
    connected piece's plane, in [-1, 1] across its half-sizes; a round decal's (a
    roundel) as it is, a long one's (a number) shifted by :data:`NUMBER_U`, its u
    reading left to right seen from outside (the side away from ``body_centre``) and its v up."""
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    tri = v[f]
    uv = np.zeros((len(f), 3, 2))
    labels = _components(f)
    for piece in np.unique(labels):
        sel = labels == piece
        points = v[np.unique(f[sel])]
        centre = points.mean(axis=0)
        axes = _principal_axes(points)
        normal = axes[2]
        if normal @ (centre - np.asarray(body_centre, dtype=np.float64)) < 0:  # outward: away from the body's middle
            normal = -normal
        along = axes[0]
        if along @ np.cross([0.0, 0.0, 1.0], normal) < 0 or (abs(normal[2]) > 0.9 and along[0] < 0):
            along = -along  # reads left to right from outside (on a wing: towards the nose)
        up = np.cross(normal, along)
        local = points - centre
        half = np.maximum(np.abs(np.stack([local @ along, local @ up], axis=1)).max(axis=0), 1e-6)
        p = tri[sel] - centre
        a, b = (p @ along) / half[0], (p @ up) / half[1]
        long_ = half[0] > 1.5 * half[1]
        uv[sel] = np.stack([a + (NUMBER_U if long_ else 0.0), b], axis=-1)
    return _unwelded(tri, uv)


def exhaust_sites(vertices: NDArray, faces: NDArray) -> tuple[tuple[float, float, float, float], ...]:
    """Per connected piece of an exhaust mesh (a nozzle): its centre and radius ``(x, y, z, r)``,
    largest first, at most :data:`MAX_EXHAUSTS`."""
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    if not len(f):
        return ()
    labels = _components(f)
    sites = []
    for piece in np.unique(labels):
        points = v[np.unique(f[labels == piece])]
        lo, hi = points.min(axis=0), points.max(axis=0)
        centre = (lo + hi) / 2.0
        sites.append((float(centre[0]), float(centre[1]), float(centre[2]), float(max(hi[1:] - lo[1:]) / 2.0)))
    return tuple(sorted(sites, key=lambda s: -s[3])[:MAX_EXHAUSTS])


#: The lights an aircraft carries: name, colour (linear RGB, unit luminance order), flashing.
LIGHTS: Final = (("port", (1.0, 0.04, 0.02), False), ("starboard", (0.05, 1.0, 0.35), False),
                 ("tail", (1.0, 1.0, 1.0), False), ("beacon_top", (1.0, 0.05, 0.02), True),
                 ("beacon_bottom", (1.0, 0.05, 0.02), True))


def light_sites(vertices: NDArray, centre_y_m: float) -> dict[str, NDArray[np.float64]]:
    """Where an aircraft's :data:`LIGHTS` sit, from its painted skin's vertices: the
    wingtips (left: port, red; right: starboard, green), the tail's aftmost point near the
    centreline, and the beacons at the top and the bottom of the body near the centreline."""
    v = np.asarray(vertices, dtype=np.float64)
    near = np.abs(v[:, 1] - centre_y_m) < max(0.05 * float(np.ptp(v[:, 1])), 0.2)
    body = v[near] if near.any() else v
    sites = {"port": v[np.argmax(v[:, 1])], "starboard": v[np.argmin(v[:, 1])],
             "tail": body[np.argmin(body[:, 0])], "beacon_top": body[np.argmax(body[:, 2])]}
    lower = body[body[:, 0] > np.percentile(body[:, 0], 30)]
    sites["beacon_bottom"] = lower[np.argmin(lower[:, 2])]
    return sites
