"""What a drogue and its hose look like: a table of canopies as flown, and the hose's marker bands.

In-service drogues are far from one look: many canopies are black or dark grey fabric, some
olive, some white or day-glo; many carry a contrasting band at the rim or painted panels in
alternate gores, a ring of reflective tape at the rim, struts painted or bare, and a bare
metal coupling. Hoses are black or grey rubber with painted marker bands near the drogue
(they show the hose's extension).

:data:`CANOPIES` holds those schemes; :func:`draw_drogue` draws one approach's drogue and hose
from :func:`datagen.core.conventions.world_rng` ``(seed, approach, "drogue")``: the materials
of the drogue's parts (:data:`DROGUE_CLASSES`), the hose's, and its bands. Colours are linear
reflectances, given as HSV ranges of the linear values.
"""

from __future__ import annotations

import colorsys
from dataclasses import dataclass
from typing import Final, Literal

import numpy as np

from datagen.core.transforms import vec3

__all__ = [
    "CANOPIES",
    "DARK_FABRICS",
    "DROGUE_CLASSES",
    "FABRICS",
    "HOSE_BANDS_M",
    "HOSE_BAND_COLOURS",
    "HOSE_TEXELS",
    "HOSE_TEXEL_M",
    "Canopy",
    "DrogueDraw",
    "Fabric",
    "draw_drogue",
    "hose_band_texture",
]


@dataclass(frozen=True)
class Fabric:
    """A colour as HSV ranges of linear reflectance, and its roughness range."""

    hue: tuple[float, float]
    saturation: tuple[float, float]
    value: tuple[float, float]
    roughness: tuple[float, float] = (0.65, 0.95)

    def drawn(self, rng: np.random.Generator) -> tuple[tuple[float, float, float], float]:
        h = float(rng.uniform(*self.hue)) % 1.0
        rgb = colorsys.hsv_to_rgb(h, float(rng.uniform(*self.saturation)), float(rng.uniform(*self.value)))
        return vec3(rgb), float(rng.uniform(*self.roughness))


#: Fabrics and paints by name (linear reflectance).
FABRICS: Final[dict[str, Fabric]] = {
    "black": Fabric((0.0, 1.0), (0.0, 0.12), (0.015, 0.045)),
    "dark_grey": Fabric((0.0, 1.0), (0.0, 0.08), (0.06, 0.13)),
    "olive": Fabric((0.16, 0.21), (0.35, 0.6), (0.05, 0.11)),
    "grey": Fabric((0.0, 1.0), (0.0, 0.06), (0.18, 0.4)),
    "white": Fabric((0.0, 1.0), (0.0, 0.05), (0.55, 0.8)),
    "orange": Fabric((0.03, 0.075), (0.8, 0.97), (0.45, 0.75)),
    "yellow": Fabric((0.115, 0.15), (0.75, 0.95), (0.45, 0.72)),
    "red": Fabric((-0.02, 0.015), (0.8, 0.95), (0.22, 0.42)),
}

Pattern = Literal["plain", "band", "alternate", "alternate_band"]


@dataclass(frozen=True)
class Canopy:
    """A canopy scheme: its fabric, a trim (the rim band or the alternate gores, by
    ``pattern``), and how often it carries reflective tape at the rim (each scheme's share
    of drogues is the config's: :class:`datagen.config.schema.DrogueLookConfig`)."""

    fabric: str
    trim: str
    pattern: Pattern
    tape: float = 0.6


#: Canopy schemes by name.
CANOPIES: Final[dict[str, Canopy]] = {
    "black": Canopy("black", "black", "plain"),
    "black_white_band": Canopy("black", "white", "band"),
    "black_yellow_panels": Canopy("black", "yellow", "alternate"),
    "olive": Canopy("olive", "olive", "plain"),
    "dark_grey_orange_band": Canopy("dark_grey", "orange", "band"),
    "grey_white_panels": Canopy("grey", "white", "alternate"),
    "white_red_panels": Canopy("white", "red", "alternate_band"),
    "orange_white_band": Canopy("orange", "white", "band"),
    "white": Canopy("white", "white", "plain"),
}
#: The canopies whose fabric is dark (linear reflectance at most 0.13).
DARK_FABRICS: Final = ("black", "dark_grey", "olive")

#: The drogue's material classes this table draws (:data:`datagen.assets.models.MATERIAL_CLASSES`):
#: the gores (two alternating sets), the rim band, the two marked gores, the rim's tape,
#: the struts, the coupling.
DROGUE_CLASSES: Final = ("fabric", "fabric_alt", "fabric_band", "markings", "tape", "strut", "metal")
#: Marker-band colours of hoses.
HOSE_BAND_COLOURS: Final[dict[str, Fabric]] = {
    "white": Fabric((0.0, 1.0), (0.0, 0.05), (0.55, 0.8), (0.4, 0.7)),
    "yellow": FABRICS["yellow"],
    "orange": FABRICS["orange"],
    "red": FABRICS["red"],
}
#: The hose's marker-band texture: texels along the hose from the coupling, each this long (m).
HOSE_TEXEL_M: Final = 0.01
#: Texels of that texture (16 m; beyond, the hose is plain).
HOSE_TEXELS: Final = 1600
#: The bands lie within this distance of the coupling (m).
HOSE_BANDS_M: Final = 12.0


