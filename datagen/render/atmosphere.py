"""Aerial perspective: the light the air between the camera and a surface takes away and
adds, for a round earth whose air thins with altitude.

A pixel's surface radiance ``L0`` at distance ``s`` along the view ray ``d`` reaches the
camera as ``L0 T + A(d) min(1, (1 - T) / (1 - T_ref(d)))``:

- ``T = exp(-tau)``, the transmittance of the path: ``tau`` sums, per RGB channel, the
  molecular (Rayleigh) and aerosol extinction at sea level times the path's
  :func:`air_mass` for each one's scale height (density ``exp(-h / H)`` at altitude ``h``
  along the ray, the earth round: :func:`altitude_along`).
- ``A(d)``, the sky's own radiance in the ray's direction (the frame's ``sunsky``, the
  sun's disc excluded, below the horizon the sky just above it: :func:`airlight_directions`).
  ``sunsky`` is the sky an observer at sea level sees: the light the air column along
  ``d`` from sea level scatters towards it, whose transmittance is ``T_ref(d)``
  (:meth:`Atmosphere.column_transmittance`). Scattering the same light per unit of optical
  depth (single scattering, one phase angle along a direction), a path of transmittance
  ``T`` adds ``A (1 - T) / (1 - T_ref)``: nothing on a short path, the sky's own colour on
  a path as opaque as the column (the sea at the horizon, which then meets the sky above it
  without a step, over a width that follows from the visibility drawn).

The aerosol's extinction at sea level follows from the meteorological visibility ``V``
(Koschmieder, 2% contrast at 550 nm: ``beta(550) = 3.912 / V``, the molecules' share taken
out) and spreads over the channels with an Angstrom exponent. Sky pixels are left as the
sky renders them (their radiance is already the column's). Everything here is numpy or,
through :class:`~datagen.assets.noise.Ops`, Dr.Jit (:mod:`datagen.render.aerial`).
"""

from __future__ import annotations

import copy
from typing import Final

import numpy as np
from numpy.typing import NDArray

from datagen.assets.noise import NUMPY, Ops
from datagen.core.conventions import EARTH_RADIUS_M

__all__ = ["AEROSOL_ANGSTROM", "KOSCHMIEDER", "RAYLEIGH_SCALE_HEIGHT_M", "RAYLEIGH_SEA_LEVEL", "Atmosphere",
           "air_mass", "air_masses", "airlight_directions", "altitude_along", "column_distance", "dip_rad",
           "extinction_at_sea_level", "table_coordinates", "table_paths", "through_air",
           "transmittance_table"]

#: Molecular (Rayleigh) extinction at sea level, per metre, at the RGB channels' wavelengths
#: (680, 550, 440 nm; Bruneton and Neyret 2008) and its scale height.
RAYLEIGH_SEA_LEVEL: Final = (5.802e-6, 13.558e-6, 33.1e-6)
RAYLEIGH_SCALE_HEIGHT_M: Final = 8_000.0
#: The channels' wavelengths (nm) and the aerosol's Angstrom exponent (maritime to continental
#: aerosols span about 0.5 to 1.5).
CHANNEL_NM: Final = (680.0, 550.0, 440.0)
AEROSOL_ANGSTROM: Final = 1.0
#: Koschmieder's constant: visibility V = KOSCHMIEDER / extinction (a 2% contrast threshold).
KOSCHMIEDER: Final = 3.912
#: The top of the air for the column a direction looks through (above it, less than 1e-3 of
#: the molecules' sea-level density).
AIR_TOP_M: Final = 60_000.0
#: The lowest elevation (degrees) at which the sky's radiance is looked up: directions below
#: see the sky just above the horizon (``sunsky`` is black below it).
HORIZON_ELEVATION_DEG: Final = 1.0
#: Segments of a path's air-mass integral (its altitude linear in each, the density's
#: exponential exact there): 12 keep a path within 2% of the integral (a level path from
#: 500 m rises along a parabola, which the segments cut into chords; 8 segments: 3%).
SEGMENTS: Final = 12
#: The transmittance table a render looks each sample's path up in (:func:`transmittance_table`):
#: TABLE_MU elevations, denser towards the horizontal (``sign(mu) sqrt|mu|`` evenly spaced),
#: by TABLE_S distances evenly spaced in ``log(s)`` from TABLE_S_M[0] to TABLE_S_M[1]
#: (shorter paths: the first; longer ones: the last).
TABLE_MU: Final = 512
TABLE_S: Final = 384
TABLE_S_M: Final = (10.0, 8.0e5)


