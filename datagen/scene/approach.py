"""Monte Carlo refueling approaches (paper 3.1): pure numpy, no rendering.

The local frame of the paper's Fig. 7 (centred on the *average* drogue
position, axes along tanker forward, left, up) is exactly the tanker body frame
of :mod:`datagen.core.conventions`, so the simulation runs in the tanker frame and
places the tanker in the world afterwards.

One approach:

1. the receiver's probe tip starts at a random bearing behind (and mostly
   below) the drogue, at the range's far end ('distance' sampling) or at a
   uniform distance in range ('time' sampling); its attitude is the tanker's,
   perturbed uniformly within +-yaw, +-pitch, +-roll;
2. every step it follows the true probe-to-drogue (PtD) vector expressed in its
   own frame: the PtD components shrink at ``forward_gain`` along receiver x
   and ``lateral_gain_ratio`` times faster along y and z (speed-limited), on top
   of the drogue's own motion, which the receiver matches (so that contact can
   happen while the drogue moves); its attitude slerps back to the tanker's
   with time constant ``attitude_time_constant_s``;
3. contact is a PtD distance below ``contact_m`` (1 cm); 'time' sampling then
   starts a new approach, as the paper's simulation did.

The drogue moves about its average position under turbulence (see
:class:`datagen.config.schema.DrogueConfig`); the hose runs from the tanker's port to
the drogue as a cubic Hermite curve; the tanker flies straight and level or in
a coordinated banking turn. The camera sits on its mount with a per-approach
pose perturbation: extrinsics are unknown and change in flight.

Frames are grouped ``frames_per_approach`` at a time: frames
``[a*K, (a+1)*K)`` come from approach chain ``a``, whose every draw comes from
:func:`datagen.core.conventions.approach_rng` ``(seed, a)``. A frame's state is thus
a pure function of (config, seed, frame index), and any frame can be
regenerated alone on any worker.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from datagen.assets.rig import HOSE_ATTACH_DROGUE_M, HOSE_PORT_TANKER_M, MOUNTS
from datagen.config.schema import Config
from datagen.core.conventions import GRAVITY_MPS2, approach_rng, gust_rng
from datagen.core.transforms import (
    invert_rigid,
    make_transform,
    rotation_from_rotvec,
    rotation_from_ypr,
    rotvec_from_rotation,
)

__all__ = [
    "ApproachStart",
    "DrogueTurbulence",
    "FrameState",
    "FrameStates",
    "TankerFlight",
    "frame_state",
    "frame_states",
    "hose_curve",
    "simulate_chain",
    "trace_approach",
]

#: Turbulence runs this long before an approach starts, so the drogue starts in its stationary motion.
TURBULENCE_WARMUP_S = 10.0
#: How much earlier :attr:`FrameState.earlier` is, seconds (image motion by finite differences).
MOTION_DT_S = 1.0e-3
#: Points along the hose polyline.
HOSE_POINTS = 48

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class ApproachStart:
    """The random initial conditions of one approach (tanker frame)."""

    distance_m: float
    azimuth_rad: float
    elevation_rad: float
    yaw_rad: float
    pitch_rad: float
    roll_rad: float


@dataclass(frozen=True, eq=False)
class FrameState:
    """Everything about one frame's geometry. All poses are 4x4 ``world_from_x``;
    the camera frame is OpenCV's."""

    frame_index: int
    approach_index: int  # the approach chain (frames_per_approach frames)
    approach_number: int  # 0 for the chain's first approach, +1 after each contact ('time' sampling)
    time_s: float  # since the chain started
    world_from_tanker: FloatArray
    world_from_receiver: FloatArray
    world_from_drogue: FloatArray
    world_from_cam: FloatArray
    hose_points_world: FloatArray  # (HOSE_POINTS, 3) from the port to the drogue coupling
    ptd_receiver_m: FloatArray  # drogue centre in the receiver frame (probe tip -> drogue)
    distance_m: float
    mount: str
    turbulence_intensity: float
    bank_deg: float
    #: Makes :attr:`earlier` when it is first asked for (only motion blur does); None: no earlier state.
    earlier_from: Callable[[], FrameState] | None = field(default=None, repr=False)

    @functools.cached_property
    def earlier(self) -> FrameState | None:
        """This state MOTION_DT_S earlier (relative motion: motion blur), made on first use."""
        return None if self.earlier_from is None else self.earlier_from()

    @property
    def cam_from_world(self) -> FloatArray:
        return invert_rigid(self.world_from_cam)

    def world_from(self, name: str) -> FloatArray:
        return {"tanker": self.world_from_tanker, "receiver": self.world_from_receiver,
                "drogue": self.world_from_drogue}[name]


