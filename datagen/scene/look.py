"""A frame's appearance: sky, sun, exposure and per-part materials, drawn from
the frame's own RNG stream (pure numpy; the renderer only applies them).

:func:`draw_look` draws every randomized appearance parameter of a frame in a
fixed order from :func:`datagen.core.conventions.frame_rng` ``(seed, i)``, so a
frame's look is a pure function of (config, seed, frame index) and does not
depend on rendering: labels-only builds record the same draws.
"""

from __future__ import annotations

import colorsys
import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Final, TypeVar

import numpy as np
from numpy.typing import NDArray

from datagen.assets.models import MATERIAL_CLASSES
from datagen.assets.sea import cox_munk_roughness
from datagen.core.conventions import OBJECT_NAMES
from datagen.core.transforms import vec3

if TYPE_CHECKING:
    from datagen.config.schema import Config
    from datagen.scene.approach import FrameState

__all__ = [
    "FrameLook",
    "Material",
    "draw_look",
    "draw_world",
    "frame_look",
    "monahan_whitecap_fraction",
    "neutral_look",
    "sun_direction_world",
]

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
    haze_visibility_m: float | None  # sea-level meteorological visibility (None: no aerial perspective)
    materials: dict[str, dict[str, Material]] = field(default_factory=dict)  # object -> class -> material
    # The world (each None where its randomizer is off; see draw_world).
    sun_backlit: bool | None = None  # the sun was put near the camera's forward azimuth
    haze_scale_height_m: float | None = None  # the aerosol's scale height
    cloud_type: str | None = None  # the deck's form (datagen.assets.clouds.CLOUD_FORMS)
    cloud_deck_coverage: float | None = None
    cloud_deck_altitude_m: float | None = None  # above sea level
    cloud_deck_thickness_m: float | None = None  # its thickest cells
    cloud_layer_coverage: float | None = None
    cloud_layer_altitude_m: float | None = None
    cloud_layer_thickness_m: float | None = None
    cloud_opacity: float | None = None
    cloud_albedo: float | None = None
    cloud_seed: int | None = None  # seeds the layers' noise fields
    sea_wind_direction_deg: float | None = None  # the wind blows towards (waves)
    sea_wave_slope_variance: float | None = None  # mean square slope the wave trains carry
    sea_whitecap_fraction: float | None = None
    sea_colour: tuple[float, float, float] | None = None  # linear RGB body colour
    sea_seed: int | None = None  # seeds the wave phases and whitecaps
    ground_type: str | None = None  # datagen.assets.ground.GROUND_TYPES
    ground_seed: int | None = None  # seeds the land's fields
    receiver_livery: str | None = None
    tanker_livery: str | None = None
    livery_weathering: float | None = None
    livery_seed: int | None = None
    aircraft_lights: bool | None = None  # the navigation lights and beacons are on this approach
    aircraft_light_scale: float | None = None  # a steady light's radiance over a white diffuser's in daylight
    sensor_iso: float | None = None
    sensor_exposure_time_s: float | None = None
    sensor_vignetting: float | None = None
    sensor_glare: float | None = None
    sensor_distortion: tuple[float, float, float, float, float] | None = None  # OpenCV k1, k2, p1, p2, k3
    sensor_jpeg_quality: int | None = None
    sensor_video_crf: int | None = None  # x264's CRF of the frame's video round trip (instead of JPEG)
    sensor_readout_s: float | None = None  # a rolling shutter's readout, seconds (None: a global shutter)
    sensor_seed: int | None = None  # seeds the sensor noise
    camera_vibration_rms_deg: float | None = None  # the approach's vibration (datagen.scene.vibration)
    camera_vibration_hz: float | None = None  # its power-weighted mean frequency
    drogue_canopy: str | None = None  # datagen.assets.drogues.CANOPIES (its colours: materials)
    drogue_tape: bool | None = None  # reflective tape at the rim
    hose_band_colour: tuple[float, float, float] | None = None  # linear RGB of the hose's marker bands
    hose_band_spacing_m: float | None = None
    hose_band_width_m: float | None = None
    other_aircraft: str | None = None  # "none", "receiver" or "tanker" (datagen.scene.traffic)
    other_aircraft_tanker_m: tuple[float, float, float] | None = None  # its place in the tanker frame
    other_aircraft_heading_deg: float | None = None  # its heading off the tanker's
    window_dirt: float | None = None  # dirt on the camera's window (datagen.render.window)
    window_droplets: int | None = None  # water droplets on a pod's window (None: a windscreen)
    window_reflection: float | None = None  # a windscreen's reflection of the cockpit (None: a pod)
    window_seed: int | None = None  # seeds the window's fields and droplets
    sensor_lens_blur_px: float | None = None  # the lens's Gaussian point spread (sigma)
    sensor_chromatic_aberration_px: float | None = None  # red-blue separation at the farthest corner
    sensor_white_balance_k: float | None = None  # the daylight the camera is balanced for (the scene's: D65)
    sensor_tint: float | None = None  # the white balance's green offset
    sensor_tone_gamma: float | None = None
    sensor_tone_shoulder: float | None = None


