"""The configuration schema: pydantic models, frozen, unknown keys refused, one docstring
per field, every number finite and bounded.

A scene config is a YAML file (the shipped ones: ``datagen scenes``); :mod:`datagen.config.load` reads it.

Angles are degrees in configs and radians in code; lengths are metres; pixel
quantities are continuous pixels (:mod:`datagen.core.conventions`).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Annotated, Any, Final, Literal

from pydantic import (
    AfterValidator,
    BaseModel,
    BeforeValidator,
    ConfigDict,
    Field,
    Strict,
    create_model,
    field_validator,
    model_validator,
)

from datagen.core.camera import (
    MAX_IMAGE_PX,
    MAX_READOUT_S,
    MIN_FOCAL_PX,
    MIN_PIXEL_ANGLE_RAD,
    Intrinsics,
    distortion_margin_px,
    hfov_bounds_deg,
)
from datagen.core.conventions import CAMERA_MOUNTS, RIGID_OBJECTS
from datagen.core.features import FEATURE_VARIANTS
from datagen.core.keypoints import TruncatedObjects
from datagen.core.label_boxes import SmallBoxes
from datagen.core.labelling_context import RULE_BOUNDS, LabelFormat, LabelRules

__all__ = [
    "WORLD_RANDOMIZERS",
    "ApproachConfig",
    "CameraConfig",
    "CloudsConfig",
    "Config",
    "DatasetConfig",
    "DrogueConfig",
    "FeaturesConfig",
    "LabelsConfig",
    "LiveryConfig",
    "MaterialsConfig",
    "MountJitterConfig",
    "ObjectSpec",
    "ObjectsConfig",
    "RandomizationConfig",
    "RenderConfig",
    "SensorConfig",
    "SkyConfig",
    "TankerConfig",
    "world_off",
]

Mount = Literal[CAMERA_MOUNTS]  # type: ignore[valid-type]
LabeledObject = Literal[RIGID_OBJECTS]  # type: ignore[valid-type]
Variant = Literal[FEATURE_VARIANTS]  # type: ignore[valid-type]


def _real(value: Any) -> Any:
    """Numbers only: YAML ``true`` or ``"55"`` is not a number (pydantic would take both)."""
    if isinstance(value, str):
        try:
            float(value)
        except ValueError:
            pass
        else:  # YAML 1.1 reads 1e12 (no dot) and quoted numbers as text
            raise ValueError(f"must be a number, got the text {value!r} (write exponents with a dot and a sign, as "
                             "1.0e+12, and numbers without quotes)")
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ValueError(f"must be a number, got {type(value).__name__}")
    return value


#: A finite number (an integer is a number too; booleans and strings are not).
Number = Annotated[float, BeforeValidator(_real)]
def _whole(value: Any) -> Any:
    """A whole number written as text (YAML 1.1 reads ``1e4`` without a dot, and a quoted
    number, as text) is refused saying so; anything else is left to the strict check."""
    if isinstance(value, str):
        try:
            number = float(value)
        except ValueError:
            pass
        else:
            whole = f"{number:.0f}" if number.is_integer() and abs(number) < 1e18 else "the digits"
            raise ValueError(f"must be a whole number, got the text {value!r} (YAML reads exponents without a dot, "
                             f"and quoted numbers, as text: write {whole})")
    return value


#: An integer (not a boolean, not a float, not a string).
Integer = Annotated[int, BeforeValidator(_whole), Strict()]
#: true or false (not 0, 1 or a string).
Flag = Annotated[bool, Strict()]


def _ordered(bounds: tuple[float, float]) -> tuple[float, float]:
    lo, hi = bounds
    if lo > hi:
        raise ValueError(f"range must be [low, high] with low <= high, got [{lo}, {hi}]")
    return bounds


#: A closed interval ``[low, high]`` written as a two-element list in YAML.
Range = Annotated[tuple[Number, Number], AfterValidator(_ordered)]


def _within(low: float, high: float) -> AfterValidator:
    """A :data:`Range` (or an integer range) whose ends must lie in ``[low, high]``: every range
    has a documented bound."""
    def check(bounds: tuple[float, float]) -> tuple[float, float]:
        lo, hi = bounds
        if lo < low or hi > high:
            raise ValueError(f"must lie within [{low:g}, {high:g}], got [{lo!r}, {hi!r}]")
        return bounds

    return AfterValidator(check)


#: Clouds keep at least this far (metres) beyond the approach's far end from the tanker's altitude.
CLOUD_CLEARANCE_M = 200.0
#: The world's randomizers by name, each as the config overrides that switch it
#: off: the ablation switches a user flips, bench/bench_render.py times and the tests check.
WORLD_RANDOMIZERS: Final[dict[str, dict[str, Any]]] = {
    "clouds": {"randomization.clouds.enabled": False},
    "haze": {"randomization.haze.enabled": False},
    "ground": {"randomization.ground.enabled": False},
    "sea": {"randomization.sea.waves": False, "randomization.sea.whitecaps": False,
            "randomization.sea.colour": False},
    "livery": {"randomization.livery.enabled": False},
    "sensor": {"randomization.sensor.enabled": False},
    "backlit sun": {"randomization.sky.backlit_fraction": 0.0},
    "vibration": {"camera.vibration.enabled": False},
    "drogue": {"randomization.drogue.enabled": False},
    "window": {"randomization.window.enabled": False},
    "traffic": {"randomization.traffic.enabled": False},
}


def world_off(*names: str) -> dict[str, Any]:
    """Config overrides that switch the named world randomizers off (every one when none is
    named): with all of them off a frame has a clear sky, a flat uniform sea, plain paint and a
    pinhole camera."""
    unknown = set(names) - set(WORLD_RANDOMIZERS)
    if unknown:
        raise KeyError(f"no world randomizer {sorted(unknown)}; there are {list(WORLD_RANDOMIZERS)}")
    return {k: v for name in (names or WORLD_RANDOMIZERS) for k, v in WORLD_RANDOMIZERS[name].items()}


class _Section(BaseModel):
    model_config = ConfigDict(
        extra="forbid", frozen=True, use_attribute_docstrings=True, validate_default=True,
        allow_inf_nan=False,
    )


# --- camera --------------------------------------------------------------------
class MountJitterConfig(_Section):
    """Per-approach perturbation of the camera mount: extrinsics are unknown and drift."""

    translation_m: Number = Field(0.02, ge=0.0, le=1.0)
    """Each mount offset component is drawn uniformly in [-t, t] metres per approach."""

    rotation_deg: Number = Field(1.0, ge=0.0, le=30.0)
    """Each of yaw, pitch, roll of the mount is drawn uniformly in [-r, r] degrees per approach."""


class VibrationConfig(_Section):
    """The camera's vibration and buffet (:mod:`datagen.scene.vibration`): a small turn of the
    camera about its own axes, a sum of sinusoids whose amplitude and spectrum each approach
    draws from its mount's band; it moves the view and blurs the image along its motion."""

    enabled: Flag = True
    """Vibrate the camera; off: it is fixed to its mount."""

    scale: Number = Field(1.0, ge=0.0, le=10.0)
    """Multiplies the mount's amplitudes (1: the mount's band)."""


