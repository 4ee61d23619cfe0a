"""A frame's appearance: sky, sun, exposure, haze and per-part materials, drawn from
the frame's own RNG stream (pure numpy; the renderer only applies them).

:func:`draw_look` draws every randomized appearance parameter of a frame in a
fixed order from :func:`datagen.core.conventions.frame_rng` ``(seed, i)``, so a
frame's look is a pure function of (config, seed, frame index) and does not
depend on rendering: labels-only builds record the same draws.
"""

from __future__ import annotations

import colorsys
import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Final

import numpy as np
from numpy.typing import NDArray

from datagen.assets.models import MATERIAL_CLASSES
from datagen.core.conventions import OBJECT_NAMES

if TYPE_CHECKING:
    from datagen.config.schema import Config
    from datagen.scene.approach import FrameState

__all__ = [
    "HAZE_VISIBILITY_M",
    "SKY_SCALE_LEVELS",
    "FrameLook",
    "Material",
    "cox_munk_roughness",
    "draw_look",
    "neutral_look",
    "sun_direction_world",
]

#: Number of distinct values sun_scale and sky_scale take (see :func:`_levels`).
SKY_SCALE_LEVELS: Final = 5


#: Haze visibility (distance at which contrast falls to 1/e), metres, when haze is on.
HAZE_VISIBILITY_M: Final = (15_000.0, 60_000.0)


def cox_munk_roughness(wind_speed_mps: float) -> float:
    """The principled-BSDF roughness of a sea under a wind of ``wind_speed_mps``.

    Cox and Munk (1954) measured the mean square slope of the open sea from sun
    glitter as sigma^2 = 0.003 + 5.12e-3 W (W in m/s, clean surface, both axes
    together). A Beckmann-like microfacet lobe of width alpha has mean square slope
    alpha^2, and the principled BSDF's alpha is its roughness squared, so
    roughness = sigma^2 ** (1/4): 0.37 at 3 m/s, 0.50 at 12 m/s. The lobe stands
    for wave facets smaller than a pixel; the sun's glint then spreads over the
    area of the sea whose slopes reflect it, as it does in photographs."""
    return float((0.003 + 5.12e-3 * float(wind_speed_mps)) ** 0.25)


@dataclass(frozen=True)
class Material:
    base_color: tuple[float, float, float]
    roughness: float
    metallic: float = 0.0
    specular: float = 0.5


@dataclass(frozen=True)
class FrameLook:
    """Every appearance draw of one frame (recorded in the manifests)."""

    sun_elevation_deg: float
    sun_azimuth_deg: float
    turbidity: float
    sun_scale: float
    sky_scale: float
    exposure_ev: float
    sea_roughness: float
    sea_wind_speed_mps: float | None  # the wind the roughness follows (None: drawn uniformly)
    haze_visibility_m: float | None
    materials: dict[str, dict[str, Material]] = field(default_factory=dict)  # object -> class -> material


def _uniform(rng: np.random.Generator, bounds) -> float:
    lo, hi = bounds
    return float(rng.uniform(lo, hi))


def _levels(rng: np.random.Generator, bounds) -> float:
    """One of :data:`SKY_SCALE_LEVELS` evenly spaced values across ``bounds``, each
    equally likely. Mitsuba's ``sunsky`` keeps its sun and sky scales as scalars that
    are baked into the compiled kernel: a continuous draw would compile (and keep in
    memory) a new kernel for every frame; a few levels bound the kernels at
    ``SKY_SCALE_LEVELS**2`` for the whole dataset."""
    lo, hi = bounds
    step = int(rng.integers(SKY_SCALE_LEVELS))  # every level equally likely
    return lo + (hi - lo) * step / (SKY_SCALE_LEVELS - 1)


def _hsv(rng: np.random.Generator, saturation, value) -> tuple[float, float, float]:
    h = float(rng.uniform(0.0, 1.0))
    return tuple(float(c) for c in colorsys.hsv_to_rgb(h, _uniform(rng, saturation), _uniform(rng, value)))


