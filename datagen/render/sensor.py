"""The camera after the render: what a real camera does to the light the path tracer
computed, in the light's order: image arithmetic on numpy arrays, and where a vectorized
variant renders, the motion blur and steps 4-8 with the 8-bit encoding (one kernel,
:func:`develop_on_device`: one copy back, of the 8-bit image) as Dr.Jit kernels on the
render's device.

1. motion blur: each pixel averaged along its true image motion over the exposure,
   centred on the frame's time (:func:`image_motion`, :func:`motion_blur`); then a
   rolling shutter's skew: each row as it was at its own time (:func:`rolling_shutter`);
2. lens distortion: the pinhole render, made with a margin, resampled through OpenCV's
   Brown-Conrady model (:func:`distort_image`), the model the labels are projected with;
3. the window the camera looks through: dirt, droplets, a windscreen's reflection
   (:mod:`datagen.render.window`), then the lens's blur and lateral chromatic aberration (:func:`lens_blur`,
   :func:`chromatic_aberration`: red and blue magnified about the principal point, green,
   which carries most of the luma, where the labels project);
4. vignetting: ``1 - v r^2`` falloff, ``r`` = 1 at the corners;
5. veiling glare and ghosts from the sun when it is in or near the view (:func:`sun_glare`);
6. exposure: fixed (``exposure_ev``) or metered (:func:`auto_exposure_scale`);
7. photon shot noise and read noise at the drawn ISO (:func:`sensor_noise`);
8. the camera's processing: a white balance set for another light than the scene's
   (:func:`white_balance_gains`), then (with the sRGB encoding, in one table) a tone curve
   (:func:`datagen.render.tonemap.tone_curve`);
9. after the sRGB encoding: a JPEG round trip (:func:`jpeg_round_trip`), or on a share of
   frames an H.264 one (:func:`video_round_trip`).

Each step is skipped where its draw is None (its switch off).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Final

import numpy as np
from numpy.typing import NDArray

from datagen.core.camera import Intrinsics, distort_normalized, distortion_margin_px, undistort_px
from datagen.core.conventions import (
    OBJECT_NAMES,
    OTHER_AIRCRAFT_ID,
    REC709_LUMA,
    index_px,
    object_id,
    pixel_centre,
    pixel_centres,
    row_time_s,
    texture_rng,
)
from datagen.core.transforms import invert_rigid
from datagen.render.timing import StageClock
from datagen.render.tonemap import SRGB_LEVELS, WHITE_RADIANCE, encoding_table, exposure_scale

if TYPE_CHECKING:
    from datagen.scene.approach import FrameState
    from datagen.scene.look import FrameLook

__all__ = [
    "AUTO_EXPOSURE_KEY",
    "FULL_WELL_E",
    "MOTION_STRIDE",
    "READ_NOISE_E",
    "Development",
    "SensorResult",
    "apply_sensor",
    "auto_exposure_scale",
    "chromatic_aberration",
    "daylight_white",
    "develop",
    "develop_on_device",
    "distort_image",
    "distortion_margin_px",
    "image_motion",
    "jpeg_round_trip",
    "lens_blur",
    "motion_blur",
    "noise_sigma",
    "rolling_shutter",
    "sensor_noise",
    "sun_glare",
    "tone_of",
    "video_round_trip",
    "warm_up_on_device",
    "white_balance_gains",
]

#: Electrons a pixel holds at ISO 100 (a 4-5 um industrial sensor); ISO S holds 100/S of it.
FULL_WELL_E: Final = 15_000.0
#: Read noise, electrons RMS.
READ_NOISE_E: Final = 3.0
#: Auto-exposure maps the centre-weighted log-average luminance to this display value.
AUTO_EXPOSURE_KEY: Final = 0.18
#: Auto-exposure stays within this many stops of the fixed exposure.
AUTO_EXPOSURE_STOPS: Final = 2.0
#: Glare is applied when the sun is within this many degrees outside the field of view.
GLARE_REACH_DEG: Final = 25.0
#: The glare's grid is at most this many times coarser than the image (:func:`sun_glare`).
GLARE_STEP: Final = 4
#: The lens's ghosts: where on the line from the image centre to the sun (0: the centre,
#: 1: the sun), their radius (a share of the image's width) and their tint.
GHOSTS: Final = ((-0.4, 0.05, (0.6, 0.8, 1.0)), (-0.9, 0.09, (0.7, 1.0, 0.6)), (0.5, 0.03, (1.0, 0.7, 0.5)))
#: Mixed into the noise's seed for the PCG32 streams' increment (any odd-bit pattern will do).
NOISE_STREAM: Final = 0x9E3779B97F4A7C15
#: The image motion is computed at one pixel of every ``MOTION_STRIDE`` x ``MOTION_STRIDE`` block.
MOTION_STRIDE: Final = 2
#: Most samples along a pixel's motion.
MAX_BLUR_SAMPLES: Final = 24



@dataclass
class SensorResult:
    """The sensor's output and what it measured on the way."""

    # display-linear RGB (1 = white), noise included; where the device holds it, a function that copies it back
    linear: NDArray[np.float32] | Callable[[], NDArray[np.float32]]
    depth: NDArray[np.float32] | None
    object_id: NDArray[np.uint32] | None
    surface: NDArray[np.uint8] | None
    measured: dict = field(default_factory=dict)  # auto_exposure_ev, motion_blur_px, sun_in_view, sun_glare
    srgb8: NDArray[np.uint8] | None = None  # its 8-bit encoding (tone curve included) where the device made it