class CameraConfig(_Section):
    """The pinhole camera (paper Table 1) and where it is mounted."""

    mount: Mount
    """wingcam: receiver right wing pod, forward; dashcam: receiver cockpit, forward;
    podcam: tanker hose pod next to the hose port, rearward."""

    hfov_deg: Number = Field(gt=0.0, lt=180.0)
    """Horizontal field of view in degrees; fx = fy = (W/2) / tan(hFOV/2)."""

    width: Integer = Field(2048, gt=0, le=MAX_IMAGE_PX)
    """Image width in pixels (Table 1: 2048)."""

    height: Integer = Field(1080, gt=0, le=MAX_IMAGE_PX)
    """Image height in pixels (Table 1: 1080)."""

    mount_jitter: MountJitterConfig = MountJitterConfig()
    """Bounds of the per-approach mount pose perturbation."""

    vibration: VibrationConfig = VibrationConfig()
    """The camera's vibration and buffet per approach."""

    @model_validator(mode="after")
    def _makeable(self) -> CameraConfig:
        lo, hi = hfov_bounds_deg(self.width)
        if not lo <= self.hfov_deg <= hi:
            raise ValueError(f"hfov_deg {self.hfov_deg:.10g} at width {self.width}: a pinhole of this width can be "
                             f"made with {lo:.4g} to {hi:.6g} degrees (neighbouring pixels' rays at least "
                             f"{MIN_PIXEL_ANGLE_RAD:.3g} rad apart, a focal length of at least {MIN_FOCAL_PX:g} px)")
        return self


# --- objects and features ------------------------------------------------------
class ObjectSpec(_Section):
    """Which mesh and feature file an object uses; null means the built-in asset."""

    mesh: Path | None = None
    """OBJ, PLY or GLB mesh in the object's body frame (metres); relative to the config file."""

    features: Path | None = None
    """Feature set file for this object; relative to the config file."""


#: The rigid objects of the scene (the hose is procedural and needs no entry): one
#: :class:`ObjectSpec` per object of :data:`datagen.core.conventions.RIGID_OBJECTS`.
_OBJECT_FIELDS: dict[str, Any] = {
    name: (ObjectSpec, Field(default_factory=ObjectSpec, description=f"The {name}'s mesh and feature file."))
    for name in RIGID_OBJECTS}
ObjectsConfig = create_model(
    "ObjectsConfig",
    __base__=_Section,
    __doc__="Meshes and feature files of the rigid objects; null means the built-in asset.",
    **_OBJECT_FIELDS,
)


class FeaturesConfig(_Section):
    """Which feature sets become YOLO classes."""

    objects: tuple[LabeledObject, ...] = Field(("receiver", "tanker"), min_length=1)
    """Objects whose features are labeled; class ids follow this order."""

    variant: Variant = "baseline"
    """Feature set variant: the paper's baseline, the co-located size variants
    (models J, K, L) or seeded random surface features (model I)."""

    random_per_object: Integer = Field(40, ge=3, le=1000)
    """Number of random surface features per object when variant is 'random'."""

    @field_validator("objects")
    @classmethod
    def _unique_objects(cls, objects: tuple[str, ...]) -> tuple[str, ...]:
        if len(set(objects)) != len(objects):
            raise ValueError("objects must not repeat")
        return objects


# --- approach ------------------------------------------------------------------
class ApproachConfig(_Section):
    """Monte Carlo refueling approaches (paper 3.1) and how frames are taken from them."""

    range_m: Annotated[Range, _within(0.0, 10_000.0)] = (0.0, 120.0)
    """Probe-to-drogue distance range the dataset covers, metres."""

    yaw_deg: Number = Field(10.0, ge=0.0, le=180.0)
    """Initial receiver yaw perturbation, uniform in [-yaw, yaw] degrees."""

    pitch_deg: Number = Field(15.0, ge=0.0, le=90.0)
    """Initial receiver pitch perturbation, uniform in [-pitch, pitch] degrees."""

    roll_deg: Number = Field(45.0, ge=0.0, le=180.0)
    """Initial receiver roll perturbation, uniform in [-roll, roll] degrees."""

    start_azimuth_deg: Number = Field(15.0, ge=0.0, le=90.0)
    """Start position bearing from the drogue, uniform in [-a, a] degrees off dead astern."""

    start_elevation_deg: Annotated[Range, _within(-90.0, 90.0)] = (-12.0, 3.0)
    """Start position elevation from the drogue, degrees (negative: the receiver starts below)."""

    sampling: Literal["distance", "time"] = "distance"
    """'distance': each approach starts at the range's far end and contributes one frame per
    distance stratum, so the dataset covers its range evenly; 'time': approaches start at a
    uniform distance in range and frames are taken every stride_steps simulation steps,
    through contact and the next approach."""

    model: Literal[1, 2] = 2
    """The approach simulation's version. 2: the drogue's gusts from a stream of their own,
    drawn in blocks, stepping a shard's chains together (2.6x faster alone, 4-5x together); 1: every draw from the
    chain's one stream, step by step, for reproducing datasets built before model 2. The
    dynamics are the same; the sampled trajectories differ."""

    frames_per_approach: Integer = Field(16, ge=1, le=100_000)
    """Consecutive frames taken from one approach (the unit of simulation). A build too
    small to span min_approaches approaches of this many frames takes fewer from each
    (dataset.frames / min_approaches, at least 1): see Config.frames_per_chain."""

    min_approaches: Integer = Field(8, ge=1, le=100_000)
    """The fewest approaches a build takes its frames from, when it has that many frames:
    each approach has its own sky, sun, sea, clouds and liveries, so a small build still
    shows the world's variety. Builds of frames_per_approach x min_approaches frames or
    more are unaffected; 1 turns this off."""

    stride_steps: Integer = Field(15, ge=1, le=100_000)
    """Simulation steps between frames in 'time' sampling."""

    dt_s: Number = Field(1.0 / 30.0, gt=0.0, le=0.2)
    """Simulation time step, seconds."""

    forward_gain: Number = Field(0.12, gt=0.0, le=10.0)
    """Convergence rate of the PtD vector's forward (receiver x) component, 1/s."""

    lateral_gain_ratio: Number = Field(2.0, gt=0.0, le=10.0)
    """Lateral and vertical convergence rates relative to the forward one (paper: about 2)."""

    max_closure_mps: Number = Field(4.0, gt=0.0, le=100.0)
    """Speed limit of the receiver relative to the drogue along its x axis, m/s."""

    max_lateral_mps: Number = Field(2.0, gt=0.0, le=100.0)
    """Speed limit of the receiver relative to the drogue along its y and z axes, m/s."""

    attitude_time_constant_s: Number = Field(6.0, gt=0.0, le=3600.0)
    """Time constant of the attitude slerp back to the tanker's orientation, s."""

    contact_m: Number = Field(0.01, gt=0.0, le=10.0)
    """PtD distance that counts as contact (paper: 1 cm)."""

    max_steps: Integer = Field(100_000, ge=100, le=1_000_000)
    """Safety limit on the steps of one approach."""

    @model_validator(mode="after")
    def _non_negative_range(self) -> ApproachConfig:
        if self.range_m[0] < 0.0:
            raise ValueError(f"range_m must not be negative, got {list(self.range_m)}")
        if self.range_m[1] <= 0.0:
            raise ValueError(f"range_m upper bound must be positive, got {list(self.range_m)}")
        return self