# --- pieces ----------------------------------------------------------------------
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


def tanker_drogue_rotation(drogue_offset: FloatArray) -> FloatArray:
    """Attitude of the drogue in the tanker frame: the hose tension turns it toward its average
    position, by the displacement's angle seen from the port."""
    reach = float(np.hypot(HOSE_PORT_TANKER_M[0], HOSE_PORT_TANKER_M[1])) or 1.0
    yaw = math.atan2(-drogue_offset[1], reach)
    pitch = math.atan2(drogue_offset[2], reach)
    return rotation_from_ypr(yaw, pitch, 0.0)


def hose_curve(tanker_from_drogue: FloatArray, n: int = HOSE_POINTS) -> FloatArray:
    """Hose centreline ``(n, 3)`` in the tanker frame, from the port to the drogue coupling.

    A cubic Hermite curve: it leaves the port heading aft and 35 degrees down, and meets
    the coupling along the drogue's axis (drag straightens the hose near the drogue).
    """
    p0 = HOSE_PORT_TANKER_M
    p1 = tanker_from_drogue[:3, :3] @ HOSE_ATTACH_DROGUE_M + tanker_from_drogue[:3, 3]
    chord = float(np.linalg.norm(p1 - p0))
    t0 = chord * np.array([-math.cos(math.radians(35.0)), 0.0, -math.sin(math.radians(35.0))])
    t1 = -chord * tanker_from_drogue[:3, 0]
    s = np.linspace(0.0, 1.0, n)[:, None]
    h00, h10 = 2 * s**3 - 3 * s**2 + 1, s**3 - 2 * s**2 + s
    h01, h11 = -2 * s**3 + 3 * s**2, s**3 - s**2
    return h00 * p0 + h10 * t0 + h01 * p1 + h11 * t1


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


def _mount_jitter(config: Config, rng: np.random.Generator) -> tuple[FloatArray, FloatArray]:
    """One approach's mount perturbation: a translation ``(3,)`` in the body frame and a
    rotation ``(3, 3)`` about the camera's own axes, each within the configured bounds."""
    j = config.camera.mount_jitter
    shift = rng.uniform(-j.translation_m, j.translation_m, size=3)
    ypr = np.radians(rng.uniform(-j.rotation_deg, j.rotation_deg, size=3))
    return shift, rotation_from_ypr(*ypr)


# --- the simulation ---------------------------------------------------------------
@dataclass
class _Snapshot:
    approach_number: int
    time_s: float
    probe_tanker: FloatArray
    attitude_rotvec: FloatArray
    drogue_offset: FloatArray
    body_from_cam: FloatArray
    tanker: TankerFlight
    intensity: float
    # Rates at this instant (tanker frame), for the state MOTION_DT_S earlier (motion blur).
    probe_velocity: FloatArray = field(default_factory=lambda: np.zeros(3))
    rotvec_rate: FloatArray = field(default_factory=lambda: np.zeros(3))
    drogue_velocity: FloatArray = field(default_factory=lambda: np.zeros(3))

    def earlier(self, dt: float) -> _Snapshot:
        """This snapshot ``dt`` seconds earlier, moved back along its rates (the chain's
        motion is smooth on that scale: the simulation step is 1/30 s)."""
        return dataclasses.replace(
            self, time_s=self.time_s - dt, probe_tanker=self.probe_tanker - dt * self.probe_velocity,
            attitude_rotvec=self.attitude_rotvec - dt * self.rotvec_rate,
            drogue_offset=self.drogue_offset - dt * self.drogue_velocity)


