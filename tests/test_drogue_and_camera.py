"""The drogue and hose as flown (canopy schemes, marker bands), the camera's vibration, and
the lens and processing steps of the camera model: each against what it claims."""

from __future__ import annotations

import math
import typing

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from datagen.assets.drogues import (
    CANOPIES,
    DARK_FABRICS,
    DROGUE_CLASSES,
    FABRICS,
    HOSE_BANDS_M,
    HOSE_TEXEL_M,
    HOSE_TEXELS,
    draw_drogue,
    hose_band_texture,
)
from datagen.assets.models.drogue import BAND_SHARE, RIM_X, THROAT_X, build_drogue, hose_texcoords
from datagen.config import load_config, override_config
from datagen.config.schema import CanopyName, world_off
from datagen.core.camera import Intrinsics
from datagen.core.conventions import object_id
from datagen.core.transforms import rotvec_from_rotation
from datagen.render.sensor import (
    D65_K,
    chromatic_aberration,
    daylight_white,
    lens_blur,
    white_balance_gains,
)
from datagen.render.tonemap import drogue_statistics, to_srgb8, tone_curve
from datagen.scene.approach import FrameStates
from datagen.scene.look import _approach_world as approach_world
from datagen.scene.look import frame_look, sensor_draws
from datagen.scene.vibration import MOUNT_VIBRATION, vibration

_REC709 = np.array([0.2126, 0.7152, 0.0722])


# --- the drogue ---------------------------------------------------------------------
def test_the_configs_canopy_names_are_the_tables() -> None:
    assert set(typing.get_args(CanopyName)) == set(CANOPIES)
    assert all(c.fabric in FABRICS and c.trim in FABRICS for c in CANOPIES.values())


def test_dark_canopies_take_their_configured_share_of_approaches_and_are_dark() -> None:
    config = load_config("podcam25")
    shares = config.randomization.drogue.canopies
    expected = sum(v for name, v in shares.items() if CANOPIES[name].fabric in DARK_FABRICS) / sum(shares.values())
    drawn = [approach_world(config, 11, a, 6000.0)["drogue_draw"] for a in range(600)]
    dark = [d for d in drawn if CANOPIES[d.canopy].fabric in DARK_FABRICS]
    assert abs(len(dark) / len(drawn) - expected) < 0.06, (len(dark) / len(drawn), expected)
    for d in dark:
        assert max(d.materials["fabric"][0]) <= FABRICS["dark_grey"].value[1] + 1e-9
    light = [d for d in drawn if d.canopy in ("white", "white_red_panels")]
    assert light and all(min(d.materials["fabric"][0]) >= 0.5 for d in light)


def test_a_drogue_belongs_to_its_approach_and_changes_only_the_drogues_and_hoses_materials() -> None:
    config = load_config("podcam15")
    states = FrameStates(config)
    k = config.frames_per_chain
    on = [frame_look(config, states(i)) for i in (0, 1, k)]
    off_config = override_config(config, world_off("drogue"))
    off = [frame_look(off_config, FrameStates(off_config)(i)) for i in (0, 1, k)]
    def drogue(look):
        return {cls: look.materials["drogue"][cls] for cls in DROGUE_CLASSES}, look.materials["hose"]["rubber"]

    assert on[0].drogue_canopy is not None and drogue(on[0]) == drogue(on[1])
    assert on[0].hose_band_colour == on[1].hose_band_colour
    assert drogue(on[0]) != drogue(on[2])
    for a, b in zip(on, off, strict=True):
        assert {o: m for o, m in a.materials.items() if o not in ("drogue", "hose")} == {
            o: m for o, m in b.materials.items() if o not in ("drogue", "hose")}
        assert {c: m for c, m in a.materials["drogue"].items() if c not in DROGUE_CLASSES} == {
            c: m for c, m in b.materials["drogue"].items() if c not in DROGUE_CLASSES}
        assert drogue(a) != drogue(b)
        # Off: the finer parts take the frame's own fabric and metal, as the canopy and ribs did.
        parts = b.materials["drogue"]
        assert parts["fabric_alt"] == parts["fabric_band"] == parts["tape"] == parts["fabric"]
        assert parts["strut"] == parts["metal"]