class DrogueConfig(_Section):
    """Drogue motion about its average position under turbulence.

    Each axis of the tanker frame carries a gust state that is a first-order
    Gauss-Markov process (the Dryden longitudinal gust filter driven by white
    noise) with standard deviation ``rms_m * intensity`` and correlation time
    ``gust_time_s``; the drogue's displacement follows it through a damped
    second-order hose-drogue response (natural frequency ``natural_hz``,
    damping ratio ``damping``)."""

    rms_m: tuple[Number, Number, Number] = (0.15, 0.4, 0.3)
    """Gust-equilibrium RMS displacement along tanker x, y, z at intensity 1, metres."""

    intensity: Annotated[Range, _within(0.0, 100.0)] = (0.0, 1.0)
    """Turbulence intensity multiplier, drawn once per approach."""

    gust_time_s: Number = Field(3.0, gt=0.0, le=3600.0)
    """Gust correlation time (Dryden L / V), seconds."""

    natural_hz: Number = Field(0.5, gt=0.0, le=10.0)
    """Natural frequency of the hose-drogue response, Hz."""

    damping: Number = Field(0.4, gt=0.0, le=5.0)
    """Damping ratio of the hose-drogue response."""

    @field_validator("rms_m")
    @classmethod
    def _non_negative(cls, rms: tuple[float, float, float]) -> tuple[float, float, float]:
        if min(rms) < 0.0 or max(rms) > 100.0:
            raise ValueError(f"rms_m components must lie within [0, 100] m, got {list(rms)}")
        return rms


class TankerConfig(_Section):
    """Tanker flight: straight and level, or a coordinated banking turn."""

    speed_mps: Number = Field(150.0, gt=0.0, le=400.0)
    """True airspeed, m/s."""

    altitude_m: Annotated[Range, _within(0.0, 20_000.0)] = (4000.0, 8000.0)
    """Altitude above the sea surface (world z = 0), metres, drawn per approach."""

    turn_probability: Number = Field(0.3, ge=0.0, le=1.0)
    """Share of approaches flown in a banking turn instead of straight and level."""

    bank_deg: Range = (15.0, 30.0)
    """Bank angle magnitude of a turn, degrees (left or right with equal odds)."""

    @model_validator(mode="after")
    def _physical(self) -> TankerConfig:
        lo, hi = self.bank_deg
        if lo < 0.0 or hi >= 80.0:
            raise ValueError(f"bank_deg must lie within [0, 80), got [{lo}, {hi}]")
        if self.altitude_m[0] <= 0.0:
            raise ValueError(f"altitude_m must be positive, got {list(self.altitude_m)}")
        return self


# --- randomization -------------------------------------------------------------
class SkyConfig(_Section):
    """Physically based sky (Mitsuba ``sunsky``) and sun."""

    sun_elevation_deg: Range = (2.0, 70.0)
    """Sun elevation above the horizon, degrees (from 2: low, reddened sun and long shadows;
    sunsky is black below the horizon)."""

    sun_azimuth_deg: Annotated[Range, _within(-720.0, 720.0)] = (0.0, 360.0)
    """Sun azimuth, degrees counter-clockwise from the tanker's initial heading."""

    turbidity: Range = (2.0, 5.0)
    """Atmospheric turbidity (sunsky accepts 1 to 10)."""

    sun_scale: Range = (0.8, 1.2)
    """Multiplier on the sun's radiance, drawn uniformly across the range (a kernel input:
    :mod:`datagen.render.sky`)."""

    sky_scale: Range = (0.8, 1.2)
    """Multiplier on the sky's radiance, drawn uniformly across the range."""

    backlit_fraction: Number = Field(0.2, ge=0.0, le=1.0)
    """Share of frames whose sun is put within ``backlit_azimuth_deg`` of the camera's
    forward azimuth (the target backlit, the sun in or near the view: lens glare). 0 keeps
    every frame's azimuth as drawn from ``sun_azimuth_deg``."""

    backlit_azimuth_deg: Number = Field(25.0, ge=0.0, le=180.0)
    """Half-width of the backlit azimuth window around the camera's forward azimuth, degrees."""

    @model_validator(mode="after")
    def _physical(self) -> SkyConfig:
        checks = [
            ("sun_elevation_deg", self.sun_elevation_deg, -90.0, 90.0),
            ("turbidity", self.turbidity, 1.0, 10.0),
            ("sun_scale", self.sun_scale, 0.0, 100.0),
            ("sky_scale", self.sky_scale, 0.0, 100.0),
        ]
        for name, (lo, hi), low, high in checks:
            if lo < low or hi > high:
                raise ValueError(f"{name} must lie within [{low}, {high}], got [{lo}, {hi}]")
        return self