def extinction_at_sea_level(visibility_m: float) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(Rayleigh, aerosol) extinction per metre at sea level for each RGB channel, the
    aerosol's from the meteorological visibility ``visibility_m`` (Koschmieder at 550 nm)."""
    rayleigh = np.asarray(RAYLEIGH_SEA_LEVEL, dtype=np.float64)
    aerosol_550 = max(KOSCHMIEDER / float(visibility_m) - rayleigh[1], 0.0)
    aerosol = aerosol_550 * (np.asarray(CHANNEL_NM) / 550.0) ** -AEROSOL_ANGSTROM
    return rayleigh, aerosol


def altitude_along(altitude_m, sin_elevation, distance_m, ops: Ops = NUMPY):
    """Altitude above the sea of the point ``distance_m`` along a ray leaving ``altitude_m``
    at elevation ``asin(sin_elevation)`` over a round earth, computed without the
    cancellation of ``sqrt(r0^2 + ...) - R`` (``r - r0 = (s^2 + 2 r0 s mu) / (r + r0)``):
    float32 keeps it within centimetres. Arrays of numpy or, with ``ops``, Dr.Jit."""
    r0 = altitude_m + ops.f32(EARTH_RADIUS_M)
    q = distance_m * (distance_m + ops.f32(2.0) * r0 * sin_elevation)
    r = ops.sqrt(ops.clip(r0 * r0 + q, 0.0, 1e30))
    return altitude_m + q / (r + r0)


def air_masses(altitude_m, sin_elevation, distance_m, scale_heights_m, *, segments: int = SEGMENTS,
               spacing: float = 1.0, ops: Ops = NUMPY) -> list:
    """The path's length in sea-level air for each scale height ``H``: the integral of
    ``exp(-h(s) / H)`` over the first ``distance_m`` metres of the ray (``h``:
    :func:`altitude_along`). The path is cut into ``segments`` at ``distance (k /
    segments) ** spacing`` (``spacing`` 2 packs them near the camera, where an upward
    ray's density changes fastest); within each the altitude is linear and the
    exponential integrated exactly. ``altitude_m`` and the heights are scalars (with
    ``ops``, made kernel inputs by the caller); the rest arrays."""
    f = ops.f32
    totals = [distance_m * f(0.0) for _ in scale_heights_m]
    e_prev = [ops.exp(-altitude_m / scale) + distance_m * f(0.0) for scale in scale_heights_m]
    s_prev, h_prev = distance_m * f(0.0), altitude_m + distance_m * f(0.0)
    for k in range(1, segments + 1):
        s_k = distance_m * f((k / segments) ** spacing)
        # (A path under the sea, which only a table holds, goes along it.)
        h_k = ops.clip(altitude_along(altitude_m, sin_elevation, s_k, ops), 0.0, 1e30)
        ds, dh = s_k - s_prev, h_k - h_prev
        for i, scale in enumerate(scale_heights_m):
            x = dh / scale
            e_k = e_prev[i] * ops.exp(-x)
            # exact for linear h: ds (e_prev - e_k) / x; its limit ds e_prev (1 - x / 2) at small x
            small = ops.abs(x) < f(1e-3)
            safe = ops.select(small, f(1.0), x)
            totals[i] = totals[i] + ds * ops.select(small, e_prev[i] * (f(1.0) - f(0.5) * x), (e_prev[i] - e_k) / safe)
            e_prev[i] = e_k
        s_prev, h_prev = s_k, h_k
    return totals


def air_mass(altitude_m: float, sin_elevation: NDArray, distance_m: NDArray, scale_height_m: float,
             **kw) -> NDArray[np.float64]:
    """:func:`air_masses` of one scale height, numpy."""
    return _air_masses_numpy(altitude_m, sin_elevation, distance_m, (scale_height_m,), **kw)[0]


def _air_masses_numpy(altitude_m: float, sin_elevation: NDArray, distance_m: NDArray, scale_heights_m,
                      **kw) -> list[NDArray[np.float64]]:
    """:func:`air_masses` in float64 numpy, the arrays broadcast together."""
    s = np.asarray(distance_m, dtype=np.float64)
    mu = np.broadcast_to(np.asarray(sin_elevation, dtype=np.float64), np.broadcast(s, sin_elevation).shape)
    return air_masses(float(altitude_m), mu, np.broadcast_to(s, mu.shape),
                      tuple(float(h) for h in scale_heights_m), **kw)