@pytest.mark.parametrize("name", sorted(CANOPIES))
def test_a_canopys_pattern_colours_its_gores_and_band_as_it_says(name: str) -> None:
    canopy = CANOPIES[name]
    drawn = draw_drogue(np.random.default_rng(7), name, bands=True)
    m = drawn.materials
    assert drawn.canopy == name
    banded = canopy.pattern in ("band", "alternate_band")
    alternating = canopy.pattern in ("alternate", "alternate_band")
    assert (m["fabric_band"] != m["fabric"]) == (banded and canopy.trim != canopy.fabric)
    assert (m["fabric_alt"] != m["fabric"]) == (alternating and canopy.trim != canopy.fabric)
    assert m["metal"][2] == 1.0 and all(0.0 <= c <= 1.0 for c in m["fabric"][0])


def test_the_drogue_mesh_splits_its_canopy_into_alternate_gores_a_rim_band_and_marked_gores() -> None:
    parts = build_drogue().parts
    assert {"fabric", "fabric_alt", "fabric_band", "markings", "tape", "struts", "metal"} <= set(parts)
    band_x = RIM_X + BAND_SHARE * (THROAT_X - 0.02 - RIM_X)
    assert parts["fabric_band"].triangles_center[:, 0].max() < band_x
    for name in ("fabric", "fabric_alt", "markings"):
        assert parts[name].triangles_center[:, 0].min() > band_x
    # Eight gores in each alternating set, less the two marked ones (one in each set).
    assert abs(parts["fabric"].area - parts["fabric_alt"].area) < 1e-9
    assert parts["markings"].area == pytest.approx(2 * parts["fabric"].area / 7, rel=1e-3)


@given(spacing=st.floats(1.0, 3.0), width=st.floats(0.1, 0.3))
@settings(max_examples=40, deadline=None)
def test_the_hoses_bands_have_the_drawn_spacing_and_width_within_their_reach(spacing: float, width: float) -> None:
    texture = hose_band_texture((0.03, 0.03, 0.03), (0.7, 0.7, 0.7), spacing, width)
    assert texture.shape == (2, HOSE_TEXELS, 3) and np.array_equal(texture[0], texture[1])
    band = texture[0, :, 0] > 0.5
    edges = np.flatnonzero(np.diff(band.astype(int)))
    starts, ends = (edges[0::2] + 1) * HOSE_TEXEL_M, (edges[1::2] + 1) * HOSE_TEXEL_M
    assert len(starts) == len(ends) >= int(HOSE_BANDS_M / spacing) - 1
    assert np.all(np.abs((ends - starts) - width) <= HOSE_TEXEL_M + 1e-9)
    assert np.all(np.abs(np.diff(starts) - spacing) <= HOSE_TEXEL_M + 1e-9)
    assert not band[math.ceil(HOSE_BANDS_M / HOSE_TEXEL_M):].any()  # plain beyond the reach (and clamped)


def test_the_hoses_texture_coordinates_are_its_length_from_the_drogue_end() -> None:
    rng = np.random.default_rng(3)
    points = np.cumsum(rng.normal(size=(48, 3)), axis=0)
    span = HOSE_TEXELS * HOSE_TEXEL_M
    uv = hose_texcoords(points, span, sides=12)
    length = np.linalg.norm(np.diff(points, axis=0), axis=1).sum()
    assert uv.shape == (48 * 12 + 2, 2) and np.all(uv[:, 1] == 0.5)
    assert uv[-12 - 2, 0] == 0.0 and uv[0, 0] == pytest.approx(length / span, rel=1e-6)
    assert np.all(np.diff(uv[:48 * 12:12, 0]) < 0)  # falling towards the drogue


# --- the camera's vibration ----------------------------------------------------------
@given(seed=st.integers(0, 2**31 - 1), approach=st.integers(0, 10_000),
       mount=st.sampled_from(sorted(MOUNT_VIBRATION)), scale=st.floats(0.1, 3.0))