class MaterialsConfig(_Section):
    """Per-part principled-BSDF draws."""

    paint_value: Range = (0.25, 0.75)
    """Brightness (HSV value) of the paint base colour."""

    paint_saturation: Range = (0.0, 0.15)
    """Saturation of the paint base colour (military greys are nearly neutral)."""

    paint_roughness: Range = (0.25, 0.7)
    """Principled roughness of painted parts."""

    metal_roughness: Range = (0.1, 0.4)
    """Principled roughness of bare-metal parts."""

    @model_validator(mode="after")
    def _unit(self) -> MaterialsConfig:
        for name in type(self).model_fields:
            lo, hi = getattr(self, name)
            if lo < 0.0 or hi > 1.0:
                raise ValueError(f"{name} must lie within [0, 1], got [{lo}, {hi}]")
        return self


class SeaConfig(_Section):
    """The sea's surface roughness (one principled BSDF over a plane at sea level).

    ``cox_munk`` (default) draws a wind speed and derives the microfacet roughness from
    Cox and Munk's (1954) sun-glint measurements of the open sea: the mean square wave
    slope is 0.003 + 5.12e-3 W for a wind of W m/s (:func:`datagen.assets.sea.cox_munk_roughness`).
    ``uniform`` draws the roughness itself from ``roughness``; its default (0.05-0.25, a
    mirror-calm sea no wind gives) is glossier than any wind leaves the sea: it reflects
    the sun onto the aircraft as a caustic the path tracer samples as fireflies that no
    spp count removes (``bench/bench_quality.py`` counts them)."""

    model: Literal["cox_munk", "uniform"] = "cox_munk"
    """How the roughness is drawn: from a wind speed (Cox-Munk) or uniformly."""

    wind_speed_mps: Annotated[Range, _within(0.0, 30.0)] = (3.0, 12.0)
    """Wind speed over the sea, m/s (model cox_munk): 3-12 m/s is a moderate open-ocean breeze."""

    roughness: Annotated[Range, _within(0.0, 1.0)] = (0.05, 0.25)
    """Principled roughness of the sea (model uniform)."""

    waves: Flag = True
    """Waves a pilot sees: a normal map from a directional Pierson-Moskowitz spectrum at the
    drawn wind (the resolved slopes; the microfacet roughness then keeps the rest of Cox and
    Munk's slope variance), so that the sun's glint follows the wave slopes."""

    wind_direction_deg: Annotated[Range, _within(-720.0, 720.0)] = (0.0, 360.0)
    """Direction the wind blows towards, degrees counter-clockwise from world x (waves)."""

    whitecaps: Flag = True
    """Whitecaps (breaking crests) covering Monahan and O'Muircheartaigh's (1980) fraction
    3.84e-6 W^3.41 of the sea at the drawn wind. At 4-8 km a whitecap is smaller than a
    pixel, so they lift the sea's mean albedo towards foam's (0.22) by that fraction."""

    colour: Flag = True
    """Draw the sea's body colour (deep blue to blue-green); off: one dark blue."""


#: Livery schemes :mod:`datagen.assets.liveries` paints.
LiveryScheme = Literal["grey_camouflage", "two_tone", "high_visibility", "bare_metal"]


def _unit_range(bounds: tuple[float, float]) -> tuple[float, float]:
    lo, hi = bounds
    if lo < 0.0 or hi > 1.0:
        raise ValueError(f"must lie within [0, 1], got [{lo!r}, {hi!r}]")
    return bounds


#: A :data:`Range` within [0, 1].
UnitRange = Annotated[Range, AfterValidator(_unit_range)]


def _shares(shares: dict[str, float]) -> dict[str, float]:
    if any(not (math.isfinite(v) and v >= 0.0) for v in shares.values()) or not sum(shares.values()) > 0.0:
        raise ValueError(f"shares must be 0 or more, at least one of them above 0, got {dict(shares)}")
    return shares


#: The cloud deck's forms (:data:`datagen.assets.clouds.CLOUD_FORMS`).
CloudForm = Literal["cumulus", "stratocumulus", "overcast"]
#: Relative shares of named kinds, one drawn per approach in proportion (any positive scale).
CloudShares = Annotated[dict[CloudForm, Number], AfterValidator(_shares)]
#: The ground's types (:data:`datagen.assets.ground.GROUND_TYPES`).
GroundType = Literal["sea", "coast", "farmland", "desert", "snow", "mountains"]
GroundShares = Annotated[dict[GroundType, Number], AfterValidator(_shares)]


class HazeConfig(_Section):
    """Aerial perspective (:mod:`datagen.render.atmosphere`): the air between the camera and
    every surface (sea, clouds, aircraft) dims it and adds the sky's own light in its
    direction, by the path's optical depth over a round earth, the air thinning with
    altitude (molecules over 8 km, the aerosol over the scale height drawn). Visibility and
    scale height are drawn per approach (one weather an approach)."""

    enabled: Flag = True
    """Render aerial perspective; off: surfaces as if seen through a vacuum (the sea's
    horizon a hard step under the sky)."""

    visibility_m: Annotated[Range, _within(1_000.0, 280_000.0)] = (20_000.0, 150_000.0)
    """Meteorological visibility at sea level, metres (Koschmieder: 2% contrast at 550 nm;
    the air's molecules alone give 288 km), drawn log-uniform."""

    aerosol_scale_height_m: Annotated[Range, _within(200.0, 5_000.0)] = (800.0, 2_000.0)
    """Height over which the aerosol's density falls by e, metres (the boundary layer's haze)."""


