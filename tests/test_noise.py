"""The procedural world: band-limited noise written once for numpy and Dr.Jit, cloud layers
without a texel grid, the cells that bound where their cloud can be, and the sea's wave
trains and the roughness that stands for the waves a pixel cannot hold."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from datagen.assets.clouds import CLOUD_CORE, CLOUD_CORE_TOLERANCE, CLOUD_EDGE, CloudLayer
from datagen.assets.noise import FADE_HI, FADE_LO, NOISE_BOUND, NUMPY, FractalField, gradient_noise
from datagen.assets.sea import (
    WAVE_SHARE_MAX,
    SeaWaves,
    cox_munk_roughness,
    cox_munk_slope_variance,
    wave_slope_variance,
)

coordinates = st.floats(-1e5, 1e5, allow_nan=False, width=32)


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), x=coordinates, y=coordinates)
def test_gradient_noise_stays_within_its_bound_and_vanishes_on_the_lattice(seed: int, x: float, y: float) -> None:
    xs = np.float32(x) + np.linspace(0, 1, 64, dtype=np.float32)
    value = gradient_noise(xs, np.full(64, np.float32(y)), np.uint32(seed))
    assert np.all(np.abs(value) <= NOISE_BOUND)
    corner = gradient_noise(np.floor(xs), np.floor(np.full(64, np.float32(y))), np.uint32(seed))
    assert np.all(corner == 0.0)


def test_gradient_noise_over_a_million_points_stays_within_its_bound_and_varies() -> None:
    rng = np.random.default_rng(3)
    x, y = rng.uniform(-1e4, 1e4, (2, 1_000_000)).astype(np.float32)
    value = gradient_noise(x, y, np.uint32(11))
    assert np.abs(value).max() <= NOISE_BOUND and 0.1 < value.std() < 0.3 and abs(value.mean()) < 0.01


def test_a_field_far_away_keeps_only_the_octaves_a_pixel_can_hold() -> None:
    field = FractalField.drawn(np.random.default_rng(5), 6000.0, 10, 0.55)
    rng = np.random.default_rng(6)
    x, y = rng.uniform(-3e4, 3e4, (2, 4096)).astype(np.float32)
    # A footprint at which octaves 0-2 are whole (wavelength >= FADE_HI footprints), octave 3
    # is in between, and octaves 4 on are gone (wavelength <= FADE_LO footprints).
    footprint = np.float32(6000.0 / 2**3 / 3.0)
    assert 6000.0 / 2**2 >= FADE_HI * footprint and 6000.0 / 2**4 <= FADE_LO * footprint
    filtered = field(x, y, np.full_like(x, footprint))
    partial = field(x, y, octaves=3)
    octave3 = field(x, y, octaves=4) - partial
    weight = field.weight(3, footprint)
    np.testing.assert_allclose(filtered, partial + weight * octave3, atol=1e-5)
    assert 0.0 < weight < 1.0


@pytest.mark.render
def test_a_kernel_series_sums_the_terms_before_each_lanes_stop_in_or_after_its_straight_line_rows(
        ) -> None:
    pytest.importorskip("mitsuba")
    from datagen.render.procedural import UNROLLED, evaluate
    from datagen.render.runtime import use_variant

    use_variant("llvm_ad_rgb")
    layer = CloudLayer.drawn(np.random.default_rng(15), 0.5, 0.9, 168_000.0)
    rows = layer.field.rows()
    rng = np.random.default_rng(16)
    x, y = rng.uniform(-3e4, 3e4, (2, 40_000)).astype(np.float32)
    footprint = (10.0 ** rng.uniform(-1.0, 3.5, 40_000)).astype(np.float32)
    for core in (False, True):
        total, going, stops = np.zeros_like(x), np.ones(x.shape, bool), np.zeros(x.shape, int)
        sums = [np.zeros_like(x)] + [layer.field(x, y, footprint, octaves=k) for k in range(1, layer.field.octaves + 1)]
        for k in range(layer.field.octaves):  # the loop's rule, row by row, in numpy
            row = {name: values[k] for name, values in rows.items()}
            going &= (row["wavelength"] > FADE_LO * footprint) & ~layer.settled((total,), row, core=core)
            stops += going
            total = np.where(going, total + (sums[k + 1] - sums[k]), total)
        assert (stops < UNROLLED).any() and (stops > UNROLLED).any()
        kernel = evaluate(lambda x, y, f, ops, core=core: layer.value(x, y, f, ops, core=core), x, y, footprint)
        np.testing.assert_allclose(kernel, total, atol=2e-6)
        assert (kernel != layer.field(x, y, footprint))[stops < UNROLLED].any()  # settled ones sum fewer terms


@pytest.mark.render
def test_the_kernel_evaluates_the_same_field_as_numpy() -> None:
    mi = pytest.importorskip("mitsuba")
    import drjit as dr

    from datagen.render.procedural import texture_class
    from datagen.render.runtime import use_variant

    variant = use_variant("llvm_ad_rgb")
    layer = CloudLayer.drawn(np.random.default_rng(8), 0.5, 0.9, 168_000.0)
    texture = texture_class(variant)(pixel_rad=1.0 / 1500.0)
    texture.camera = (0.0, 0.0, 20.0)
    texture.shade = lambda x, y, footprint, ops: layer(x, y, footprint, ops)
    rng = np.random.default_rng(9)
    x, y = rng.uniform(-2e4, 2e4, (2, 20_000)).astype(np.float32)
    z = np.full_like(x, 900.0)
    si = dr.zeros(mi.SurfaceInteraction3f, len(x))
    si.p = mi.Point3f(mi.Float(x), mi.Float(y), mi.Float(z))
    kernel = np.asarray(texture.eval_1(si))
    footprint = (np.sqrt(x.astype(np.float64)**2 + y**2 + (z - 20.0)**2) / 1500.0).astype(np.float32)
    np.testing.assert_allclose(kernel, layer(x, y, footprint), atol=1e-5)
    assert 0.0 < (kernel > 0.0).mean() < 1.0


def _layer_points(seed: int, coverage: float, log_footprint: float):
    """A cloud layer drawn from ``seed``, its series table, a generator for further draws, and
    4,000 points over it seen at a footprint of ``10 ** log_footprint`` metres."""
    layer = CloudLayer.drawn(np.random.default_rng(seed), coverage, 0.9, 168_000.0)
    rng = np.random.default_rng(seed + 1)
    x, y = rng.uniform(-8e4, 8e4, (2, 4000)).astype(np.float32)
    return layer, layer.field.rows(), rng, x, y, np.float32(10.0**log_footprint)


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**16), coverage=st.floats(0.05, 0.95), log_footprint=st.floats(-1.0, 2.5))
def test_a_lane_stops_summing_octaves_only_where_the_rest_cannot_change_opacity_nor_the_core_beyond_its_tolerance(
        seed: int, coverage: float, log_footprint: float) -> None:
    layer, rows, _, x, y, footprint = _layer_points(seed, coverage, log_footprint)
    full = layer.field(x, y, footprint)
    stopped = 0
    for k in range(1, layer.field.octaves):
        partial = layer.field(x, y, footprint, octaves=k)
        row = {name: values[k] for name, values in rows.items()}
        for core in (True, False):
            here = layer.settled((partial,), row, core=core)
            stopped += int(here.sum())
            np.testing.assert_array_equal(layer.opacity_of(partial[here]), layer.opacity_of(full[here]))
            if core:  # the smoothstep's steepest slope is 1.5 over its width
                moved = np.abs(layer.core_of(partial[here]) - layer.core_of(full[here]))
                assert np.all(moved <= 1.5 / CLOUD_CORE * CLOUD_CORE_TOLERANCE + 1e-5)
    assert stopped > 0  # the rule stops lanes at all


@pytest.mark.render
def test_the_kernel_shades_the_same_opacity_as_numpy_and_the_core_within_its_tolerance_where_lanes_stop_early(
        ) -> None:
    pytest.importorskip("mitsuba")
    from datagen.render.procedural import evaluate
    from datagen.render.runtime import use_variant

    use_variant("llvm_ad_rgb")
    layer = CloudLayer.drawn(np.random.default_rng(21), 0.4, 0.9, 168_000.0)
    rng = np.random.default_rng(22)
    x, y = rng.uniform(-8e4, 8e4, (2, 50_000)).astype(np.float32)
    footprint = (10.0 ** rng.uniform(-1.0, 2.5, 50_000)).astype(np.float32)
    def opacity(x, y, f, ops):
        return layer(x, y, f, ops)

    def core(x, y, f, ops):
        return layer.core_of(layer.value(x, y, f, ops), ops)

    np.testing.assert_array_equal(evaluate(opacity, x, y, footprint), opacity(x, y, footprint, NUMPY))
    moved = np.abs(evaluate(core, x, y, footprint) - core(x, y, footprint, NUMPY))
    assert moved.max() <= 1.5 / CLOUD_CORE * CLOUD_CORE_TOLERANCE + 1e-5 and (moved > 0).any()
    value = evaluate(lambda x, y, f, ops: layer.value(x, y, f, ops), x, y, footprint)
    assert (value != layer.field(x, y, footprint)).mean() > 0.1  # many lanes did stop early


def _layer_hits(rng: np.random.Generator, n: int):
    """``n`` surface interactions on a horizontal cloud layer 880 m above the camera of
    :func:`_cloud_masks`, half of them seen from its front (returned as a mask)."""
    import drjit as dr
    import mitsuba as mi

    x, y = rng.uniform(-2e4, 2e4, (2, n)).astype(np.float32)
    si = dr.zeros(mi.SurfaceInteraction3f, n)
    si.p = mi.Point3f(mi.Float(x), mi.Float(y), mi.Float(np.full(n, 900.0, np.float32)))
    si.sh_frame = mi.Frame3f(mi.Vector3f(0, 0, 1))
    facing = rng.random(n) < 0.5
    si.wi = mi.Vector3f(0.3, 0.1, mi.Float(np.where(facing, 0.9, -0.9).astype(np.float32)))
    return si, facing


def _cloud_masks():
    """The datagen cloud mask and Mitsuba's ``mask`` over a black mirror, in the current
    variant, with one cloud layer's opacity seen from a camera at (0, 0, 20)."""
    import mitsuba as mi

    from datagen.render.procedural import mask_class, texture_class

    layer = CloudLayer.drawn(np.random.default_rng(7), 0.5, 0.9, 168_000.0)
    opacity = texture_class(mi.variant())(pixel_rad=1.0 / 1500.0)
    opacity.camera = (0.0, 0.0, 20.0)
    opacity.shade = layer
    theirs = mi.load_dict({"type": "mask", "opacity": opacity, "bsdf": {
        "type": "conductor", "specular_reflectance": {"type": "rgb", "value": 0.0}}})
    return mask_class(mi.variant())(opacity), theirs


