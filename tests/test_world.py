"""The world's randomizers (issue 18): clouds, sea state, liveries, the camera model and the
backlit sun. Each is switchable without touching any other draw, is drawn from its own
stream (per approach or per frame), is recorded in the manifest and the audit's appearance
section, and keeps the labels exact (lens distortion: labels, audit and PnP follow it)."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from datagen.analysis.audit import audit
from datagen.analysis.evaluate import evaluate
from datagen.config import load_config, override_config
from datagen.config.schema import WORLD_RANDOMIZERS, world_off
from datagen.dataset.columns import APPEARANCE, MEASURED_COLUMNS
from datagen.dataset.reader import load_dataset
from datagen.pipeline.build import build_dataset
from datagen.scene.approach import FrameStates
from datagen.scene.look import FrameLook, frame_look

from .support import ROOT, manifest_rows

#: The FrameLook fields each randomizer draws (None when it is off).
_FIELDS = [f.name for f in dataclasses.fields(FrameLook)]
DRAWS = {
    "clouds": [f for f in _FIELDS if f.startswith("cloud_")],
    "sea": ["sea_wind_direction_deg", "sea_wave_slope_variance", "sea_whitecap_fraction", "sea_colour", "sea_seed"],
    "livery": ["receiver_livery", "tanker_livery", "livery_weathering", "livery_seed", "aircraft_lights",
               "aircraft_light_scale"],
    "sensor": [f for f in _FIELDS if f.startswith("sensor_")],
    "backlit sun": ["sun_backlit"],
    "haze": ["haze_visibility_m", "haze_scale_height_m"],
    "ground": ["ground_type", "ground_seed"],
    "vibration": ["camera_vibration_rms_deg", "camera_vibration_hz"],
    "drogue": ["drogue_canopy", "drogue_tape", "hose_band_colour", "hose_band_spacing_m", "hose_band_width_m"],
    "window": ["window_dirt", "window_droplets", "window_seed"],
    "traffic": ["other_aircraft", "other_aircraft_tanker_m", "other_aircraft_heading_deg"],
}
#: Draws of a mount other than the wingcam these tests use (a cockpit's windscreen).
OTHER_MOUNTS = {"window_reflection"}
#: Draws only some approaches make while their randomizer is on (most have no other aircraft),
#: and the sensor's optional ones: the video round trip (``video_share`` 0) and the rolling
#: shutter (``rolling_shutter`` off) by default.
SOMETIMES = {"other_aircraft_tanker_m", "other_aircraft_heading_deg", "sensor_video_crf", "sensor_readout_s"}
#: Draws a randomizer replaces when on: the sea's approach wind replaces the frame's own
#: wind draw (waves, whitecaps and glint then agree); a backlit sun moves the sun's azimuth.
#: The drogue's draw replaces the frame's own draws of the drogue's and the hose's materials.
REPLACES = {"sea": ["sea_wind_speed_mps", "sea_roughness"], "backlit sun": ["sun_azimuth_deg"],
            "drogue": ["materials"]}


def wingcam(**updates):
    config = load_config("wingcam55")
    return override_config(config, {"randomization.sensor.distortion": True, **updates})


def looks(config, frames) -> list[FrameLook]:
    states = FrameStates(config)
    return [frame_look(config, states(i)) for i in frames]


def test_the_draw_table_covers_every_world_field_of_the_look() -> None:
    world = set(_FIELDS[_FIELDS.index("sun_backlit"):]) | {"haze_visibility_m"}
    assert set().union(*map(set, DRAWS.values())) | OTHER_MOUNTS == world and set(DRAWS) == set(WORLD_RANDOMIZERS)


@pytest.mark.parametrize("name", list(WORLD_RANDOMIZERS))
def test_a_randomizer_switched_off_draws_none_of_its_fields_and_changes_no_other_draw(name: str) -> None:
    config = wingcam()
    frames = range(0, 240, 7)
    on, off = looks(config, frames), looks(override_config(config, world_off(name)), frames)
    untouched = [f for f in _FIELDS if f not in DRAWS[name] + REPLACES.get(name, [])]
    for a, b in zip(on, off, strict=True):
        assert all(getattr(b, f) is None for f in DRAWS[name]), name
        assert all(getattr(a, f) is not None for f in DRAWS[name] if f not in SOMETIMES), name
        for f in untouched:
            assert getattr(a, f) == getattr(b, f), (name, f)
    if name == "backlit sun":  # about a fifth of the frames put the sun ahead of the camera
        share = np.mean([look.sun_backlit for look in on])
        assert 0.05 < share < 0.45, share


def test_weather_and_liveries_belong_to_the_approach_and_the_sensor_to_the_frame() -> None:
    config = wingcam()
    states = FrameStates(config)
    per_approach = config.frames_per_chain
    a0, a1, b0 = (frame_look(config, states(i)) for i in (0, 1, per_approach))
    assert states(0).approach_index == states(1).approach_index != states(per_approach).approach_index
    for field in ("cloud_seed", "cloud_deck_coverage", "sea_seed", "sea_wind_speed_mps", "receiver_livery",
                  "livery_seed", "haze_visibility_m", "haze_scale_height_m"):
        assert getattr(a0, field) == getattr(a1, field), field
    assert (a0.cloud_seed, a0.sea_seed, a0.livery_seed) != (b0.cloud_seed, b0.sea_seed, b0.livery_seed)
    assert a0.sensor_seed != a1.sensor_seed and a0.sensor_distortion != a1.sensor_distortion
    # Clouds stay at their altitude while the camera moves along the approach.
    assert a0.cloud_deck_altitude_m == a1.cloud_deck_altitude_m


def test_the_draws_lie_within_the_configured_ranges() -> None:
    config = wingcam()
    r = config.randomization
    for look in looks(config, range(0, 400, 3)):
        altitude_low = look.cloud_deck_altitude_m
        assert r.clouds.deck_coverage[0] <= look.cloud_deck_coverage <= r.clouds.deck_coverage[1]
        assert altitude_low > 0 and r.clouds.opacity[0] <= look.cloud_opacity <= r.clouds.opacity[1]
        assert r.sensor.iso[0] <= look.sensor_iso <= r.sensor.iso[1]
        assert r.sensor.exposure_time_s[0] <= look.sensor_exposure_time_s <= r.sensor.exposure_time_s[1]
        assert r.sensor.jpeg_quality[0] <= look.sensor_jpeg_quality <= r.sensor.jpeg_quality[1]
        k1, k2, _, _, k3 = look.sensor_distortion
        assert r.sensor.k1[0] <= k1 <= r.sensor.k1[1] and r.sensor.k2[0] <= k2 <= r.sensor.k2[1] and k3 == 0.0
        assert look.receiver_livery in r.livery.schemes and look.tanker_livery in r.livery.schemes
        assert 0.0 <= look.sea_whitecap_fraction < 0.1 and look.sea_wave_slope_variance > 0
        assert r.sky.sun_elevation_deg[0] <= look.sun_elevation_deg <= r.sky.sun_elevation_deg[1]
        assert r.haze.visibility_m[0] <= look.haze_visibility_m <= r.haze.visibility_m[1]
        assert r.haze.aerosol_scale_height_m[0] <= look.haze_scale_height_m <= r.haze.aerosol_scale_height_m[1]


@pytest.fixture(scope="module")
def distorted(tmp_path_factory) -> Path:
    """A labels-only wingcam55 build with every randomizer on, lens distortion included."""
    root = tmp_path_factory.mktemp("world") / "distorted"
    build_dataset(override_config(wingcam(), {"dataset.frames": 120, "dataset.shard_size": 60}), root, render=False)
    return root


def test_every_world_draw_is_in_the_manifest_and_the_audit_appearance_section(distorted: Path) -> None:
    rows = manifest_rows(distorted)
    for row in rows.values():
        for field in (f for fields in DRAWS.values() for f in fields if f not in SOMETIMES):
            assert row[field] is not None, field
        assert all(row[c] is None for c in MEASURED_COLUMNS)  # nothing rendered, nothing measured
    result = audit(load_dataset(distorted))
    assert result.passed, [c for c in result.checks if not c.passed]
    section = result.stats.appearance
    assert set(section) == set(APPEARANCE)
    assert section["clouds"]["cloud_deck_coverage"].frames == len(rows)
    assert sum(section["sensor"]["sensor_iso"].histogram or []) == len(rows)
    assert sum((section["livery"]["tanker_livery"].values or {}).values()) == len(rows)
    assert section["image"]["share_cloud"].frames == 0  # labels only: no image statistics


def test_a_switched_off_randomizer_shows_as_not_drawn_in_the_audit(tmp_path: Path) -> None:
    config = override_config(load_config("wingcam55"), {"dataset.frames": 20, **world_off("clouds", "livery")})
    build_dataset(config, tmp_path / "ds", render=False)
    section = audit(load_dataset(tmp_path / "ds")).stats.appearance
    assert all(entry.frames == 0 for entry in section["clouds"].values())
    assert section["livery"]["receiver_livery"].frames == 0 and section["sensor"]["sensor_iso"].frames == 20


def test_distorted_labels_differ_from_pinhole_ones_and_the_audit_recomputes_them(distorted: Path, tmp_path) -> None:
    pinhole = tmp_path / "pinhole"
    build_dataset(override_config(wingcam(**{"randomization.sensor.distortion": False}),
                                  {"dataset.frames": 120, "dataset.shard_size": 60}), pinhole, render=False)
    a, b = load_dataset(distorted), load_dataset(pinhole)
    assert a.distortion.any(axis=1).all() and not b.distortion.any()
    both = a.labeled & b.labeled
    shift = np.linalg.norm(a.center_px - b.center_px, axis=-1)[both]
    assert shift.max() > 1.0  # the lens moves labels by pixels near the edges
    np.testing.assert_allclose(a.recompute().center_px[a.labeled], a.center_px[a.labeled], atol=1e-6)


def test_pnp_through_the_recorded_lens_recovers_the_true_vector(distorted: Path) -> None:
    result = evaluate(load_dataset(distorted), noise_px=0.0)
    ok = result.success
    assert ok.mean() > 0.8
    assert result.error_m[ok].max() < 1e-3


@pytest.mark.parametrize("seed", [0, 55, 2**31 - 1])
def test_the_materials_drawn_in_one_call_equal_each_drawn_from_the_generator(seed: int, monkeypatch) -> None:
    """draw_look takes the materials' uniforms in one call (look._Uniforms); each must be
    the value the generator's own ``uniform(lo, hi)`` returns, so that the looks of every
    dataset built before stay the same bit for bit."""
    from datagen.core.conventions import frame_rng
    from datagen.scene import look as look_module

    config = load_config("wingcam55")
    batched = [look_module.draw_look(config, frame_rng(seed, i)) for i in range(40)]

    class OneByOne:  # every draw straight from the generator, as before the batching
        def __init__(self, rng, n):
            self.uniform = rng.uniform

    monkeypatch.setattr(look_module, "_Uniforms", OneByOne)
    one_by_one = [look_module.draw_look(config, frame_rng(seed, i)) for i in range(40)]
    assert batched == one_by_one
    assert len({lk.materials["receiver"]["paint"].base_color for lk in batched}) == 40  # the draws do vary


def test_looks_drawn_with_a_shared_approach_dict_equal_looks_drawn_alone() -> None:
    """The writer keeps each chain's weather and liveries for its other frames: the looks
    are those each frame gets alone, with every world randomizer on, in any frame order."""
    config = wingcam(**{"randomization.sensor.enabled": True})
    states = FrameStates(config)
    frames = [int(i) for i in np.random.default_rng(2).permutation(300)[:120]]
    approaches: dict = {}
    shared = [frame_look(config, states(i), approaches) for i in frames]
    assert shared == [frame_look(config, states(i)) for i in frames]
    assert len(approaches) == len({states(i).approach_index for i in frames}) < len(frames)


# --- light through the cloud layers ---------------------------------------------------------
@pytest.mark.render
def test_sunlight_through_cloud_edges_makes_no_fireflies() -> None:
    """Three wingcam55 frames over a broken cloud deck (every randomizer on, sensor and
    denoiser off, 512x270, 128 spp): with shadow rays that stop at a cloud's mask (Mitsuba's
    ``path``) the sun reached the sea through thin cloud edges only by BSDF sampling and
    these frames held 64 isolated hot pixels; with shadow rays through the mask's null
    transmission (``volpath``) they hold at most a stray one or two."""
    from datagen.analysis.image_quality import fireflies
    from datagen.pipeline.frame import draw_frame
    from datagen.render.renderer import Renderer
    from datagen.scene.resolved import Scene

    config = override_config(load_config(ROOT / "scenes" / "wingcam55.yaml"),
                             {"render.denoise": "off", "randomization.sensor.enabled": False,
                              "camera.width": 512, "camera.height": 270})
    scene = Scene.resolve(config)
    renderer = Renderer(scene, spp=128)
    assert renderer.world.integrator == "volpath"
    states = FrameStates(config)
    hot = 0
    for frame in (0, 5, 21):
        draws = draw_frame(scene, states, frame)
        assert draws.look.cloud_deck_coverage  # the frames this test is about: clouds in view
        hot += int(fireflies(renderer.render(draws.state, draws.look, draws.render_seed, geometry=False).rgb).sum())
    assert hot <= 3, hot
    cloudless = Renderer(Scene.resolve(override_config(config, world_off("clouds"))), spp=1)
    assert cloudless.world.integrator == "path"  # no null surfaces: the scene renders as before


@pytest.mark.render
def test_the_seas_waves_bring_no_fireflies_back() -> None:
    """Three wingcam55 frames over a sea with wave normals (the randomizers on, clouds,
    camera model and denoiser off, 512x270, 64 spp, suns 15-70 degrees high): at most a
    stray hot pixel on the sea and the aircraft together (issue 32 blamed the wave normals
    for speckles that came from the cloud layers: this keeps the sea itself honest)."""
    from datagen.analysis.image_quality import fireflies
    from datagen.pipeline.frame import draw_frame
    from datagen.render.renderer import Renderer
    from datagen.scene.resolved import Scene

    config = override_config(load_config(ROOT / "scenes" / "wingcam55.yaml"),
                             {"render.denoise": "off", "camera.width": 512, "camera.height": 270,
                              "randomization.sky.sun_elevation_deg": [15.0, 70.0], **world_off("clouds", "sensor")})
    assert config.randomization.sea.waves and config.randomization.sea.model == "cox_munk"
    scene = Scene.resolve(config)
    renderer = Renderer(scene, spp=64)
    states = FrameStates(config)
    hot = 0
    for frame in (0, 14, 21):
        draws = draw_frame(scene, states, frame)
        result = renderer.render(draws.state, draws.look, draws.render_seed, geometry=True)
        sea = (result.object_id == 0) & np.isfinite(result.depth)
        assert sea.mean() > 0.2  # the frames this test is about: the sea in view
        hot += int(fireflies(result.rgb).sum())
    assert hot <= 3, hot