class CloudsConfig(_Section):
    """Cloud layers: a deck below the aircraft and a scattered layer above or below them.

    Each layer is a sheet on the sphere of its altitude, out to the horizon, whose opacity
    is a thresholded fractal-noise field (coverage) and whose body is a height field of the
    drawn thickness (:mod:`datagen.assets.clouds`): sunlit slopes and tops, self-shadowed lee
    sides, bases darker the thicker the cloud above them. The deck's form (cumulus,
    stratocumulus, overcast) sets its cells' size, shape, coverage and thickness; the
    scattered layer is thin altocumulus. A layer between the sun and the aircraft or the sea
    shades them. Altitudes are drawn per approach relative to the tanker's (constant over an
    approach), never closer to it than the approach's far end plus 200 m, so that no cloud
    lies between the camera and a labeled feature."""

    enabled: Flag = True
    """Render cloud layers; off: a clear sky (the scene then has no cloud meshes at all)."""

    forms: CloudShares = {"cumulus": 0.4, "stratocumulus": 0.35, "overcast": 0.25}
    """The deck's forms and their shares of approaches (cumulus fields, stratocumulus rolls,
    an overcast); each form draws its own coverage and thickness."""

    deck_coverage: UnitRange = (0.0, 1.0)
    """Bounds on the share of the deck's area that is cloud (the form's own draw is clipped to them)."""

    deck_below_m: Annotated[Range, _within(0.0, 20_000.0)] = (600.0, 3000.0)
    """How far below the tanker the deck lies, metres."""

    layer_coverage: UnitRange = (0.0, 0.7)
    """Share of the scattered layer's area that is cloud."""

    layer_thickness_m: Annotated[Range, _within(0.0, 3_000.0)] = (100.0, 600.0)
    """How thick the scattered layer's thickest cells are, metres."""

    layer_offset_m: Annotated[Range, _within(0.0, 20_000.0)] = (600.0, 4000.0)
    """How far above or below the tanker the scattered layer lies (the side is drawn), metres."""

    opacity: UnitRange = (0.97, 1.0)
    """Opacity of a cloud's thick core (a droplet cloud 100 m thick lets through under 1% of
    the light: its thin edges carry the rest of the transparency; lower values make veils,
    which at a few samples a pixel render as speckle)."""

    albedo: UnitRange = (0.6, 0.95)
    """Diffuse reflectance of the cloud tops (brightness)."""


class GroundConfig(_Section):
    """The ground below: open sea or land (:mod:`datagen.assets.ground`), one type per
    approach drawn by its share: a coast (land and sea), farmland, desert, snow, mountains,
    each with its own albedo and relief (shaded; the horizon stays the sphere's)."""

    enabled: Flag = True
    """Draw a ground type per approach; off: open sea everywhere (the surface then has no land in its kernel)."""

    shares: GroundShares = {"sea": 0.55, "coast": 0.15, "farmland": 0.1, "desert": 0.08, "snow": 0.05,
                            "mountains": 0.07}
    """Each ground type's share of approaches (sea the majority by default)."""


#: The drogues' canopy schemes (:data:`datagen.assets.drogues.CANOPIES`).
CanopyName = Literal["black", "black_white_band", "black_yellow_panels", "olive", "dark_grey_orange_band",
                     "grey_white_panels", "white_red_panels", "orange_white_band", "white"]
CanopyShares = Annotated[dict[CanopyName, Number], AfterValidator(_shares)]


class DrogueLookConfig(_Section):
    """The drogue and hose as flown (:mod:`datagen.assets.drogues`): a canopy scheme per
    approach (dark and light fabrics, a rim band or painted gores, reflective tape, struts
    painted or bare, a metal coupling) and the hose's rubber and marker bands."""

    enabled: Flag = True
    """Draw a drogue per approach; off: the drogue's parts take the frame's fabric and metal draws."""

    canopies: CanopyShares = {"black": 0.2, "black_white_band": 0.15, "black_yellow_panels": 0.1, "olive": 0.1,
                              "dark_grey_orange_band": 0.1, "grey_white_panels": 0.1, "white_red_panels": 0.1,
                              "orange_white_band": 0.075, "white": 0.075}
    """Each canopy scheme's share of approaches (dark fabrics 65% by default)."""

    hose_bands: Flag = True
    """Painted marker bands along the hose near the drogue."""


class WindowConfig(_Section):
    """What the camera looks through (:mod:`datagen.render.window`), drawn per approach: a pod
    camera's window with dirt and, on some approaches, water droplets; a cockpit camera's
    windscreen with dirt and a reflection of the cockpit. Labels do not move."""

    enabled: Flag = True
    """Draw the window; off: a clean window (none at all)."""

    dirt: UnitRange = (0.0, 0.5)
    """Strength of the dirt (0 clean; its patches scatter and absorb up to 0.75 of the light at 1)."""

    droplet_share: Number = Field(0.25, ge=0.0, le=1.0)
    """Share of approaches whose pod window carries water droplets."""

    droplets: Annotated[tuple[Integer, Integer], AfterValidator(_ordered), _within(0, 200)] = (1, 25)
    """How many droplets such a window carries (integer range)."""

    reflection: UnitRange = (0.0, 0.12)
    """Strength of a windscreen's reflection of the cockpit, as a share of the image's mean light."""

    canopy_frame: Flag = True
    """A cockpit camera sees its windscreen's frame at the edges of its view (it occludes features)."""


#: The kinds of other aircraft (:mod:`datagen.scene.traffic`).
TrafficKind = Literal["receiver", "tanker"]


class TrafficConfig(_Section):
    """Another aircraft in view (:mod:`datagen.scene.traffic`): on a share of approaches a
    second receiver or tanker flies in formation with the tanker somewhere in the camera's
    field of view; drawn and recorded, never labeled (it occludes like anything else)."""

    enabled: Flag = True
    """Draw other aircraft; off: the tanker, the receiver and the drogue are alone."""

    share: Number = Field(0.25, ge=0.0, le=1.0)
    """Share of approaches with another aircraft."""

    kinds: Annotated[dict[TrafficKind, Number], AfterValidator(_shares)] = {"receiver": 0.7, "tanker": 0.3}
    """Each kind's share of those aircraft."""

    range_m: Annotated[Range, _within(10.0, 20_000.0)] = (80.0, 800.0)
    """Its distance from the camera's nominal place, metres (log-uniform)."""

    heading_deg: Number = Field(15.0, ge=0.0, le=180.0)
    """Its heading lies within this many degrees of the tanker's."""


class LiveryConfig(_Section):
    """Aircraft paint: generated liveries on the receiver's and tanker's painted parts."""

    enabled: Flag = True
    """Paint liveries; off: one flat colour per material class, as before."""

    schemes: tuple[LiveryScheme, ...] = Field(
        ("grey_camouflage", "two_tone", "high_visibility", "bare_metal"), min_length=1, max_length=4)
    """Schemes drawn from (equally likely)."""

    panel_lines: Flag = True
    """Panels along the structure: dark seams, rivet rows and panel-to-panel tones."""

    markings: Flag = True
    """National roundels and aircraft numbers on the markings' decals."""

    surface_detail: Flag = True
    """The skin's normal: its ripple, the seams' grooves, the rivets' heads (a ``normalmap``)."""

    weathering: UnitRange = (0.0, 0.7)
    """Grime, streaks, soot and fading strength (0 clean, 1 heavily weathered)."""

    lights: Flag = True
    """Navigation lights (wingtips, tail) and flashing anti-collision beacons."""

    lights_share: Number = Field(0.75, ge=0.0, le=1.0)
    """Share of approaches flown with the lights on."""

    light_scale: Annotated[Range, _within(0.0, 100.0)] = (0.5, 3.0)
    """A steady light's radiance over that of a white diffuser in the frame's daylight (beacons 3x)."""


