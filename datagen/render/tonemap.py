"""From linear radiance to the 8-bit sRGB training image: exposure, the sRGB transfer.

Everything here is image arithmetic on numpy arrays (no Mitsuba).
"""

from __future__ import annotations

import functools
from typing import Final

import numpy as np
from numpy.typing import NDArray

from datagen.core.conventions import REC709_LUMA

__all__ = ["MIN_OBJECT_PX", "SRGB_LEVELS", "TONE_RANGE", "WHITE_RADIANCE", "drogue_statistics", "encoding_table",
           "exposure_scale", "image_statistics", "to_srgb8", "tone_curve"]

#: Linear radiance that maps to sRGB white at 0 EV (sunsky radiance is in W/(m^2 sr nm)-like units).
WHITE_RADIANCE: Final = 0.7


#: Linear values are quantized to 16 bits before the sRGB table: finer than one 8-bit
#: step everywhere (the steepest part, near black, moves by 0.05 of a step).
SRGB_LEVELS: Final = 65536


#: With a tone curve, the table spans linear values up to this (beyond it every shoulder is
#: within 1e-6 of white, and a clip is white).
TONE_RANGE: Final = 8


def tone_curve(x: NDArray[np.floating], gamma: float, shoulder: float) -> NDArray[np.float64]:
    """A camera's tone curve on display-linear values: ``x ** gamma``, then above the knee
    ``k = 1 - 0.5 shoulder`` the highlight shoulder ``k + (1 - k)(1 - exp(-(y - k) / (1 - k)))``,
    which meets the line with its slope and approaches white (``shoulder`` 0: a hard clip)."""
    y = np.power(np.maximum(np.asarray(x, dtype=np.float64), 0.0), gamma)
    room = 0.5 * shoulder  # 1 - k
    if room <= 1e-9:  # no shoulder to speak of: the clip
        return np.minimum(y, 1.0)
    k = 1.0 - room
    return np.where(y > k, k + room * -np.expm1(-np.maximum(y - k, 0.0) / room), y)


def _encoded(x: NDArray[np.float64]) -> NDArray[np.uint8]:
    x = np.clip(x, 0.0, 1.0)
    srgb = np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)
    return np.round(srgb * 255.0).astype(np.uint8)


@functools.cache
def _srgb_table() -> NDArray[np.uint8]:
    return _encoded(np.linspace(0.0, 1.0, SRGB_LEVELS))


#: Entries of the table with a tone curve: the linear values 0 to :data:`TONE_RANGE` in steps
#: of 1 / (:data:`SRGB_LEVELS` - 1).
_TONE_ENTRIES: Final = TONE_RANGE * (SRGB_LEVELS - 1) + 1


def _tone_value(i: NDArray[np.int64], gamma: float, shoulder: float) -> NDArray[np.uint8]:
    """Entries ``i`` of the table with a tone curve: ``np.linspace(0, TONE_RANGE, _TONE_ENTRIES)[i]``
    (numpy's own arithmetic: ``i * step``, the last entry the range's end) toned and encoded."""
    step = TONE_RANGE / (_TONE_ENTRIES - 1)
    x = np.where(i == _TONE_ENTRIES - 1, float(TONE_RANGE), i.astype(np.float64) * step)
    return _encoded(tone_curve(x, gamma, shoulder))