@settings(max_examples=30, deadline=None)
def test_a_vibrations_pointing_rms_is_its_drawn_rms_within_the_mounts_band(seed, approach, mount, scale) -> None:
    config = load_config({"wingcam": "wingcam55", "dashcam": "dashcam75", "podcam": "podcam15"}[mount])
    config = override_config(config, {"camera.vibration.scale": scale})
    shake = vibration(config.camera, seed, approach)
    band = MOUNT_VIBRATION[mount]
    assert band.rms_deg[0] * scale * (1 - 1e-9) <= shake.rms_deg <= band.rms_deg[1] * scale * (1 + 1e-9)
    assert np.all((shake.frequency_hz >= band.frequency_hz[0]) & (shake.frequency_hz <= band.frequency_hz[1]))
    # The RMS over a long time (many periods of the slowest component) is the drawn one, where
    # no two components of an axis beat more slowly than a tenth of that time (they would not
    # average out in it: 8.111 and 8.117 Hz beat once in 175 s).
    span = 400.0 / band.frequency_hz[0]
    gaps = np.abs(shake.frequency_hz[:, None, :] - shake.frequency_hz[None, :, :])[~np.eye(len(shake.frequency_hz),
                                                                                          dtype=bool)]
    assume(gaps.min() > 10.0 / span)
    turn = shake.rotvec(np.linspace(0.0, span, 200_001))
    pointing = math.degrees(math.sqrt(float(np.mean((turn[:, :2] ** 2).sum(axis=1)))))
    roll = math.degrees(math.sqrt(float(np.mean(turn[:, 2] ** 2))))
    assert pointing == pytest.approx(shake.rms_deg, rel=0.1)
    assert roll == pytest.approx(band.roll_share * shake.rms_deg, rel=0.15)


def test_vibration_turns_the_frames_camera_by_its_rotation_at_the_frames_time_and_earlier() -> None:
    config = load_config("podcam15")
    still = override_config(config, world_off("vibration"))
    shake = vibration(config.camera, config.dataset.seed, 0)
    for i in (0, 5):
        a, b = FrameStates(config)(i), FrameStates(still)(i)
        assert a.approach_index == 0
        turn = b.world_from_cam[:3, :3].T @ a.world_from_cam[:3, :3]
        np.testing.assert_allclose(rotvec_from_rotation(turn), shake.rotvec(a.time_s), atol=1e-12)
        np.testing.assert_array_equal(a.world_from_cam[:3, 3], b.world_from_cam[:3, 3])
        earlier = b.earlier.world_from_cam[:3, :3].T @ a.earlier.world_from_cam[:3, :3]
        np.testing.assert_allclose(rotvec_from_rotation(earlier), shake.rotvec(a.earlier.time_s), atol=1e-12)
    assert vibration(still.camera, config.dataset.seed, 0) is None


# --- the lens and the camera's processing -------------------------------------------
def test_the_lens_blurs_an_edge_to_a_10_90_width_of_2_56_sigma() -> None:
    img = np.zeros((64, 400, 3), np.float32)
    img[:, 200:] = 1.0
    for sigma in (1.0, 2.0, 3.0):  # (below a pixel the samples are too coarse to read a width off)
        row = lens_blur(img, sigma)[32, :, 1]
        x = np.arange(400)
        lo, hi = np.interp(0.1, row, x), np.interp(0.9, row, x)
        assert hi - lo == pytest.approx(2.5631 * sigma, rel=0.08), sigma
    assert lens_blur(img, 0.0) is img


def test_chromatic_aberration_keeps_green_and_moves_red_out_and_blue_in_by_the_drawn_pixels() -> None:
    k = Intrinsics.from_hfov_deg(640, 360, 55.0)
    img = np.zeros((360, 640, 3), np.float32)
    img[20:26, 30:36] = 1.0  # a square near the top-left corner
    out = chromatic_aberration(img, k, 1.5)
    np.testing.assert_array_equal(out[..., 1], img[..., 1])

    def centroid(channel):
        ys, xs = np.mgrid[0:360, 0:640]
        w = out[..., channel]
        return np.array([(xs * w).sum(), (ys * w).sum()]) / w.sum()

    centre = np.array([k.cx, k.cy]) - 0.5
    reach = math.hypot(centre[0], centre[1])
    start = np.array([32.5, 22.5])
    radial = (start - centre) / np.linalg.norm(start - centre)
    moved = 1.5 * np.linalg.norm(start - centre) / reach
    np.testing.assert_allclose(centroid(0) - start, moved * radial, atol=0.02)
    np.testing.assert_allclose(centroid(2) - start, -moved * radial, atol=0.02)


@given(temperature=st.floats(4000.0, 25000.0), tint=st.floats(-0.2, 0.2))
def test_white_balance_keeps_a_greys_luminance(temperature: float, tint: float) -> None:
    gains = white_balance_gains(temperature, tint)
    assert float(_REC709 @ gains) == pytest.approx(1.0, abs=1e-6)