class SensorConfig(_Section):
    """The camera model applied to the linear image after the render, each effect
    switchable; every parameter is drawn per frame and recorded in the manifest.

    Order (the light's): motion blur, lens distortion, vignetting, glare, exposure (auto
    or fixed), photon shot and read noise at the drawn ISO, then the sRGB encoding and a
    JPEG round trip. Labels follow the distortion exactly (:mod:`datagen.core.camera`)."""

    enabled: Flag = True
    """Apply the camera model; off: the path tracer's pinhole image, exposed and encoded."""

    auto_exposure: Flag = True
    """Meter the frame (centre-weighted log-average luminance to mid-grey, clamped to
    +-2 stops of the fixed exposure) before ``exposure_ev`` compensation."""

    iso: Annotated[Range, _within(25.0, 102_400.0)] = (100.0, 1600.0)
    """Sensor gain, ISO (log-uniform): full well 15,000 e- at ISO 100, 3 e- read noise."""

    noise: Flag = True
    """Photon shot noise and read noise at the drawn ISO."""

    exposure_time_s: Annotated[Range, _within(1.0e-5, 1.0)] = (1.0 / 4000.0, 1.0 / 250.0)
    """Exposure time, seconds (log-uniform): the length of the motion blur."""

    motion_blur: Flag = True
    """Blur each pixel along its true image motion (relative camera and object motion from
    the approach) over the exposure, centred on the frame's time."""

    vignetting: UnitRange = (0.0, 0.4)
    """Light falloff towards the corners: the corners receive (1 - v) of the centre."""

    glare: UnitRange = (0.0, 1.0)
    """Strength of the lens's veiling glare and ghosts when the sun is in or near the view."""

    distortion: Flag = False
    """Brown-Conrady lens distortion (OpenCV's k1, k2, p1, p2, k3 = 0) drawn per frame;
    labels are projected through it (the paper assumed none)."""

    k1: Annotated[Range, _within(-0.5, 0.5)] = (-0.12, 0.04)
    """Radial coefficient k1 (negative: barrel)."""

    k2: Annotated[Range, _within(-0.5, 0.5)] = (-0.03, 0.03)
    """Radial coefficient k2."""

    tangential: Annotated[Range, _within(-0.05, 0.05)] = (-0.001, 0.001)
    """Tangential coefficients p1 and p2 (each drawn from this range)."""

    jpeg_quality: Annotated[tuple[Integer, Integer], AfterValidator(_ordered), _within(1, 100)] = (70, 98)
    """JPEG quality of the compression round trip (integer range; 100 keeps the image closest)."""

    jpeg: Flag = True
    """Round-trip the 8-bit image through JPEG at the drawn quality (the artefacts of a
    compressed video link), whatever ``render.image_format`` stores."""

    rolling_shutter: Flag = False
    """Read the rows out from the top down over ``readout_s`` instead of all at once: each
    row shows the scene at its own time (the image warped along its true motion), and the
    labels put each point where it was when its row was exposed
    (:data:`datagen.core.conventions.row_time_s`)."""

    readout_s: Annotated[Range, _within(0.0, MAX_READOUT_S)] = (0.005, 0.03)
    """A rolling shutter's top-to-bottom readout time, seconds (uniform per frame)."""

    video_share: Number = Field(0.0, ge=0.0, le=1.0)
    """Share of frames round-tripped through H.264 instead of JPEG: x264 at the drawn
    ``video_crf``, 4:2:0 chroma, the frame coded as a key frame
    (:func:`datagen.render.sensor.video_round_trip`). Needs the ``[video]`` extra (PyAV,
    whose bundled FFmpeg and x264 are GPL)."""

    video_crf: Annotated[tuple[Integer, Integer], AfterValidator(_ordered), _within(0, 51)] = (20, 34)
    """x264's constant rate factor of the video round trip (integer range; lower keeps more:
    18 is near transparent, 30 a streaming link's, 40 a starved one's)."""

    @field_validator("video_share")
    @classmethod
    def _video_installed(cls, value: float) -> float:
        import importlib.util

        if value > 0.0 and importlib.util.find_spec("av") is None:
            raise ValueError("a video round trip needs PyAV, which is not installed: pip install 'datagen[video]'")
        return value

    lens: Flag = True
    """The lens's blur and lateral chromatic aberration, drawn per frame."""

    lens_blur_px: Annotated[Range, _within(0.0, 10.0)] = (0.2, 1.0)
    """Standard deviation of the lens's Gaussian point spread, pixels (its 10-90% edge width
    is 2.56 times it, on top of the render's own)."""

    chromatic_aberration_px: Annotated[Range, _within(0.0, 10.0)] = (0.0, 1.2)
    """Lateral chromatic aberration: red and blue displaced apart by this much at the
    image's farthest corner, pixels (each half of it, in opposite directions)."""

    colour: Flag = True
    """The camera's white balance and tone curve, drawn per frame."""

    white_balance_k: Annotated[Range, _within(4000.0, 25000.0)] = (5300.0, 8000.0)
    """The daylight temperature the camera is white-balanced for (the scene's is D65's 6504 K),
    K, drawn uniformly in mired (1e6 / K): lower turns the image blue, higher amber."""

    tint: Annotated[Range, _within(-0.2, 0.2)] = (-0.03, 0.03)
    """Green gain's offset of the white balance (negative: magenta)."""

    tone_gamma: Annotated[Range, _within(0.5, 2.0)] = (0.85, 1.15)
    """Exponent of the tone curve on display-linear values (above 1: more contrast in the mid-tones)."""

    tone_shoulder: UnitRange = (0.0, 1.0)
    """Strength of the tone curve's highlight shoulder (0: a hard clip at white)."""


