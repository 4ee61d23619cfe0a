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

Frames are grouped ``Config.frames_per_chain`` at a time: frames
``[a*K, (a+1)*K)`` come from approach chain ``a``, whose every draw comes from
:func:`datagen.core.conventions.approach_rng` ``(seed, a)``. A frame's state is thus
a pure function of (config, seed, frame index), and any frame can be
regenerated alone on any worker.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from datagen.assets.rig import HOSE_ATTACH_DROGUE_M, HOSE_PORT_TANKER_M, MOUNTS
from datagen.config.schema import Config
from datagen.core.transforms import (
    invert_rigid,
    make_transform,
    rotation_from_rotvec,
    rotation_from_ypr,
)
from datagen.scene.chains import ChainSnapshot, simulate_chain, simulate_chains
from datagen.scene.vibration import vibration

__all__ = [
    "FrameState",
    "FrameStates",
    "frame_state",
    "frame_states",
    "hose_curve",
]

#: How much earlier :attr:`FrameState.earlier` is, seconds (image motion by finite differences).
MOTION_DT_S = 1.0e-3
#: Points along the hose polyline.
HOSE_POINTS = 48

FloatArray = NDArray[np.float64]


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

    def cam_from_per_s(self, name: str) -> FloatArray:
        """The time derivative of ``cam_from_<name>`` at the frame's time, per second: by
        finite difference against :attr:`earlier` (zeros without one). A rolling shutter's
        labels move each point along it (:class:`datagen.core.camera.RollingShutter`)."""
        before = self.earlier
        if before is None:
            return np.zeros((4, 4))
        now = self.cam_from_world @ self.world_from(name)
        return (now - before.cam_from_world @ before.world_from(name)) / (self.time_s - before.time_s)


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


def _read_only(array: FloatArray) -> FloatArray:
    array.setflags(write=False)
    return array


def _state(config: Config, seed: int, frame_index: int, approach_index: int, snap: ChainSnapshot,
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
        world_from_cam=_read_only(world_from_body @ _body_from_cam(config, seed, approach_index, snap)),
        hose_points_world=hose_world,
        ptd_receiver_m=ptd[:3],  # a view of the read-only ptd
        distance_m=float(np.linalg.norm(ptd[:3])),
        mount=config.camera.mount,
        turbulence_intensity=snap.intensity,
        bank_deg=math.degrees(snap.tanker.bank),
        earlier_from=(functools.partial(_earlier_state, config, seed, frame_index, approach_index, snap)
                      if earlier else None),
    )


def _body_from_cam(config: Config, seed: int, approach_index: int, snap: ChainSnapshot) -> FloatArray:
    """The camera on its body at the snapshot's time: the approach's mount, turned by the
    approach's vibration at that time (:mod:`datagen.scene.vibration`)."""
    shake = vibration(config.camera, seed, approach_index)
    if shake is None:
        return snap.body_from_cam
    turned = snap.body_from_cam.copy()
    turned[:3, :3] = turned[:3, :3] @ shake.rotation(snap.time_s)
    return turned


def _earlier_state(config: Config, seed: int, frame_index: int, approach_index: int,
                   snap: ChainSnapshot) -> FrameState:
    """The state of ``snap`` MOTION_DT_S earlier (:attr:`FrameState.earlier`)."""
    return _state(config, seed, frame_index, approach_index, snap.earlier(MOTION_DT_S), False)


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
        self._chains: dict[int, list[ChainSnapshot | FrameState]] = {}
        self._keep = max(1, chains)

    def _add(self, approach_index: int, snapshots: list[ChainSnapshot]) -> None:
        while len(self._chains) >= self._keep:
            self._chains.pop(next(iter(self._chains)))
        self._chains[approach_index] = list(snapshots)

    def prefetch(self, frame_indices) -> None:
        """Simulate the chains of ``frame_indices`` that are not held, together
        (:func:`simulate_chains`), each only as far as its last frame here, and hold
        every chain of them."""
        k = self.config.frames_per_chain
        upto: dict[int, int] = {}
        for i in frame_indices:
            a, j = divmod(int(i), k)
            upto[a] = max(upto.get(a, 0), j + 1)
        self._keep = max(self._keep, len(upto))
        missing = [a for a in upto if a not in self._chains or len(self._chains[a]) < upto[a]]
        for a, snapshots in simulate_chains(self.config, self.seed, missing, upto).items():
            self._add(a, snapshots)

    def __call__(self, frame_index: int) -> FrameState:
        k = self.config.frames_per_chain
        a, j = divmod(frame_index, k)
        if a not in self._chains or j >= len(self._chains[a]):  # not held, or held only up to an earlier frame
            self._add(a, simulate_chain(self.config, self.seed, a))
        chain = self._chains[a]
        held = chain[j]
        if isinstance(held, ChainSnapshot):
            held = chain[j] = _state(self.config, self.seed, frame_index, a, held)
        return held


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
