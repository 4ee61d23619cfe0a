"""From linear radiance to the 8-bit sRGB training image: exposure, the sRGB transfer.

Everything here is image arithmetic on numpy arrays (no Mitsuba).
"""

from __future__ import annotations

import functools
from typing import Final

import numpy as np
from numpy.typing import NDArray

__all__ = ["WHITE_RADIANCE", "exposure_scale", "image_statistics", "to_srgb8"]

#: Linear radiance that maps to sRGB white at 0 EV (sunsky radiance is in W/(m^2 sr nm)-like units).
WHITE_RADIANCE: Final = 0.7


#: Linear values are quantized to 16 bits before the sRGB table: finer than one 8-bit
#: step everywhere (the steepest part, near black, moves by 0.05 of a step).
_SRGB_LEVELS: Final = 65536


@functools.cache
def _srgb_table() -> NDArray[np.uint8]:
    x = np.linspace(0.0, 1.0, _SRGB_LEVELS)
    srgb = np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)
    return np.round(srgb * 255.0).astype(np.uint8)


def to_srgb8(linear: NDArray[np.floating]) -> NDArray[np.uint8]:
    """8-bit sRGB from linear RGB in [0, 1] (clipped), the IEC 61966-2-1 transfer."""
    x = np.clip(np.asarray(linear, dtype=np.float32), 0.0, 1.0)
    return _srgb_table()[np.rint(x * np.float32(_SRGB_LEVELS - 1)).astype(np.int32)]


def exposure_scale(exposure_ev: float) -> np.float32:
    """The factor that maps linear radiance to display-linear values at ``exposure_ev``
    stops (:data:`WHITE_RADIANCE` becomes white at 0 EV)."""
    return np.float32(2.0 ** exposure_ev / WHITE_RADIANCE)


def image_statistics(srgb8: NDArray[np.uint8], surface: NDArray[np.uint8] | None,
                     surfaces: tuple[str, ...] = ("sky", "sea", "cloud", "object")) -> dict[str, float | None]:
    """What the final training image shows: its mean Rec. 709 luma (sRGB-encoded, 0-1),
    RMS contrast (the luma's standard deviation), and the share of pixels whose first hit
    is each of ``surfaces`` (indexed by the codes of ``surface``; None without one)."""
    luma = (srgb8.astype(np.float32) @ np.array([0.2126, 0.7152, 0.0722], np.float32)) / np.float32(255.0)
    stats: dict[str, float | None] = {"image_mean_luminance": float(luma.mean()),
                                      "image_rms_contrast": float(luma.std())}
    counts = None if surface is None else np.bincount(surface.ravel(), minlength=len(surfaces)) / surface.size
    for code, name in enumerate(surfaces):
        stats[f"share_{name}"] = None if counts is None else float(counts[code])
    return stats