class RandomizationConfig(_Section):
    """Per-frame appearance randomization; every range is drawn from the frame's RNG."""

    sea: SeaConfig = SeaConfig()
    """The sea's roughness: from a drawn wind speed (Cox-Munk) or uniform."""

    sky: SkyConfig = SkyConfig()
    """Sky and sun."""

    materials: MaterialsConfig = MaterialsConfig()
    """Materials of the airframes."""

    exposure_ev: Annotated[Range, _within(-20.0, 20.0)] = (-0.5, 0.5)
    """Exposure compensation in stops applied before the sRGB transform."""

    haze: HazeConfig = HazeConfig()
    """Aerial perspective (``haze: false`` or ``true`` switches it as ``haze.enabled`` does)."""

    @field_validator("haze", mode="before")
    @classmethod
    def _haze_switch(cls, value: Any) -> Any:
        return {"enabled": value} if isinstance(value, bool) else value

    clouds: CloudsConfig = CloudsConfig()
    """Cloud deck and scattered layer."""

    ground: GroundConfig = GroundConfig()
    """Land as well as sea: the ground type drawn per approach."""

    livery: LiveryConfig = LiveryConfig()
    """Aircraft liveries, panel lines, markings and weathering."""

    drogue: DrogueLookConfig = DrogueLookConfig()
    """The drogue's canopy and the hose's marker bands, per approach."""

    window: WindowConfig = WindowConfig()
    """Dirt, droplets and reflections on the window the camera looks through, per approach."""

    traffic: TrafficConfig = TrafficConfig()
    """Another aircraft in view on a share of approaches."""

    sensor: SensorConfig = SensorConfig()
    """The camera model after the render: exposure, noise, blur, vignetting, glare,
    distortion, JPEG."""


# --- render --------------------------------------------------------------------
class RenderConfig(_Section):
    """Mitsuba rendering settings."""

    variant: Literal["auto", "llvm_ad_rgb", "cuda_ad_rgb", "scalar_rgb"] = "auto"
    """Mitsuba variant; 'auto' picks cuda_ad_rgb with a GPU, else llvm_ad_rgb, else scalar_rgb."""

    spp: Integer = Field(4, ge=1, le=65536)
    """Samples per pixel (4 with the denoiser: 43.6 dB against a converged reference in
    bench/bench_quality.py, where 16 spp without it gave 31.7 dB in more time)."""

    max_depth: Integer = Field(6, ge=1, le=64)
    """Path tracer maximum depth."""

    target_spp: Integer = Field(4, ge=0, le=65536)
    """Samples per pixel added over a window on the objects (``datagen.render.target``):
    the denoiser keeps more of the aircraft's and the drogue's detail where a detector
    looks (``bench/bench_detail.py``). 0: no target pass."""

    target_window: Number = Field(0.5, gt=0.0, le=1.0)
    """The target pass's window: this share of the image's width and of its height."""

    denoise: Literal["off", "oidn"] = "oidn"
    """Denoise the linear image with Intel Open Image Denoise (``mitsuba-oidn``) before
    exposure and encoding, on the variant's device; the EXR keeps the denoised linear image."""

    denoise_guides: Flag = False
    """Give the denoiser the first hit's albedo and shading normal (Mitsuba's ``aov``
    integrator; the beauty image is unchanged by it). Off by default: measured, they
    gain 0.1-0.3 dB and double the time in ``mi.render``."""

    frozen: Flag = True
    """Record the path tracing once and replay it for later frames (Dr.Jit's ``dr.freeze``;
    a JIT variant): the frame's values reach the recording as data, so a replay makes the
    traced render's image bit for bit (``bench/bench_freeze.py``; ``tests/test_frozen.py``,
    three approaches with every randomizer on) without tracing the kernel again. A renderer
    records once, at its first frame, and compiles nothing after it (as the traced render);
    off, every frame traces the kernel again (the fixed cost of a frame, each way:
    docs/performance.md)."""

    denoise_quality: Literal["fast", "balanced", "high"] = "high"
    """OIDN's filter quality: ``fast`` takes about half the time of ``high``."""

    image_format: Literal["png", "jpg"] = "png"
    """8-bit sRGB training image format."""

    @property
    def image_suffix(self) -> str:
        """The file suffix of the training images, ``.png`` or ``.jpg``."""
        return f".{self.image_format}"

    jpeg_quality: Integer = Field(95, ge=1, le=100)
    """JPEG quality when image_format is 'jpg'."""

    exr: Flag = False
    """Also write a linear EXR with R, G, B, Z (camera depth, metres) and object_id."""


# --- labels --------------------------------------------------------------------
def _rule(default: float, key: str):
    """A label rule's field, bounded as :data:`datagen.core.labelling_context.RULE_BOUNDS` says."""
    lo, hi = RULE_BOUNDS[key]
    return Field(default, ge=lo, le=hi)


class LabelsConfig(_Section):
    """How boxes are made (paper 3.2)."""

    corrected: Flag = True
    """Corrected boxes centred on the true 3D centre projection; false gives tight
    boxes (the paper's uncorrected ablation, model H)."""

    edge_margin_px: Number = _rule(10.0, "edge_margin_px")
    """A feature is labeled only if its box lies at least this far inside every border."""

    min_visible_fraction: Number = _rule(0.0, "min_visible_fraction")
    """Drop features whose visible share of points is below this; 0 keeps occluded
    features (the paper's choice)."""

    train_imgsz: Integer = _rule(864, "train_imgsz")
    """Ultralytics' training image size (the recipe's imgsz; the paper trained at 864):
    label sizes are judged as the trainer sees them there (datagen.core.training)."""

    min_box_px: Number = _rule(48.0, "min_box_px")
    """Smallest side a label box may have at train_imgsz, in the trainer's pixels; 0 keeps
    boxes as they are. A detector learns a box only if the untrained head's assigner gives
    it a target, which needs sides of at least ASSIGNABLE_SIDE_PX there
    (datagen.core.training); 48 gives about six times the target of that minimum. A box
    near a border grows only as far as the edge margin allows, so no feature is lost."""

    small_boxes: SmallBoxes = "grow"
    """A label box with a side under min_box_px: 'grow' widens it symmetrically about its
    centre (the true centre stays exact); 'exclude' drops the feature as too_small."""

    format: LabelFormat = "detect"
    """Label files: 'detect' (one box per feature, centred on its true centre), 'pose' (one
    instance per object whose keypoints are its features' true centres, Ultralytics' pose
    format: datagen.core.keypoints) or 'both' (detect in labels/, the pose set beside it in
    pose/ with its own data.yaml and hyp.yaml)."""

    truncated_objects: TruncatedObjects = "exclude"
    """A pose instance whose full-object box is not inside the image's edge margin (or whose
    mesh reaches behind the camera): 'exclude' it, or 'clip' it to the box of its in-view
    part. A camera on the receiver never sees the whole receiver: only 'clip' gives the
    probe's keypoints an instance there."""

    @field_validator("train_imgsz")
    @classmethod
    def _stride_multiple(cls, imgsz: int) -> int:
        if imgsz % 32:
            raise ValueError(f"must be a multiple of 32 (the detector's largest stride), got {imgsz}")
        return imgsz

    @model_validator(mode="after")
    def _box_fits_input(self) -> LabelsConfig:
        if self.min_box_px >= self.train_imgsz:
            raise ValueError(f"min_box_px {self.min_box_px:g} must be smaller than train_imgsz {self.train_imgsz}")
        return self

    def rules(self) -> LabelRules:
        """This section as the labelling reads it (:class:`datagen.core.labelling_context.LabelRules`)."""
        return LabelRules(**self.model_dump())


