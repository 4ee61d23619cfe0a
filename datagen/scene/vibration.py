"""The camera's vibration and buffet: a small rotation of the camera about its own axes,
a sum of sinusoids whose amplitude and spectrum each approach draws from its mount's band.

A pod or a wing tip is not a rigid tripod: the airframe's structural modes and the air's
buffet turn the camera by a few hundredths of a degree at a few to a few tens of hertz.
:func:`vibration` draws an approach's components from
:func:`datagen.core.conventions.world_rng` ``(seed, approach, "vibration")``;
:meth:`Vibration.rotation` is the camera's turn at a time, which
:mod:`datagen.scene.approach` puts into the frame's camera pose (and into the pose
:data:`~datagen.scene.approach.MOTION_DT_S` earlier, so that the image motion and the motion
blur carry the vibration's angular rate). Labels project through that pose: their centres
stay the true projections.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Final

import numpy as np
from numpy.typing import NDArray

from datagen.core.transforms import rotation_from_rotvec

if TYPE_CHECKING:
    from datagen.config.schema import CameraConfig

__all__ = ["COMPONENTS", "MOUNT_VIBRATION", "MountVibration", "Vibration", "vibration"]

#: Sinusoids per axis.
COMPONENTS: Final = 3


@dataclass(frozen=True)
class MountVibration:
    """A mount's band: the RMS pointing angle (degrees, over the two axes that move the
    image) and the frequencies (Hz) its components are drawn from (log-uniform)."""

    rms_deg: tuple[float, float]
    frequency_hz: tuple[float, float]
    roll_share: float  # the roll's RMS as a share of the pointing RMS


#: Per mount: a receiver's wing pod rides the wing's bending and torsion modes (low, larger);
#: a cockpit camera the fuselage's vibration (higher, small); a tanker's hose pod its ram-air
#: turbine and the buffet of the hose's wake (highest, small).
MOUNT_VIBRATION: Final[dict[str, MountVibration]] = {
    "wingcam": MountVibration((0.02, 0.15), (2.0, 12.0), 0.5),
    "dashcam": MountVibration((0.01, 0.06), (8.0, 40.0), 0.3),
    "podcam": MountVibration((0.005, 0.04), (6.0, 60.0), 0.3),
}


@dataclass(frozen=True)
class Vibration:
    """An approach's vibration: ``(COMPONENTS, 3)`` amplitudes (radians), frequencies (Hz) and
    phases (radians) about the camera's x, y and z axes (OpenCV: pitch, yaw, roll)."""

    amplitude_rad: NDArray[np.float64]
    frequency_hz: NDArray[np.float64]
    phase_rad: NDArray[np.float64]

    @property
    def rms_deg(self) -> float:
        """RMS pointing angle (the turn about the x and y axes together), degrees."""
        return math.degrees(math.sqrt(float((self.amplitude_rad[:, :2] ** 2).sum()) / 2.0))

    @property
    def mean_frequency_hz(self) -> float:
        """Frequency weighted by the power of each component (pointing axes)."""
        power = self.amplitude_rad[:, :2] ** 2
        return float((power * self.frequency_hz[:, :2]).sum() / power.sum())

    def rotvec(self, time_s) -> NDArray[np.float64]:
        """The camera's turn at ``time_s`` (a float, or an array of times: ``(..., 3)``) as a
        rotation vector in the camera frame."""
        t = np.asarray(time_s, dtype=np.float64)[..., None, None]
        return (self.amplitude_rad * np.sin(2.0 * math.pi * self.frequency_hz * t + self.phase_rad)).sum(axis=-2)

    def rotation(self, time_s: float) -> NDArray[np.float64]:
        """``cam_nominal_from_cam`` at ``time_s``: a ``(3, 3)`` rotation."""
        return rotation_from_rotvec(self.rotvec(time_s))


def vibration(camera: CameraConfig, seed: int, approach_index: int) -> Vibration | None:
    """Approach ``approach_index``'s vibration of ``camera``, or None where its vibration is off."""
    v = camera.vibration
    if not v.enabled or v.scale == 0.0:
        return None
    return _drawn(camera.mount, float(v.scale), int(seed), int(approach_index))


@functools.lru_cache(maxsize=256)
def _drawn(mount: str, scale: float, seed: int, approach_index: int) -> Vibration:
    from datagen.core.conventions import world_rng

    band = MOUNT_VIBRATION[mount]
    rng = world_rng(seed, approach_index, "vibration")
    rms = math.radians(math.exp(rng.uniform(*np.log(band.rms_deg)))) * scale
    low, high = np.log(band.frequency_hz)
    frequency = np.exp(rng.uniform(low, high, size=(COMPONENTS, 3)))
    phase = rng.uniform(0.0, 2.0 * math.pi, size=(COMPONENTS, 3))
    weight = rng.uniform(0.5, 1.0, size=(COMPONENTS, 3)) / frequency  # more power at the low end
    weight[:, 2] *= band.roll_share * np.sqrt((weight[:, :2] ** 2).sum() / (weight[:, 2] ** 2).sum())
    # The pointing axes' RMS (each sinusoid's mean square is a^2 / 2, two axes) is ``rms``.
    amplitude = weight * rms / math.sqrt(float((weight[:, :2] ** 2).sum()) / 2.0)
    for array in (amplitude, frequency, phase):
        array.setflags(write=False)
    return Vibration(amplitude, frequency, phase)
