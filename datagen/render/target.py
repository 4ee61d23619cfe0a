"""More samples where a detector looks: the target pass.

At the frame's few samples per pixel the denoiser smooths the aircraft's and the drogue's
surfaces with the noise (its waxy look, ``bench/bench_detail.py``), and no filter of the
denoised or the noisy image gets that detail back. What does is samples. The target pass
renders a window of the frame, a fixed share of its width and height, again with
``render.target_spp`` samples of their own, through a second sensor whose pixels are exactly
the frame's pixels there (its principal point moved; the same focal length). The window is
placed where it holds most of the objects, as a coarse grid of rays in the geometry pass's
cast finds them. Its samples are merged into the frame's before the denoiser, each pixel the
two estimates' sample-weighted mean, their weight falling to 0 over :data:`FEATHER` of the
window at its edges inside the image, so that the noise changes smoothly, with no rectangle
for a detector to learn.

Both estimates are unbiased, so any weighting is: the image converges to the same frame,
with less noise where the objects are. The window is a fixed size, so that the pass and the
merge record once with the frame's path tracing (one frozen function,
:meth:`datagen.render.renderer.Renderer.trace`) and replay; its offset is data (the sensor's
principal point and the merge's offsets).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from datagen.core.camera import Intrinsics
from datagen.core.conventions import OBJECT_NAMES, pixel_centres

__all__ = ["FEATHER", "TARGET_SENSOR", "TargetWindow", "merge_target", "target_size", "target_window", "window_offsets"]

#: The share of the window's width (height) over which the target pass's weight falls to 0
#: at an edge of the window inside the image.
FEATHER = 0.125

#: The target pass's sensor: the scene's second (``"target_sensor"``; the frame's is the first).
TARGET_SENSOR = 1

#: The window is placed on a grid of this many pixels, from the objects the geometry pass's
#: cast finds at the centres of blocks of this size.
PLACEMENT_STRIDE_PX = 4


@dataclass(frozen=True)
class TargetWindow:
    """Where the target pass renders: its top-left pixel and size in the frame's pixels, and
    which of its edges lie on the image's border (no feathering there)."""

    u0: int
    v0: int
    width: int
    height: int
    image_width: int
    image_height: int

    @property
    def principal_point_offset(self) -> tuple[float, float]:
        """Mitsuba's ``principal_point_offset_x`` and ``_y`` (shares of the window's width
        and height) that make the window's sensor see exactly the frame's pixels
        ``[u0, u0 + width) x [v0, v0 + height)``: the frame's principal point is at its centre
        (:mod:`datagen.core.conventions`)."""
        return ((self.u0 + self.width / 2 - self.image_width / 2) / self.width,
                (self.v0 + self.height / 2 - self.image_height / 2) / self.height)

    @property
    def on_border(self) -> tuple[bool, bool, bool, bool]:
        """Whether the window's left, right, top and bottom edges are the image's."""
        return (self.u0 == 0, self.u0 + self.width == self.image_width,
                self.v0 == 0, self.v0 + self.height == self.image_height)


def target_size(intrinsics: Intrinsics, share: float) -> tuple[int, int]:
    """The window's width and height: ``share`` of the image's each, at least one pixel."""
    return (max(1, min(intrinsics.width, round(intrinsics.width * share))),
            max(1, min(intrinsics.height, round(intrinsics.height * share))))


