"""Where things sit on the airframes: camera mounts and the hose port.

Positions are in the body frames of :mod:`datagen.core.conventions` (x forward,
y left, z up, metres): the receiver frame has its origin at the probe tip, the
tanker frame at the *average* drogue centre. The built-in meshes are modelled
around these points, so a camera mount is on its pod and the hose leaves its port.

Receiver: an F/A-18-class fighter whose retractable probe sits on the right of
the nose, its tip about 0.6 m right of the centreline and slightly ahead of the
radome. Tanker: a KC-46-class tanker with a centreline drogue system; the hose
trails about 22 m aft and 6 m below its port to the average drogue position.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Final, Literal

import numpy as np

from datagen.core.transforms import make_transform, vec3

__all__ = [
    "HOSE_ATTACH_DROGUE_M",
    "HOSE_PORT_TANKER_M",
    "MOUNTS",
    "RECEIVER_CENTRELINE_Y_M",
    "Mount",
    "body_from_cam_looking",
]

#: The receiver's centreline lies this far to the left (+y) of the probe tip.
RECEIVER_CENTRELINE_Y_M: Final[float] = 0.6

#: Hose exit port of the centreline drogue pod, in the tanker frame.
HOSE_PORT_TANKER_M: Final = np.array([22.0, 0.0, 6.0])
HOSE_PORT_TANKER_M.setflags(write=False)

#: Where the hose meets the drogue's coupling, in the drogue frame (ahead of the basket centre).
HOSE_ATTACH_DROGUE_M: Final = np.array([0.45, 0.0, 0.0])
HOSE_ATTACH_DROGUE_M.setflags(write=False)

def body_from_cam_looking(position_m, direction, up=(0.0, 0.0, 1.0)) -> np.ndarray:
    """``body_from_cam`` (OpenCV camera) at ``position_m`` with its optical axis along
    ``direction`` and image "up" as close to body ``up`` as possible, 4x4."""
    z = np.asarray(direction, dtype=np.float64)
    z = z / np.linalg.norm(z)
    x = np.cross(z, np.asarray(up, dtype=np.float64))
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    return make_transform(np.column_stack([x, y, z]), position_m)


@dataclass(frozen=True)
class Mount:
    """A nominal camera mount: which body it is on, where, and where it looks."""

    name: str
    body: Literal["receiver", "tanker"]
    position_m: tuple[float, float, float]
    direction: tuple[float, float, float]  # optical axis in the body frame
    window: Literal["pod", "windscreen"] = "pod"  # what the camera looks through (datagen.render.window)

    def body_from_cam(self) -> np.ndarray:
        """Nominal ``body_from_cam`` (OpenCV camera), 4x4."""
        return body_from_cam_looking(self.position_m, self.direction)


def _forward(yaw_deg: float, pitch_deg: float) -> tuple[float, float, float]:
    """Unit direction turned left by ``yaw_deg`` and up by ``pitch_deg`` from body +x."""
    y, p = math.radians(yaw_deg), math.radians(pitch_deg)
    return (math.cos(p) * math.cos(y), math.cos(p) * math.sin(y), math.sin(p))


_PODCAM_POSITION = HOSE_PORT_TANKER_M + np.array([0.4, -0.5, 0.0])

#: The paper's camera positions (3.1): receiver wing pod on the probe side
#: (looking forward, turned slightly inboard and up), receiver cockpit (forward),
#: tanker hose pod beside the port (rearward, aimed at the average drogue centre).
MOUNTS: Final[dict[str, Mount]] = {
    "wingcam": Mount("wingcam", "receiver", (-8.6, RECEIVER_CENTRELINE_Y_M - 3.6, -0.9), _forward(2.0, 2.0)),
    "dashcam": Mount("dashcam", "receiver", (-4.3, RECEIVER_CENTRELINE_Y_M, 0.75), _forward(-1.5, -1.0),
                     "windscreen"),
    "podcam": Mount("podcam", "tanker", vec3(_PODCAM_POSITION),
                    vec3(-_PODCAM_POSITION)),
}