@dataclass(frozen=True)
class DrogueDraw:
    """One approach's drogue and hose: the canopy's name, ``{class: (rgb, roughness,
    metallic, specular)}`` of the drogue's classes, the hose's rubber and bands."""

    canopy: str
    materials: dict[str, tuple[tuple[float, float, float], float, float, float]]
    hose: tuple[tuple[float, float, float], float]
    band_colour: tuple[float, float, float] | None
    band_spacing_m: float | None
    band_width_m: float | None
    tape: bool


def draw_drogue(rng: np.random.Generator, name: str, bands: bool) -> DrogueDraw:
    """Drogue ``name`` of :data:`CANOPIES` and its hose: its colours, tape, struts, coupling,
    the hose and its bands (when ``bands``), drawn in that order."""
    canopy = CANOPIES[name]
    fabric, roughness = FABRICS[canopy.fabric].drawn(rng)
    trim, trim_roughness = FABRICS[canopy.trim].drawn(rng)
    fabric_specular = float(rng.uniform(0.2, 0.4))  # nylon and Kevlar weaves: a dull sheen
    plain = (fabric, roughness, 0.0, fabric_specular)
    trimmed = (trim, trim_roughness, 0.0, fabric_specular)
    band = trimmed if canopy.pattern in ("band", "alternate_band") else plain
    alternate = trimmed if canopy.pattern in ("alternate", "alternate_band") else plain
    tape = bool(rng.random() < canopy.tape)
    silver = float(rng.uniform(0.6, 0.85))
    rim = ((silver, silver, silver), float(rng.uniform(0.15, 0.35)), 0.7, 0.5) if tape else band
    bare = bool(rng.random() < 0.5)
    steel = float(rng.uniform(0.45, 0.7))
    strut = (((steel, steel, steel), float(rng.uniform(0.3, 0.55)), 1.0, 0.5) if bare
             else (fabric, float(rng.uniform(0.4, 0.7)), 0.0, 0.5))
    metal = float(rng.uniform(0.5, 0.8))
    coupling = ((metal, metal * 0.98, metal * 0.95), float(rng.uniform(0.25, 0.5)), 1.0, 0.5)
    marked = trimmed if canopy.pattern != "plain" else plain  # the two marked gores: trim where there is one
    materials = {"fabric": plain, "fabric_alt": alternate, "fabric_band": band, "markings": marked, "tape": rim,
                 "strut": strut, "metal": coupling}
    grey = bool(rng.random() < 0.3)
    hose = FABRICS["grey" if grey else "black"].drawn(rng)
    if not bands:
        return DrogueDraw(name, materials, hose, None, None, None, tape)
    colour_name = list(HOSE_BAND_COLOURS)[int(rng.integers(len(HOSE_BAND_COLOURS)))]
    colour, _ = HOSE_BAND_COLOURS[colour_name].drawn(rng)
    spacing = float(rng.uniform(1.0, 3.0))
    width = float(rng.uniform(0.1, 0.3))
    return DrogueDraw(name, materials, hose, colour, spacing, width, tape)


def hose_band_texture(rubber: tuple[float, float, float], colour: tuple[float, float, float] | None,
                      spacing_m: float | None, width_m: float | None) -> np.ndarray:
    """``(2, HOSE_TEXELS, 3)`` linear RGB along the hose from the coupling (two equal rows: a
    bitmap is at least 2 x 2; texel ``i`` covers ``[i, i + 1) * HOSE_TEXEL_M``): the rubber, with
    a band ``width_m`` long every
    ``spacing_m``, the first centred at ``spacing_m / 2``, each wholly within
    :data:`HOSE_BANDS_M` (none without a colour)."""
    out = np.empty((2, HOSE_TEXELS, 3), dtype=np.float32)
    out[:] = np.asarray(rubber, dtype=np.float32)
    if colour is None or not spacing_m or not width_m:
        return out
    centre = (np.arange(HOSE_TEXELS) + 0.5) * HOSE_TEXEL_M
    first = 0.5 * (spacing_m - width_m)  # where the first band starts
    n = np.floor((centre - first) / spacing_m)  # the band each texel may lie in
    start = first + n * spacing_m
    inside = (n >= 0) & (centre - start < width_m) & (start + width_m <= HOSE_BANDS_M)
    out[:, inside] = np.asarray(colour, dtype=np.float32)
    return out