def _uniform(rng: np.random.Generator | _Uniforms, bounds) -> float:
    lo, hi = bounds
    return float(rng.uniform(lo, hi))


class _Uniforms:
    """``n`` uniform draws of a generator taken in one call and handed out in order:
    ``uniform(lo, hi)`` is what the generator's own ``uniform(lo, hi)`` would have
    returned next (numpy computes it as ``lo + (hi - lo) * random()``, as here)."""

    def __init__(self, rng: np.random.Generator, n: int) -> None:
        self._next = iter(rng.random(n).tolist()).__next__

    def uniform(self, lo: float, hi: float) -> float:
        return lo + (hi - lo) * self._next()


def _scales(rng: np.random.Generator, sun_bounds, sky_bounds) -> tuple[float, float]:
    """The sun's and the sky's scales, uniform across their bounds, from one 64-bit draw
    of the generator (two float32 uniforms: every later draw of the look is what it was
    when these were two of five levels, which took one)."""
    u_sun, u_sky = rng.random(2, dtype=np.float32).tolist()
    return (sun_bounds[0] + (sun_bounds[1] - sun_bounds[0]) * u_sun,
            sky_bounds[0] + (sky_bounds[1] - sky_bounds[0]) * u_sky)


def _hsv(rng: np.random.Generator | _Uniforms, saturation, value) -> tuple[float, float, float]:
    h = float(rng.uniform(0.0, 1.0))
    return vec3(colorsys.hsv_to_rgb(h, _uniform(rng, saturation), _uniform(rng, value)))


#: Uniform draws of one object's materials in :func:`draw_look`: seven parts, each a hue,
#: a saturation, a value and a roughness.
MATERIAL_DRAWS: Final = 7 * 4


def draw_look(config: Config, rng: np.random.Generator) -> FrameLook:
    """Draw a frame's sky, sun, exposure and per-part materials, in a fixed order."""
    r = config.randomization
    sky, mat = r.sky, r.materials
    look: dict[str, Any] = dict(
        sun_elevation_deg=_uniform(rng, sky.sun_elevation_deg),
        sun_azimuth_deg=_uniform(rng, sky.sun_azimuth_deg),
        turbidity=_uniform(rng, sky.turbidity),
    )
    look["sun_scale"], look["sky_scale"] = _scales(rng, sky.sun_scale, sky.sky_scale)
    look["exposure_ev"] = _uniform(rng, r.exposure_ev)
    # One draw either way, so that the sea's model changes no other draw.
    if r.sea.model == "cox_munk":
        wind = _uniform(rng, r.sea.wind_speed_mps)
        look.update(sea_roughness=cox_munk_roughness(wind), sea_wind_speed_mps=wind)
    else:
        look.update(sea_roughness=_uniform(rng, r.sea.roughness), sea_wind_speed_mps=None)
    materials: dict[str, dict[str, Material]] = {}
    draws = _Uniforms(rng, MATERIAL_DRAWS * len(OBJECT_NAMES))  # the materials' draws in one call
    for obj in OBJECT_NAMES:
        materials[obj] = {
            "paint": Material(_hsv(draws, mat.paint_saturation, mat.paint_value), _uniform(draws, mat.paint_roughness)),
            "metal": Material(_hsv(draws, (0.0, 0.05), (0.6, 0.9)), _uniform(draws, mat.metal_roughness), 1.0),
            "glass": Material(_hsv(draws, (0.0, 0.3), (0.01, 0.06)), _uniform(draws, (0.02, 0.08)), 0.0, 1.0),
            "markings": Material(_hsv(draws, (0.0, 0.8), (0.05, 0.6)), _uniform(draws, mat.paint_roughness)),
            "dark": Material(_hsv(draws, (0.0, 0.1), (0.005, 0.03)), _uniform(draws, (0.4, 0.8))),
            "fabric": Material(_hsv(draws, (0.0, 0.2), (0.55, 0.9)), _uniform(draws, (0.6, 0.9))),
            "rubber": Material(_hsv(draws, (0.0, 0.1), (0.02, 0.06)), _uniform(draws, (0.5, 0.8))),
        }
        # The drogue's finer parts without a drogue draw (draw_world): as the fabric and metal were.
        fabric = materials[obj]["fabric"]
        materials[obj].update(fabric_alt=fabric, fabric_band=fabric, tape=fabric, strut=materials[obj]["metal"])
    return FrameLook(**look, haze_visibility_m=None, materials=materials)  # the air is the approach's (draw_world)