def column_distance(altitude_m: float, sin_elevation: NDArray) -> NDArray[np.float64]:
    """How far a ray leaving ``altitude_m`` at ``asin(sin_elevation)`` travels to the top
    of the air (:data:`AIR_TOP_M`)."""
    r0 = EARTH_RADIUS_M + float(altitude_m)
    mu = np.asarray(sin_elevation, dtype=np.float64)
    top = EARTH_RADIUS_M + AIR_TOP_M
    return -r0 * mu + np.sqrt(np.maximum(r0 * r0 * mu * mu + top * top - r0 * r0, 0.0))


def airlight_directions(directions: NDArray, sun: NDArray, sun_aperture_deg: float) -> NDArray[np.float64]:
    """Where each direction's airlight is looked up in the sky: at least
    :data:`HORIZON_ELEVATION_DEG` above the horizon (the same azimuth; +x straight down)
    and outside the
    sun's disc and its rim (pushed along the great circle from the sun to twice the
    disc's radius), unit vectors (world frame, z up)."""
    d = np.asarray(directions, dtype=np.float64)
    d = d / np.linalg.norm(d, axis=-1, keepdims=True)
    low = np.sin(np.radians(HORIZON_ELEVATION_DEG))
    horizontal = np.hypot(d[..., 0], d[..., 1])
    level = horizontal > 1e-9  # straight down looks up the sky along +x
    x, y = np.where(level, d[..., 0], 1.0), np.where(level, d[..., 1], 0.0)
    scale = np.sqrt(1.0 - low * low) / np.where(level, horizontal, 1.0)
    lifted = np.stack([x * scale, y * scale, np.full(d.shape[:-1], low)], axis=-1)
    d = np.where((d[..., 2] < low)[..., None], lifted, d)
    sun = np.asarray(sun, dtype=np.float64) / np.linalg.norm(sun)
    rim = np.radians(sun_aperture_deg)  # twice the disc's radius
    cos = d @ sun
    inside = cos > np.cos(rim)
    if inside.any():
        away = d[inside] - cos[inside, None] * sun
        norm = np.linalg.norm(away, axis=-1, keepdims=True)
        helper = np.array([1.0, 0.0, 0.0]) if abs(sun[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
        fallback = np.cross(sun, helper)
        away = np.where(norm > 1e-12, away / np.maximum(norm, 1e-12), fallback / np.linalg.norm(fallback))
        d[inside] = np.cos(rim) * sun + np.sin(rim) * away
    return d


class Atmosphere:
    """The air of one frame: the camera's altitude, the visibility and the aerosol's scale
    height drawn for the approach."""

    def __init__(self, camera_altitude_m: float, visibility_m: float, aerosol_scale_height_m: float) -> None:
        self.altitude_m = float(camera_altitude_m)
        self.rayleigh, self.aerosol = extinction_at_sea_level(visibility_m)
        self.aerosol_scale_height_m = float(aerosol_scale_height_m)

    def optical_depth(self, sin_elevation: NDArray, distance_m: NDArray, **kw) -> NDArray[np.float64]:
        """(..., 3) optical depth per RGB channel of the paths (numpy)."""
        return self.depth_of(*_air_masses_numpy(self.altitude_m, sin_elevation, distance_m,
                                                (RAYLEIGH_SCALE_HEIGHT_M, self.aerosol_scale_height_m), **kw))

    def depth_of(self, rayleigh_mass: NDArray, aerosol_mass: NDArray) -> NDArray:
        """(..., 3) optical depth of paths of the given air masses (:func:`air_masses`)."""
        return np.asarray(rayleigh_mass)[..., None] * self.rayleigh + np.asarray(aerosol_mass)[..., None] * self.aerosol

    def column_transmittance(self, sin_elevation: NDArray) -> NDArray[np.float64]:
        """(..., 3) transmittance of the air column the sky's radiance in a direction comes
        through: from sea level (where ``sunsky``'s observer stands) to the top of the air,
        directions below the horizon taken at :data:`HORIZON_ELEVATION_DEG` (as their
        airlight is)."""
        mu = np.maximum(np.asarray(sin_elevation, dtype=np.float64), np.sin(np.radians(HORIZON_ELEVATION_DEG)))
        ground = copy.copy(self)
        ground.altitude_m = 0.0
        tau = ground.optical_depth(mu, column_distance(0.0, mu), segments=64, spacing=2.0)
        return np.exp(-tau)

    def seen_through(self, rgb, airlight, column_transmittance, sin_elevation, distances, weights=None) -> list:
        """The three channels of surfaces' radiance ``rgb`` (three arrays) as the camera
        sees them through the air along rays of ``sin_elevation`` (:func:`through_air`),
        given each ray's airlight (the sky's radiance in its direction) and the
        transmittance of the column it comes through (three arrays each), numpy.

        ``distances``: the paths a pixel shows (0: the sky, left as it is), one array each,
        averaged with ``weights`` (arrays summing to 1; one path: none): a cloud's edge
        shows the cloud and what lies behind it, by its opacity."""
        weights = weights if weights is not None else [1.0]
        depths = [self.optical_depth(sin_elevation, d) for d in distances]
        return [sum(w * through_air(rgb[c], airlight[c], column_transmittance[c], np.exp(-tau[..., c]))
                    for tau, w in zip(depths, weights, strict=True)) for c in range(3)]


def table_coordinates(sin_elevation, distance_m, ops: Ops = NUMPY):
    """Continuous (row, column) of paths in the :func:`transmittance_table`, clamped to it."""
    f = ops.f32
    warped = ops.select(sin_elevation < f(0.0), -ops.sqrt(ops.clip(-sin_elevation, 0.0, 1.0)),
                        ops.sqrt(ops.clip(sin_elevation, 0.0, 1.0)))
    row = (warped + f(1.0)) * f(0.5 * (TABLE_MU - 1))
    lo, hi = np.log(TABLE_S_M[0]), np.log(TABLE_S_M[1])
    log_s = ops.log(ops.clip(distance_m, TABLE_S_M[0], TABLE_S_M[1]))
    column = (log_s - f(lo)) * f((TABLE_S - 1) / (hi - lo))
    return ops.clip(row, 0.0, TABLE_MU - 1.0), ops.clip(column, 0.0, TABLE_S - 1.0)


def table_paths() -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The (TABLE_MU, TABLE_S) elevations (sines) and distances of the
    :func:`transmittance_table`'s entries."""
    warped = np.linspace(-1.0, 1.0, TABLE_MU)
    s = np.exp(np.linspace(np.log(TABLE_S_M[0]), np.log(TABLE_S_M[1]), TABLE_S))
    return np.meshgrid(np.sign(warped) * warped * warped, s, indexing="ij")


def transmittance_table(air: Atmosphere, ops: Ops = NUMPY, paths=None):
    """(TABLE_MU, TABLE_S, 3) transmittance of the paths from the camera of ``air`` at the
    table's elevations and distances (:func:`table_paths`), which a render interpolates
    bilinearly in its coordinates (:func:`table_coordinates`). With ``ops``, of Dr.Jit's
    ``paths`` (the table's, flat), as three flat arrays."""
    if ops is NUMPY:
        mu, s = table_paths()
        return np.exp(-air.optical_depth(mu, s)).astype(np.float32)
    p = ops.param_f32
    mu, s = paths
    rayleigh_mass, aerosol_mass = air_masses(p(air.altitude_m), mu, s,
                                             (RAYLEIGH_SCALE_HEIGHT_M, p(air.aerosol_scale_height_m)), ops=ops)
    return [ops.exp(-(rayleigh_mass * ops.f32(air.rayleigh[c]) + aerosol_mass * p(air.aerosol[c])))
            for c in range(3)]


def through_air(radiance, airlight, column_transmittance, transmittance, ops: Ops = NUMPY):
    """One channel of a surface's ``radiance`` seen along a path of ``transmittance``, whose
    direction's airlight (the sky's radiance there) comes through a column of
    ``column_transmittance``: ``L0 T + A min(1, (1 - T) / (1 - T_ref))``."""
    f = ops.f32
    room = ops.clip(f(1.0) - column_transmittance, 1e-12, 1.0)
    return radiance * transmittance + airlight * ops.clip((f(1.0) - transmittance) / room, 0.0, 1.0)


def dip_rad(altitude_m: float) -> float:
    """How far the sea's horizon lies below the horizontal seen from ``altitude_m``:
    ``arccos(R / (R + h))``."""
    return float(np.arccos(EARTH_RADIUS_M / (EARTH_RADIUS_M + float(altitude_m))))
