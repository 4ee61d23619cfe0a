"""The pieces of one approach that the chains of :mod:`datagen.scene.chains` step through:
the receiver's random start (paper 3.1), the drogue's turbulence, the tanker's flight and the
camera mount's perturbation (pure numpy)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from datagen.config.schema import Config, MountJitterConfig
from datagen.core.conventions import GRAVITY_MPS2
from datagen.core.transforms import make_transform, rotation_from_ypr

__all__ = ["TURBULENCE_WARMUP_S", "ApproachStart", "DrogueTurbulence", "TankerFlight", "draw_start",
           "mount_jitter", "start_offset"]

FloatArray = NDArray[np.float64]


#: Turbulence runs this long before an approach starts, so the drogue starts in its stationary motion.
TURBULENCE_WARMUP_S = 10.0


@dataclass(frozen=True)
class ApproachStart:
    """The random initial conditions of one approach (tanker frame)."""

    distance_m: float
    azimuth_rad: float
    elevation_rad: float
    yaw_rad: float
    pitch_rad: float
    roll_rad: float


def draw_start(config: Config, rng: np.random.Generator, distance_m: float) -> ApproachStart:
    """Initial receiver placement and attitude perturbation (paper 3.1)."""
    a = config.approach
    el_lo, el_hi = a.start_elevation_deg
    return ApproachStart(
        distance_m=distance_m,
        azimuth_rad=math.radians(rng.uniform(-a.start_azimuth_deg, a.start_azimuth_deg)),
        elevation_rad=math.radians(rng.uniform(el_lo, el_hi)),
        yaw_rad=math.radians(rng.uniform(-a.yaw_deg, a.yaw_deg)),
        pitch_rad=math.radians(rng.uniform(-a.pitch_deg, a.pitch_deg)),
        roll_rad=math.radians(rng.uniform(-a.roll_deg, a.roll_deg)),
    )


def start_offset(start: ApproachStart) -> FloatArray:
    """Probe tip minus drogue centre at the start, tanker frame: behind, off to the side, below."""
    ce = math.cos(start.elevation_rad)
    direction = np.array([-ce * math.cos(start.azimuth_rad), ce * math.sin(start.azimuth_rad),
                          math.sin(start.elevation_rad)])
    return start.distance_m * direction


class DrogueTurbulence:
    """Dryden-filtered gusts (first-order Gauss-Markov per axis) driving a damped
    second-order drogue response; displacement in the tanker frame."""

    def __init__(self, config: Config, rng: np.random.Generator, dt: float, normals=None, *, warmup: bool = True):
        d = config.drogue
        self.rng = rng
        # Each step's three standard normals: from ``rng`` (model 1) or ``normals()``.
        self._normals = normals or (lambda: rng.standard_normal(3))
        self.intensity = float(rng.uniform(*d.intensity))
        self.sigma = np.asarray(d.rms_m) * self.intensity
        self.decay = math.exp(-dt / d.gust_time_s)
        self.kick = math.sqrt(1.0 - self.decay**2)
        self.omega = 2.0 * math.pi * d.natural_hz
        self.zeta = d.damping
        self.dt = dt
        self.gust = self.sigma * rng.standard_normal(3)
        self.position = self.gust.copy()
        self.velocity = np.zeros(3)
        self.warmup_steps = round(TURBULENCE_WARMUP_S / dt)
        for _ in range(self.warmup_steps if warmup else 0):
            self.step()

    def step(self) -> None:
        self.gust = self.gust * self.decay + self.sigma * self.kick * np.asarray(self._normals())
        accel = self.omega**2 * (self.gust - self.position) - 2.0 * self.zeta * self.omega * self.velocity
        self.velocity = self.velocity + self.dt * accel  # semi-implicit Euler: stable for omega*dt < 2
        self.position = self.position + self.dt * self.velocity


class TankerFlight:
    """World pose of the tanker over time: straight and level, or a coordinated turn."""

    def __init__(self, config: Config, rng: np.random.Generator):
        t = config.tanker
        self.speed = t.speed_mps
        self.altitude = float(rng.uniform(*t.altitude_m))
        self.heading0 = float(rng.uniform(0.0, 2.0 * math.pi))
        turning = bool(rng.random() < t.turn_probability)
        bank = math.radians(rng.uniform(*t.bank_deg)) * (1.0 if rng.random() < 0.5 else -1.0)
        self.bank = bank if turning else 0.0
        # Positive bank is right wing down: a right turn, heading (counter-clockwise) decreasing.
        self.rate = -GRAVITY_MPS2 * math.tan(self.bank) / self.speed

    def world_from_tanker(self, time_s: float) -> FloatArray:
        heading = self.heading0 + self.rate * time_s
        if abs(self.rate) < 1e-12:
            pos = [self.speed * time_s * math.cos(heading), self.speed * time_s * math.sin(heading)]
        else:
            r = self.speed / self.rate
            pos = [r * (math.sin(heading) - math.sin(self.heading0)),
                   -r * (math.cos(heading) - math.cos(self.heading0))]
        return make_transform(rotation_from_ypr(heading, 0.0, self.bank), [pos[0], pos[1], self.altitude])


def mount_jitter(jitter: MountJitterConfig, rng: np.random.Generator) -> tuple[FloatArray, FloatArray]:
    """One approach's mount perturbation: a translation ``(3,)`` in the body frame and a
    rotation ``(3, 3)`` about the camera's own axes, each within ``jitter``'s bounds."""
    j = jitter
    shift = rng.uniform(-j.translation_m, j.translation_m, size=3)
    ypr = np.radians(rng.uniform(-j.rotation_deg, j.rotation_deg, size=3))
    return shift, rotation_from_ypr(*ypr)