def draw_look(config: Config, rng: np.random.Generator) -> FrameLook:
    """Draw a frame's sky, sun, exposure, haze and per-part materials, in a fixed order."""
    r = config.randomization
    sky, mat = r.sky, r.materials
    look = dict(
        sun_elevation_deg=_uniform(rng, sky.sun_elevation_deg),
        sun_azimuth_deg=_uniform(rng, sky.sun_azimuth_deg),
        turbidity=_uniform(rng, sky.turbidity),
        sun_scale=_levels(rng, sky.sun_scale),
        sky_scale=_levels(rng, sky.sky_scale),
        exposure_ev=_uniform(rng, r.exposure_ev),
    )
    # One draw either way, so that the sea's model changes no other draw.
    if r.sea.model == "cox_munk":
        wind = _uniform(rng, r.sea.wind_speed_mps)
        look.update(sea_roughness=cox_munk_roughness(wind), sea_wind_speed_mps=wind)
    else:
        look.update(sea_roughness=_uniform(rng, r.sea.roughness), sea_wind_speed_mps=None)
    haze = _uniform(rng, HAZE_VISIBILITY_M) if r.haze else None
    materials: dict[str, dict[str, Material]] = {}
    for obj in OBJECT_NAMES:
        materials[obj] = {
            "paint": Material(_hsv(rng, mat.paint_saturation, mat.paint_value), _uniform(rng, mat.paint_roughness)),
            "metal": Material(_hsv(rng, (0.0, 0.05), (0.6, 0.9)), _uniform(rng, mat.metal_roughness), 1.0),
            "glass": Material(_hsv(rng, (0.0, 0.3), (0.01, 0.06)), _uniform(rng, (0.02, 0.08)), 0.0, 1.0),
            "markings": Material(_hsv(rng, (0.0, 0.8), (0.05, 0.6)), _uniform(rng, mat.paint_roughness)),
            "dark": Material(_hsv(rng, (0.0, 0.1), (0.005, 0.03)), _uniform(rng, (0.4, 0.8))),
            "fabric": Material(_hsv(rng, (0.0, 0.2), (0.55, 0.9)), _uniform(rng, (0.6, 0.9))),
            "rubber": Material(_hsv(rng, (0.0, 0.1), (0.02, 0.06)), _uniform(rng, (0.5, 0.8))),
        }
    return FrameLook(**look, haze_visibility_m=haze, materials=materials)


def neutral_look(config: Config) -> FrameLook:
    """The middle of every range of ``config`` (no randomness): what a scene is loaded
    with before a frame's own look is applied."""
    r = config.randomization
    sky, mat = r.sky, r.materials

    def mid(bounds) -> float:
        return 0.5 * (bounds[0] + bounds[1])

    grey = Material((mid(mat.paint_value),) * 3, mid(mat.paint_roughness))
    classes = {cls: grey for cls in dict.fromkeys(MATERIAL_CLASSES.values())}
    classes["metal"] = Material((0.75, 0.75, 0.75), mid(mat.metal_roughness), 1.0)
    classes["glass"] = Material((0.03, 0.03, 0.03), 0.05, 0.0, 1.0)
    return FrameLook(mid(sky.sun_elevation_deg), mid(sky.sun_azimuth_deg), mid(sky.turbidity), mid(sky.sun_scale),
                     mid(sky.sky_scale), mid(r.exposure_ev), 0.15, None, None,
                     {obj: dict(classes) for obj in OBJECT_NAMES})


def sun_direction_world(state: FrameState, look: FrameLook) -> NDArray[np.float64]:
    """Unit vector towards the sun, world frame: elevation above the horizon,
    azimuth counter-clockwise from the tanker's heading at this frame."""
    x_axis = state.world_from_tanker[:3, 0]
    heading = math.atan2(x_axis[1], x_axis[0])
    az = heading + math.radians(look.sun_azimuth_deg)
    el = math.radians(look.sun_elevation_deg)
    return np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)])
