"""The camera model's shortcuts against the computation they shorten (numpy, no Mitsuba)."""

from __future__ import annotations

import numpy as np
import pytest

from datagen.core.camera import Intrinsics
from datagen.render.sensor import sun_glare


@pytest.mark.parametrize(("size", "hfov_deg", "sun_cam"), [
    ((2048, 1080), 55.0, (0.02, 0.01, 1.0)),  # the sun near the centre
    ((2048, 1080), 55.0, (0.6, 0.4, 1.0)),  # just outside a corner
    ((2048, 1080), 55.0, (-0.2, 0.25, 1.0)),
    ((1000, 501), 75.0, (0.8, -0.3, 0.5)),  # far outside, within reach
    ((1000, 501), 75.0, (0.3, -0.1, 1.0)),
    ((640, 338), 15.0, (0.05, -0.02, 1.0)),  # a narrow lens: a fine grid
], ids=["centre", "corner", "inside", "outside", "1000px", "narrow"])
def test_glare_on_a_coarse_grid_is_the_glare_at_every_pixel_within_one_percent_of_its_peak(size, hfov_deg,
                                                                                         sun_cam) -> None:
    w, h = size
    k = Intrinsics.from_hfov_deg(w, h, hfov_deg)
    coarse, inside = sun_glare((h, w), k, np.array(sun_cam), 0.8, 3.0)
    fine, inside_fine = sun_glare((h, w), k, np.array(sun_cam), 0.8, 3.0, step=1)
    assert coarse.shape == fine.shape == (h, w, 3) and inside == inside_fine
    error = np.abs(coarse - fine)
    assert error.max() <= 0.01 * fine.max(), error.max() / fine.max()
    assert error.mean() <= 0.003 * fine.mean()
    assert abs(coarse.sum() / fine.sum() - 1.0) < 0.003  # the same light in the image


def test_no_glare_where_the_sun_is_beyond_its_reach() -> None:
    k = Intrinsics.from_hfov_deg(640, 338, 55.0)
    assert sun_glare((338, 640), k, np.array([0.0, 0.0, -1.0]), 0.8, 3.0) == (None, False)


LEVELS = (0.0, 0.003, 0.05, 0.4, 1.0)


def _noisy(device: bool, seed: int, iso: float = 400.0, n: int = 200_000) -> tuple[np.ndarray, np.ndarray]:
    """Flat patches at each of LEVELS through the sensor's noise: (levels (L,), noisy (L, n))."""
    from datagen.render.sensor import sensor_noise

    if device:
        pytest.importorskip("mitsuba")
        from datagen.render.runtime import has_backend, use_variant

        if not has_backend("llvm"):
            pytest.skip("the device path needs Dr.Jit's LLVM backend")
        use_variant("llvm_ad_rgb")
    levels = np.array(LEVELS, np.float32)
    rgb = np.repeat(levels[:, None], n, axis=1).reshape(len(levels), n // 4, 4).astype(np.float32)
    return levels, sensor_noise(rgb, iso, seed, device=device).reshape(len(levels), n)


@pytest.mark.parametrize("device", [False, True], ids=["numpy", "device"])
def test_sensor_noise_has_the_models_mean_and_variance_at_every_level(device) -> None:
    from datagen.render.sensor import noise_sigma

    levels, noisy = _noisy(device, seed=12345)
    sigma = noise_sigma(np.clip(levels, 0.0, 1.0), np.float32(1.5e6 / 400.0), np.sqrt)
    n = noisy.shape[1]
    assert np.all(np.abs(noisy.mean(axis=1) - levels) < 5 * sigma / np.sqrt(n))
    np.testing.assert_allclose(noisy.var(axis=1), sigma**2, rtol=5 * np.sqrt(2 / n))


def test_device_noise_is_gaussian_and_independent_from_pixel_to_pixel() -> None:
    _, noisy = _noisy(True, seed=99)
    z = (noisy - noisy.mean(axis=1, keepdims=True)) / noisy.std(axis=1, keepdims=True)
    kurtosis = (z**4).mean(axis=1)
    assert np.all(np.abs(kurtosis - 3.0) < 0.06), kurtosis  # a Gaussian's (standard error 0.011)
    assert np.all(np.abs((z[:, 1:] * z[:, :-1]).mean(axis=1)) < 0.012)  # neighbours uncorrelated
    assert np.all(np.abs((z[:, 4:] * z[:, :-4]).mean(axis=1)) < 0.012)  # and channels of a pixel's neighbour


def test_device_noise_is_the_same_for_a_seed_and_another_for_another() -> None:
    _, a = _noisy(True, seed=7, n=4_000)
    _, b = _noisy(True, seed=7, n=4_000)
    _, c = _noisy(True, seed=8, n=4_000)
    assert np.array_equal(a, b) and not np.allclose(a[1:], c[1:])
