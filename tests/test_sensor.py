"""The camera model's shortcuts against the computation they shorten, and its steps on the
render's device against the same steps in numpy and OpenCV."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

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


@pytest.mark.parametrize("device", [False, pytest.param(True, marks=pytest.mark.render)], ids=["numpy", "device"])
def test_sensor_noise_has_the_models_mean_and_variance_at_every_level(device) -> None:
    from datagen.render.sensor import noise_sigma

    levels, noisy = _noisy(device, seed=12345)
    sigma = noise_sigma(np.clip(levels, 0.0, 1.0), np.float32(1.5e6 / 400.0), np.sqrt)
    n = noisy.shape[1]
    assert np.all(np.abs(noisy.mean(axis=1) - levels) < 5 * sigma / np.sqrt(n))
    np.testing.assert_allclose(noisy.var(axis=1), sigma**2, rtol=5 * np.sqrt(2 / n))


@pytest.mark.render
def test_device_noise_is_gaussian_and_independent_from_pixel_to_pixel() -> None:
    _, noisy = _noisy(True, seed=99)
    z = (noisy - noisy.mean(axis=1, keepdims=True)) / noisy.std(axis=1, keepdims=True)
    kurtosis = (z**4).mean(axis=1)
    assert np.all(np.abs(kurtosis - 3.0) < 0.06), kurtosis  # a Gaussian's (standard error 0.011)
    assert np.all(np.abs((z[:, 1:] * z[:, :-1]).mean(axis=1)) < 0.012)  # neighbours uncorrelated
    assert np.all(np.abs((z[:, 4:] * z[:, :-4]).mean(axis=1)) < 0.012)  # and channels of a pixel's neighbour


@pytest.mark.render
def test_device_noise_is_the_same_for_a_seed_and_another_for_another() -> None:
    _, a = _noisy(True, seed=7, n=4_000)
    _, b = _noisy(True, seed=7, n=4_000)
    _, c = _noisy(True, seed=8, n=4_000)
    assert np.array_equal(a, b) and not np.allclose(a[1:], c[1:])


def _llvm() -> None:
    pytest.importorskip("mitsuba")
    from datagen.render.runtime import has_backend, use_variant

    if not has_backend("llvm"):
        pytest.skip("the device path needs Dr.Jit's LLVM backend")
    use_variant("llvm_ad_rgb")


@pytest.mark.render
@pytest.mark.parametrize(("shift", "spread"), [((0.3, 0.1), 0.0), ((2.5, -1.5), 1.0), ((7.0, 3.0), 4.0),
                                               ((-40.0, 25.0), 30.0), ((1e4, 0.0), 0.0)],
                         ids=["short", "mixed", "long", "past-the-border", "past-the-diagonal"])
@pytest.mark.parametrize("stride", [1, 2])
def test_motion_blur_on_the_device_is_opencvs_remap_average(shift, spread, stride) -> None:
    """The device's blur (bilinear gathers, reflected border) against OpenCV's remap, for
    short, long and varying motion, displacements crossing the border several times and
    one shortened to the diagonal, given at every pixel or at every 2 x 2 block of an
    image of odd size."""
    import cv2

    from datagen.render.sensor import motion_blur

    _llvm()
    rng = np.random.default_rng(5)
    h, w = 61, 97
    rgb = cv2.GaussianBlur(rng.random((h, w, 3), dtype=np.float32) * 4, (0, 0), 1.5)
    grid = (-(-h // stride), -(-w // stride), 2)
    displacement = (np.asarray(shift, np.float32) + spread * rng.standard_normal(grid)).astype(np.float32)
    cpu = motion_blur(rgb, displacement, stride=stride)
    dev = motion_blur(rgb, displacement, stride=stride, device=True)
    assert dev.shape == cpu.shape and dev.dtype == np.float32
    np.testing.assert_allclose(dev, cpu, atol=2e-3 * rgb.max())  # OpenCV rounds positions to 1/32 px


@pytest.mark.render
def test_motion_blur_on_the_device_keeps_the_light_and_blurs_along_the_motion_only() -> None:
    """A vertical line moved 6 px sideways during the exposure becomes a 6 px wide band of
    the same total light; a horizontal line moved the same way stays sharp."""
    from datagen.render.sensor import motion_blur

    _llvm()
    h, w = 40, 64
    rgb = np.zeros((h, w, 3), np.float32)
    rgb[:, 30] = 1.0
    rgb[20, :] = 1.0
    moved = motion_blur(rgb, np.broadcast_to(np.float32([6.0, 0.0]), (h, w, 2)).copy(), device=True)
    row = moved[5, :, 0]
    assert row.sum() == pytest.approx(1.0, rel=1e-5)
    assert np.count_nonzero(row > 1e-6) in (6, 7) and row.max() < 0.2
    np.testing.assert_allclose(moved[20, 10:50, 0], 1.0, atol=1e-6)


@pytest.mark.render
def test_the_warm_up_compiles_the_kernel_a_frames_motion_blur_runs() -> None:
    """A worker whose first frames stand still compiles the blur's kernel at warm-up, not
    frames later: a full-size blur afterwards launches no kernel the warm-up did not."""
    from datagen.render.runtime import KernelCensus
    from datagen.render.sensor import MOTION_STRIDE, motion_blur, warm_up_on_device

    _llvm()
    census = KernelCensus()
    rng = np.random.default_rng(2)
    with census.recording():
        warm_up_on_device()
        assert census.new_kernels() > 0
        h, w = 91, 160
        grid = (-(-h // MOTION_STRIDE), -(-w // MOTION_STRIDE), 2)
        motion_blur(rng.random((h, w, 3), dtype=np.float32), rng.normal(0.0, 5.0, grid).astype(np.float32),
                    stride=MOTION_STRIDE, device=True)
        assert census.new_kernels() == 0


@settings(max_examples=40, deadline=None)
@given(gamma=st.floats(0.5, 2.0), shoulder=st.one_of(st.just(0.0), st.floats(0.0, 1.0)))
@example(gamma=0.5, shoulder=1.0)  # white never reached (254 at the table's top): a level whose search ended
def test_the_tone_table_found_by_bisection_equals_evaluating_every_entry(gamma: float, shoulder: float) -> None:
    from datagen.render import tonemap

    tonemap._tone_table.cache_clear()
    every = tonemap._encoded(tonemap.tone_curve(np.linspace(0.0, tonemap.TONE_RANGE, tonemap._TONE_ENTRIES),
                                                gamma, shoulder))
    np.testing.assert_array_equal(tonemap._tone_table(gamma, shoulder), every)


def _development(draw, h: int, w: int):
    """A frame's last steps as a build draws them, each one present or not."""
    from datagen.render.sensor import Development, white_balance_gains

    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    glare = rng.random((h, w, 3), dtype=np.float32) * np.float32(draw(st.floats(0.0, 3.0))) \
        if draw(st.booleans()) else None
    return Development(
        vignetting=draw(st.one_of(st.just(0.0), st.floats(0.05, 0.6))),
        glare=glare,
        gain=float(np.float32(draw(st.floats(0.05, 8.0)))),
        noise=draw(st.one_of(st.none(), st.tuples(st.floats(100.0, 3200.0), st.integers(0, 2**63 - 1)))),
        white_balance=draw(st.one_of(st.none(), st.builds(white_balance_gains, st.floats(4000.0, 9000.0),
                                                          st.floats(-0.1, 0.1)))),
        tone=draw(st.one_of(st.none(), st.tuples(st.floats(0.5, 2.0), st.floats(0.0, 1.0)))),
    )


