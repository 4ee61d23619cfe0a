"""Clouds with body and land below (issue 56, items 3 and 4): the cloud forms and ground
types drawn by their shares and within their own ranges, a layer's height field shading
its slopes and bases, the layer reaching the horizon and ending there, the land where its
type puts it, and the kernels' answers the same as numpy's."""

from __future__ import annotations

import math
from collections import Counter

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from datagen.assets.clouds import CLOUD_FORMS, CloudLayer, CloudLight, forward_scattered
from datagen.assets.ground import GROUND_TYPES, Ground
from datagen.assets.noise import Slant
from datagen.config.load import load_config, override_config
from datagen.scene.look import _approach_world

APPROACHES = 1500


def _worlds(config) -> list[dict]:
    return [_approach_world(config, 7, i, 6000.0) for i in range(APPROACHES)]


def _shares_match(drawn: Counter, shares: dict[str, float]) -> None:
    """Each name drawn about its share of :data:`APPROACHES` (within 4.5 binomial sigmas)."""
    total = sum(shares.values())
    for name, share in shares.items():
        p = share / total
        sigma = math.sqrt(APPROACHES * p * (1 - p))
        assert abs(drawn[name] - APPROACHES * p) <= 4.5 * sigma + 1, (name, drawn[name], APPROACHES * p)
    assert set(drawn) <= set(shares)


def test_cloud_forms_and_ground_types_are_drawn_by_their_configured_shares() -> None:
    config = override_config(load_config("wingcam55"), {
        "randomization.clouds.forms": {"cumulus": 1.0, "stratocumulus": 2.0, "overcast": 1.0},
        "randomization.ground.shares": {"sea": 3.0, "desert": 1.0, "snow": 1.0, "mountains": 0.0}})
    worlds = _worlds(config)
    _shares_match(Counter(w["cloud_type"] for w in worlds), config.randomization.clouds.forms)
    _shares_match(Counter(w["ground_type"] for w in worlds), config.randomization.ground.shares)
    assert "mountains" not in {w["ground_type"] for w in worlds}  # a share of 0 is never drawn


def test_the_shipped_default_keeps_the_sea_the_majority_and_draws_every_ground_type() -> None:
    worlds = _worlds(load_config("wingcam55"))
    drawn = Counter(w["ground_type"] for w in worlds)
    assert drawn["sea"] > APPROACHES / 2 and set(drawn) == set(GROUND_TYPES)


def test_each_cloud_form_draws_coverage_and_thickness_within_its_own_ranges_clipped_by_the_config() -> None:
    config = override_config(load_config("wingcam55"), {"randomization.clouds.deck_coverage": [0.0, 0.95]})
    r = config.randomization.clouds
    for w in _worlds(config)[:400]:
        form = CLOUD_FORMS[w["cloud_type"]]
        lo, hi = max(form.coverage[0], r.deck_coverage[0]), min(form.coverage[1], r.deck_coverage[1])
        assert lo <= w["cloud_deck_coverage"] <= hi
        assert form.thickness_m[0] <= w["cloud_deck_thickness_m"] <= form.thickness_m[1]
        assert r.layer_thickness_m[0] <= w["cloud_layer_thickness_m"] <= r.layer_thickness_m[1]


def test_a_config_with_no_positive_share_is_refused_naming_the_key() -> None:
    from datagen.core.errors import ConfigError

    with pytest.raises(ConfigError, match=r"randomization\.ground\.shares: .*shares must be 0 or more"):
        override_config(load_config("wingcam55"), {"randomization.ground.shares": {"sea": 0.0}})
    with pytest.raises(ConfigError, match=r"randomization\.clouds\.forms"):
        override_config(load_config("wingcam55"), {"randomization.clouds.forms": {"cirrus": 1.0}})


def _light(sun_elevation_deg: float) -> CloudLight:
    el = math.radians(sun_elevation_deg)
    return CloudLight((1.0, 1.0, 1.0), (0.3, 0.3, 0.3), (math.cos(el), 0.0, math.sin(el)), 0.9)