@pytest.mark.render
def test_a_one_sided_emitters_texture_sums_no_term_behind_it_and_emits_the_same() -> None:
    mi = pytest.importorskip("mitsuba")

    from datagen.assets.clouds import CloudLayer
    from datagen.render.procedural import texture_class
    from datagen.render.runtime import use_variant

    variant = use_variant("llvm_ad_rgb")
    layer = CloudLayer.drawn(np.random.default_rng(5), 0.6, 0.9, 168_000.0)
    si, facing = _layer_hits(np.random.default_rng(6), 20_000)
    emitted, footprints = {}, {}
    for front_only in (False, True):
        texture = texture_class(variant)(pixel_rad=1.0 / 1500.0, colour=True, front_only=front_only)
        texture.camera = (0.0, 0.0, 20.0)
        texture.shade = lambda x, y, f, ops: mi.Color3f(layer(x, y, f, ops))
        emitter = mi.load_dict({"type": "area", "radiance": texture})
        emitted[front_only] = np.asarray(emitter.eval(si))
        texture.shade = lambda x, y, f, ops: mi.Color3f(f)
        footprints[front_only] = np.asarray(texture.eval(si))[0]
    np.testing.assert_array_equal(emitted[True], emitted[False])
    assert np.all(np.isinf(footprints[True][~facing])) and np.all(np.isfinite(footprints[True][facing]))
    assert np.all(np.isfinite(footprints[False]))
    assert (emitted[True][:, facing] > 0).any()  # (3, lanes): the front does emit