def test_white_balance_is_none_at_d65_and_a_lower_setting_turns_the_image_blue() -> None:
    np.testing.assert_allclose(white_balance_gains(D65_K, 0.0), 1.0, atol=1e-6)
    cold, warm = white_balance_gains(5300.0, 0.0), white_balance_gains(8000.0, 0.0)
    assert cold[2] > 1.0 > cold[0] and warm[0] > 1.0 > warm[2]
    white = daylight_white(D65_K)
    np.testing.assert_allclose(white / white[1], [1.0, 1.0, 1.0], atol=0.01)  # D65 is sRGB's white


@given(gamma=st.floats(0.5, 2.0), shoulder=st.floats(0.0, 1.0))
def test_the_tone_curve_rises_follows_the_power_below_its_knee_and_never_passes_white(gamma: float,
                                                                                      shoulder: float) -> None:
    x = np.linspace(0.0, 8.0, 4001)
    y = tone_curve(x, gamma, shoulder)
    assert np.all(np.diff(y) >= 0.0) and y.max() <= 1.0 + 1e-12
    knee = 1.0 - 0.5 * shoulder
    below = x ** gamma <= knee
    np.testing.assert_allclose(y[below], x[below] ** gamma)


def test_the_encoding_with_a_neutral_tone_is_the_plain_srgb_encoding() -> None:
    x = np.random.default_rng(0).uniform(0.0, 1.3, size=(50, 60, 3)).astype(np.float32)
    np.testing.assert_array_equal(to_srgb8(x, (1.0, 0.0)), to_srgb8(x))
    assert np.all(to_srgb8(x, (1.0, 1.0)).astype(int) <= to_srgb8(x).astype(int))


def test_a_dark_drogue_against_a_bright_sky_has_a_negative_contrast_and_its_own_luminance() -> None:
    luma = np.full((100, 100), 0.8, np.float32)
    ids = np.zeros((100, 100), np.uint32)
    ids[40:60, 40:60] = object_id("drogue")
    luma[40:60, 40:60] = 0.1
    stats = drogue_statistics(luma, ids)
    assert stats["drogue_luminance"] == pytest.approx(0.1)
    assert stats["drogue_contrast"] == pytest.approx((0.1 - 0.8) / 0.9)
    ids[:] = 0
    assert drogue_statistics(luma, ids) == {"drogue_luminance": None, "drogue_contrast": None}


# --- the window ---------------------------------------------------------------------------
def test_a_pod_window_is_wet_on_its_share_of_approaches_and_a_windscreen_reflects_instead() -> None:
    pod, cockpit = load_config("podcam15"), load_config("dashcam75")
    share = pod.randomization.window.droplet_share
    pods = [approach_world(pod, 5, a, 6000.0) for a in range(400)]
    wet = np.mean([w["window_droplets"] > 0 for w in pods])
    assert abs(wet - share) < 0.07, wet
    lo, hi = pod.randomization.window.droplets
    assert all(lo <= w["window_droplets"] <= hi for w in pods if w["window_droplets"])
    assert all(w["window_reflection"] is None for w in pods)
    screens = [approach_world(cockpit, 5, a, 6000.0) for a in range(50)]
    assert all(w["window_droplets"] is None and w["window_reflection"] is not None for w in screens)


def test_dirt_on_a_uniform_image_absorbs_a_share_of_the_light_by_its_field() -> None:
    from datagen.render.window import dirty, window_field

    img = np.full((90, 160, 3), 0.5, np.float32)
    out = dirty(img, 0.8, 42)
    field = window_field(42, 160, 90, "dirt")
    assert field.min() == 0.0 and field.max() > 0.5  # patches, and clean glass between them
    np.testing.assert_allclose(out, img * (1.0 - 0.15 * 0.8 * field)[..., None], rtol=1e-5)
    assert dirty(img, 0.0, 42) is img


def test_a_droplet_changes_only_the_pixels_within_its_streak() -> None:
    from datagen.render.window import DROPLET_RADIUS, STREAK, droplets

    rng = np.random.default_rng(1)
    img = rng.random((270, 512, 3)).astype(np.float32)
    for seed in range(20):
        out = droplets(img, 1, seed)
        changed = np.argwhere(np.any(out != img, axis=-1))
        if not len(changed):
            continue
        extent = changed.max(axis=0) - changed.min(axis=0) + 1
        assert extent.max() <= 2 * DROPLET_RADIUS[1] * STREAK[1] * 512 + 3
    assert droplets(img, 0, 3) is img