@pytest.fixture(scope="module")
def cumulus() -> CloudLayer:
    form = CLOUD_FORMS["cumulus"]
    return CloudLayer.drawn(np.random.default_rng(4), 0.35, 1.0, 168_000.0, form, 1500.0)


def test_a_clouds_slopes_facing_a_low_sun_are_brighter_than_those_facing_away(cumulus: CloudLayer) -> None:
    """Seen from above: where the height field falls towards the sun (the sun's side of a
    heap) the tops are brighter than where it rises towards it (the lee side), by more than
    the flat tops' shading varies with the cores."""
    n = 600
    x, y = (a.astype(np.float32) for a in np.meshgrid(np.linspace(0, 30_000, n), np.linspace(0, 30_000, n)))
    light = _light(15.0)
    top = cumulus.radiance(light, np.float32(0.0), x, y)[0]
    core = cumulus.core_of(cumulus.value(x, y)) > 0.99  # inside thick cloud
    step = 60.0
    slope = (cumulus.height(x + np.float32(step), y) - cumulus.height(x, y)) / step  # along the sun (+x)
    sunward, lee = core & (slope < -0.3), core & (slope > 0.3)
    assert sunward.sum() > 200 and lee.sum() > 200
    assert np.median(top[sunward]) > 1.5 * np.median(top[lee])


def test_a_clouds_base_darkens_with_the_thickness_above_it() -> None:
    """From below: the same field drawn thin and thick; the thick layer's base is darker
    wherever it is cloud, and a base is darker than the top's sunlit flat."""
    form = CLOUD_FORMS["overcast"]
    thin, thick = (CloudLayer.drawn(np.random.default_rng(9), 0.97, 1.0, 168_000.0, form, t) for t in (200.0, 1500.0))
    rng = np.random.default_rng(1)
    x, y = rng.uniform(-2e4, 2e4, (2, 20_000)).astype(np.float32)
    light = _light(40.0)
    base_thin, base_thick = (layer.radiance(light, np.float32(1.0), x, y)[1] for layer in (thin, thick))
    cloud = thick.height(x, y) > 300.0
    assert cloud.mean() > 0.5
    assert np.all(base_thick[cloud] < base_thin[cloud])
    # The overcast has structure from below: its base's brightness varies over the layer.
    assert np.std(base_thick[cloud]) / np.mean(base_thick[cloud]) > 0.1


def test_the_forward_scattering_phase_is_normalized_and_peaks_at_unit_optical_depth() -> None:
    """:func:`forward_scattered` per unit ``tau exp(-tau)`` integrates to 1 over the sphere
    (a phase function), and over optical depth it is largest at 1 and under 1e-6 of that
    through a thick core (tau 20)."""
    cos = np.linspace(-1.0, 1.0, 200_001)
    phase = forward_scattered(np.float64(1.0), cos) / math.exp(-1.0)
    assert abs(np.trapezoid(phase, cos) * 2.0 * math.pi - 1.0) < 1e-3
    tau = np.linspace(0.0, 20.0, 2001)
    out = forward_scattered(tau, np.float64(0.9))
    assert abs(tau[np.argmax(out)] - 1.0) < 0.011
    assert out[-1] < 1e-6 * out.max()


def test_a_bases_thin_edges_glow_towards_the_sun_and_not_away_from_it() -> None:
    """From below, a thin layer's edges (opacity under 1) looked at towards the sun are
    brighter than the same edges looked at away from it, by more than twice; its thick
    cores (hardly any light scattered once gets through them) look the same both ways, within
    1%."""
    layer = CloudLayer.drawn(np.random.default_rng(3), 0.4, 1.0, 168_000.0, CLOUD_FORMS["layer"], 300.0)
    rng = np.random.default_rng(5)
    x, y = rng.uniform(-2e4, 2e4, (2, 40_000)).astype(np.float32)
    light = _light(20.0)  # the sun towards +x
    footprint = np.full(x.shape, 2.0, np.float32)
    looks = {}
    for name, sx in (("sunward", 2.0), ("away", -2.0)):  # views 63 degrees from the zenith
        slant = Slant(footprint, np.full(x.shape, sx, np.float32), np.zeros_like(x))
        looks[name] = layer.radiance(light, np.float32(1.0), x, y, slant)[1]
    opacity = layer(x, y, footprint)
    edge, core = (opacity > 0.05) & (opacity < 0.9), layer.height(x, y) > 250.0
    assert edge.sum() > 200 and core.sum() > 200
    assert np.median(looks["sunward"][edge]) > 2.0 * np.median(looks["away"][edge])
    np.testing.assert_allclose(looks["sunward"][core], looks["away"][core], rtol=1e-2)


