"""Another aircraft in view: on some approaches a second receiver or tanker flies in formation
with the tanker, somewhere in the camera's field of view, tens to hundreds of metres away.

It is drawn (an instance of the receiver's or the tanker's meshes, in the renderer) and
recorded (:data:`datagen.scene.look.FrameLook` ``other_aircraft*``), never labeled: it has no
features, and where it hides a feature of the target the feature is excluded as occluded, as
by anything else in the scene.

Its place is drawn per approach from :func:`datagen.core.conventions.world_rng`
``(seed, approach, "traffic")``, in the tanker frame around the camera's nominal line of
sight: the mount's position and axis on its body, with a receiver's body taken at contact
(its frame's origin, the probe's tip, at the tanker's average drogue centre, which is the
tanker frame's origin, and its axes the tanker's).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Final

import numpy as np
from numpy.typing import NDArray

from datagen.assets.rig import MOUNTS
from datagen.core.transforms import make_transform, rotation_from_ypr

if TYPE_CHECKING:
    from datagen.config.schema import CameraConfig, TrafficConfig
    from datagen.scene.approach import FrameState

__all__ = ["CLEARANCE_M", "VIEW_SHARE", "draw_traffic", "world_from_traffic"]

#: The other aircraft keeps at least this far from the tanker frame's origin and the camera.
CLEARANCE_M: Final = 70.0
#: Its direction lies within this share of the half fields of view about the nominal axis.
VIEW_SHARE: Final = 0.9
#: Draws of a place before the farthest one drawn is taken.
TRIES: Final = 16


def draw_traffic(traffic: TrafficConfig, camera: CameraConfig, rng: np.random.Generator) -> dict:
    """An approach's other aircraft: ``other_aircraft`` (``"none"`` on most approaches, else
    its kind), its place in the tanker frame (in ``camera``'s view) and its heading off the
    tanker's."""
    from datagen.core.camera import Intrinsics

    t = traffic
    present = bool(rng.random() < t.share)
    names = list(t.kinds)
    weights = np.cumsum([t.kinds[n] for n in names], dtype=np.float64)
    kind = names[min(int(np.searchsorted(weights / weights[-1], rng.random(), side="right")), len(names) - 1)]
    mount = MOUNTS[camera.mount]
    origin = np.asarray(mount.position_m, dtype=np.float64)
    axes = mount.body_from_cam()[:3, :3]  # camera axes in the body (= tanker) frame
    k = Intrinsics.from_hfov_deg(camera.width, camera.height, camera.hfov_deg)
    half_w, half_h = math.tan(k.hfov_rad / 2) * VIEW_SHARE, math.tan(k.vfov_rad / 2) * VIEW_SHARE
    best, best_clearance = origin, -math.inf
    for _ in range(TRIES):
        ray = axes @ np.array([rng.uniform(-half_w, half_w), rng.uniform(-half_h, half_h), 1.0])
        place = origin + math.exp(rng.uniform(*np.log(t.range_m))) * ray / np.linalg.norm(ray)
        clearance = float(np.linalg.norm(place))
        if clearance > best_clearance:
            best, best_clearance = place, clearance
        if clearance >= CLEARANCE_M:
            break
    heading = float(rng.uniform(-t.heading_deg, t.heading_deg))
    return {"other_aircraft": kind if present else "none",
            "other_aircraft_tanker_m": tuple(float(v) for v in best) if present else None,
            "other_aircraft_heading_deg": heading if present else None}


def world_from_traffic(state: FrameState, place_tanker_m, heading_deg: float | None) -> NDArray[np.float64] | None:
    """The other aircraft's pose in the world at ``state``, from its drawn place in the tanker
    frame and heading (a look's ``other_aircraft_tanker_m`` and ``other_aircraft_heading_deg``;
    None where there is none): it flies with the tanker."""
    if place_tanker_m is None:
        return None
    turn = rotation_from_ypr(math.radians(heading_deg or 0.0), 0.0, 0.0)
    return state.world_from_tanker @ make_transform(turn, np.asarray(place_tanker_m, dtype=np.float64))