def _log_uniform(rng: np.random.Generator, bounds) -> float:
    lo, hi = bounds
    return float(math.exp(rng.uniform(math.log(lo), math.log(hi))))


_Name = TypeVar("_Name", bound=str)


def _share(rng: np.random.Generator, shares: Mapping[_Name, float]) -> _Name:
    """One of ``shares``' names, each drawn with its share of their sum (one uniform draw)."""
    names = list(shares)
    weights = np.asarray([shares[n] for n in names], dtype=np.float64)
    return names[int(np.searchsorted(np.cumsum(weights) / weights.sum(), rng.random(), side="right").clip(
        0, len(names) - 1))]


def _seed(rng: np.random.Generator) -> int:
    return int(rng.integers(2**31))


def monahan_whitecap_fraction(wind_speed_mps: float) -> float:
    """Share of the sea covered by whitecaps at a 10 m wind of W m/s: Monahan and
    O'Muircheartaigh (1980), 3.84e-6 W^3.41 (0.1% at 5 m/s, 1.9% at 12 m/s)."""
    return float(min(3.84e-6 * max(float(wind_speed_mps), 0.0) ** 3.41, 1.0))


def frame_look(config: Config, state: FrameState, approaches: dict | None = None) -> FrameLook:
    """The whole look of the frame ``state`` poses: :func:`draw_look` from the frame's own
    stream, then :func:`draw_world` (what a build renders it with). ``approaches``: a dict
    that keeps each approach chain's weather and liveries for its other frames."""
    from datagen.core.conventions import frame_rng

    seed = config.dataset.seed
    return draw_world(config, draw_look(config, frame_rng(seed, state.frame_index)), seed, state, approaches)


def draw_world(config: Config, look: FrameLook, seed: int, state: FrameState,
               approaches: dict | None = None) -> FrameLook:
    """``look`` with the frame's world drawn onto it: a backlit sun, the air, clouds, sea
    state, liveries, the drogue, the camera's vibration and the sensor, each from its own
    stream (:func:`datagen.core.conventions.world_rng`) and only where its randomizer is on,
    so that one switch changes no other draw.

    The weather (air, clouds, sea), the aircraft's liveries, the drogue and the camera's
    vibration belong to the approach chain (streams keyed by ``state.approach_index``): the
    frames of one approach see the same clouds, sea, aircraft and drogue, as a camera flying
    it would. The sun's backlit draw and the
    sensor's are the frame's own. Cloud altitudes are relative to the tanker's, which is
    constant over an approach, so that the clouds stay where they are as the camera moves.
    ``approaches``: a dict keeping each chain's draws (:func:`frame_look`)."""
    from datagen.assets.rig import MOUNTS
    from datagen.core.conventions import world_rng
    from datagen.scene.vibration import vibration

    r = config.randomization
    world: dict = {}
    sky = r.sky
    if sky.backlit_fraction > 0.0:
        rng = world_rng(seed, state.frame_index, "sun")
        backlit = bool(rng.random() < sky.backlit_fraction)
        offset = float(rng.uniform(-sky.backlit_azimuth_deg, sky.backlit_azimuth_deg))
        world["sun_backlit"] = backlit
        if backlit:
            d = MOUNTS[config.camera.mount].direction
            world["sun_azimuth_deg"] = math.degrees(math.atan2(d[1], d[0])) % 360.0 + offset
    base = float(state.world_from_tanker[2, 3])  # the tanker flies level: one weather per approach
    key = (state.approach_index, base)
    chain = approaches.get(key) if approaches is not None else None
    if chain is None:
        chain = _approach_world(config, seed, state.approach_index, base)
        if approaches is not None:
            approaches[key] = chain
    world.update({k: v for k, v in chain.items() if k != "drogue_draw"})
    if "drogue_draw" in chain:
        drawn = chain["drogue_draw"]
        materials = {obj: dict(classes) for obj, classes in look.materials.items()}
        materials["drogue"].update({cls: Material(*m) for cls, m in drawn.materials.items()})
        materials["hose"]["rubber"] = Material(drawn.hose[0], drawn.hose[1], 0.0, 0.35)
        world["materials"] = materials
    shake = vibration(config.camera, seed, state.approach_index)
    if shake is not None:
        world.update(camera_vibration_rms_deg=shake.rms_deg, camera_vibration_hz=shake.mean_frequency_hz)
    world.update(sensor_draws(config, seed, state.frame_index))
    return dataclasses.replace(look, **world) if world else look