def test_droplets_are_drawn_out_along_the_airflow_by_up_to_their_streak() -> None:
    from datagen.render.window import STREAK, droplets

    img = np.random.default_rng(2).random((400, 600, 3)).astype(np.float32)
    ratios = []
    for seed in range(30):
        changed = np.argwhere(np.any(droplets(img, 1, seed) != img, axis=-1))
        if len(changed) < 50 or changed.min() <= 0 or (changed.max(axis=0) >= np.array([399, 599])).any():
            continue  # none, too small to measure, or cut by the border
        low, high = np.linalg.eigvalsh(np.cov(changed.T.astype(np.float64)))
        ratios.append(float(np.sqrt(high / low)))
    assert len(ratios) >= 10, ratios
    assert max(ratios) <= STREAK[1] * 1.15 and max(ratios) > 2.0 and min(ratios) < 1.5, ratios


def test_the_windscreens_frame_is_blurred_by_its_blur_circle_and_the_far_scene_kept() -> None:
    from datagen.render.window import COCKPIT_APERTURE_M, defocus_near

    h, w, fx = 120, 200, 1000.0
    rgb = np.full((h, w, 3), 0.8, np.float32)
    depth = np.full((h, w), np.inf, np.float32)
    rgb[:, 90:110], depth[:, 90:110] = 0.02, 0.5  # a dark post half a metre ahead, against the sky
    out = defocus_near(rgb, depth, fx)
    sigma = 0.25 * fx * COCKPIT_APERTURE_M / 0.5  # 1.5 px
    row = out[60, :, 1]
    levels = [-(0.8 - share * 0.78) for share in (0.1, 0.9)]  # 10% and 90% of the fall, negated to rise
    lo, hi = (np.interp(level, -row[60:100], np.arange(60, 100)) for level in levels)
    # The post's left edge (falling from sky to post) is spread to a Gaussian's 10-90% width.
    assert abs(abs(hi - lo) - 2.5631 * sigma) < 0.5, (lo, hi)
    np.testing.assert_allclose(out[:, :70], rgb[:, :70], atol=1e-6)  # far from the post: as it was
    assert out[60, 100, 1] < 0.05  # the post's middle stays dark
    np.testing.assert_array_equal(defocus_near(rgb, np.full((h, w), 50.0, np.float32), fx), rgb)  # nothing near


def test_a_windscreens_reflection_adds_grey_light_up_to_its_strength_of_the_mean_luminance() -> None:
    from datagen.analysis.image_quality import luminance
    from datagen.render.window import reflection

    img = np.random.default_rng(2).random((90, 160, 3)).astype(np.float32) * np.float32([1.0, 0.6, 0.3])
    out = reflection(img, 0.1, 9)
    added = out - img
    assert added.min() >= 0.0 and added.max() <= 0.1 * float(luminance(img).mean()) + 1e-6
    np.testing.assert_allclose(added[..., 0], added[..., 2], atol=1e-6)  # grey, whatever the scene's colour


# --- another aircraft -------------------------------------------------------------------------
def test_the_configs_traffic_kinds_are_the_renderers() -> None:
    from datagen.config.schema import TrafficKind
    from datagen.render.renderer import TRAFFIC_KINDS

    assert set(typing.get_args(TrafficKind)) == set(TRAFFIC_KINDS)


@pytest.mark.parametrize("scene", ["podcam25", "dashcam75", "wingcam55"])
def test_another_aircraft_is_in_the_cameras_nominal_view_in_range_and_clear_of_the_tanker(scene: str) -> None:
    from datagen.assets.rig import MOUNTS
    from datagen.scene.traffic import CLEARANCE_M, VIEW_SHARE

    config = load_config(scene)
    t = config.randomization.traffic
    k = Intrinsics.from_hfov_deg(config.camera.width, config.camera.height, config.camera.hfov_deg)
    mount = MOUNTS[config.camera.mount]
    cam_from_body = np.linalg.inv(mount.body_from_cam())
    draws = [approach_world(config, 17, a, 6000.0) for a in range(300)]
    present = [w for w in draws if w["other_aircraft"] != "none"]
    assert abs(len(present) / len(draws) - t.share) < 0.07
    assert {w["other_aircraft"] for w in present} == {"receiver", "tanker"}
    for w in present:
        p = cam_from_body[:3, :3] @ np.asarray(w["other_aircraft_tanker_m"]) + cam_from_body[:3, 3]
        assert p[2] > 0
        assert abs(p[0] / p[2]) <= math.tan(k.hfov_rad / 2) * VIEW_SHARE + 1e-9
        assert abs(p[1] / p[2]) <= math.tan(k.vfov_rad / 2) * VIEW_SHARE + 1e-9
        assert t.range_m[0] * (1 - 1e-9) <= np.linalg.norm(p) <= t.range_m[1] * (1 + 1e-9)
        assert abs(w["other_aircraft_heading_deg"]) <= t.heading_deg
    assert np.mean([np.linalg.norm(w["other_aircraft_tanker_m"]) >= CLEARANCE_M for w in present]) > 0.95