class _Chain:
    """One approach chain: the tanker, the turbulence, and a receiver that flies
    approach after approach; every draw from one RNG, in a fixed order."""

    def __init__(self, config: Config, rng: np.random.Generator):
        a = config.approach
        self.config = config
        self.rng = rng
        self.dt = a.dt_s
        self.tanker = TankerFlight(config, rng)
        self.turbulence = self._turbulence()
        self.gains = a.forward_gain * np.array([1.0, a.lateral_gain_ratio, a.lateral_gain_ratio])
        self.limits = np.array([a.max_closure_mps, a.max_lateral_mps, a.max_lateral_mps])
        self.attitude_decay = math.exp(-self.dt / a.attitude_time_constant_s)
        self.time_s = 0.0
        self.approach_number = -1
        self.steps_this_approach = 0

    def _turbulence(self) -> DrogueTurbulence:
        return DrogueTurbulence(self.config, self.rng, self.dt)

    def _sync(self) -> None:
        """Bring the arrays (probe, rotvec, turbulence) up to date (a subclass may step in floats)."""

    def new_approach(self, distance_m: float) -> None:
        self.approach_number += 1
        self.steps_this_approach = 0
        start = draw_start(self.config, self.rng, distance_m)
        self.probe = self.turbulence.position + start_offset(start)
        self.rotvec = rotvec_from_rotation(rotation_from_ypr(start.yaw_rad, start.pitch_rad, start.roll_rad))
        shift, rot = _mount_jitter(self.config, self.rng)
        nominal = MOUNTS[self.config.camera.mount].body_from_cam()
        self.body_from_cam = make_transform(np.eye(3), shift) @ nominal @ make_transform(rot, np.zeros(3))

    @property
    def ptd_tanker(self) -> FloatArray:
        return self.turbulence.position - self.probe

    @property
    def distance(self) -> float:
        return float(np.linalg.norm(self.ptd_tanker))

    def step(self) -> None:
        if self.steps_this_approach >= self.config.approach.max_steps:
            raise RuntimeError(
                f"an approach did not reach contact in {self.config.approach.max_steps} steps "
                f"(distance {self.distance:.3f} m): check the approach gains and speed limits"
            )
        drogue_before = self.turbulence.position
        self.turbulence.step()
        rotation = rotation_from_rotvec(self.rotvec)
        ptd_receiver = rotation.T @ (drogue_before - self.probe)
        velocity_receiver = np.clip(self.gains * ptd_receiver, -self.limits, self.limits)
        # Match the drogue's own motion, then close on it along the receiver's axes.
        self.probe = self.probe + (self.turbulence.position - drogue_before) + self.dt * (
            rotation @ velocity_receiver)
        self.rotvec = self.rotvec * self.attitude_decay  # slerp toward the tanker's attitude
        self.time_s += self.dt
        self.steps_this_approach += 1

    def snap(self) -> _Snapshot:
        rotation = rotation_from_rotvec(self.rotvec)
        ptd_receiver = rotation.T @ (self.turbulence.position - self.probe)
        closing = rotation @ np.clip(self.gains * ptd_receiver, -self.limits, self.limits)
        return _Snapshot(self.approach_number, self.time_s, self.probe.copy(), self.rotvec.copy(),
                         self.turbulence.position.copy(), self.body_from_cam, self.tanker,
                         self.turbulence.intensity,
                         probe_velocity=self.turbulence.velocity + closing,
                         rotvec_rate=self.rotvec * (self.attitude_decay - 1.0) / self.dt,
                         drogue_velocity=self.turbulence.velocity.copy())


#: Rows of gust normals approach model 2 draws at a time.
GUST_BLOCK = 1024


def _rotation_rows(rx: float, ry: float, rz: float) -> tuple[float, ...]:
    """Row-major ``(3, 3)`` rotation of a rotation vector in plain floats (Rodrigues)."""
    angle = math.sqrt(rx * rx + ry * ry + rz * rz)
    if angle < 1e-12:
        return (1.0, -rz, ry, rz, 1.0, -rx, -ry, rx, 1.0)
    x, y, z = rx / angle, ry / angle, rz / angle
    s, c = math.sin(angle), 1.0 - math.cos(angle)
    return (1.0 - c * (y * y + z * z), -s * z + c * x * y, s * y + c * x * z,
            s * z + c * x * y, 1.0 - c * (x * x + z * z), -s * x + c * y * z,
            -s * y + c * x * z, s * x + c * y * z, 1.0 - c * (x * x + y * y))


