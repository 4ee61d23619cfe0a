"""What lies between the lens and the world: the window a pod camera looks through, with dirt
and water droplets on it, and the windscreen a cockpit camera looks through, which reflects
the cockpit. Image arithmetic on the linear render (numpy and OpenCV), before vignetting.

A window sits a few centimetres from a lens focused at infinity, so what is on it is far out
of focus: dirt scatters part of the light passing it into a wide veil (:func:`dirty`);
a droplet is a small lens that shows the scene behind it inverted and minified, blurred, and
darkens at its rim where it bends light out of the aperture (:func:`droplets`); a windscreen
adds a faint, smooth reflection of the lit cockpit (:func:`reflection`), and the windscreen's
frame, half a metre from the lens, is out of focus too (:func:`defocus_near`).

An approach's window (:data:`datagen.scene.look.FrameLook` ``window_*``) stays as it is over
its frames; its fields come from the recorded ``window_seed`` at any image size (positions and
sizes are shares of the image's width). Nothing here moves a label: a feature behind a
droplet is still where it projects.
"""

from __future__ import annotations

import functools
from typing import Any, Final

import numpy as np
from numpy.typing import NDArray

from datagen.core.conventions import texture_rng

__all__ = ["COCKPIT_APERTURE_M", "DROPLET_RADIUS", "EDGE", "NEAR_M", "STREAK", "VEIL_SIGMA", "defocus_near", "dirty",
           "droplets", "reflection", "window_field"]

#: Droplet radii, as shares of the image's width.
DROPLET_RADIUS: Final = (0.006, 0.03)
#: The scattered veil's Gaussian width, as a share of the image's width.
VEIL_SIGMA: Final = 0.03
#: A droplet's outline is blurred over this share of its radius (it is out of focus).
EDGE: Final = 0.2
#: How far the airflow draws a droplet out along it: its length over its width.
STREAK: Final = (1.0, 3.5)
#: The veil is computed on an image this many times smaller (it is smooth).
VEIL_STEP: Final = 8
#: The entrance pupil of a cockpit camera, metres (a small camera's lens of 6-10 mm at f/2-f/2.8).
COCKPIT_APERTURE_M: Final = 0.003
#: What is nearer than this, metres, is the windscreen's frame (nothing else comes this close).
NEAR_M: Final = 2.0


@functools.lru_cache(maxsize=8)
def window_field(seed: int, width: int, height: int, kind: str) -> NDArray[np.float32]:
    """A smooth field in [0, 1] over the image, ``(height, width)``: octaves of bicubically
    enlarged uniform noise from ``texture_rng(seed)`` (``kind``: another stream of the same seed),
    soft-thresholded into patches for ``"dirt"`` and left smooth for ``"reflection"``."""
    import cv2

    rng = texture_rng(seed + {"dirt": 1, "reflection": 2}[kind])
    total = np.zeros((height, width), np.float32)
    weight = 0.0
    for cells, amplitude in ((4, 1.0), (9, 0.55), (20, 0.3), (44, 0.15)):
        grid = rng.random((max(2, round(cells * height / width)), cells)).astype(np.float32)
        total += amplitude * cv2.resize(grid, (width, height), interpolation=cv2.INTER_CUBIC)
        weight += amplitude
    total /= weight
    if kind == "dirt":  # patches: the upper part of the field, soft-edged
        total = np.clip((total - 0.5) / 0.15, 0.0, 1.0)
    return np.clip(total, 0.0, 1.0)