@pytest.mark.render
@settings(max_examples=30, deadline=None)
@given(data=st.data(), h=st.integers(1, 40), w=st.integers(1, 70))
def test_developing_on_the_device_gives_the_numpy_steps_image_and_its_8_bit_encoding_exactly(data, h, w) -> None:
    """One kernel for vignetting, glare, exposure, noise, clip, white balance and the 8-bit
    table against the same steps in numpy (the noise the device's own, :func:`sensor_noise`)
    and :func:`to_srgb8`: the same display-linear values and the same bytes, whatever steps
    a frame has, over linear values from black past the tone table's top."""
    from datagen.render.sensor import develop_on_device, sensor_noise, vignette
    from datagen.render.tonemap import to_srgb8

    _llvm()
    steps = _development(data.draw, h, w)
    rng = np.random.default_rng(data.draw(st.integers(0, 2**32 - 1)))
    rgb = (rng.random((h, w, 3), dtype=np.float32) * np.float32(12.0)) ** 2 / np.float32(12.0)
    rgb[rng.random((h, w)) < 0.1] = 0.0
    expected = vignette(rgb, steps.vignetting) if steps.vignetting else rgb
    expected = expected if steps.glare is None else expected + steps.glare
    expected = expected * np.float32(steps.gain)
    if steps.noise is not None:
        expected = sensor_noise(expected, *steps.noise, device=True)
    expected = np.maximum(expected, np.float32(0.0))
    expected = expected if steps.white_balance is None else expected * steps.white_balance
    linear, srgb8 = develop_on_device(rgb, steps)
    assert srgb8.dtype == np.uint8 and srgb8.shape == (h, w, 3)
    assert np.array_equal(linear(), expected)
    assert np.array_equal(srgb8, to_srgb8(expected, steps.tone))


@pytest.mark.render
def test_developing_on_the_device_runs_one_kernel_whatever_steps_a_frame_has() -> None:
    """Frames with and without each step (vignetting, glare, noise, white balance, a tone
    curve) and of other sizes launch the kernel the first frame compiled, and no other."""
    from datagen.render.runtime import KernelCensus
    from datagen.render.sensor import Development, develop_on_device

    _llvm()
    rng = np.random.default_rng(3)
    census = KernelCensus()
    plain = Development(0.0, None, 1.0, None, None, None)
    frames = [((34, 64), plain), ((34, 64), Development(0.3, None, 1.0, None, None, None)),
              ((34, 64), Development(0.0, rng.random((34, 64, 3), dtype=np.float32), 1.0, None, None, None)),
              ((17, 30), Development(0.0, None, 0.5, (800.0, 11), None, None)),
              ((34, 64), Development(0.0, None, 1.0, None, np.float32([1.1, 1.0, 0.9]), None)),
              ((9, 5), Development(0.2, rng.random((9, 5, 3), dtype=np.float32), 2.0, (100.0, 3),
                                   np.float32([0.9, 1.0, 1.2]), (0.8, 0.4)))]
    with census.recording():
        for n, (shape, steps) in enumerate(frames):
            develop_on_device(rng.random((*shape, 3), dtype=np.float32), steps)
            compiled = census.new_kernels()
            assert compiled == (1 if n == 0 else 0), (n, compiled)