class _FastChain(_Chain):
    """Approach model 2: :class:`_Chain`'s dynamics with the drogue's gusts drawn in blocks
    of :data:`GUST_BLOCK` from a stream of their own (:func:`gust_rng`), and each step in
    plain floats instead of 3-vectors (numpy's per-call cost dominated model 1)."""

    def __init__(self, config: Config, rng: np.random.Generator, gusts: np.random.Generator, *, warm: bool = True):
        self._gusts = gusts
        self._normals: list[list[float]] = []
        super().__init__(config, rng)
        t = self.turbulence
        self._sigma_kick = [float(v) * t.kick for v in t.sigma]
        self._gust = [float(v) for v in t.gust]
        self._position = [float(v) for v in t.position]
        self._velocity = [float(v) for v in t.velocity]
        self._gains = [float(v) for v in self.gains]
        self._limits = [float(v) for v in self.limits]
        for _ in range(t.warmup_steps if warm else 0):  # else the caller warms it up (simulate_chains)
            self._gust_step()

    def _gust_step(self) -> None:
        """One step of the drogue's turbulence (:meth:`DrogueTurbulence.step` in floats)."""
        t, dt = self.turbulence, self.dt
        n = self._normal()
        gust = [g * t.decay + k * e for g, k, e in zip(self._gust, self._sigma_kick, n, strict=True)]
        w2, damp = t.omega * t.omega, 2.0 * t.zeta * t.omega
        velocity = [v + dt * (w2 * (g - p) - damp * v)
                    for g, p, v in zip(gust, self._position, self._velocity, strict=True)]
        self._position = [p + dt * v for p, v in zip(self._position, velocity, strict=True)]
        self._gust, self._velocity = gust, velocity

    def _turbulence(self) -> DrogueTurbulence:
        return DrogueTurbulence(self.config, self.rng, self.dt, normals=self._normal, warmup=False)

    def _normal(self) -> list[float]:
        if not self._normals:
            self._normals = self._gusts.standard_normal((GUST_BLOCK, 3)).tolist()[::-1]
        return self._normals.pop()

    def new_approach(self, distance_m: float) -> None:
        self._sync()
        super().new_approach(distance_m)
        self._probe = [float(v) for v in self.probe]
        self._rotvec = [float(v) for v in self.rotvec]

    def _sync(self) -> None:
        """The float state back into the arrays :meth:`snap` and :meth:`new_approach` read."""
        t = self.turbulence
        t.gust, t.position, t.velocity = np.array(self._gust), np.array(self._position), np.array(self._velocity)
        if hasattr(self, "_probe"):  # after the chain's first approach began
            self.probe, self.rotvec = np.array(self._probe), np.array(self._rotvec)

    @property
    def distance(self) -> float:
        p, q = self._position, self._probe
        return math.sqrt((p[0] - q[0]) ** 2 + (p[1] - q[1]) ** 2 + (p[2] - q[2]) ** 2)

    def step(self) -> None:
        if self.steps_this_approach >= self.config.approach.max_steps:
            super().step()  # raises, naming the distance
        dt = self.dt
        before = self._position
        self._gust_step()
        position = self._position
        r = _rotation_rows(*self._rotvec)
        e = [b - q for b, q in zip(before, self._probe, strict=True)]
        ptd = (r[0] * e[0] + r[3] * e[1] + r[6] * e[2], r[1] * e[0] + r[4] * e[1] + r[7] * e[2],
               r[2] * e[0] + r[5] * e[1] + r[8] * e[2])  # rotation.T @ e
        v = [min(max(g * x, -lim), lim) for g, x, lim in zip(self._gains, ptd, self._limits, strict=True)]
        closing = (r[0] * v[0] + r[1] * v[1] + r[2] * v[2], r[3] * v[0] + r[4] * v[1] + r[5] * v[2],
                   r[6] * v[0] + r[7] * v[1] + r[8] * v[2])
        self._probe = [q + (p - b) + dt * c for q, p, b, c in zip(self._probe, position, before, closing, strict=True)]
        decay = self.attitude_decay
        self._rotvec = [x * decay for x in self._rotvec]
        self.time_s += dt
        self.steps_this_approach += 1

    def snap(self) -> _Snapshot:
        self._sync()
        return super().snap()