@functools.lru_cache(maxsize=4)
def _tone_table(gamma: float, shoulder: float) -> NDArray[np.uint8]:
    """The 8-bit table of a tone curve (``gamma``, ``shoulder``): a rising step function of at
    most 256 steps, so it is found from where each step begins (a bisection per level over
    the entries, all levels at once: a few thousand entries evaluated, not half a million;
    a frame draws its own curve). The same table as evaluating every entry
    (``tests/test_sensor.py``)."""
    n = _TONE_ENTRIES
    levels = np.arange(1, 256)
    lo, hi = np.zeros(255, dtype=np.int64), np.full(255, n, dtype=np.int64)  # first entry >= level in [lo, hi]
    while np.any(searching := lo < hi):
        mid = np.minimum((lo + hi) // 2, n - 1)  # an entry (below hi <= n where the level is still searched)
        rising = _tone_value(mid, gamma, shoulder) >= levels
        # Only the levels still searched move: one whose search has ended stays where it is
        # (at n if the curve never reaches it).
        lo, hi = np.where(searching & ~rising, mid + 1, lo), np.where(searching & rising, mid, hi)
    # Entry i holds the highest level that begins at or before it (levels up to entry 0's begin at 0).
    starts = np.concatenate([[0], lo])  # where each level from 0 to 255 begins (n: never reached)
    return np.repeat(np.arange(256, dtype=np.uint8), np.diff(np.concatenate([starts, [n]])))


def encoding_table(tone: tuple[float, float] | None = None) -> tuple[NDArray[np.uint8], int]:
    """The 8-bit encoding as a table and the linear value its last entry stands for: entry
    ``i`` holds the code of the linear value ``i / (SRGB_LEVELS - 1)``, from 0 to that top
    (1, or :data:`TONE_RANGE` with a tone curve); :func:`to_srgb8` indexes it."""
    if tone is None:
        return _srgb_table(), 1
    return _tone_table(float(tone[0]), float(tone[1])), TONE_RANGE


def to_srgb8(linear: NDArray[np.floating], tone: tuple[float, float] | None = None) -> NDArray[np.uint8]:
    """8-bit sRGB from linear RGB in [0, 1] (clipped), the IEC 61966-2-1 transfer; with
    ``tone`` = (gamma, shoulder), through :func:`tone_curve` first (one table for both):
    the linear value clipped to the table's top and rounded (half to even) to its entry."""
    table, top = encoding_table(tone)
    x = np.clip(np.asarray(linear, dtype=np.float32), 0.0, np.float32(top))
    return table[np.rint(x * np.float32(SRGB_LEVELS - 1)).astype(np.int32)]


def exposure_scale(exposure_ev: float) -> np.float32:
    """The factor that maps linear radiance to display-linear values at ``exposure_ev``
    stops (:data:`WHITE_RADIANCE` becomes white at 0 EV)."""
    return np.float32(2.0 ** exposure_ev / WHITE_RADIANCE)


#: The drogue's statistics need at least this many of its pixels.
MIN_OBJECT_PX: Final = 16


def image_statistics(srgb8: NDArray[np.uint8], surface: NDArray[np.uint8] | None,
                     surfaces: tuple[str, ...] = ("sky", "sea", "cloud", "object"),
                     object_ids: NDArray[np.uint32] | None = None) -> dict[str, float | None]:
    """What the final training image shows: its mean Rec. 709 luma (sRGB-encoded, 0-1),
    RMS contrast (the luma's standard deviation), the share of pixels whose first hit is
    each of ``surfaces`` (indexed by the codes of ``surface``; None without one), and the
    drogue against what is behind it (``object_ids``, same grid as the image:
    :func:`drogue_statistics`)."""
    luma = (srgb8.astype(np.float32) @ REC709_LUMA) / np.float32(255.0)
    stats: dict[str, float | None] = {"image_mean_luminance": float(luma.mean()),
                                      "image_rms_contrast": float(luma.std())}
    counts = None if surface is None else np.bincount(surface.ravel(), minlength=len(surfaces)) / surface.size
    for code, name in enumerate(surfaces):
        stats[f"share_{name}"] = None if counts is None else float(counts[code])
    stats.update(drogue_statistics(luma, object_ids))
    return stats


def drogue_statistics(luma: NDArray[np.float32], object_ids: NDArray[np.uint32] | None) -> dict[str, float | None]:
    """The drogue's mean luma (``drogue_luminance``) and its contrast against the background
    around it (``drogue_contrast``: (L_drogue - L_background) / (L_drogue + L_background), -1
    to 1, negative where it is darker), the background being the pixels of no object within
    its bounding box grown by half its size on every side. None where fewer than
    :data:`MIN_OBJECT_PX` of its pixels (or of the background's) are seen."""
    from datagen.core.conventions import object_id

    none: dict[str, float | None] = {"drogue_luminance": None, "drogue_contrast": None}
    if object_ids is None or object_ids.shape != luma.shape:
        return none
    mine = object_ids == object_id("drogue")
    if int(mine.sum()) < MIN_OBJECT_PX:
        return none
    rows, cols = np.flatnonzero(mine.any(axis=1)), np.flatnonzero(mine.any(axis=0))
    grow_r, grow_c = (rows[-1] - rows[0] + 1) // 2, (cols[-1] - cols[0] + 1) // 2
    window = np.s_[max(rows[0] - grow_r, 0):rows[-1] + grow_r + 1, max(cols[0] - grow_c, 0):cols[-1] + grow_c + 1]
    background = object_ids[window] == 0
    inside = float(luma[mine].mean())
    if int(background.sum()) < MIN_OBJECT_PX:
        return {"drogue_luminance": inside, "drogue_contrast": None}
    behind = float(luma[window][background].mean())
    total = inside + behind
    return {"drogue_luminance": inside, "drogue_contrast": (inside - behind) / total if total > 0.0 else 0.0}
