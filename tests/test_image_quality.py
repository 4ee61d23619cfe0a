"""The image-quality measures of bench/bench_quality.py and the sea's Cox-Munk roughness."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from datagen.analysis.image_quality import (
    FIREFLY_MIN_EXCESS,
    SPECKLE_EXCESS,
    fireflies,
    noise_speckles,
    psnr,
    speckles,
    ssim,
)
from datagen.assets.sea import cox_munk_roughness
from datagen.config import load_config, override_config
from datagen.core.conventions import frame_rng
from datagen.scene.look import draw_look


def test_fireflies_are_isolated_speckles_and_a_glint_is_not_one() -> None:
    image = np.full((40, 60, 3), 0.2, dtype=np.float32)
    image[10, 10] = 3.0  # a speckle
    image[20:24, 30:35] = 5.0  # a glint several pixels across
    image[5, 40:52] = [[v] * 3 for v in (0.5, 1.5, *[4.0] * 8, 1.5, 0.5)]  # a highlight along a thin edge, tapering
    image[33, 20:22] = 4.0  # two speckles side by side
    image[30, 50] = 0.2 + FIREFLY_MIN_EXCESS / 2  # too faint to be seen as one
    found = fireflies(image)
    assert found[10, 10] and found[33, 20:22].all() and found.sum() == 3


def test_noise_speckles_are_the_speckles_two_independent_halves_do_not_share() -> None:
    half_a = np.full((40, 60, 3), 95, np.uint8)  # a smooth grey
    half_b = half_a.copy()
    half_a[10, 10] = 250  # a sample's outlier: in one half only
    half_b[20, 30] = 95 + SPECKLE_EXCESS + 20  # another, in the other half, in one channel
    half_b[20, 30, 1:] = half_a[20, 30, 1:]
    for half in (half_a, half_b):  # a converged bright rivet: in both halves alike
        half[30, 45] = 240
    half_a[5, 5] = half_b[5, 5] = 95 + SPECKLE_EXCESS  # not brighter than the median by more
    both = speckles(half_a) | speckles(half_b)
    assert both[10, 10] and both[20, 30] and both[30, 45] and not both[5, 5]
    noise = noise_speckles(half_a, half_b)
    assert noise[10, 10] and noise[20, 30] and noise.sum() == 2


def test_psnr_and_ssim_of_an_image_against_itself_and_against_noise() -> None:
    rng = np.random.default_rng(0)
    ref = rng.integers(0, 256, (50, 70, 3), dtype=np.uint8)
    assert psnr(ref, ref) == float("inf") and ssim(ref, ref) == pytest.approx(1.0)
    noisy = np.clip(ref.astype(int) + rng.integers(-8, 9, ref.shape), 0, 255).astype(np.uint8)
    mse = np.mean((noisy / 255.0 - ref / 255.0) ** 2)
    assert psnr(noisy, ref) == pytest.approx(10 * np.log10(1 / mse))
    assert 0.5 < ssim(noisy, ref) < 1.0
    assert ssim(255 - ref, ref) < ssim(noisy, ref)


@given(st.floats(0.0, 30.0))
def test_cox_munk_roughness_squared_squared_is_the_mean_square_slope(wind: float) -> None:
    """Principled alpha = roughness^2 and alpha^2 = mean square slope = 0.003 + 5.12e-3 W."""
    assert cox_munk_roughness(wind) ** 4 == pytest.approx(0.003 + 5.12e-3 * wind, rel=1e-12)


def test_cox_munk_gives_a_rougher_sea_than_the_glassy_uniform_draw() -> None:
    assert cox_munk_roughness(3.0) == pytest.approx(0.368, abs=1e-3)
    assert cox_munk_roughness(12.0) == pytest.approx(0.504, abs=1e-3)
    assert cox_munk_roughness(3.0) > 0.25  # above the old uniform range's top


def test_the_sea_model_changes_no_other_draw_of_a_frame() -> None:
    config = load_config("wingcam55")
    uniform = override_config(config, {"randomization.sea.model": "uniform"})
    assert config.randomization.sea.model == "cox_munk"
    for i in range(20):
        a, b = draw_look(config, frame_rng(55, i)), draw_look(uniform, frame_rng(55, i))
        lo, hi = config.randomization.sea.wind_speed_mps
        assert lo <= a.sea_wind_speed_mps <= hi and a.sea_roughness == cox_munk_roughness(a.sea_wind_speed_mps)
        assert b.sea_wind_speed_mps is None and 0.05 <= b.sea_roughness <= 0.25
        same = {"sea_roughness": 0.0, "sea_wind_speed_mps": None}
        assert dataclasses.replace(a, **same) == dataclasses.replace(b, **same)


def test_the_detail_ratio_is_one_for_the_reference_under_one_blurred_and_over_one_with_noise() -> None:
    from scipy.ndimage import gaussian_filter

    from datagen.analysis.image_quality import detail_ratio

    rng = np.random.default_rng(3)
    reference = np.clip(rng.uniform(0.2, 0.8, (64, 96, 3)), 0.0, 1.0)
    mask = np.zeros((64, 96), bool)
    mask[10:50, 20:80] = True
    assert detail_ratio(reference, reference, mask) == pytest.approx(1.0)
    waxy = gaussian_filter(reference, (1.0, 1.0, 0.0))
    assert detail_ratio(waxy, reference, mask) < 0.6
    noisy = np.clip(reference + rng.normal(0.0, 0.1, reference.shape), 0.0, 1.0)
    assert detail_ratio(noisy, reference, mask) > 1.05
    assert np.isnan(detail_ratio(reference, reference, np.zeros_like(mask)))


def test_detail_rms_is_zero_on_a_smooth_ramp_grows_with_a_patterns_contrast_and_reads_only_the_mask() -> None:
    from datagen.analysis.image_quality import detail_rms

    ramp = np.broadcast_to(np.linspace(0.2, 0.8, 96)[None, :, None], (64, 96, 3)).copy()
    inside = np.zeros((64, 96), bool)
    inside[16:48, 24:72] = True
    assert detail_rms(ramp, inside) == pytest.approx(0.0, abs=1e-9)
    checks = (np.indices((64, 96)).sum(axis=0) % 2).astype(float)[..., None]
    weak, strong = ramp + 0.02 * checks, ramp + 0.04 * checks
    assert detail_rms(strong, inside) == pytest.approx(2.0 * detail_rms(weak, inside), rel=1e-6)
    outside_only = ramp.copy()
    outside_only[~inside] += 0.04 * checks[~inside]
    interior = np.zeros_like(inside)
    interior[22:42, 30:66] = True  # farther from the pattern than the blur reaches (3.5 sigma)
    assert detail_rms(outside_only, interior) == pytest.approx(0.0, abs=1e-9)
    assert detail_rms(strong, interior) > 0.01
    assert np.isnan(detail_rms(ramp, np.zeros_like(inside)))