def _start_chain(config: Config, seed: int, approach_index: int) -> tuple[_Chain, FloatArray | None]:
    """Chain ``approach_index`` with its first approach begun, and for 'distance' sampling
    its distance targets (far to near). The one place that fixes the order of the chain's
    first draws, so that a traced approach is the one its frames come from."""
    rng = approach_rng(seed, approach_index)
    chain = (_Chain(config, rng) if config.approach.model == 1
             else _FastChain(config, rng, gust_rng(seed, approach_index)))
    return chain, _begin_chain(chain)


def _begin_chain(chain: _Chain) -> FloatArray | None:
    """Begin a new chain's first approach (:func:`_start_chain`); its distance targets or None."""
    a = chain.config.approach
    k = a.frames_per_approach
    lo, hi = a.range_m
    if a.sampling == "distance":
        # One frame per distance stratum, visited from far to near, on one approach.
        targets = np.sort(lo + (np.arange(k) + chain.rng.random(k)) * (hi - lo) / k)[::-1]
        chain.new_approach(hi)
        return targets
    chain.new_approach(float(chain.rng.uniform(lo, hi)))
    return None


def simulate_chain(config: Config, seed: int, approach_index: int) -> list[_Snapshot]:
    """Simulate approach chain ``approach_index``; return its ``frames_per_approach`` snapshots."""
    a = config.approach
    k = a.frames_per_approach
    chain, targets = _start_chain(config, seed, approach_index)
    snapshots: list[_Snapshot] = []
    if targets is not None:
        while True:
            distance = chain.distance
            contact = distance < a.contact_m
            while len(snapshots) < k and (contact or targets[len(snapshots)] >= distance):
                snapshots.append(chain.snap())
            if len(snapshots) == k:
                return snapshots
            chain.step()
    # 'time': a frame every stride_steps steps, through contact and the next approaches.
    step = 0
    while True:
        if step % a.stride_steps == 0:
            snapshots.append(chain.snap())
            if len(snapshots) == k:
                return snapshots
        if chain.distance < a.contact_m:
            chain.new_approach(float(chain.rng.uniform(*a.range_m)))
        chain.step()
        step += 1