@pytest.mark.render
def test_the_cloud_mask_passes_thin_parts_with_their_transmission_and_elsewhere_samples_as_mitsubas_mask(
        ) -> None:
    """Where the opacity is at most :data:`MASK_SPLIT` every path passes with weight
    ``1 - opacity``; elsewhere paths stop and pass exactly as Mitsuba's ``mask`` makes them
    (same answers, weights and directions); shadow rays' transmission is ``mask``'s."""
    mi = pytest.importorskip("mitsuba")
    from datagen.render.procedural import MASK_SPLIT
    from datagen.render.runtime import use_variant

    use_variant("llvm_ad_rgb")
    rng = np.random.default_rng(8)
    si, _ = _layer_hits(rng, 50_000)
    ours, theirs = _cloud_masks()
    u = mi.Float(rng.random(50_000).astype(np.float32))
    ctx = mi.BSDFContext()
    (bs_a, w_a), (bs_b, w_b) = (b.sample(ctx, si, u, mi.Point2f(0.5, 0.5)) for b in (ours, theirs))
    passes_a, passes_b = (np.asarray(mi.has_flag(bs.sampled_type, mi.BSDFFlags.Null)) for bs in (bs_a, bs_b))
    alpha = np.clip(np.asarray(ours.opacity.eval_1(si)), 0.0, 1.0)
    thin = alpha <= MASK_SPLIT
    assert 0.05 < thin.mean() < 0.95 and ((alpha > 0.0) & thin).any()
    assert passes_a[thin].all()
    np.testing.assert_array_equal(np.asarray(w_a)[:, thin], np.broadcast_to(1.0 - alpha[thin], (3, thin.sum())))
    np.testing.assert_array_equal(passes_a[~thin], passes_b[~thin])
    assert 0.05 < passes_a[~thin].mean() < 0.95  # both answers occur
    np.testing.assert_array_equal(np.asarray(w_a)[:, ~thin], np.asarray(w_b)[:, ~thin])
    np.testing.assert_array_equal(np.asarray(bs_a.wo)[:, passes_a], -np.asarray(si.wi)[:, passes_a])
    np.testing.assert_array_equal(np.asarray(bs_a.wo)[:, ~thin], np.asarray(bs_b.wo)[:, ~thin])
    np.testing.assert_array_equal(np.asarray(ours.eval_null_transmission(si)),
                                  np.asarray(theirs.eval_null_transmission(si)))
    assert not np.asarray(ours.eval(ctx, si, mi.Vector3f(0, 0, 1))).any()


