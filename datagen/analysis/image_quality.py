"""Image quality against a reference: PSNR and SSIM on the encoded image, and the share of
isolated outlier pixels ("fireflies") in a linear image (numpy and scipy only).

PSNR and SSIM compare what a detector is trained on: the 8-bit sRGB encoding of the
exposure-scaled linear image (:func:`datagen.render.tonemap.to_srgb8`), as floats in [0, 1].
"""

from __future__ import annotations

from typing import Final

import numpy as np
from numpy.typing import NDArray
from scipy.ndimage import gaussian_filter, median_filter, rank_filter

from datagen.core.conventions import luminance

__all__ = ["DETAIL_SIGMA_PX", "FIREFLY_MIN_EXCESS", "FIREFLY_RATIO", "SPECKLE_EXCESS", "detail_ratio", "detail_rms",
           "fireflies", "luminance", "noise_speckles", "psnr", "speckles", "ssim"]

#: A pixel is a firefly when its luminance exceeds the second brightest of its 8
#: neighbours by this factor ...
FIREFLY_RATIO: Final = 4.0
#: ... and by at least this much display-linear luminance (1 is white at the frame's
#: exposure): an isolated speckle a viewer sees, not a dim pixel beside a black one.
FIREFLY_MIN_EXCESS: Final = 0.25

#: An 8-bit pixel is a speckle when it is brighter than the median of its 5 x 5
#: neighbourhood by more than this many levels of 255 (in any channel).
SPECKLE_EXCESS: Final = 32

def fireflies(rgb: NDArray[np.floating]) -> NDArray[np.bool_]:
    """Pixels of a display-linear RGB image that stand far above their neighbourhood:
    luminance above :data:`FIREFLY_RATIO` times the second brightest of the 8
    neighbours and above it by :data:`FIREFLY_MIN_EXCESS`. A sun glint or a specular
    highlight covers several pixels, or at least a line of them, so that two of its
    neighbours are bright too, and does not count (but the last pixel of a line that
    ends abruptly would); two speckles side by side do count."""
    lum = luminance(rgb)
    ring = np.ones((3, 3), dtype=bool)
    ring[1, 1] = False
    second = rank_filter(lum, rank=-2, footprint=ring, mode="nearest")
    return (lum > FIREFLY_RATIO * second) & (lum - second > FIREFLY_MIN_EXCESS)


def speckles(srgb8: NDArray[np.uint8]) -> NDArray[np.bool_]:
    """Pixels of an 8-bit image brighter than their 5 x 5 median by more than
    :data:`SPECKLE_EXCESS` in some channel. Noise makes them, and so does converged
    detail finer than the window: a sunlit filament of cloud, a rivet, a glint's rim."""
    a = np.asarray(srgb8, dtype=np.int16)
    median = np.stack([median_filter(a[..., c], size=5, mode="nearest") for c in range(a.shape[-1])], axis=-1)
    return ((a - median) > SPECKLE_EXCESS).any(axis=-1)


def noise_speckles(half_a: NDArray[np.uint8], half_b: NDArray[np.uint8]) -> NDArray[np.bool_]:
    """The :func:`speckles` of a reference that are noise: a speckle in either of two
    renders of the same frame with independent samples (each half of the reference's
    spp) that the other does not share within :data:`SPECKLE_EXCESS` levels. Converged
    detail is a speckle in both halves alike; a sample's outlier lands in one."""
    a, b = np.asarray(half_a, dtype=np.int16), np.asarray(half_b, dtype=np.int16)
    apart = (np.abs(a - b) > SPECKLE_EXCESS).any(axis=-1)
    return (speckles(half_a) | speckles(half_b)) & apart


def _unit(image: NDArray) -> NDArray[np.float64]:
    a = np.asarray(image)
    return a.astype(np.float64) / 255.0 if a.dtype == np.uint8 else a.astype(np.float64)


def psnr(image: NDArray, reference: NDArray) -> float:
    """Peak signal-to-noise ratio in dB of ``image`` against ``reference`` (8-bit, or
    floats in [0, 1]); infinite when they are equal."""
    mse = float(np.mean((_unit(image) - _unit(reference)) ** 2))
    return float("inf") if mse == 0.0 else float(10.0 * np.log10(1.0 / mse))


def ssim(image: NDArray, reference: NDArray) -> float:
    """Structural similarity (Wang et al. 2004: Gaussian window sigma 1.5, K1 0.01,
    K2 0.03, data range 1) of ``image`` against ``reference``, averaged over the
    pixels and the channels."""
    x, y = _unit(image), _unit(reference)
    if x.ndim == 2:
        x, y = x[..., None], y[..., None]
    c1, c2 = 0.01**2, 0.03**2
    values = []
    for ch in range(x.shape[-1]):
        a, b = x[..., ch], y[..., ch]

        def blur(v):
            return gaussian_filter(v, 1.5, truncate=3.5)

        mu_a, mu_b = blur(a), blur(b)
        var_a = blur(a * a) - mu_a**2
        var_b = blur(b * b) - mu_b**2
        cov = blur(a * b) - mu_a * mu_b
        s = ((2 * mu_a * mu_b + c1) * (2 * cov + c2)) / ((mu_a**2 + mu_b**2 + c1) * (var_a + var_b + c2))
        values.append(s.mean())
    return float(np.mean(values))


#: The fine detail :func:`detail_ratio` weighs: what a Gaussian of this sigma (pixels) removes.
DETAIL_SIGMA_PX: Final = 1.5


def detail_rms(image: NDArray, mask: NDArray[np.bool_]) -> float:
    """The fine detail of ``image`` where ``mask`` is: the RMS of its luminance's high-pass
    (the image less its Gaussian blur of :data:`DETAIL_SIGMA_PX`) on the 8-bit (or [0, 1])
    encoding. NaN where the mask is empty."""
    m = np.asarray(mask, dtype=bool)
    if not m.any():
        return float("nan")
    y = luminance(_unit(image))
    return float(np.sqrt(np.mean((y - gaussian_filter(y, DETAIL_SIGMA_PX, truncate=3.5))[m] ** 2)))


def detail_ratio(image: NDArray, reference: NDArray, mask: NDArray[np.bool_]) -> float:
    """How much of the reference's fine detail ``image`` keeps where ``mask`` is: its
    :func:`detail_rms` over the reference's. 1: as detailed; under 1: smoothed (a denoiser's
    waxy look); over 1: noisier. NaN where the mask is empty or the reference has no detail
    there."""
    ref = detail_rms(reference, mask)
    return float("nan") if not ref > 0.0 else detail_rms(image, mask) / ref