def simulate_chains(config: Config, seed: int, approach_indices,
                    upto: dict[int, int] | None = None) -> dict[int, list[_Snapshot]]:
    """:func:`simulate_chain` of many chains. With approach model 2 they step together,
    each step one numpy operation over every chain instead of one Python step per chain:
    the same arithmetic in the same order, element by element (sines and cosines per
    chain, through :mod:`math`), so each chain's snapshots are bit for bit those it has
    alone, whichever chains it is simulated with.

    ``upto``: per chain, how many of its first snapshots are wanted; a chain stops once it
    has them (model 2; the rest are not simulated), others run to their last frame."""
    indices = list(dict.fromkeys(int(i) for i in approach_indices))
    a = config.approach
    if a.model == 1 or len(indices) < 2:
        return {i: simulate_chain(config, seed, i) for i in indices}
    k = a.frames_per_approach
    wanted = np.array([min(max(int((upto or {}).get(i, k)), 1), k) for i in indices])
    chains = [_FastChain(config, approach_rng(seed, i), gust_rng(seed, i), warm=False) for i in indices]
    snapshots: list[list[_Snapshot]] = [[] for _ in indices]
    first = chains[0]
    t = first.turbulence
    dt, decay, w2, damp = first.dt, t.decay, t.omega * t.omega, 2.0 * t.zeta * t.omega
    attitude_decay = first.attitude_decay
    gains, limits = np.array(first._gains), np.array(first._limits)
    # Each chain's gusts, a block at a time, as _FastChain._normal draws them.
    normals = np.array([ch._gusts.standard_normal((GUST_BLOCK, 3)) for ch in chains])
    used = 0

    def gusts(state: dict[str, FloatArray], rows: NDArray[np.int64]) -> FloatArray:
        """One step of the turbulence of ``rows``' chains (_FastChain._gust_step); the
        drogue positions before it."""
        nonlocal normals, used
        if used == normals.shape[1]:
            block = np.zeros((len(chains), GUST_BLOCK, 3))
            for c in rows.tolist():
                block[c] = chains[c]._gusts.standard_normal((GUST_BLOCK, 3))
            normals, used = block, 0
        before = state["_position"]
        gust = state["_gust"] * decay + state["_sigma_kick"] * normals[rows, used]
        used += 1
        velocity = state["_velocity"] + dt * (w2 * (gust - before) - damp * state["_velocity"])
        state["_gust"], state["_velocity"], state["_position"] = gust, velocity, before + dt * velocity
        return before

    # The warm-up of every chain together, then each chain's first approach in its own terms.
    active = list(range(len(chains)))
    warm = {name: np.array([getattr(ch, name) for ch in chains]) for name in ("_gust", "_position", "_velocity",
                                                                            "_sigma_kick")}
    for _ in range(t.warmup_steps):
        gusts(warm, np.array(active))
    for row, ch in enumerate(chains):
        ch._gust, ch._position, ch._velocity = (warm[name][row].tolist() for name in ("_gust", "_position",
                                                                                     "_velocity"))
    targets = [_begin_chain(ch) for ch in chains]

    def load() -> dict[str, FloatArray]:
        rows = [chains[c] for c in active]
        return {name: np.array([getattr(ch, name) for ch in rows]).reshape(len(rows), -1)
                for name in ("_gust", "_position", "_velocity", "_probe", "_rotvec", "_sigma_kick")} | {
            "time_s": np.array([ch.time_s for ch in rows])}

    def store(state: dict[str, FloatArray], rows) -> None:
        """The state of ``rows`` (of ``active``) into their chains, which snap and begin approaches."""
        for row in rows:
            ch = chains[active[row]]
            for name in ("_gust", "_position", "_velocity", "_probe", "_rotvec"):
                setattr(ch, name, state[name][row].tolist())
            ch.time_s = float(state["time_s"][row])
            ch.steps_this_approach = int(steps[active[row]])

    inf = math.inf
    next_target = np.array([tg[0] if tg is not None else inf for tg in targets])
    steps = np.array([ch.steps_this_approach for ch in chains])
    state = load()
    step = 0
    while active:
        rows = np.array(active)
        q = state["_probe"]
        p = state["_position"]
        distance = np.sqrt((p[:, 0] - q[:, 0]) ** 2 + (p[:, 1] - q[:, 1]) ** 2 + (p[:, 2] - q[:, 2]) ** 2)
        contact = distance < a.contact_m
        if a.sampling == "distance":
            due = np.flatnonzero(contact | (next_target[rows] >= distance)).tolist()
        else:
            due = list(range(len(active))) if step % a.stride_steps == 0 else np.flatnonzero(contact).tolist()
        if due:  # a snapshot, a new approach or a chain done: in each chain's own terms
            store(state, due)
            for row in due:
                c = active[row]
                chain = chains[c]
                if a.sampling == "distance":
                    while len(snapshots[c]) < k and (contact[row] or targets[c][len(snapshots[c])] >= distance[row]):
                        snapshots[c].append(chain.snap())
                    next_target[c] = targets[c][len(snapshots[c])] if len(snapshots[c]) < k else inf
                else:
                    if step % a.stride_steps == 0:
                        snapshots[c].append(chain.snap())
                    if len(snapshots[c]) < k and contact[row]:
                        chain.new_approach(float(chain.rng.uniform(*a.range_m)))
                        steps[c] = chain.steps_this_approach
                        state["_probe"][row], state["_rotvec"][row] = chain._probe, chain._rotvec
            keep = [row for row, c in enumerate(active) if len(snapshots[c]) < wanted[c]]
            if not keep:
                break
            if len(keep) < len(active):
                state = {name: values[keep] for name, values in state.items()}
                active = [active[row] for row in keep]
                rows = np.array(active)
        if (steps[rows] >= a.max_steps).any():
            store(state, range(len(active)))
            for c in active:
                chains[c].step()  # raises for the chain that did not reach contact
        # One step of every active chain: _FastChain.step, element by element.
        before = gusts(state, rows)
        position = state["_position"]
        r = _rotation_batch(state["_rotvec"])
        e = before - state["_probe"]
        ptd = np.stack([r[:, 0] * e[:, 0] + r[:, 3] * e[:, 1] + r[:, 6] * e[:, 2],
                        r[:, 1] * e[:, 0] + r[:, 4] * e[:, 1] + r[:, 7] * e[:, 2],
                        r[:, 2] * e[:, 0] + r[:, 5] * e[:, 1] + r[:, 8] * e[:, 2]], axis=1)
        v = np.minimum(np.maximum(gains * ptd, -limits), limits)
        closing = np.stack([r[:, 0] * v[:, 0] + r[:, 1] * v[:, 1] + r[:, 2] * v[:, 2],
                            r[:, 3] * v[:, 0] + r[:, 4] * v[:, 1] + r[:, 5] * v[:, 2],
                            r[:, 6] * v[:, 0] + r[:, 7] * v[:, 1] + r[:, 8] * v[:, 2]], axis=1)
        state["_probe"] = state["_probe"] + (position - before) + dt * closing
        state["_rotvec"] = state["_rotvec"] * attitude_decay
        state["time_s"] = state["time_s"] + dt
        steps[rows] += 1
        step += 1
    return dict(zip(indices, snapshots, strict=True))