@pytest.mark.render
def test_the_cloud_mask_samples_under_the_scalar_variant_as_under_llvm() -> None:
    """Under ``scalar_rgb``, point by point: thin parts pass with weight ``1 - opacity``,
    the rest stop or pass as Mitsuba's ``mask`` makes them; both answers occur."""
    mi = pytest.importorskip("mitsuba")
    from datagen.render.procedural import MASK_SPLIT
    from datagen.render.runtime import use_variant

    use_variant("scalar_rgb")
    try:
        ours, theirs = _cloud_masks()
        rng = np.random.default_rng(9)
        answers = set()
        for _ in range(80):
            si = mi.SurfaceInteraction3f()
            si.p = mi.Point3f(*rng.uniform(-2e4, 2e4, 2), 900.0)
            si.sh_frame = mi.Frame3f(mi.Vector3f(0, 0, 1))
            si.wi = mi.Vector3f(0.3, 0.1, 0.9)
            u = float(rng.random())
            (bs_a, w_a), (bs_b, w_b) = (b.sample(mi.BSDFContext(), si, u, mi.Point2f(0.5, 0.5)) for b in (ours, theirs))
            passes = mi.has_flag(bs_a.sampled_type, mi.BSDFFlags.Null)
            alpha = min(max(float(ours.opacity.eval_1(si)), 0.0), 1.0)
            if alpha <= MASK_SPLIT:
                assert passes and np.allclose(np.asarray(w_a), 1.0 - alpha)
            else:
                assert passes == mi.has_flag(bs_b.sampled_type, mi.BSDFFlags.Null)
                assert np.array_equal(np.asarray(w_a), np.asarray(w_b))
            answers.add((alpha <= MASK_SPLIT, bool(passes)))
        assert answers == {(True, True), (False, True), (False, False)}
    finally:
        use_variant("llvm_ad_rgb")