# --- dataset -------------------------------------------------------------------
class DatasetConfig(_Section):
    """Size, sharding, split and seed of the dataset."""

    frames: Integer = Field(ge=1, le=10_000_000)
    """Number of frames."""

    shard_size: Integer = Field(500, ge=1, le=100_000)
    """Frames per shard (a shard is the unit of work, resumption and manifest files). A build
    too small to make min_shards shards of this size makes smaller ones: see
    Config.frames_per_shard."""

    min_shards: Integer = Field(16, ge=1, le=100_000)
    """The fewest shards a build is cut into, when it has that many frames, so that a small
    build keeps every worker busy. Builds of shard_size x min_shards frames or more are
    unaffected; 1 turns this off."""

    val_fraction: Number = Field(0.2, ge=0.0, lt=1.0)
    """Share of frames assigned to the validation split, decided per frame from the seed."""

    split_by: Literal["frame", "approach"] = "frame"
    """Unit of the train/val split: 'frame' decides every frame on its own; 'approach'
    keeps the frames of one approach chain (Config.frames_per_chain consecutive frames,
    which share a trajectory) in the same split, so that validation frames are not
    near-duplicates of training frames."""

    seed: Integer = Field(0, ge=0, lt=2**63)
    """Root seed; frame i draws from SeedSequence(seed, spawn_key=(i,))."""


class Config(_Section):
    """A datagen scene config."""

    name: str = Field(pattern=r"^[A-Za-z0-9][A-Za-z0-9_.-]*$", max_length=100)
    """Short identifier (letters, digits, '_', '-', '.')."""

    description: str = Field("", max_length=10_000)
    """Free text: what the config is for."""

    paper_model: str | None = Field(None, pattern=r"^[A-Z]$")
    """The model of the paper's Table 3 this config reproduces (A-L), if any."""

    camera: CameraConfig
    """The camera."""

    objects: ObjectsConfig = ObjectsConfig()
    """Meshes and feature sets of the objects."""

    features: FeaturesConfig = FeaturesConfig()
    """Labeled feature sets."""

    approach: ApproachConfig = ApproachConfig()
    """Approach sampling."""

    drogue: DrogueConfig = DrogueConfig()
    """Drogue turbulence response."""

    tanker: TankerConfig = TankerConfig()
    """Tanker flight."""

    randomization: RandomizationConfig = RandomizationConfig()
    """Appearance randomization."""

    render: RenderConfig = RenderConfig()
    """Rendering."""

    labels: LabelsConfig = LabelsConfig()
    """Label generation."""

    dataset: DatasetConfig
    """Dataset size, split and seed."""

    @property
    def frames_per_shard(self) -> int:
        """Frames per shard: dataset.shard_size, or fewer in a build of fewer than
        shard_size x min_shards frames (dataset.frames // min_shards, at least 1)."""
        d = self.dataset
        return max(1, min(d.shard_size, d.frames // d.min_shards))

    @property
    def frames_per_chain(self) -> int:
        """Consecutive frames taken from one approach chain: approach.frames_per_approach,
        or fewer in a build of fewer than frames_per_approach x min_approaches frames
        (dataset.frames // min_approaches, at least 1)."""
        a = self.approach
        return max(1, min(a.frames_per_approach, self.dataset.frames // a.min_approaches))

    @model_validator(mode="after")
    def _margin_fits(self) -> Config:
        from datagen.core.training import TrainView

        m = self.labels.edge_margin_px
        w, h = self.camera.width, self.camera.height
        if 2.0 * m >= min(w, h):
            raise ValueError(f"labels.edge_margin_px {m} leaves no room inside a {w}x{h} image")
        box_w, box_h = TrainView(w, h, self.labels.train_imgsz).min_label_size_px(self.labels.min_box_px)
        if box_w + 2.0 * m > w or box_h + 2.0 * m > h:
            raise ValueError(f"labels.min_box_px {self.labels.min_box_px:g} at train_imgsz {self.labels.train_imgsz} "
                             f"is a {box_w:.0f}x{box_h:.0f} px box, which does not fit inside the edge margin "
                             f"of a {w}x{h} image")
        sensor = self.randomization.sensor
        if sensor.enabled and sensor.distortion:
            k = Intrinsics.from_hfov_deg(w, h, self.camera.hfov_deg)
            margin = distortion_margin_px(k, sensor.k1, sensor.k2, sensor.tangential)
            if not max(w, h) + 2 * margin <= MAX_IMAGE_PX:
                need = "a lens whose inverse does not converge" if margin == math.inf else \
                    f"a pinhole render {margin:g} px wider on every side ({w + 2 * margin:g}x{h + 2 * margin:g})"
                raise ValueError(f"randomization.sensor.k1, k2 and tangential at camera.hfov_deg "
                                 f"{self.camera.hfov_deg:g}: the lenses these ranges allow need {need}; a render "
                                 f"is at most {MAX_IMAGE_PX} px a side: narrow the ranges or the field of view")
        clouds = self.randomization.clouds
        if clouds.enabled:
            clear = self.approach.range_m[1] + CLOUD_CLEARANCE_M
            for key in ("deck_below_m", "layer_offset_m"):
                if getattr(clouds, key)[0] < clear:
                    raise ValueError(f"randomization.clouds.{key} must start at {clear:g} m or more "
                                     f"(approach.range_m's far end plus {CLOUD_CLEARANCE_M:g} m), so that no cloud "
                                     f"lies between the camera and a feature; got {list(getattr(clouds, key))}")
            if clouds.deck_below_m[1] >= self.tanker.altitude_m[0]:
                raise ValueError(f"randomization.clouds.deck_below_m {list(clouds.deck_below_m)} must stay below "
                                 f"tanker.altitude_m's low end {self.tanker.altitude_m[0]:g} m "
                                 "(the deck is above the sea)")
        return self