def _rotation_batch(rotvec: FloatArray) -> FloatArray:
    """:func:`_rotation_rows` of each row of ``rotvec`` ``(C, 3)``: ``(C, 9)``, the same
    arithmetic element by element."""
    rx, ry, rz = rotvec[:, 0], rotvec[:, 1], rotvec[:, 2]
    angle = np.sqrt(rx * rx + ry * ry + rz * rz)
    small = angle < 1e-12
    safe = np.where(small, 1.0, angle)
    x, y, z = rx / safe, ry / safe, rz / safe
    s = np.array([math.sin(v) for v in angle.tolist()])
    c = np.array([1.0 - math.cos(v) for v in angle.tolist()])
    full = np.stack([1.0 - c * (y * y + z * z), -s * z + c * x * y, s * y + c * x * z,
                     s * z + c * x * y, 1.0 - c * (x * x + z * z), -s * x + c * y * z,
                     -s * y + c * x * z, s * x + c * y * z, 1.0 - c * (x * x + y * y)], axis=1)
    if small.any():
        one = np.ones_like(rx)
        tiny = np.stack([one, -rz, ry, rz, one, -rx, -ry, rx, one], axis=1)
        full = np.where(small[:, None], tiny, full)
    return full


def trace_approach(config: Config, seed: int, approach_index: int, every: int = 3) -> dict[str, FloatArray]:
    """The first approach of chain ``approach_index`` from start to contact, every ``every``
    steps: ``time_s``, ``distance_m``, ``ptd_receiver_m`` (T, 3) and ``probe_drogue_m``
    (T, 3), the probe tip in the drogue-centred local frame (paper Fig. 7)."""
    a = config.approach
    chain, _ = _start_chain(config, seed, approach_index)
    rows: list[tuple] = []
    step = 0
    while True:
        if step % every == 0 or chain.distance < a.contact_m:
            chain._sync()
            rotation = rotation_from_rotvec(chain.rotvec)
            rows.append((chain.time_s, chain.distance, rotation.T @ chain.ptd_tanker, -chain.ptd_tanker))
        if chain.distance < a.contact_m:
            break
        chain.step()
        step += 1
    return {
        "time_s": np.array([r[0] for r in rows]),
        "distance_m": np.array([r[1] for r in rows]),
        "ptd_receiver_m": np.array([r[2] for r in rows]),
        "probe_drogue_m": np.array([r[3] for r in rows]),
    }


def _read_only(array: FloatArray) -> FloatArray:
    array.setflags(write=False)
    return array