@pytest.mark.parametrize("coverage", [0.1, 0.4, 0.8])
def test_a_cloud_layer_covers_the_share_of_sky_it_was_drawn_with(coverage: float) -> None:
    span = 168_000.0
    layer = CloudLayer.drawn(np.random.default_rng(int(coverage * 10)), coverage, 1.0, span)
    rng = np.random.default_rng(1)
    x, y = rng.uniform(-span / 2, span / 2, (2, 200_000)).astype(np.float32)
    cloudy = (layer(x, y) > 0.0).mean()
    assert abs(cloudy - coverage) < 0.05


def test_a_layer_without_coverage_has_no_cloud_anywhere() -> None:
    layer = CloudLayer.drawn(np.random.default_rng(0), 0.0, 1.0, 168_000.0)
    x = np.linspace(-8e4, 8e4, 1000, dtype=np.float32)
    assert not np.any(layer(x, x[::-1]))


def test_cloud_edges_have_no_preferred_direction() -> None:
    """Where a layer's opacity ramps up (its edges), the directions of its gradient are
    spread evenly: the old textures' edges followed the texel grid (peaks at 0 and 90
    degrees). Along each axis and diagonal lies the same share of edge pixels, within 20%."""
    layer = CloudLayer.drawn(np.random.default_rng(12), 0.4, 1.0, 168_000.0)
    n, spacing = 1024, 12.0
    c = (np.arange(n, dtype=np.float32) - n / 2) * np.float32(spacing)
    x, y = np.meshgrid(c, c)
    opacity = layer(x, y)
    gy, gx = np.gradient(opacity)
    edge = (opacity > 0.05) & (opacity < 0.95 * layer.opacity) & (np.hypot(gx, gy) > 1e-4)
    assert edge.sum() > 5000
    angle = np.degrees(np.arctan2(gy[edge], gx[edge])) % 180.0
    shares = [np.mean(np.abs((angle - centre + 90.0) % 180.0 - 90.0) < 7.5) for centre in (0, 45, 90, 135)]
    assert max(shares) < 1.2 * min(shares), shares
    assert all(abs(s - 15.0 / 180.0) < 0.3 * 15.0 / 180.0 for s in shares), shares


