"""Whether an 8-bit image shows anything inside a label box: a detector cannot learn a
feature whose box is saturated, black or flat (one value throughout).

A box covers the pixels its continuous extent touches (:mod:`datagen.core.conventions`),
clipped to the image. Its verdict is one of :data:`BLANK_REASONS`' codes.
"""

from __future__ import annotations

from typing import Final

import numpy as np
from numpy.typing import NDArray

__all__ = ["BLANK_REASONS", "BLANK_SHARE", "DARK_LEVEL", "FLAT_LEVELS", "SATURATED_LEVEL", "blank_boxes"]

#: A pixel whose every channel is at or above this level is saturated.
SATURATED_LEVEL: Final = 250
#: A pixel whose every channel is at or below this level is black.
DARK_LEVEL: Final = 5
#: A box is saturated (or black) when at least this share of its pixels is.
BLANK_SHARE: Final = 0.98
#: A box is flat when each channel spans at most this many levels inside it.
FLAT_LEVELS: Final = 1
#: Code -> what a box shows: 0 something, then why it shows nothing.
BLANK_REASONS: Final = (None, "saturated", "black", "flat")


def blank_boxes(image: NDArray[np.uint8], boxes_xyxy: NDArray[np.float64]) -> NDArray[np.int8]:
    """``(N,)`` codes of :data:`BLANK_REASONS` for the continuous-pixel boxes ``(N, 4)`` in
    an 8-bit ``(H, W)`` or ``(H, W, C)`` image (0 where a box lies wholly outside it, or is
    not finite: there is nothing to judge)."""
    h, w = image.shape[:2]
    pixels = image.reshape(h, w, -1)
    out = np.zeros(len(boxes_xyxy), np.int8)
    for i, box in enumerate(np.asarray(boxes_xyxy, dtype=np.float64)):
        if not np.isfinite(box).all():
            continue
        x0, y0 = max(0, int(np.floor(box[0]))), max(0, int(np.floor(box[1])))
        x1, y1 = min(w, int(np.ceil(box[2]))), min(h, int(np.ceil(box[3])))
        if x1 <= x0 or y1 <= y0:
            continue
        patch = pixels[y0:y1, x0:x1].reshape(-1, pixels.shape[2])
        if (patch.min(axis=1) >= SATURATED_LEVEL).mean() >= BLANK_SHARE:
            out[i] = 1
        elif (patch.max(axis=1) <= DARK_LEVEL).mean() >= BLANK_SHARE:
            out[i] = 2
        elif (patch.max(axis=0).astype(np.int16) - patch.min(axis=0) <= FLAT_LEVELS).all():
            out[i] = 3
    return out