def _state(config: Config, frame_index: int, approach_index: int, snap: _Snapshot,
           earlier: bool = True) -> FrameState:
    world_from_tanker = snap.tanker.world_from_tanker(snap.time_s)
    tanker_from_receiver = make_transform(rotation_from_rotvec(snap.attitude_rotvec), snap.probe_tanker)
    tanker_from_drogue = make_transform(tanker_drogue_rotation(snap.drogue_offset), snap.drogue_offset)
    world_from_receiver = world_from_tanker @ tanker_from_receiver
    world_from_drogue = world_from_tanker @ tanker_from_drogue
    body = MOUNTS[config.camera.mount].body
    world_from_body = world_from_receiver if body == "receiver" else world_from_tanker
    hose_tanker = hose_curve(tanker_from_drogue)
    hose_world = hose_tanker @ world_from_tanker[:3, :3].T + world_from_tanker[:3, 3]
    ptd = invert_rigid(world_from_receiver) @ world_from_drogue[:, 3]
    for array in (world_from_tanker, world_from_receiver, world_from_drogue, hose_world, ptd):
        array.setflags(write=False)
    return FrameState(
        frame_index=frame_index,
        approach_index=approach_index,
        approach_number=snap.approach_number,
        time_s=snap.time_s,
        world_from_tanker=world_from_tanker,
        world_from_receiver=world_from_receiver,
        world_from_drogue=world_from_drogue,
        world_from_cam=_read_only(world_from_body @ snap.body_from_cam),
        hose_points_world=hose_world,
        ptd_receiver_m=ptd[:3],  # a view of the read-only ptd
        distance_m=float(np.linalg.norm(ptd[:3])),
        mount=config.camera.mount,
        turbulence_intensity=snap.intensity,
        bank_deg=math.degrees(snap.tanker.bank),
        earlier_from=functools.partial(_earlier_state, config, frame_index, approach_index, snap) if earlier else None,
    )


def _earlier_state(config: Config, frame_index: int, approach_index: int, snap: _Snapshot) -> FrameState:
    """The state of ``snap`` MOTION_DT_S earlier (:attr:`FrameState.earlier`)."""
    return _state(config, frame_index, approach_index, snap.earlier(MOTION_DT_S), False)


class FrameStates:
    """The frame states of one config and root seed, each approach chain simulated once.

    Holds the last ``chains`` chains it simulated (frames of one chain are
    consecutive, so a shard rarely needs more; :meth:`prefetch` keeps all it is given);
    whoever creates it owns the memory. A frame's state is made when it is first asked
    for. The states' arrays are read-only. ``FrameStates(config)(i)`` is
    :func:`frame_state` ``(config, i)``.
    """

    def __init__(self, config: Config, seed: int | None = None, *, chains: int = 4) -> None:
        self.config = config
        self.seed = config.dataset.seed if seed is None else seed
        self._chains: dict[int, list[_Snapshot | FrameState]] = {}
        self._keep = max(1, chains)

    def _add(self, approach_index: int, snapshots: list[_Snapshot]) -> None:
        while len(self._chains) >= self._keep:
            self._chains.pop(next(iter(self._chains)))
        self._chains[approach_index] = list(snapshots)

    def prefetch(self, frame_indices) -> None:
        """Simulate the chains of ``frame_indices`` that are not held, together
        (:func:`simulate_chains`), each only as far as its last frame here, and hold
        every chain of them."""
        k = self.config.approach.frames_per_approach
        upto: dict[int, int] = {}
        for i in frame_indices:
            a, j = divmod(int(i), k)
            upto[a] = max(upto.get(a, 0), j + 1)
        self._keep = max(self._keep, len(upto))
        missing = [a for a in upto if a not in self._chains or len(self._chains[a]) < upto[a]]
        for a, snapshots in simulate_chains(self.config, self.seed, missing, upto).items():
            self._add(a, snapshots)

    def __call__(self, frame_index: int) -> FrameState:
        k = self.config.approach.frames_per_approach
        a, j = divmod(frame_index, k)
        if a not in self._chains or j >= len(self._chains[a]):  # not held, or held only up to an earlier frame
            self._add(a, simulate_chain(self.config, self.seed, a))
        chain = self._chains[a]
        if isinstance(chain[j], _Snapshot):
            chain[j] = _state(self.config, frame_index, a, chain[j])
        return chain[j]


def frame_state(config: Config, frame_index: int, seed: int | None = None) -> FrameState:
    """The state of frame ``frame_index``: a pure function of (config, seed, frame index).

    ``seed`` defaults to the config's dataset seed. It simulates the frame's whole
    approach chain; for many frames use :func:`frame_states` or :class:`FrameStates`.
    """
    return FrameStates(config, seed, chains=1)(frame_index)


def frame_states(config: Config, frame_indices, seed: int | None = None) -> list[FrameState]:
    """:func:`frame_state` for many frames (each chain is simulated once)."""
    states = FrameStates(config, seed)
    return [states(i) for i in frame_indices]