# --- the video link ----------------------------------------------------------------------------
def _scene_like(h: int, w: int) -> np.ndarray:
    """A smooth sky gradient with a sharp dark drogue-like disc and fine stripes: what a codec
    smooths and rings."""
    ys, xs = np.mgrid[0:h, 0:w]
    img = np.stack([80 + 100 * ys / h, 120 + 80 * ys / h, 200 - 40 * xs / w], axis=-1)
    disc = (xs - w / 2) ** 2 + (ys - h / 2) ** 2 < (h / 5) ** 2
    img[disc] = (25, 25, 30)
    img[(xs // 3) % 2 == 0 & (ys < h // 6)] += 40
    return np.clip(img, 0, 255).astype(np.uint8)


def _psnr(a: np.ndarray, b: np.ndarray) -> float:
    return 10.0 * math.log10(255.0**2 / float(np.mean((a.astype(np.float64) - b) ** 2)))


@pytest.mark.parametrize(("h", "w"), [(270, 512), (271, 513)])
def test_the_video_round_trip_keeps_the_size_and_loses_more_at_a_higher_crf(h: int, w: int) -> None:
    pytest.importorskip("av", reason="needs the video extra: pip install -e '.[video]'")
    from datagen.render.sensor import video_round_trip

    img = _scene_like(h, w)
    out = {crf: video_round_trip(img, crf) for crf in (16, 30, 44)}
    assert all(o.shape == img.shape and o.dtype == np.uint8 for o in out.values())
    psnr = {crf: _psnr(o, img) for crf, o in out.items()}
    assert psnr[16] > psnr[30] > psnr[44] > 20.0, psnr
    assert psnr[16] > 38.0, psnr  # near transparent
    np.testing.assert_array_equal(video_round_trip(img, 30), out[30])  # the same on every call


def test_video_takes_its_share_of_frames_and_replaces_their_jpeg_round_trip() -> None:
    pytest.importorskip("av", reason="needs the video extra: pip install -e '.[video]'")
    config = override_config(load_config("wingcam55"), {"randomization": {"sensor": {"video_share": 0.4,
                                                                                     "video_crf": [22, 26]}}})
    seed = config.dataset.seed
    looks = [sensor_draws(config, seed, i) for i in range(400)]
    video = [d for d in looks if d.get("sensor_video_crf") is not None]
    assert abs(len(video) / len(looks) - 0.4) < 0.08
    assert {d["sensor_video_crf"] for d in video} == {22, 23, 24, 25, 26}
    assert all(d["sensor_jpeg_quality"] is None for d in video)
    assert all(d["sensor_jpeg_quality"] is not None for d in looks if d.get("sensor_video_crf") is None)
    plain = [sensor_draws(load_config("wingcam55"), seed, i) for i in range(400)]
    assert all(d.get("sensor_video_crf") is None for d in plain)
    # The draw comes after every earlier draw of the frame's sensor stream: those are unchanged.
    for a, b in zip(looks, plain, strict=True):
        assert {k: v for k, v in a.items() if k not in ("sensor_video_crf", "sensor_jpeg_quality")} == {
            k: v for k, v in b.items() if k != "sensor_jpeg_quality"}
    # And a frame's look carries them.
    look = frame_look(config, FrameStates(config)(int(np.flatnonzero([d.get("sensor_video_crf") for d in looks])[0])))
    assert look.sensor_video_crf is not None and look.sensor_jpeg_quality is None


def test_a_video_share_without_pyav_is_one_line_naming_the_key_and_the_extra(monkeypatch) -> None:
    import importlib.util

    from datagen.core.errors import ConfigError

    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec", lambda name, *a: None if name == "av" else real(name, *a))
    with pytest.raises(ConfigError) as caught:
        override_config(load_config("wingcam55"), {"randomization": {"sensor": {"video_share": 0.1}}})
    message = str(caught.value)
    assert "randomization.sensor.video_share" in message and "datagen[video]" in message, message
    assert "\n" not in message