@pytest.mark.render
def test_the_cloud_cull_keeps_the_cells_that_sampling_every_cell_in_full_keeps() -> None:
    pytest.importorskip("mitsuba")
    from datagen.assets.clouds import CLOUD_FORMS
    from datagen.render.procedural import evaluate
    from datagen.render.runtime import use_variant
    from datagen.render.world import (
        CULL_OCTAVES,
        CULL_SAMPLES,
        CULL_SUBSET,
        _cell_layout,
        _cell_maxima,
        _cloudy_cells,
        _cull_slack,
    )

    use_variant("llvm_ad_rgb")
    x0, y0, size = _cell_layout()
    forms = list(CLOUD_FORMS.values()) if isinstance(CLOUD_FORMS, dict) else list(CLOUD_FORMS)
    culled = full_only = 0
    for seed, form in enumerate(forms):
        layer = CloudLayer.drawn(np.random.default_rng(seed), 0.15, 1.0, 168_000.0, form=form)
        field = layer.field
        full = np.zeros(len(x0), dtype=bool)
        for cell in np.unique(size):
            group = np.flatnonzero(size == cell)
            offsets = (np.arange(CULL_SAMPLES) + 0.5) * cell / CULL_SAMPLES
            slack = _cull_slack(field, cell / CULL_SAMPLES)
            maxima = _cell_maxima(field, x0[group], y0[group], offsets)
            full[group] = maxima + slack > layer.threshold
            subset = _cell_maxima(field, x0[group], y0[group], offsets[CULL_SUBSET // 2::CULL_SUBSET])
            full_only += int((full[group] & ~(subset + slack > layer.threshold)).sum())
            # The device's maxima are numpy's points' (float32, rounded once), evaluated one by one.
            some = group[:: max(1, len(group) // 3)][:3]
            x = (x0[some, None, None] + offsets[None, None, :]).astype(np.float32)
            y = (y0[some, None, None] + offsets[None, :, None]).astype(np.float32)
            x, y = np.broadcast_arrays(x, y)
            points = evaluate(lambda x, y, ops, field=field: field(x, y, ops=ops, octaves=CULL_OCTAVES), x, y)
            assert np.array_equal(points.reshape(len(some), -1).max(axis=1), maxima[np.searchsorted(group, some)])
        culled += int((~full).sum())
        assert np.array_equal(_cloudy_cells(layer), full)
    assert culled > 0 and full_only > 0  # cells of both outcomes the subset could not decide alone


@pytest.mark.render
def test_the_cloud_cull_compiles_no_kernel_for_another_cell_count_or_subset() -> None:
    pytest.importorskip("mitsuba")
    from datagen.render.runtime import KernelCensus, use_variant
    from datagen.render.world import CULL_SAMPLES, _cell_maxima

    use_variant("llvm_ad_rgb")
    field = CloudLayer.drawn(np.random.default_rng(3), 0.3, 1.0, 168_000.0).field
    offsets = (np.arange(CULL_SAMPLES) + 0.5) * 40.0
    corners = np.arange(5, dtype=np.float64) * 1500.0
    census = KernelCensus()
    with census.recording():
        first = _cell_maxima(field, corners, corners, offsets)
        census.new_kernels()
        one = _cell_maxima(field, corners[3:4], corners[3:4], offsets)
        subset = _cell_maxima(field, corners[:2], corners[:2], offsets[2::4])
        assert census.new_kernels() == 0
    assert one.shape == (1,) and one[0] == first[3] and subset.shape == (2,)
    assert np.all(subset <= first[:2])  # a subset of a cell's samples: no larger a maximum


@pytest.mark.render
def test_every_point_with_cloud_lies_in_a_cell_the_layer_keeps() -> None:
    pytest.importorskip("mitsuba")
    from datagen.render.runtime import use_variant
    from datagen.render.world import CLOUD_CELL_M, CLOUD_SIZE_M, _cloudy_cells

    use_variant("llvm_ad_rgb")
    for seed, coverage in ((1, 0.15), (2, 0.5)):
        layer = CloudLayer.drawn(np.random.default_rng(seed), coverage, 1.0, CLOUD_SIZE_M)
        kept = _cloudy_cells(layer)
        cells = round(CLOUD_SIZE_M / CLOUD_CELL_M)
        assert 0 < kept.sum() < kept.size
        x, y = np.random.default_rng(seed).uniform(-CLOUD_SIZE_M / 2, CLOUD_SIZE_M / 2, (2, 400_000)).astype(
            np.float32)
        cloudy = layer(x, y) > 0.0  # every octave: the finest detail there is
        i = np.clip(((x + CLOUD_SIZE_M / 2) // CLOUD_CELL_M).astype(int), 0, cells - 1)
        j = np.clip(((y + CLOUD_SIZE_M / 2) // CLOUD_CELL_M).astype(int), 0, cells - 1)
        assert kept[j * cells + i][cloudy].all()


def test_opacity_ramps_over_the_edge_width_of_the_field() -> None:
    layer = CloudLayer(FractalField.drawn(np.random.default_rng(0), 1000.0, 2, 0.5), 0.1, 0.8)
    values = np.array([0.1, 0.1 + CLOUD_EDGE / 2, 0.1 + CLOUD_EDGE, 1.0], dtype=np.float32)
    np.testing.assert_allclose(layer.opacity_of(values), [0.0, 0.4, 0.8, 0.8], atol=1e-6)
    assert math.isinf(CloudLayer.drawn(np.random.default_rng(0), 0.0, 1.0, 1e4).threshold)


def test_the_texel_check_fails_each_frame_whose_world_texel_exceeds_the_limit() -> None:
    from types import SimpleNamespace

    from datagen.analysis.audit.dataset_files import MAX_WORLD_TEXEL_PX, check_texels

    rows = SimpleNamespace(world_texel_px=[0.2, None, MAX_WORLD_TEXEL_PX, 3.0], frame_id=np.arange(4),
                           manifest_file=["manifests/shard-00000.parquet"] * 4)
    check = check_texels(rows).finish()
    assert (check.checked, check.failures, check.worst) == (3, 1, 3.0)
    assert "frame 3" in check.offenders[0] and not check.passed
    labels_only = check_texels(SimpleNamespace(world_texel_px=[None, None], frame_id=np.arange(2),
                                               manifest_file=["m"] * 2)).finish()
    assert not labels_only.applicable and labels_only.checked == 0


def test_the_sea_clouds_and_liveries_report_no_texel_where_they_are_seen_and_none_where_unseen() -> None:
    from datagen.config import load_config
    from datagen.core.conventions import object_id
    from datagen.render.world import SURFACES, World

    world = World(load_config("wingcam55").randomization, pixel_rad=1e-3)
    depth = np.array([[5000.0, 4200.0], [80.0, np.inf]])
    ids = np.array([[0, 0], [object_id("tanker"), 0]], dtype=np.uint32)
    surface = np.array([[1, 1], [3, 0]], dtype=np.uint8)
    assert SURFACES[1] == "sea" and SURFACES[3] == "object"
    out = world.texel_footprint_px(depth, ids, surface, fx=2000.0)
    assert out == {"world_texel_px": 0.0, "livery_texel_px": 0.0}  # procedural: no texel anywhere
    drogue_only = np.where(ids > 0, object_id("drogue"), 0).astype(np.uint32)
    assert world.texel_footprint_px(depth, drogue_only, surface, fx=2000.0)["livery_texel_px"] is None
    assert world.texel_footprint_px(None, None, None, fx=2000.0) == {"world_texel_px": None,
                                                                     "livery_texel_px": None}


def _sea_grid(n: int, spacing: float) -> tuple[np.ndarray, np.ndarray]:
    c = (np.arange(n, dtype=np.float32) - n / 2) * np.float32(spacing)
    return np.meshgrid(c, c)


@settings(max_examples=12, deadline=None)
@given(wind=st.floats(0.5, 30.0), direction=st.floats(0.0, 360.0), seed=st.integers(0, 2**32 - 1))
def test_resolved_waves_and_roughness_together_hold_cox_and_munks_slope_variance(
        wind: float, direction: float, seed: int) -> None:
    """Close up (every train resolved) the trains' mean square slope, measured on the
    surface, plus the roughness's (roughness ** 4) is Cox and Munk's total at the wind;
    far away (nothing resolved) the roughness alone is: one sea at every range."""
    waves = SeaWaves.drawn(np.random.default_rng(seed), wind, direction)
    shortest = float(waves.rows()["wavelength"].min())
    x, y = _sea_grid(384, shortest / 3.0)
    x = x + np.float32(37.0)
    sx, sy = waves.slope(x, y, np.float32(shortest / 8.0))  # every train whole
    measured = float(np.mean(sx**2 + sy**2))
    carried = wave_slope_variance(wind)
    assert measured == pytest.approx(carried, rel=0.35)  # one realization: trains beat against each other
    total = cox_munk_slope_variance(wind)
    close, far = waves.roughness(np.float32([shortest / 8.0, 1e6]), cox_munk_roughness(wind))
    assert close**4 + carried == pytest.approx(total, rel=1e-4)
    assert far**4 == pytest.approx(total, rel=1e-4)
    assert carried <= WAVE_SHARE_MAX * total * (1 + 1e-9)


def test_waves_a_pixel_cannot_hold_are_filtered_out_of_the_normals() -> None:
    """At a footprint, no wave shorter than FADE_LO footprints is left in the slope field:
    its spectrum beyond that wavenumber is empty."""
    waves = SeaWaves.drawn(np.random.default_rng(4), 9.0, 20.0)
    footprint = 4.0
    n, spacing = 512, 1.0
    x, y = _sea_grid(n, spacing)
    sx, _ = waves.slope(x, y, np.float32(footprint))
    window = np.outer(np.hanning(n), np.hanning(n))  # the trains are not periodic in the window
    power = np.abs(np.fft.fft2(sx * window)) ** 2
    k = 2 * np.pi * np.fft.fftfreq(n, d=spacing)
    kk = np.hypot(*np.meshgrid(k, k))
    cutoff = 2 * np.pi / (FADE_LO * footprint)
    beyond = power[kk > cutoff * 1.1].sum() / power.sum()
    assert power.sum() > 0 and beyond < 1e-3, beyond


@pytest.mark.render
def test_the_kernel_evaluates_the_same_sea_as_numpy() -> None:
    mi = pytest.importorskip("mitsuba")
    import drjit as dr

    from datagen.render.procedural import texture_class
    from datagen.render.runtime import use_variant

    variant = use_variant("llvm_ad_rgb")
    waves = SeaWaves.drawn(np.random.default_rng(14), 11.0, 250.0)
    texture = texture_class(variant)(pixel_rad=1.0 / 4000.0)
    texture.camera = (0.0, 0.0, 0.0)
    texture.shade = lambda x, y, footprint, ops: waves.slope(x, y, footprint, ops)[0]
    rng = np.random.default_rng(15)
    x, y = rng.uniform(-3e3, 3e3, (2, 20_000)).astype(np.float32)
    z = np.full_like(x, -1500.0)
    si = dr.zeros(mi.SurfaceInteraction3f, len(x))
    si.p = mi.Point3f(mi.Float(x), mi.Float(y), mi.Float(z))
    kernel = np.asarray(texture.eval_1(si))
    footprint = (np.sqrt(x.astype(np.float64)**2 + y**2 + z**2) / 4000.0).astype(np.float32)
    np.testing.assert_allclose(kernel, waves.slope(x, y, footprint)[0], atol=2e-4)
    assert np.std(kernel) > 0.01


def test_wave_crests_have_no_preferred_grid_axis() -> None:
    """The waves run with the wind, but not along a grid: rotating the wind rotates the
    slopes' orientation histogram with it (no texel axes pin it)."""
    x, y = _sea_grid(512, 0.5)

    def histogram(direction: float) -> np.ndarray:
        sx, sy = SeaWaves.drawn(np.random.default_rng(21), 9.0, direction).slope(x, y, np.float32(0.05))
        angle = np.degrees(np.arctan2(sy, sx)) % 180.0
        return np.histogram(angle, bins=36, range=(0, 180), weights=np.hypot(sx, sy))[0]

    base = histogram(0.0)
    rotated = histogram(25.0)
    assert np.argmax(base) != np.argmax(rotated)
    np.testing.assert_allclose(np.roll(base, 5), rotated, rtol=0.35, atol=0.05 * base.max())