# --- motion -----------------------------------------------------------------------
def image_motion(state: FrameState, depth: NDArray[np.float32], ids: NDArray[np.uint32],
                 intrinsics: Intrinsics, stride: int = 1) -> NDArray[np.float32]:
    """Image velocity ``(H, W, 2)`` in pixels per second of what each pixel sees: its
    point (from the z-depth) carried by its object's motion relative to the camera
    (background: the world's; the sky: the camera's rotation alone), by finite
    difference against ``state.earlier``. With ``stride`` 2, computed at the top-left
    pixel of every 2 x 2 block only, in the image's pixels per second, shape
    ``(ceil(H / 2), ceil(W / 2), 2)``: the motion field is smooth, and :func:`motion_blur`
    takes it on that grid (a quarter of the work)."""
    full = depth.shape
    if stride > 1:
        out = image_motion(state, depth[::stride, ::stride], ids[::stride, ::stride],
                           Intrinsics(-(-full[1] // stride), -(-full[0] // stride), intrinsics.fx / stride,
                                      intrinsics.fy / stride, pixel_centre(float(index_px(intrinsics.cx)) / stride),
                                      pixel_centre(float(index_px(intrinsics.cy)) / stride)))
        return out * np.float32(stride)
    before = state.earlier
    h, w = depth.shape
    out = np.zeros((h, w, 2), np.float32)
    if before is None:
        return out
    dt = state.time_s - before.time_s
    k = intrinsics
    u = (pixel_centre(np.arange(w, dtype=np.float32)) - k.cx) / k.fx
    v = (pixel_centre(np.arange(h, dtype=np.float32)) - k.cy) / k.fy
    x_n, y_n = np.meshgrid(u, v)
    finite = np.isfinite(depth)
    earlier_from_now = {0: before.cam_from_world @ state.world_from_cam}  # the world (sea, clouds, sky)
    for name in OBJECT_NAMES:
        body = "drogue" if name == "hose" else name  # the hose moves with its drogue
        earlier_from_now[object_id(name)] = (before.cam_from_world @ before.world_from(body)
                                             @ invert_rigid(state.world_from(body)) @ state.world_from_cam)
    earlier_from_now[OTHER_AIRCRAFT_ID] = earlier_from_now[object_id("tanker")]  # it flies with the tanker
    for oid, m in earlier_from_now.items():
        sel = ids == oid
        if not sel.any():
            continue
        m = m.astype(np.float32)
        z = np.where(finite[sel], depth[sel], np.float32(1.0))
        p = np.stack([x_n[sel] * z, y_n[sel] * z, z], axis=-1)
        at_infinity = ~finite[sel]
        q = p @ m[:3, :3].T + np.where(at_infinity[:, None], np.float32(0.0), m[:3, 3])
        qz = np.maximum(q[:, 2], np.float32(1e-6))
        du = (x_n[sel] - q[:, 0] / qz) * k.fx / dt
        dv = (y_n[sel] - q[:, 1] / qz) * k.fy / dt
        out[sel] = np.stack([du, dv], axis=-1)
    return out


def motion_blur(rgb: NDArray[np.float32], displacement_px: NDArray[np.float32], *, stride: int = 1,
                device: bool = False) -> NDArray[np.float32]:
    """Average each pixel over its displacement during the exposure, centred on the
    pixel (the frame's time is the middle of the exposure, where the labels are): ``n``
    bilinear samples evenly spaced along it, ``n`` from the longest displacement (at most
    :data:`MAX_BLUR_SAMPLES`), the image reflected at its border (OpenCV's
    ``BORDER_REFLECT``). ``displacement_px`` is given at the top-left pixel of every
    ``stride`` x ``stride`` block and holds over the block (:func:`image_motion`). With
    ``device``, on the render's device (a vectorized Mitsuba variant is set:
    :func:`_motion_blur_on_device`), else with OpenCV's ``remap``.

    A displacement longer than the image's diagonal (a pixel near the horizon of a very
    wide lens) is shortened to it: beyond that, the average crosses the whole image
    either way, and the reflected border would walk the excess a width at a time."""
    h, w = rgb.shape[:2]
    grid = (-(-h // stride), -(-w // stride))
    if displacement_px.shape[:2] != grid:
        raise ValueError(f"a {w}x{h} image's displacement at stride {stride} is {grid[1]}x{grid[0]}, "
                         f"not {displacement_px.shape[1]}x{displacement_px.shape[0]}")
    lengths = np.sqrt((displacement_px**2).sum(axis=-1))
    diagonal = np.float32(math.hypot(w, h))
    if not (np.isfinite(lengths).all() and lengths.max(initial=0.0) <= diagonal):
        finite = np.isfinite(lengths)
        scale = np.where(finite, np.minimum(np.float32(1.0), diagonal / np.where(finite, np.maximum(lengths, 1e-30),
                                                                                   1.0)), 0.0)
        displacement_px = np.where(finite[..., None], displacement_px, 0.0) * scale[..., None].astype(np.float32)
        lengths = np.sqrt((displacement_px**2).sum(axis=-1))
    length = float(lengths.max(initial=0.0))
    if length < 0.25:
        return rgb
    n = int(min(MAX_BLUR_SAMPLES, max(2, math.ceil(2.0 * length))))
    if device:
        return _motion_blur_on_device(rgb, displacement_px, stride, n)
    import cv2

    if stride > 1:
        displacement_px = np.repeat(np.repeat(displacement_px, stride, axis=0), stride, axis=1)[:h, :w]
    gx, gy = np.meshgrid(np.arange(w, dtype=np.float32), np.arange(h, dtype=np.float32))
    out = np.zeros_like(rgb)
    for s in (np.arange(n, dtype=np.float32) + 0.5) / n - 0.5:
        out += cv2.remap(rgb, gx + s * displacement_px[..., 0], gy + s * displacement_px[..., 1],
                         cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT)
    return out / np.float32(n)


def _motion_blur_on_device(rgb: NDArray[np.float32], displacement_px: NDArray[np.float32], stride: int,
                           n: int) -> NDArray[np.float32]:
    """:func:`motion_blur`'s ``n`` samples as one Dr.Jit kernel on the render's device: each
    pixel's displacement gathered from its block, a symbolic loop over the samples (``n``,
    the image's size and the step are opaque, so every frame runs the same kernel),
    bilinear gathers from the image's channels."""
    import drjit as dr
    import mitsuba as mi

    from datagen.render.mitsuba import jit_array

    h, w = rgb.shape[:2]
    channels = [jit_array(mi.Float, rgb[..., c].reshape(-1)) for c in range(3)]
    width, height = dr.opaque(mi.Int32, w), dr.opaque(mi.Int32, h)
    index = mi.Int32(dr.arange(mi.UInt32, h * w))
    col, row = index % width, index // width
    block = dr.opaque(mi.Int32, stride)
    block_index = mi.UInt32((row // block) * dr.opaque(mi.Int32, displacement_px.shape[1]) + col // block)
    dx, dy = (dr.gather(mi.Float, jit_array(mi.Float, displacement_px[..., i].reshape(-1)), block_index)
              for i in range(2))
    px, py = mi.Float(col), mi.Float(row)  # OpenCV's grid: integers at pixel centres
    samples, step = dr.opaque(mi.UInt32, n), dr.opaque(mi.Float, 1.0 / n)

    def reflected(i, size):  # BORDER_REFLECT, repeated: ... c b a | a b c ... z | z y x ...
        m = i % (2 * size)
        m = dr.select(m < 0, m + 2 * size, m)
        return dr.select(m < size, m, 2 * size - 1 - m)

    def body(i, *sums):
        s = (mi.Float(i) + 0.5) * step - 0.5
        x, y = px + s * dx, py + s * dy
        x0, y0 = dr.floor(x), dr.floor(y)
        fx, fy = x - x0, y - y0
        c0, c1 = reflected(mi.Int32(x0), width), reflected(mi.Int32(x0) + 1, width)
        r0, r1 = reflected(mi.Int32(y0), height) * width, reflected(mi.Int32(y0) + 1, height) * width
        out = []
        for channel, total in zip(channels, sums):
            def at(j, channel=channel):
                return dr.gather(mi.Float, channel, mi.UInt32(j))
            top = dr.lerp(at(r0 + c0), at(r0 + c1), fx)
            bottom = dr.lerp(at(r1 + c0), at(r1 + c1), fx)
            out.append(total + dr.lerp(top, bottom, fy))
        return (i + 1, *out)

    zero = dr.zeros(mi.Float, h * w)
    _, *sums = dr.while_loop(state=(mi.UInt32(0), zero, mi.Float(zero), mi.Float(zero)),
                             cond=lambda i, *_: i < samples, body=body)
    sums = [total * step for total in sums]
    dr.eval(sums)
    return np.stack([np.asarray(total, dtype=np.float32) for total in sums], axis=-1).reshape(h, w, 3)


def warm_up_on_device() -> None:
    """Compile (or load) the camera model's device kernels that a frame launches only
    sometimes, on a 4 x 4 image: the motion blur runs only where a frame's image moves a
    quarter pixel or more, so without this a worker whose first frames stand still would
    compile it frames later (the kernels do not depend on the image's size)."""
    rgb = np.zeros((4, 4, 3), np.float32)
    _motion_blur_on_device(rgb, np.ones((2, 2, 2), np.float32), MOTION_STRIDE, 2)


# --- distortion --------------------------------------------------------------------
def _remap(images: dict[str, NDArray], map_x: NDArray[np.float32], map_y: NDArray[np.float32],
           border: int) -> dict[str, NDArray]:
    """Each of ``images`` resampled at ``(map_x, map_y)`` (OpenCV's grid): bilinear for ``rgb``,
    nearest for the geometry pass (object ids through float32 and back); None stays None."""
    import cv2

    out: dict[str, NDArray] = {}
    for name, img in images.items():
        if img is None:
            out[name] = None
            continue
        interp = cv2.INTER_LINEAR if name == "rgb" else cv2.INTER_NEAREST
        src_img = img if img.dtype != np.uint32 else img.astype(np.float32)
        warped = cv2.remap(src_img, map_x, map_y, interp, borderMode=border)
        out[name] = warped.astype(img.dtype) if img.dtype == np.uint32 else warped
    return out


def rolling_shutter(images: dict[str, NDArray], velocity_px_s: NDArray[np.float32], stride: int, readout_s: float,
                    output: Intrinsics, margin_px: int, distortion=None) -> dict[str, NDArray]:
    """Pinhole renders (``output`` grown by ``margin_px`` on every side) as a rolling shutter
    of ``readout_s`` sees them: each pixel shows what its point showed at its row's time
    (:func:`datagen.core.conventions.row_time_s` of the row it lands on in the output image,
    through the lens ``distortion`` when given), the content carried there along its image
    velocity (``velocity_px_s`` at ``stride``: :func:`image_motion`), to first order, as the
    labels carry each point (:func:`datagen.core.camera.project_rolling`). Bilinear for
    ``rgb``, nearest for the geometry pass; the border reflected."""
    import cv2

    h, w = images["rgb"].shape[:2]
    uu, vv = (c.astype(np.float64) - margin_px for c in pixel_centres(w, h))
    if distortion is not None:
        _, yn = distort_normalized((uu - output.cx) / output.fx, (vv - output.cy) / output.fy, distortion)
        vv = yn * output.fy + output.cy
    t = row_time_s(vv, output.height, readout_s).astype(np.float32)
    v = np.repeat(np.repeat(velocity_px_s, stride, axis=0), stride, axis=1)[:h, :w]
    gx, gy = np.meshgrid(np.arange(w, dtype=np.float32), np.arange(h, dtype=np.float32))
    map_x, map_y = gx - v[..., 0] * t, gy - v[..., 1] * t
    return _remap(images, map_x, map_y, cv2.BORDER_REFLECT)


def distort_image(images: dict[str, NDArray], output: Intrinsics, margin_px: int,
                  distortion) -> dict[str, NDArray]:
    """Resample pinhole renders (``output`` grown by ``margin_px`` on every side) into the
    distorted ``output`` image: each output pixel centre takes the pinhole pixel the lens
    maps onto it (bilinear for ``rgb``, nearest for the geometry pass)."""
    import cv2

    w, h = output.width, output.height
    uu, vv = pixel_centres(w, h)
    src = undistort_px(np.stack([uu, vv], axis=-1), output, distortion)
    # Continuous pinhole pixels -> the render's OpenCV grid (integers at pixel centres).
    map_x = index_px(src[..., 0] + margin_px).astype(np.float32)
    map_y = index_px(src[..., 1] + margin_px).astype(np.float32)
    return _remap(images, map_x, map_y, cv2.BORDER_REPLICATE)


# --- lens -----------------------------------------------------------------------------
def vignette(rgb: NDArray[np.float32], strength: float) -> NDArray[np.float32]:
    """``1 - strength r^2`` with ``r`` the distance from the centre, 1 at the corners."""
    return rgb * _falloff(np.float32(strength), _radius2(*rgb.shape[:2]))[..., None]


@functools.lru_cache(maxsize=4)
def _radius2(h: int, w: int) -> NDArray[np.float32]:
    """(h, w): each pixel centre's squared distance from the image's centre, 1 at the corners."""
    x = pixel_centre(np.arange(w, dtype=np.float32)) / w * 2 - 1
    y = pixel_centre(np.arange(h, dtype=np.float32)) / h * 2 - 1
    r2 = (x[None, :] ** 2 * w * w + y[:, None] ** 2 * h * h) / np.float32(w * w + h * h)
    r2.flags.writeable = False
    return r2


def _falloff(strength, r2):
    """The vignetting's factor at squared radius ``r2`` (numpy or Dr.Jit)."""
    return 1.0 - strength * r2


def lens_blur(rgb: NDArray[np.float32], sigma_px: float) -> NDArray[np.float32]:
    """The lens's point spread: a Gaussian of ``sigma_px`` (its 10-90% edge width is 2.56 sigma)."""
    import cv2

    if sigma_px <= 0.0:
        return rgb
    return np.asarray(cv2.GaussianBlur(rgb, (0, 0), sigmaX=float(sigma_px), borderType=cv2.BORDER_REFLECT), np.float32)


def chromatic_aberration(rgb: NDArray[np.float32], intrinsics: Intrinsics, corner_px: float) -> NDArray[np.float32]:
    """Lateral chromatic aberration: red magnified and blue shrunk about the principal point,
    each by ``corner_px`` at the image's farthest corner (green stays: the labels' centres)."""
    import cv2

    if corner_px <= 0.0:
        return rgb
    h, w = rgb.shape[:2]
    cx, cy = float(index_px(intrinsics.cx)), float(index_px(intrinsics.cy))  # the principal point, OpenCV's grid
    reach = math.hypot(max(cx, w - 1 - cx), max(cy, h - 1 - cy))
    out = rgb.copy()
    for channel, sign in ((0, 1.0), (2, -1.0)):
        m = 1.0 + sign * corner_px / reach  # the channel's magnification
        affine = np.array([[1.0 / m, 0.0, cx - cx / m], [0.0, 1.0 / m, cy - cy / m]])  # destination -> source
        out[..., channel] = cv2.warpAffine(np.ascontiguousarray(rgb[..., channel]), affine, (w, h),
                                           flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                                           borderMode=cv2.BORDER_REPLICATE)
    return out


def sun_glare(shape: tuple[int, int], intrinsics: Intrinsics, sun_cam: NDArray, strength: float,
              radiance: float, step: int | None = None) -> tuple[NDArray[np.float32] | None, bool]:
    """Veiling glare (a ``theta0^2 / (theta^2 + theta0^2)`` halo around the sun, theta0 = 2
    degrees) and three ghosts on the line from the sun through the image centre, in linear
    radiance, or None when the sun is more than :data:`GLARE_REACH_DEG` outside the view.
    Also returns whether the sun is inside the image.

    Both are smooth over many pixels (the halo's core spans 4 degrees; the ghosts' edges are
    blurred over 0.4% of the width, as a disc seen through a Gaussian of that width): they
    are computed on a grid ``step`` times coarser than the image and resized bilinearly (by
    default the step is half the ghosts' blur, at most :data:`GLARE_STEP`; 1: at every
    pixel)."""
    import cv2

    h, w = shape
    k = intrinsics
    d = np.asarray(sun_cam, dtype=np.float64)
    d = d / np.linalg.norm(d)
    corner = np.array([k.cx / k.fx, k.cy / k.fy, 1.0])
    half_diagonal = math.degrees(math.acos(1.0 / np.linalg.norm(corner)))
    off_axis = math.degrees(math.acos(np.clip(d[2], -1.0, 1.0)))
    if strength <= 0.0 or off_axis > half_diagonal + GLARE_REACH_DEG:
        return None, False
    blur_px = max(1.0, 0.004 * w)
    step = step or max(1, min(GLARE_STEP, int(blur_px / 2.0)))
    pad = 1  # samples beyond the image on every side
    cw, ch = -(-w // step) + 2 * pad, -(-h // step) + 2 * pad
    # Sample i of the grid sits at continuous pixel (i - pad + 1/2) step of the image: where
    # an exact resize by ``step`` puts it, the image starting ``pad * step`` pixels in.
    x = ((np.arange(cw) - pad + 0.5) * step - k.cx) / k.fx
    y = ((np.arange(ch) - pad + 0.5) * step - k.cy) / k.fy
    cos = (x[None, :] * d[0] + y[:, None] * d[1] + d[2]) / np.sqrt(x[None, :] ** 2 + y[:, None] ** 2 + 1.0)
    theta = np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))
    halo = (4.0 / (theta * theta + 4.0)).astype(np.float32)
    glare = np.repeat(halo[..., None], 3, axis=-1) * np.float32(strength * radiance)
    inside = False
    if d[2] > 0:
        su, sv = k.fx * d[0] / d[2] + k.cx, k.fy * d[1] / d[2] + k.cy
        inside = bool(0 <= su < w and 0 <= sv < h)
        from scipy.special import ndtr

        u, v = x * k.fx + k.cx, y * k.fy + k.cy  # the samples' continuous pixels
        for t, radius, tint in GHOSTS:
            gu, gv = k.cx + t * (su - k.cx), k.cy + t * (sv - k.cy)
            radius_px = max(2.0 * blur_px, radius * w)
            reach = radius_px + 4.0 * blur_px  # the samples the ghost's blurred edge reaches
            cols = slice(*np.searchsorted(u, [gu - reach, gu + reach]))
            rows = slice(*np.searchsorted(v, [gv - reach, gv + reach]))
            if cols.start == cols.stop or rows.start == rows.stop:
                continue
            # A disc blurred by a Gaussian of blur_px, by its edge's profile; the radius that
            # keeps the disc's light (pi radius^2) in the profile's (pi (r^2 + blur^2)).
            r = np.sqrt((u[None, cols] - gu) ** 2 + (v[rows, None] - gv) ** 2)
            disc = ndtr((math.sqrt(radius_px**2 - blur_px**2) - r) / blur_px).astype(np.float32)
            light = np.asarray(tint, np.float32) * np.float32(0.04 * strength * radiance)
            glare[rows, cols] += disc[..., None] * light
    if step > 1:
        glare = np.asarray(cv2.resize(glare, (cw * step, ch * step), interpolation=cv2.INTER_LINEAR), np.float32)
    return glare[pad * step:pad * step + h, pad * step:pad * step + w], inside


# --- exposure and noise ------------------------------------------------------------------
def auto_exposure_scale(rgb: NDArray[np.float32], vignetting: float = 0.0,
                        glare: NDArray[np.float32] | None = None) -> float:
    """The factor that maps the centre-weighted log-average luminance of linear ``rgb``, as
    :func:`develop` lights it before its exposure (``vignetting``, ``glare``), to
    :data:`AUTO_EXPOSURE_KEY`, within :data:`AUTO_EXPOSURE_STOPS` of the fixed exposure's
    (``1 / WHITE_RADIANCE``). Metered on every ``step``-th pixel of every ``step``-th row (no
    more than ~128 x 240 samples), vignetted and glared there only."""
    h, w = rgb.shape[:2]
    step = max(1, min(h, w) // 128)
    sub = rgb[::step, ::step]
    if vignetting:
        sub = sub * _falloff(np.float32(vignetting), _radius2(h, w)[::step, ::step])[..., None]
    if glare is not None:
        sub = sub + glare[::step, ::step]
    lum = sub @ REC709_LUMA
    y = (np.arange(sub.shape[0]) + 0.5) / sub.shape[0] - 0.5
    x = (np.arange(sub.shape[1]) + 0.5) / sub.shape[1] - 0.5
    weight = np.exp(-(x[None, :] ** 2 + y[:, None] ** 2) / (2 * 0.25**2))
    log_mean = float((weight * np.log(np.maximum(lum, 1e-6))).sum() / weight.sum())
    fixed = 1.0 / WHITE_RADIANCE
    metered = AUTO_EXPOSURE_KEY / math.exp(log_mean)
    return float(np.clip(metered, fixed * 2**-AUTO_EXPOSURE_STOPS, fixed * 2**AUTO_EXPOSURE_STOPS))


def sensor_noise(rgb: NDArray[np.float32], iso: float, seed: int, *, device: bool = False) -> NDArray[np.float32]:
    """Photon shot noise (Poisson, as its Gaussian limit) and read noise on display-linear
    ``rgb`` (1 = a full pixel): a full pixel holds ``FULL_WELL_E * 100 / iso`` electrons.
    The draws come from ``seed``: Dr.Jit's PCG32 on the render's device when ``device``
    (a vectorized Mitsuba variant is set; one stream per value, Box-Muller), else numpy's
    generator (:func:`datagen.core.conventions.texture_rng`)."""
    electrons = full_well_e(iso)
    if not device:
        normal = texture_rng(seed).standard_normal(rgb.shape, dtype=np.float32)
        return rgb + noise_sigma(np.clip(rgb, 0.0, 1.0), np.float32(electrons), np.sqrt) * normal
    import drjit as dr
    import mitsuba as mi

    from datagen.render.mitsuba import jit_array

    noisy = _noise_on_device(jit_array(mi.Float, rgb.reshape(-1)), seed, dr.opaque(mi.Float, electrons))
    dr.eval(noisy)
    return np.asarray(noisy, dtype=np.float32).reshape(rgb.shape)


def full_well_e(iso: float) -> float:
    """Electrons a full pixel holds at ``iso``."""
    return FULL_WELL_E * 100.0 / float(iso)


def _noise_on_device(x, seed: int, electrons, on=None):
    """:func:`sensor_noise` of the Dr.Jit array ``x`` (one value per lane, a stream per lane:
    Dr.Jit's PCG32, Box-Muller); ``on``, an opaque 0 or 1, scales the noise (a kernel the
    same with it or without)."""
    import drjit as dr
    import mitsuba as mi

    state = seed % 2**64
    pcg32: Any = mi.PCG32  # (a class of the variant)
    pcg = pcg32(dr.width(x), dr.opaque(mi.UInt64, state), dr.opaque(mi.UInt64, state ^ NOISE_STREAM))
    u1, u2 = pcg.next_float32(), pcg.next_float32()
    normal = dr.sqrt(-2.0 * dr.log(1.0 - u1)) * dr.cos(2.0 * dr.pi * u2)
    noise = noise_sigma(dr.clip(x, 0.0, 1.0), electrons, dr.sqrt) * normal
    return x + (noise if on is None else noise * on)


def noise_sigma(signal, electrons, sqrt):
    """The standard deviation of the noise on display-linear ``signal`` in [0, 1] (numpy or
    Dr.Jit arrays, ``sqrt`` theirs): shot noise of ``signal * electrons`` electrons and
    :data:`READ_NOISE_E`, over the full pixel's ``electrons``."""
    return sqrt(signal * electrons + READ_NOISE_E**2) / electrons


# --- the camera's processing ----------------------------------------------------------------
#: linear sRGB (Rec. 709 primaries) from CIE XYZ.
_SRGB_FROM_XYZ: Final = np.array([[3.2404542, -1.5371385, -0.4985314], [-0.9692660, 1.8760108, 0.0415560],
                                  [0.0556434, -0.2040259, 1.0572252]])
#: The white the rendered image is balanced for (D65's correlated colour temperature, K).
D65_K: Final = 6504.0


def daylight_white(temperature_k: float) -> NDArray[np.float64]:
    """Linear sRGB of the CIE daylight illuminant at ``temperature_k`` (4000-25000 K; the CIE's
    daylight-locus chromaticity), scaled to luminance 1."""
    t = float(np.clip(temperature_k, 4000.0, 25000.0))
    if t <= 7000.0:
        x = -4.6070e9 / t**3 + 2.9678e6 / t**2 + 0.09911e3 / t + 0.244063
    else:
        x = -2.0064e9 / t**3 + 1.9018e6 / t**2 + 0.24748e3 / t + 0.237040
    y = -3.0 * x * x + 2.870 * x - 0.275
    return _SRGB_FROM_XYZ @ np.array([x / y, 1.0, (1.0 - x - y) / y])


def white_balance_gains(temperature_k: float, tint: float) -> NDArray[np.float32]:
    """Per-channel gains of a camera white-balanced for daylight of ``temperature_k`` while the
    scene's white is D65 (a lower temperature turns the image blue, a higher one amber), green
    scaled by ``1 + tint`` (magenta below 0); a grey's luminance is kept."""
    gains = daylight_white(D65_K) / daylight_white(temperature_k)
    gains[1] *= 1.0 + tint
    return (gains / float(REC709_LUMA @ gains)).astype(np.float32)


def jpeg_round_trip(srgb8: NDArray[np.uint8], quality: int) -> NDArray[np.uint8]:
    """An 8-bit RGB image through a JPEG encoder and decoder at ``quality``."""
    import cv2

    ok, data = cv2.imencode(".jpg", np.ascontiguousarray(srgb8[..., ::-1]), [cv2.IMWRITE_JPEG_QUALITY, int(quality)])
    if not ok:
        raise RuntimeError("OpenCV could not encode a JPEG")
    decoded = cv2.imdecode(data, cv2.IMREAD_COLOR)
    if decoded is None:
        raise RuntimeError("OpenCV could not decode its own JPEG")
    return np.asarray(decoded, np.uint8)[..., ::-1]


def video_round_trip(srgb8: NDArray[np.uint8], crf: int) -> NDArray[np.uint8]:
    """An 8-bit RGB image through an H.264 encoder and decoder (PyAV's x264 and FFmpeg, one
    thread each, so that it is the same on every machine): BT.601 limited-range 4:2:0, the
    ``veryfast`` preset at constant rate factor ``crf``, the frame coded as a key frame (the
    artefacts of a video link's intra coding: chroma halved, blocks smoothed by the
    deblocking filter; a P frame's motion smear is not modelled). An odd side is padded by
    its last row or column for the 4:2:0 planes, and cropped again."""
    from fractions import Fraction

    import av

    h, w = srgb8.shape[:2]
    even = np.pad(srgb8, ((0, h % 2), (0, w % 2), (0, 0)), mode="edge")
    encoder = av.CodecContext.create("libx264", "w")
    encoder.width, encoder.height, encoder.pix_fmt = even.shape[1], even.shape[0], "yuv420p"
    encoder.time_base, encoder.thread_count = Fraction(1, 30), 1
    encoder.options = {"crf": str(int(crf)), "preset": "veryfast"}
    frame = av.VideoFrame.from_ndarray(np.ascontiguousarray(even), format="rgb24").reformat(format="yuv420p")
    packets = [*encoder.encode(frame), *encoder.encode(None)]
    decoder = av.CodecContext.create("h264", "r")
    decoder.thread_count = 1
    decoded = [f for p in packets for f in decoder.decode(p)] + list(decoder.decode(None))
    if len(decoded) != 1:
        raise RuntimeError(f"H.264 round trip gave {len(decoded)} frames, not one")
    return np.ascontiguousarray(decoded[0].to_ndarray(format="rgb24")[:h, :w])


# --- the whole camera --------------------------------------------------------------------
def apply_sensor(rgb: NDArray[np.float32], look: FrameLook, state: FrameState, *, render: Intrinsics,
                 output: Intrinsics, margin_px: int, depth, ids, surface, sun_cam: NDArray,
                 sun_transmittance: float, auto_exposure: bool, clock: StageClock | None = None,
                 device: bool = False) -> SensorResult:
    """Linear radiance (the render grid, ``margin_px`` wider than ``output`` on every side)
    to display-linear RGB on the output grid, through the frame's drawn camera (each step
    timed on ``clock``; ``device``: the motion blur and the noise on the render's device)."""
    clock = clock or StageClock()
    measured: dict = {"motion_blur_px": None, "auto_exposure_ev": None, "sun_in_view": None}
    velocity = None
    if look.sensor_exposure_time_s is not None and depth is not None:
        with clock.stage("motion blur"):
            velocity = image_motion(state, depth, ids, render, stride=MOTION_STRIDE)
            displacement = velocity * np.float32(look.sensor_exposure_time_s)
            measured["motion_blur_px"] = float(np.sqrt((displacement**2).sum(axis=-1)).max(initial=0.0))
            rgb = motion_blur(rgb, displacement, stride=MOTION_STRIDE, device=device)
    if look.sensor_readout_s is not None and depth is not None:
        with clock.stage("rolling shutter"):
            if velocity is None:
                velocity = image_motion(state, depth, ids, render, stride=MOTION_STRIDE)
            skewed = rolling_shutter({"rgb": rgb, "depth": depth, "ids": ids, "surface": surface}, velocity,
                                     MOTION_STRIDE, look.sensor_readout_s, output, margin_px,
                                     None if look.sensor_distortion is None else np.asarray(look.sensor_distortion))
            rgb, depth, ids, surface = skewed["rgb"], skewed["depth"], skewed["ids"], skewed["surface"]
    if look.sensor_distortion is not None:
        with clock.stage("lens distortion"):
            warped = distort_image({"rgb": rgb, "depth": depth, "ids": ids, "surface": surface}, output, margin_px,
                                   np.asarray(look.sensor_distortion))
            rgb, depth, ids, surface = warped["rgb"], warped["depth"], warped["ids"], warped["surface"]
    if look.window_seed is not None:
        from datagen.render.window import defocus_near, dirty, droplets, reflection

        with clock.stage("window"):
            if look.window_reflection is not None:  # a windscreen: its frame, near the lens
                rgb = defocus_near(rgb, depth, output.fx)
            rgb = reflection(dirty(droplets(rgb, look.window_droplets or 0, look.window_seed),
                                   look.window_dirt or 0.0, look.window_seed),
                             look.window_reflection or 0.0, look.window_seed)
    if look.sensor_lens_blur_px is not None:
        with clock.stage("lens blur"):
            rgb = chromatic_aberration(lens_blur(rgb, look.sensor_lens_blur_px), output,
                                       look.sensor_chromatic_aberration_px or 0.0)
    with clock.stage("vignetting, glare, exposure"):
        glare = None
        if look.sensor_glare is not None:
            sun_radiance = 2.0 * WHITE_RADIANCE * look.sun_scale * sun_transmittance
            glare, inside = sun_glare(rgb.shape[:2], output, sun_cam, look.sensor_glare, sun_radiance)
            measured["sun_in_view"] = inside
        fixed = float(exposure_scale(0.0))
        vignetting = look.sensor_vignetting or 0.0
        scale = auto_exposure_scale(rgb, vignetting, glare) if auto_exposure else fixed
        measured["auto_exposure_ev"] = math.log2(scale / fixed) if auto_exposure else None
        steps = Development(vignetting, glare, float(np.float32(scale * 2.0**look.exposure_ev)),
                            None if look.sensor_iso is None or look.sensor_seed is None  # (drawn together)
                            else (look.sensor_iso, look.sensor_seed),
                            None if look.sensor_white_balance_k is None
                            else white_balance_gains(look.sensor_white_balance_k, look.sensor_tint or 0.0),
                            tone_of(look))
    if device:
        with clock.stage("vignetting to 8 bits on the device"):
            linear, srgb8 = develop_on_device(rgb, steps)
        return SensorResult(linear, depth, ids, surface, measured, srgb8)
    return SensorResult(develop(rgb, steps, clock), depth, ids, surface, measured)


def tone_of(look: FrameLook) -> tuple[float, float] | None:
    """The frame's tone curve (gamma, shoulder) for :func:`~datagen.render.tonemap.encoding_table`, or None."""
    return None if look.sensor_tone_gamma is None else (look.sensor_tone_gamma, look.sensor_tone_shoulder or 0.0)


@dataclass(frozen=True)
class Development:
    """A frame's last steps from the lens's image to its 8-bit encoding, as drawn and metered."""

    vignetting: float  # the falloff's strength (0: none)
    glare: NDArray[np.float32] | None  # (H, W, 3) linear radiance the sun's glare adds
    gain: float  # the exposure's factor (a float32 value)
    noise: tuple[float, int] | None  # (ISO, seed) of the sensor's noise
    white_balance: NDArray[np.float32] | None  # per-channel gains
    tone: tuple[float, float] | None  # the tone curve, in the encoding's table


def develop(rgb: NDArray[np.float32], steps: Development, clock: StageClock | None = None) -> NDArray[np.float32]:
    """The display-linear image of ``rgb`` (the lens's, linear radiance) in numpy: vignetted,
    glared, exposed, noisy (numpy's generator), clipped at 0 and white-balanced; its 8-bit
    encoding is :func:`~datagen.render.tonemap.to_srgb8` of it with ``steps.tone``."""
    clock = clock or StageClock()
    with clock.stage("vignetting, glare, exposure"):
        if steps.vignetting:
            rgb = vignette(rgb, steps.vignetting)
        if steps.glare is not None:
            rgb = rgb + steps.glare
        rgb = rgb * np.float32(steps.gain)
    with clock.stage("sensor noise"):
        if steps.noise is not None:
            rgb = sensor_noise(rgb, *steps.noise)
        rgb = np.maximum(rgb, np.float32(0.0)).astype(np.float32)
    if steps.white_balance is not None:
        with clock.stage("white balance"):
            rgb *= steps.white_balance
    return rgb


def develop_on_device(rgb: NDArray[np.float32], steps: Development
                      ) -> tuple[Callable[[], NDArray[np.float32]], NDArray[np.uint8]]:
    """:func:`develop` and the 8-bit encoding as one Dr.Jit kernel on the render's device (a
    vectorized Mitsuba variant is set; the noise Dr.Jit's, :func:`sensor_noise`'s device
    path): the 8-bit image, copied back, and a function that copies back the display-linear
    one, left on the device until asked for. The same kernel for every frame: every step
    runs, a missing one as its identity (no falloff, a glare of 0, noise scaled by 0, gains
    of 1), and each frame's values are opaque."""
    import drjit as dr
    import mitsuba as mi

    from datagen.render.mitsuba import jit_array

    h, w = rgb.shape[:2]
    x = jit_array(mi.Float, rgb.reshape(-1))  # (H, W, 3) flattened: a lane per value
    index = dr.arange(mi.UInt32, h * w * 3)
    r2 = _radius2_on_device(mi.variant() or "", h, w)
    x = x * _falloff(dr.opaque(mi.Float, steps.vignetting), dr.gather(mi.Float, r2, index // 3))
    # (No glare: two zeros; one value would be read as a scalar, another kernel.)
    glare = jit_array(mi.Float, np.zeros(2, np.float32) if steps.glare is None else steps.glare.reshape(-1))
    x = x + dr.gather(mi.Float, glare, index * dr.opaque(mi.UInt32, int(steps.glare is not None)))
    x = x * dr.opaque(mi.Float, steps.gain)
    iso, seed = steps.noise if steps.noise is not None else (100.0, 0)
    x = _noise_on_device(x, seed, dr.opaque(mi.Float, full_well_e(iso)),
                         dr.opaque(mi.Float, float(steps.noise is not None)))
    x = dr.maximum(x, 0.0)
    gains = jit_array(mi.Float, np.ones(3, np.float32) if steps.white_balance is None else steps.white_balance)
    x = x * dr.gather(mi.Float, gains, index % 3)
    table, top = encoding_table(steps.tone)
    uint8: Any = dr.uint8_array_t(mi.Float)  # (a class of the variant)
    codes = uint8(np.ascontiguousarray(table))
    entry = mi.UInt32(dr.round(dr.minimum(x, dr.opaque(mi.Float, top)) * float(SRGB_LEVELS - 1)))
    srgb8 = dr.gather(uint8, codes, entry)
    dr.eval(x, srgb8)
    return (lambda: np.asarray(x, dtype=np.float32).reshape(h, w, 3)), np.asarray(srgb8).reshape(h, w, 3)


@functools.lru_cache(maxsize=4)
def _radius2_on_device(variant: str, h: int, w: int):
    """:func:`_radius2` on the render's device (``variant``, the current one), uploaded once."""
    import mitsuba as mi

    from datagen.render.mitsuba import jit_array

    return jit_array(mi.Float, _radius2(h, w).reshape(-1))