@settings(max_examples=25, deadline=None)
@given(height=st.floats(-9_000.0, -200.0), altitude=st.floats(0.0, 8_000.0))
def test_a_layer_seen_from_above_keeps_no_cell_past_its_horizon_and_every_cell_before_it(height: float,
                                                                                         altitude: float) -> None:
    from datagen.render.world import _cell_layout, _cloud_cells

    x0, y0, size = _cell_layout()
    cloudy = np.ones(len(x0), dtype=bool)
    verts = _cloud_cells(cloudy, height, altitude).reshape(-1, 4, 3)
    kept = np.ptp(verts[..., 0], axis=1) > 0  # a collapsed cell has no extent
    radius = 6_371_000.0 + altitude
    horizon = math.sqrt((radius - height) ** 2 - radius**2)
    nearest = np.hypot(np.clip(0.0, x0, x0 + size), np.clip(0.0, y0, y0 + size))
    assert np.array_equal(kept, nearest <= horizon)


def test_the_far_ring_meets_the_near_grid_edge_to_edge_without_overlap() -> None:
    from datagen.render.world import CLOUD_REACH_M, _cell_layout

    _, _, size = _cell_layout()
    assert math.isclose(float((size**2).sum()), (2 * CLOUD_REACH_M) ** 2, rel_tol=1e-12)  # no gap, no overlap
    # The near grid's border vertices lie on the far ring's chords: the same height at a far corner.
    from datagen.render.world import CLOUD_SIZE_M, _cloud_cells

    verts = _cloud_cells(np.ones(len(size), dtype=bool), 2000.0, 9000.0).reshape(-1, 3)
    border = np.isclose(np.abs(verts[:, 0]), CLOUD_SIZE_M / 2) & np.isclose(verts[:, 1] % 12_000.0, 0.0)
    far_corner = np.isclose(np.abs(verts[:, 0]), CLOUD_SIZE_M / 2) & (np.abs(verts[:, 1]) > CLOUD_SIZE_M / 2 - 1)
    assert border.any()
    for v in verts[border][:20]:
        twins = verts[np.all(np.isclose(verts[:, :2], v[:2]), axis=1)]
        assert np.ptp(twins[:, 2]) < 1e-3
    assert far_corner.any()


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), stretch=st.floats(1.0, 3.0), direction=st.floats(0.0, math.pi),
       footprint=st.one_of(st.none(), st.floats(1.0, 400.0)))
def test_a_fields_slope_is_the_derivative_of_its_value(seed: int, stretch: float, direction: float,
                                                       footprint: float | None) -> None:
    """FractalField.slope's value is the field's own and its derivatives are the field's
    central differences (float64 points, where float32 lattice rounding cannot hide an
    error), with and without a footprint's band weights."""
    from datagen.assets.noise import FractalField

    field = FractalField.drawn(np.random.default_rng(seed), 3_000.0, 6, 0.55, stretch=stretch, direction_rad=direction)
    x, y = np.random.default_rng(seed + 1).uniform(-5e4, 5e4, (2, 200))
    fp = None if footprint is None else np.float32(footprint)
    value, dx, dy = field.slope(x, y, fp)
    np.testing.assert_allclose(value, field(x, y, fp), rtol=0, atol=1e-6)  # float32 band weights
    e = 1e-3
    np.testing.assert_allclose(dx, (field(x + e, y, fp) - field(x - e, y, fp)) / (2 * e), rtol=0, atol=1e-8)
    np.testing.assert_allclose(dy, (field(x, y + e, fp) - field(x, y - e, fp)) / (2 * e), rtol=0, atol=1e-8)