def sensor_draws(config: Config, seed: int, frame_index: int) -> dict:
    """The frame's camera draws (its ``sensor_*`` look fields), from the frame's own
    ``sensor`` stream; empty with the sensor off. Each value is drawn whether or not its
    switch is on (off: recorded as None), so that one switch changes no other draw, and a
    draw added later comes after every earlier one."""
    from datagen.core.conventions import world_rng

    s = config.randomization.sensor
    if not s.enabled:
        return {}
    out: dict = {}
    rng = world_rng(seed, frame_index, "sensor")
    k1, k2 = _uniform(rng, s.k1), _uniform(rng, s.k2)
    p1, p2 = _uniform(rng, s.tangential), _uniform(rng, s.tangential)
    quality = int(rng.integers(s.jpeg_quality[0], s.jpeg_quality[1] + 1))
    iso, exposure = _log_uniform(rng, s.iso), _log_uniform(rng, s.exposure_time_s)
    out.update(
        sensor_iso=iso if s.noise else None,
        sensor_exposure_time_s=exposure if s.motion_blur else None,
        sensor_vignetting=_uniform(rng, s.vignetting),
        sensor_glare=_uniform(rng, s.glare),
        sensor_distortion=(k1, k2, p1, p2, 0.0) if s.distortion else None,
        sensor_jpeg_quality=quality if s.jpeg else None,
        sensor_seed=_seed(rng),
    )
    blur, aberration = _uniform(rng, s.lens_blur_px), _uniform(rng, s.chromatic_aberration_px)
    mired = _uniform(rng, (1e6 / s.white_balance_k[1], 1e6 / s.white_balance_k[0]))
    tint, gamma, shoulder = _uniform(rng, s.tint), _uniform(rng, s.tone_gamma), _uniform(rng, s.tone_shoulder)
    out.update(sensor_lens_blur_px=blur if s.lens else None,
               sensor_chromatic_aberration_px=aberration if s.lens else None,
               sensor_white_balance_k=1e6 / mired if s.colour else None,
               sensor_tint=tint if s.colour else None,
               sensor_tone_gamma=gamma if s.colour else None,
               sensor_tone_shoulder=shoulder if s.colour else None)
    video = bool(rng.random() < s.video_share)
    crf = int(rng.integers(s.video_crf[0], s.video_crf[1] + 1))
    if video:  # a link compresses once: the video round trip instead of the JPEG one
        out.update(sensor_video_crf=crf, sensor_jpeg_quality=None)
    readout = _uniform(rng, s.readout_s)
    out.update(sensor_readout_s=readout if s.rolling_shutter else None)
    return out