def target_window(ids: NDArray, size: tuple[int, int], image_size: tuple[int, int]) -> TargetWindow:
    """The window of ``size`` (width, height) over an image of ``image_size`` that holds the
    most of the objects' samples among ``ids``: the object ids the geometry pass's cast found
    on the :data:`PLACEMENT_STRIDE_PX` grid of block centres (:func:`pixel_centres`; the
    labels' objects count, not the background, another aircraft or the windscreen's frame).
    Of the positions that hold as many, the one whose centre is nearest the centre of the
    objects' samples' bounding box. Where no object is in view, the image's centre: every
    frame runs the pass, so that its recording and kernels are made at a process's first
    frame, and a frame costs the same with its objects in view or not. The grid is the same
    whatever the geometry pass's own resolution, and so is the window."""
    width, height = image_size
    tw, th = size
    objects = (ids >= 1) & (ids <= len(OBJECT_NAMES))
    if not objects.any():
        return TargetWindow((width - tw) // 2, (height - th) // 2, tw, th, width, height)
    uu, vv = pixel_centres(width, height, PLACEMENT_STRIDE_PX)
    cu, cv = uu[0], vv[:, 0]  # the grid's columns and rows (continuous pixels)
    # Every window position on the placement grid (and flush with the far borders), and the
    # object samples each holds: box sums of an integral image over the grid's rows and columns.
    us = np.unique(np.append(np.arange(0, width - tw + 1, PLACEMENT_STRIDE_PX), width - tw))
    vs = np.unique(np.append(np.arange(0, height - th + 1, PLACEMENT_STRIDE_PX), height - th))
    a, a2 = np.searchsorted(cu, us), np.searchsorted(cu, us + tw)
    b, b2 = np.searchsorted(cv, vs), np.searchsorted(cv, vs + th)
    integral = np.zeros((len(cv) + 1, len(cu) + 1), np.int64)
    integral[1:, 1:] = objects.cumsum(0, dtype=np.int64).cumsum(1)
    held = (integral[b2[:, None], a2[None, :]] - integral[b[:, None], a2[None, :]]
            - integral[b2[:, None], a[None, :]] + integral[b[:, None], a[None, :]])
    rows, cols = cv[objects.any(1)], cu[objects.any(0)]
    centre = ((cols.min() + cols.max()) / 2, (rows.min() + rows.max()) / 2)
    best = held == held.max()
    miss = (vs[:, None] + th / 2 - centre[1]) ** 2 + (us[None, :] + tw / 2 - centre[0]) ** 2
    j = int(np.argmin(np.where(best, miss, np.inf)))
    return TargetWindow(int(us[j % len(us)]), int(vs[j // len(us)]), tw, th, width, height)


def window_offsets(mi, dr, window: TargetWindow) -> tuple:
    """The window's place as opaque device values, the merge's inputs (:func:`merge_target`):
    its top-left pixel (``mi.UInt32``) and, per edge (left, right, top, bottom), how far out
    of reach its feather is moved (``mi.Float``: 0 inside the image, far where the edge is the
    image's), so that one recording and one kernel serve every frame."""
    return (dr.opaque(mi.UInt32, window.u0), dr.opaque(mi.UInt32, window.v0),
            *(dr.opaque(mi.Float, 1e9 if edge else 0.0) for edge in window.on_border))


def merge_target(mi, dr, image, window_image, offsets: tuple, spp: int, target_spp: int) -> None:
    """Merge the target pass's ``window_image`` (a ``(h, w, C)`` tensor) into the frame's
    ``image`` (``(H, W, C)``) in place, on the device, at ``offsets`` (:func:`window_offsets`):
    each pixel of the window the two estimates' mean weighted by their samples, the window's
    falling linearly to 0 over :data:`FEATHER` of the window at each edge that is not the
    image's (by the pixel centres' distances to it)."""
    h, w, c = (int(n) for n in window_image.shape)
    width = int(image.shape[1])
    u0, v0, *pads = offsets
    j = dr.arange(mi.UInt32, h * w * c)
    pixel = j // c
    x, y = pixel % w, pixel // w
    index = ((v0 + y) * width + (u0 + x)) * c + j % c
    xc, yc = mi.Float(x) + 0.5, mi.Float(y) + 0.5
    fx, fy = FEATHER * w, FEATHER * h
    wx = dr.minimum((xc + pads[0]) / fx, (w - xc + pads[1]) / fx)
    wy = dr.minimum((yc + pads[2]) / fy, (h - yc + pads[3]) / fy)
    weight = dr.clip(wx, 0.0, 1.0) * dr.clip(wy, 0.0, 1.0) * float(target_spp)
    frame = dr.gather(mi.Float, image.array, index)
    merged = (frame * float(spp) + window_image.array * weight) / (float(spp) + weight)
    dr.scatter(image.array, merged, index)