def test_a_clouds_height_slope_is_its_height_fields_derivative_towards_the_sun(cumulus: CloudLayer) -> None:
    x, y = np.random.default_rng(3).uniform(-3e4, 3e4, (2, 4000))
    ux, uy = math.cos(0.4), math.sin(0.4)
    h, slope = cumulus.height_slope(x, y, ux, uy)
    np.testing.assert_allclose(h, cumulus.height(x, y), rtol=0, atol=1e-9)
    e = 1e-2
    numeric = (cumulus.height(x + e * ux, y + e * uy) - cumulus.height(x - e * ux, y - e * uy)) / (2 * e)
    smooth = (h > 1.0) & (h < 0.999 * cumulus.thickness_m)  # the clip's kinks: one-sided there
    assert smooth.sum() > 500
    np.testing.assert_allclose(slope[smooth], numeric[smooth], rtol=1e-4, atol=1e-6)


@pytest.mark.parametrize("name", list(GROUND_TYPES))
def test_each_ground_type_puts_land_where_its_share_of_land_says(name: str) -> None:
    kind = GROUND_TYPES[name]
    ground = Ground.drawn(np.random.default_rng(3), kind)
    rng = np.random.default_rng(0)
    x, y = rng.uniform(-2e5, 2e5, (2, 40_000)).astype(np.float32)
    land = ground.land_weight(x, y, np.float32(20.0))
    assert abs(float((land > 0.5).mean()) - kind.land) < 0.08, name


def test_land_albedos_and_relief_differ_by_type_as_their_surfaces_do() -> None:
    rng = np.random.default_rng(0)
    x, y = rng.uniform(-3e4, 3e4, (2, 20_000)).astype(np.float32)
    mean = {name: np.mean(Ground.drawn(np.random.default_rng(5), GROUND_TYPES[name]).albedo(x, y, np.float32(10.0)),
                          axis=1)
            for name in ("farmland", "desert", "snow", "mountains")}
    luminance = {k: float(v @ [0.2126, 0.7152, 0.0722]) for k, v in mean.items()}
    assert luminance["snow"] > 0.5 > luminance["desert"] > 0.15 > luminance["farmland"]
    assert mean["desert"][0] > mean["desert"][2]  # sand is red over blue
    slopes = {}
    for name in ("farmland", "mountains"):
        n = Ground.drawn(np.random.default_rng(5), GROUND_TYPES[name]).normal(x, y, np.float32(30.0))
        slopes[name] = float(np.mean(np.hypot(n[0], n[1]) / n[2]))
    assert slopes["mountains"] > 5 * slopes["farmland"]


@pytest.mark.render
def test_the_kernels_shade_clouds_and_land_as_numpy_does() -> None:
    pytest.importorskip("mitsuba")
    from datagen.render.procedural import evaluate
    from datagen.render.runtime import use_variant

    use_variant("llvm_ad_rgb")
    rng = np.random.default_rng(2)
    x, y = rng.uniform(-3e4, 3e4, (2, 4000)).astype(np.float32)
    footprint = np.full(x.shape, 15.0, np.float32)
    ground = Ground.drawn(np.random.default_rng(8), GROUND_TYPES["coast"])
    for c in range(3):
        kernel = evaluate(lambda x, y, f, ops, c=c: ground.albedo(x, y, f, ops)[c] * ground.land_weight(x, y, f, ops),
                          x, y, footprint)
        np.testing.assert_allclose(kernel, ground.albedo(x, y, footprint)[c] * ground.land_weight(x, y, footprint),
                                   atol=2e-4)
    for c in range(3):
        kernel = evaluate(lambda x, y, f, ops, c=c: ground.normal(x, y, f, ops)[c], x, y, footprint)
        np.testing.assert_allclose(kernel, ground.normal(x, y, footprint)[c], atol=2e-4)
    layer = CloudLayer.drawn(np.random.default_rng(4), 0.4, 1.0, 168_000.0, CLOUD_FORMS["cumulus"], 1200.0)
    light = _light(20.0)
    kernel = evaluate(lambda x, y, f, ops: layer.radiance(light, ops.param_f32(0.0), x, y, f, ops)[0], x, y, footprint)
    np.testing.assert_allclose(kernel, layer.radiance(light, np.float32(0.0), x, y, footprint)[0], atol=2e-3)