def _approach_world(config: Config, seed: int, approach_index: int, base: float) -> dict:
    """An approach chain's air (visibility, the aerosol's scale height), clouds (their
    altitudes about the tanker's, ``base``), sea state, ground and liveries, each where its
    randomizer is on (:func:`draw_world`)."""
    from datagen.assets.sea import wave_slope_variance
    from datagen.core.conventions import world_rng

    r = config.randomization
    world: dict = {}
    if r.haze.enabled:
        rng = world_rng(seed, approach_index, "atmosphere")
        world.update(haze_visibility_m=_log_uniform(rng, r.haze.visibility_m),
                     haze_scale_height_m=_uniform(rng, r.haze.aerosol_scale_height_m))
    c = r.clouds
    if c.enabled:
        from datagen.assets.clouds import CLOUD_FORMS

        rng = world_rng(seed, approach_index, "clouds")
        side = 1.0 if rng.random() < 0.5 else -1.0
        form = _share(rng, c.forms)
        drawn = CLOUD_FORMS[form]
        world.update(
            cloud_type=form,
            cloud_deck_coverage=float(np.clip(_uniform(rng, drawn.coverage), *c.deck_coverage)),
            cloud_deck_altitude_m=base - _uniform(rng, c.deck_below_m),
            cloud_deck_thickness_m=_log_uniform(rng, drawn.thickness_m),
            cloud_layer_coverage=_uniform(rng, c.layer_coverage),
            cloud_layer_altitude_m=base + side * _uniform(rng, c.layer_offset_m),
            cloud_layer_thickness_m=_uniform(rng, c.layer_thickness_m),
            cloud_opacity=_uniform(rng, c.opacity),
            cloud_albedo=_uniform(rng, c.albedo),
            cloud_seed=_seed(rng),
        )
    sea = r.sea
    if sea.waves or sea.whitecaps or sea.colour:
        rng = world_rng(seed, approach_index, "sea")
        wind = _uniform(rng, sea.wind_speed_mps)  # the approach's wind: waves, whitecaps and glint agree
        direction = _uniform(rng, sea.wind_direction_deg)
        colour = colorsys.hsv_to_rgb(float(rng.uniform(0.48, 0.62)), float(rng.uniform(0.55, 0.9)),
                                     float(rng.uniform(0.025, 0.09)))
        if sea.model == "cox_munk":
            world.update(sea_wind_speed_mps=wind, sea_roughness=cox_munk_roughness(wind))
        if sea.waves:
            world.update(sea_wind_direction_deg=direction, sea_wave_slope_variance=wave_slope_variance(wind),
                         sea_wind_speed_mps=wind)
        if sea.whitecaps:
            world["sea_whitecap_fraction"] = monahan_whitecap_fraction(wind)
        if sea.colour:
            world["sea_colour"] = tuple(float(v) for v in colour)
        world["sea_seed"] = _seed(rng)
    if r.ground.enabled:
        rng = world_rng(seed, approach_index, "ground")
        world.update(ground_type=_share(rng, r.ground.shares), ground_seed=_seed(rng))
    lv = r.livery
    if lv.enabled:
        rng = world_rng(seed, approach_index, "livery")
        world.update(
            receiver_livery=str(lv.schemes[int(rng.integers(len(lv.schemes)))]),
            tanker_livery=str(lv.schemes[int(rng.integers(len(lv.schemes)))]),
            livery_weathering=_uniform(rng, lv.weathering),
            livery_seed=_seed(rng),
        )
        if lv.lights:
            world.update(aircraft_lights=bool(rng.uniform() < lv.lights_share),
                         aircraft_light_scale=_uniform(rng, lv.light_scale))
    d = r.drogue
    if d.enabled:
        from datagen.assets.drogues import draw_drogue

        rng = world_rng(seed, approach_index, "drogue")
        drogue = draw_drogue(rng, _share(rng, d.canopies), d.hose_bands)
        world.update(drogue_canopy=drogue.canopy, drogue_tape=drogue.tape, hose_band_colour=drogue.band_colour,
                     hose_band_spacing_m=drogue.band_spacing_m, hose_band_width_m=drogue.band_width_m,
                     drogue_draw=drogue)
    if r.traffic.enabled:
        from datagen.scene.traffic import draw_traffic

        world.update(draw_traffic(r.traffic, config.camera, world_rng(seed, approach_index, "traffic")))
    w = r.window
    if w.enabled:
        from datagen.assets.rig import MOUNTS

        rng = world_rng(seed, approach_index, "window")
        dirt = _uniform(rng, w.dirt)
        wet = bool(rng.random() < w.droplet_share)
        count = int(rng.integers(w.droplets[0], w.droplets[1] + 1))
        shine = _uniform(rng, w.reflection)
        pod = MOUNTS[config.camera.mount].window == "pod"
        world.update(window_dirt=dirt, window_droplets=(count if wet else 0) if pod else None,
                     window_reflection=None if pod else shine, window_seed=_seed(rng))
    return world


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