def _veil(rgb: NDArray[np.float32]) -> NDArray[np.float32]:
    """The image seen through a wide scattering lobe: a Gaussian of :data:`VEIL_SIGMA` of the
    width, computed :data:`VEIL_STEP` times smaller and enlarged."""
    import cv2

    h, w = rgb.shape[:2]
    small = cv2.resize(rgb, (max(1, w // VEIL_STEP), max(1, h // VEIL_STEP)), interpolation=cv2.INTER_AREA)
    small = cv2.GaussianBlur(small, (0, 0), sigmaX=VEIL_SIGMA * w / VEIL_STEP, borderType=cv2.BORDER_REFLECT)
    return np.asarray(cv2.resize(small, (w, h), interpolation=cv2.INTER_LINEAR), np.float32)


@functools.lru_cache(maxsize=2)
def _dirt_weights(seed: int, width: int, height: int, strength: float) -> tuple[NDArray[np.float32], ...]:
    """``(h, w, 3)``: the share of the light dirt lets through, and the share it scatters into the veil."""
    d = np.repeat(window_field(seed, width, height, "dirt")[..., None], 3, axis=2) * np.float32(strength)
    return np.float32(1.0) - np.float32(0.75) * d, np.float32(0.6) * d


def dirty(rgb: NDArray[np.float32], strength: float, seed: int) -> NDArray[np.float32]:
    """Dirt on the window: where its field is ``d`` (:func:`window_field`), ``0.6 strength d``
    of the light is scattered into the veil and ``0.15 strength d`` absorbed."""
    import cv2

    if strength <= 0.0:
        return rgb
    h, w = rgb.shape[:2]
    passed, scattered = _dirt_weights(seed, w, h, float(strength))
    return np.asarray(cv2.add(cv2.multiply(rgb, passed), cv2.multiply(_veil(rgb), scattered)), np.float32)


def droplets(rgb: NDArray[np.float32], count: int, seed: int) -> NDArray[np.float32]:
    """``count`` water droplets on the window, each drawn from ``texture_rng(seed)``: an
    ellipse drawn out along the window's airflow (one direction for the window, each droplet
    :data:`STREAK` times longer than wide at most; of sizes from :data:`DROPLET_RADIUS`),
    whose inside shows the scene around it inverted and minified (a ball lens, squeezed the
    same way), blurred by the defocus, with a darker rim and an outline blurred over
    :data:`EDGE` of its width."""
    import cv2

    if count <= 0:
        return rgb
    h, w = rgb.shape[:2]
    rng = texture_rng(seed)
    flow = float(rng.uniform(0.0, np.pi))  # the airflow's direction across the window, one for all droplets
    c, s = np.float32(np.cos(flow)), np.float32(np.sin(flow))
    out = rgb.copy()
    for _ in range(int(count)):
        cx, cy = rng.uniform(0.0, w), rng.uniform(0.0, h)
        r = float(np.exp(rng.uniform(*np.log(DROPLET_RADIUS)))) * w
        minify = float(rng.uniform(0.3, 0.7))
        stretch = float(rng.uniform(*STREAK))
        reach = r * stretch
        x0, x1 = max(int(cx - reach) - 1, 0), min(int(cx + reach) + 2, w)
        y0, y1 = max(int(cy - reach) - 1, 0), min(int(cy + reach) + 2, h)
        if x1 - x0 < 2 or y1 - y0 < 2:
            continue
        ys, xs = np.mgrid[y0:y1, x0:x1].astype(np.float32) + np.float32(0.5)
        dx, dy = xs - np.float32(cx), ys - np.float32(cy)
        along, across = (dx * c + dy * s) / np.float32(stretch), -dx * s + dy * c  # the droplet's round frame
        rho = np.sqrt(along * along + across * across) / np.float32(r)
        # Inverted and minified about the centre, reaching 1 / minify droplet radii out.
        map_x = (np.float32(cx) - dx / np.float32(minify) - 0.5).astype(np.float32)
        map_y = (np.float32(cy) - dy / np.float32(minify) - 0.5).astype(np.float32)
        seen = cv2.remap(rgb, map_x, map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT)
        seen = cv2.GaussianBlur(seen, (0, 0), sigmaX=max(0.2 * r, 0.5), borderType=cv2.BORDER_REFLECT)
        rim = 1.0 - 0.35 * np.clip((rho - 0.6) / 0.4, 0.0, 1.0) ** 2  # light bent out near the edge
        alpha = np.clip((1.0 - rho) / EDGE, 0.0, 1.0)[..., None]  # the outline, out of focus
        patch = out[y0:y1, x0:x1]
        out[y0:y1, x0:x1] = patch * (1.0 - alpha) + alpha * seen * rim[..., None]
    return out


def defocus_near(rgb: NDArray[np.float32], depth: NDArray[np.float32] | None, fx: float,
                 aperture_m: float = COCKPIT_APERTURE_M) -> NDArray[np.float32]:
    """What lies nearer than :data:`NEAR_M` (the windscreen's frame) out of focus for a lens
    focused at infinity: a blur circle ``fx aperture / z`` pixels across at its median z-depth
    (a Gaussian of a quarter of it, a disc's standard deviation), composited over the scene
    behind it (which the render did not see there: filled from around it by normalized
    convolution), so that its edges blend into the sky as a real frame's do."""
    import cv2

    if depth is None:
        return rgb
    near = np.isfinite(depth) & (depth < NEAR_M)
    if not near.any():
        return rgb
    sigma = max(0.25 * fx * aperture_m / float(np.median(depth[near])), 0.3)
    alpha = near.astype(np.float32)
    h, w = alpha.shape
    # The scene behind the frame, from around it, on an image four times smaller (it is smooth there).
    step = 4
    small = (max(1, w // step), max(1, h // step))
    clear = cv2.resize(1.0 - alpha, small, interpolation=cv2.INTER_AREA)
    behind = cv2.resize(rgb * (1.0 - alpha)[..., None], small, interpolation=cv2.INTER_AREA)
    reach = 3.0 * sigma / step + 4.0
    clear = cv2.GaussianBlur(clear, (0, 0), reach, borderType=cv2.BORDER_REFLECT)
    behind = cv2.GaussianBlur(behind, (0, 0), reach, borderType=cv2.BORDER_REFLECT)
    fill = cv2.resize(behind / np.maximum(clear, 1e-6)[..., None], (w, h), interpolation=cv2.INTER_LINEAR)
    background = np.where(near[..., None], fill, rgb)
    front = cv2.GaussianBlur(rgb * alpha[..., None], (0, 0), sigma, borderType=cv2.BORDER_REFLECT)
    cover = cv2.GaussianBlur(alpha, (0, 0), sigma, borderType=cv2.BORDER_REFLECT)
    return (front + (1.0 - cover)[..., None] * background).astype(np.float32)


@functools.lru_cache(maxsize=2)
def _reflection_weights(seed: int, width: int, height: int, strength: float) -> NDArray[np.float32]:
    ramp = np.linspace(0.4, 1.0, height, dtype=np.float32)[:, None]
    field = window_field(seed, width, height, "reflection") * ramp * np.float32(strength)
    return np.repeat(field[..., None], 3, axis=2)


def reflection(rgb: NDArray[np.float32], strength: float, seed: int) -> NDArray[np.float32]:
    """A windscreen's reflection of the cockpit: a smooth field (:func:`window_field`), brighter
    towards the bottom where the glare shield is, at ``strength`` of the image's mean luminance,
    grey (the cockpit's lit surfaces: a helmet, a flight suit, the sill; not the scene's colour)."""
    import cv2

    from datagen.core.conventions import luminance

    if strength <= 0.0:
        return rgb
    h, w = rgb.shape[:2]
    mean = float(luminance(rgb).mean(dtype=np.float64))
    scale: Any = (mean, mean, mean, 0.0)  # a scalar per channel (OpenCV's stubs allow only an array)
    return np.asarray(cv2.add(rgb, cv2.multiply(_reflection_weights(seed, w, h, float(strength)), scale)), np.float32)
