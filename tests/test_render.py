"""Rendering with Mitsuba: images aligned to the labels, per-frame parameters, outputs.

Marked ``render``: small resolutions, still run in CI.
"""

from __future__ import annotations

import dataclasses
import json
import subprocess
import sys
from pathlib import Path
from typing import Final

import numpy as np
import pytest

from datagen.assets.loader import load_mesh
from datagen.assets.rig import body_from_cam_looking
from datagen.assets.table import feature_table, object_paths
from datagen.atomic import write_exr
from datagen.config import load_config, override_config
from datagen.config.schema import RenderConfig, world_off
from datagen.core.camera import Intrinsics, project_points, project_xyz
from datagen.core.conventions import EARTH_RADIUS_M, OTHER_AIRCRAFT_ID, frame_rng, object_id, render_seed
from datagen.core.errors import DatagenError
from datagen.core.transforms import apply_transform, invert_rigid, make_transform, rotation_from_ypr
from datagen.render.atmosphere import dip_rad
from datagen.render.raycast import visibility_tolerance_m
from datagen.render.renderer import Renderer
from datagen.render.tonemap import to_srgb8
from datagen.render.world import EARTH_CAP_SAG, SURFACES
from datagen.scene.approach import FrameStates, frame_state
from datagen.scene.look import draw_look, frame_look
from datagen.scene.resolved import Scene

pytestmark = pytest.mark.render
ROOT = Path(__file__).resolve().parents[1]

import mitsuba as mi  # noqa: E402  (after the marker: every test here needs Mitsuba)

from datagen.render.denoise import denoise_render, guided_integrator  # noqa: E402
from datagen.render.mitsuba import sensor_dict, visible  # noqa: E402
from datagen.render.runtime import set_threads, thread_count, use_variant  # noqa: E402


@pytest.fixture(scope="module", autouse=True)
def variant() -> str:
    return use_variant("auto")


@pytest.fixture(autouse=True)
def release_renderers():
    """Each test's Mitsuba scenes and Dr.Jit memory freed after it: they sit in reference
    cycles until a collection, and the tests that followed ran up to 3x slower (this
    module: 362 s, 208 s with this). Only here: a collection after every test of the
    suite costs more than it saves elsewhere."""
    yield
    import gc

    import drjit as dr

    gc.collect()
    dr.sync_thread()
    dr.flush_malloc_cache()


@pytest.fixture
def one_thread():
    """One Dr.Jit thread for the test (byte-identical renders), the pool restored after."""
    before = thread_count()
    set_threads(1)
    yield
    set_threads(before)


def sphere_scene(hfov_deg: float, spp: int, *, radius_px: float = 1.6, dark: bool = False, guides: bool = False,
                 margin_px: int = 0, distortion=None):
    """Twelve small spheres (``radius_px`` in the image) on a jittered grid seen through a
    tilted, offset 192x108 camera: emitting on black, or (``dark``) dark grey before a
    white sky. Returns the Mitsuba scene and the label module's projection of the centres
    (through the lens ``distortion`` when given; the scene's pinhole camera then renders
    the image grown by ``margin_px``, as the renderer does for the sensor to distort)."""
    k = Intrinsics.from_hfov_deg(192, 108, hfov_deg)
    rng = np.random.default_rng(int(hfov_deg))
    world_from_cam = make_transform(rotation_from_ypr(0.4, -0.3, 0.7), [120.0, -40.0, 6000.0])
    # A 4 x 3 grid of image positions, jittered, kept away from the edges.
    uv = np.stack(np.meshgrid(np.linspace(25, 167, 4), np.linspace(22, 86, 3)), -1).reshape(-1, 2)
    uv += rng.uniform(-4, 4, uv.shape)
    depth = rng.uniform(20.0, 60.0, len(uv))
    points_cam = np.column_stack([(uv[:, 0] - k.cx) / k.fx * depth, (uv[:, 1] - k.cy) / k.fy * depth, depth])
    points_world = apply_transform(world_from_cam, points_cam)
    integrator: dict = {"type": "path", "max_depth": 6}
    if guides:
        integrator = guided_integrator(integrator)
    # Render in a camera-centred frame, as the renderer does.
    origin = world_from_cam[:3, 3]
    scene = {"type": "scene", "integrator": integrator,
             "sensor": sensor_dict(k.with_margin(margin_px), make_transform(world_from_cam[:3, :3], [0.0, 0.0, 0.0]),
                                   spp)}
    if dark:
        scene["sky"] = {"type": "constant", "radiance": {"type": "rgb", "value": 1.0}}
    for i, (p, z) in enumerate(zip(points_world - origin, depth, strict=True)):
        sphere = {"type": "sphere", "center": p.tolist(), "radius": radius_px * z / k.fx}
        if dark:
            sphere["bsdf"] = {"type": "diffuse", "reflectance": {"type": "rgb", "value": 0.05}}
        else:
            sphere["emitter"] = {"type": "area", "radiance": {"type": "rgb", "value": 1.0}}
        scene[f"s{i}"] = sphere
    points_cam = apply_transform(invert_rigid(world_from_cam), points_world)
    expected = project_points(points_cam, k) if distortion is None else np.stack(
        project_xyz(*points_cam.T, k, distortion), axis=-1)
    return mi.load_dict(scene, optimize=False), expected


def render_spheres(scene, seed: int = 3, *, denoised: bool = False) -> np.ndarray:
    """The grey image of a :func:`sphere_scene` (OIDN-denoised at the shipped quality,
    guided by the aov channels when the scene has them)."""
    image = np.asarray(mi.render(scene, seed=seed), dtype=np.float32)
    if denoised:
        out = denoise_render(image, guides=image.shape[-1] >= 9, quality=RenderConfig().denoise_quality)
        return np.asarray(out).mean(axis=-1)
    return image[..., :3].mean(axis=-1)


def sphere_stats(image: np.ndarray, expected: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per sphere: the distance of its intensity centroid (difference from the local
    background, in a 12 px window) from its label projection, px; and its contrast
    (mean of the 2x2 pixels about the centre minus the background ring's)."""
    jj, ii = np.mgrid[0 : image.shape[0], 0 : image.shape[1]]
    errors, contrasts = [], []
    for (u, v) in expected:
        du, dv = np.abs(ii + 0.5 - u), np.abs(jj + 0.5 - v)
        window = (du < 6) & (dv < 6)
        background = image[window & ~((du < 4) & (dv < 4))].mean()
        w = np.abs(image - background) * window
        centroid = np.array([(w * (ii + 0.5)).sum(), (w * (jj + 0.5)).sum()]) / w.sum()
        errors.append(np.linalg.norm(centroid - [u, v]))
        contrasts.append(image[(du < 1) & (dv < 1)].mean() - background)
    return np.array(errors), np.array(contrasts)


@pytest.mark.parametrize("hfov_deg", [15.0, 25.0, 55.0, 75.0])
def test_emissive_spheres_land_on_their_label_projection(hfov_deg: float) -> None:
    """Tiny emitting spheres render with their intensity centroid within 0.1 px of
    the label module's projection of their centres, through a tilted, offset camera."""
    scene, expected = sphere_scene(hfov_deg, 256)
    errors, _ = sphere_stats(render_spheres(scene), expected)
    assert errors.max() < 0.1, (hfov_deg, errors)


@pytest.mark.parametrize(("hfov_deg", "distortion"), [(55.0, (-0.12, 0.03, 0.001, -0.001, 0.0)),
                                                     (25.0, (0.04, 0.03, -0.001, 0.001, 0.0)),
                                                     (75.0, (-0.08, 0.01, 0.0005, 0.0, 0.0))])
def test_emissive_spheres_land_on_their_distorted_label_projection(hfov_deg: float, distortion) -> None:
    """Through the camera model's lens distortion (a pinhole render with a margin, resampled
    by :func:`datagen.render.sensor.distort_image`), the spheres' centroids lie within 0.1 px
    of the labels' projection through the same distortion, and far from the pinhole one."""
    from datagen.render.sensor import distort_image, distortion_margin_px

    k = Intrinsics.from_hfov_deg(192, 108, hfov_deg)
    k1, k2, p1, p2, _ = distortion
    margin = distortion_margin_px(k, (k1, k1), (k2, k2), (min(p1, p2), max(p1, p2)))
    scene, expected = sphere_scene(hfov_deg, 256, margin_px=margin, distortion=distortion)
    _, pinhole = sphere_scene(hfov_deg, 4)
    grey = render_spheres(scene)
    assert grey.shape == (108 + 2 * margin, 192 + 2 * margin)
    image = distort_image({"rgb": np.repeat(grey[..., None], 3, axis=-1)}, k, margin, distortion)["rgb"].mean(axis=-1)
    errors, _ = sphere_stats(image, expected)
    assert errors.max() < 0.1, (hfov_deg, errors)
    assert np.linalg.norm(expected - pinhole, axis=1).max() > 0.15  # the lens moves them beyond the tolerance


@pytest.mark.parametrize("hfov_deg", [15.0, 25.0, 55.0, 75.0])
def test_emissive_spheres_stay_on_their_label_projection_after_denoising(hfov_deg: float) -> None:
    """The same spheres denoised by OIDN (as shipped: no guides): every centroid still
    within 0.1 px of the label projection."""
    scene, expected = sphere_scene(hfov_deg, 256, guides=RenderConfig().denoise_guides)
    errors, _ = sphere_stats(render_spheres(scene, denoised=True), expected)
    assert errors.max() < 0.1, (hfov_deg, errors)


@pytest.mark.parametrize("dark", [False, True])
def test_denoising_the_default_spp_moves_centroids_no_further_than_its_sampling_noise(dark: bool) -> None:
    """At the shipped spp a sphere's centroid scatters by the noise of its edge pixels'
    coverage (about 0.1 px at 4 spp); the denoised frame's scatter stays within 0.05 px
    (mean) of the raw frame's and under 0.35 px for every sphere."""
    shipped = RenderConfig()
    scene, expected = sphere_scene(55.0, shipped.spp, dark=dark, guides=shipped.denoise_guides)
    raw, _ = sphere_stats(render_spheres(scene), expected)
    denoised, _ = sphere_stats(render_spheres(scene, denoised=True), expected)
    assert denoised.mean() <= raw.mean() + 0.05 and denoised.max() < 0.35, (raw, denoised)


@pytest.mark.parametrize(("dark", "radius_px"), [(False, 1.5), (False, 3.0), (True, 1.5), (True, 3.0)])
def test_small_features_keep_their_contrast_after_denoising(dark: bool, radius_px: float) -> None:
    """Features 3 and 6 px across, bright on black or dark on a white sky: denoised at the
    shipped spp, each keeps 0.75 to 1.6 times its contrast in a 1024-spp render (the
    denoiser neither erases nor invents them; measured 0.85-1.53)."""
    converged, expected = sphere_scene(55.0, 1024, radius_px=radius_px, dark=dark)
    _, reference = sphere_stats(render_spheres(converged), expected)
    shipped = RenderConfig()
    scene, _ = sphere_scene(55.0, shipped.spp, radius_px=radius_px, dark=dark, guides=shipped.denoise_guides)
    _, contrast = sphere_stats(render_spheres(scene, denoised=True), expected)
    ratio = contrast / reference
    assert (ratio > 0.75).all() and (ratio < 1.6).all(), ratio


def renderer_for(config_name: str, **kwargs) -> tuple[Renderer, object]:
    config = load_config(ROOT / "scenes" / config_name)
    return Renderer(Scene.resolve(config), spp=kwargs.pop("spp", 4), width=320, height=169, **kwargs), config


@pytest.mark.parametrize(("config_name", "frame", "obj"), [("podcam15.yaml", 0, "drogue"),
                                                         ("wingcam55.yaml", 2, "tanker")])
def test_object_id_silhouette_matches_projected_mesh(config_name: str, frame: int, obj: str) -> None:
    # Twice 2048 x 1080: the geometry pass alone (no path tracing) is quick, and thin
    # parts such as wing and fin tips then span pixels instead of slipping between centres
    # (at 2048 a fin's tip slipped 1.14 px inside its projection; at three times, 0.14).
    config = load_config(ROOT / "scenes" / config_name)
    renderer = Renderer(Scene.resolve(config), spp=4, width=2 * 2048, height=2 * 1080)
    k = renderer.intrinsics
    mesh = load_mesh(object_paths(config, obj)[0], obj).combined
    states = FrameStates(config)
    for i in range(frame, frame + 200):  # the first frame from ``frame`` on that shows the object whole
        state = states(i)
        cam_from_obj = invert_rigid(state.world_from_cam) @ state.world_from(obj)
        points_cam = apply_transform(cam_from_obj, mesh.vertices)
        uv = project_points(points_cam, k)
        projected = np.array([*uv.min(axis=0), *uv.max(axis=0)])
        if (points_cam[:, 2] > 0).all() and projected[0] > 0 and projected[1] > 0 and projected[2] < k.width \
                and projected[3] < k.height:
            break
    else:
        pytest.fail(f"no frame of {config_name} from {frame} on shows the {obj} whole")
    # Unoccluded: move the hose (which hangs in front of the drogue seen from the pod) away.
    state = dataclasses.replace(state, hose_points_world=state.hose_points_world + [0.0, 0.0, 5000.0])
    look = frame_look(config, state)
    renderer.pose(state, look)
    _, ids, _ = renderer.geometry_pass()
    mask = ids == object_id(obj)
    assert mask.sum() > 50, "the object should be in view"
    rows, cols = np.nonzero(mask)
    silhouette = np.array([cols.min(), rows.min(), cols.max() + 1, rows.max() + 1], dtype=float)
    np.testing.assert_array_less(np.abs(silhouette - projected) / 2, 1.0)  # in pixels at 2048 x 1080


def test_per_frame_parameters_reproduce_a_fresh_scene_load(one_thread) -> None:
    a, config = renderer_for("dashcam75.yaml")
    b, _ = renderer_for("dashcam75.yaml")
    seed = config.dataset.seed
    first, second = frame_state(config, 0), frame_state(config, 7)
    look0, look7 = frame_look(config, first), frame_look(config, second)
    a.render(first, look0, render_seed(seed, 0))  # a: posed and dressed twice
    again = a.render(second, look7, render_seed(seed, 7), geometry=True)
    fresh = b.render(second, look7, render_seed(seed, 7), geometry=True)  # b: from a fresh load
    np.testing.assert_array_equal(again.rgb, fresh.rgb)
    np.testing.assert_array_equal(again.object_id, fresh.object_id)
    np.testing.assert_array_equal(again.depth, fresh.depth)
    other = a.render(first, look0, render_seed(seed, 0))
    assert np.abs(other.rgb - fresh.rgb).mean() > 1e-3  # and the frames do differ


def test_a_frame_renders_the_same_first_in_its_process_or_after_another(one_thread) -> None:
    """A resumed build renders its frames after other frames, or first: the image must not
    change (it did in 33 of 138,240 pixels of this frame before a fresh scene was posed twice)."""
    config = override_config(load_config(ROOT / "scenes" / "wingcam55.yaml"),
                             {"camera.width": 512, "camera.height": 270, "render.spp": 4})
    seed = config.dataset.seed
    scene = Scene.resolve(config)

    def render(renderer, i):
        state = frame_state(config, i)
        return renderer.render(state, frame_look(config, state), render_seed(seed, i)).rgb

    first = render(Renderer(scene), 5)
    later = Renderer(scene)
    render(later, 4)
    np.testing.assert_array_equal(render(later, 5), first)


def test_posing_the_next_frame_of_an_approach_sets_the_drogues_and_hoses_materials_no_more(monkeypatch) -> None:
    """The drogue's and the hose's materials are drawn once an approach (the aircraft's every
    frame): the frame after an approach's first sets none of theirs again, and the next
    approach sets them."""
    from mitsuba import SceneParameters

    renderer, config = renderer_for("wingcam55.yaml", spp=1)
    assert config.approach.frames_per_approach > 2
    seed = config.dataset.seed
    set_keys: list[str] = []
    original = SceneParameters.__setitem__

    def counting(self, key, value):
        set_keys.append(key)
        original(self, key, value)

    def materials_set(i: int) -> dict[str, set[str]]:
        state = frame_state(config, i)
        set_keys.clear()
        renderer.render(state, frame_look(config, state), render_seed(seed, i))
        keys = {k for k in set_keys if ".bsdf." in k}
        return {obj: {k for k in keys if k.startswith(prefix)}
                for obj, prefix in (("drogue", "drogue_group."), ("hose", "hose.bsdf."), ("tanker", "tanker_group."))}

    monkeypatch.setattr(SceneParameters, "__setitem__", counting)
    first = materials_set(0)
    assert all(first.values())  # a fresh scene: every material
    second = materials_set(1)
    assert second["drogue"] == second["hose"] == set() and second["tanker"]
    assert all(materials_set(config.approach.frames_per_approach).values())  # the next approach's


def test_a_frame_reads_no_value_back_one_at_a_time_but_in_the_sky_models_update(monkeypatch) -> None:
    """Dr.Jit's one-value copies in a frame (after the first) are all the sky model's: sunsky's
    update gathers one known element of its tables at a time, which Dr.Jit makes copies on the
    device (no wait). The two sensors' poses (:func:`~datagen.render.mitsuba.place_sensor`),
    the scene's update, the render and the camera model read nothing back value by value (on
    a GPU each such read waits for it): through ``mi.traverse`` each sensor read 32 a frame."""
    import drjit as dr

    renderer, config = renderer_for("wingcam55.yaml", spp=1)
    assert renderer.target_spp and renderer.sensor is not None  # both sensors and the camera model
    seed = config.dataset.seed
    renderer.render(frame_state(config, 0), frame_look(config, frame_state(config, 0)), render_seed(seed, 0))
    copies = {"sky": 0, "rest": 0}

    def count(where: str) -> None:
        copies[where] += sum(k["type"] == dr.KernelType.Memcpy and k.get("size", 0) <= 8 for k in dr.kernel_history())

    sky_set = renderer.sky.set

    def counted(*args) -> None:
        count("rest")
        sky_set(*args)
        count("sky")

    monkeypatch.setattr(renderer.sky, "set", counted)
    with dr.scoped_set_flag(dr.JitFlag.KernelHistory, True):
        dr.kernel_history()
        for i in (1, 2):
            state = frame_state(config, i)
            renderer.render(state, frame_look(config, state), render_seed(seed, i))
        count("rest")
    assert copies["sky"] > 0  # what is counted is counted
    assert copies["rest"] == 0, copies


def test_depth_is_camera_z_on_the_tanker_and_the_sea_and_infinite_on_the_sky() -> None:
    renderer, config = renderer_for("wingcam55.yaml")
    state = frame_state(config, 2)
    renderer.pose(state, frame_look(config, state))
    depth, ids, surface = renderer.geometry_pass()
    tanker = ids == object_id("tanker")
    cam_from_tanker = invert_rigid(state.world_from_cam) @ state.world_from_tanker
    mesh = load_mesh(object_paths(config, "tanker")[0], "tanker").combined
    z = apply_transform(cam_from_tanker, mesh.vertices)[:, 2]
    assert tanker.sum() > 100 and z.min() - 0.5 <= depth[tanker].min() and depth[tanker].max() <= z.max() + 0.5
    # The sea (the earth's sphere, its top at world z = 0 under the camera): a pixel
    # centre's ray from the camera at height h meets it where |o + t d| = R, o = (0, 0, R + h);
    # its camera z-depth is that distance times the ray's own z (within 0.1%), and the
    # point at the measured depth lies on the sphere (within the mesh's sag there, at most
    # EARTH_CAP_SAG of its distance from the nadir, which moves a hit along a ray grazing
    # the sea at the horizon by kilometres).
    k = renderer.intrinsics
    uu, vv = np.meshgrid(np.arange(k.width) + 0.5, np.arange(k.height) + 0.5)
    d_cam = np.stack([(uu - k.cx) / k.fx, (vv - k.cy) / k.fy, np.ones_like(uu)], axis=-1)
    d_cam /= np.linalg.norm(d_cam, axis=-1, keepdims=True)
    d_world = d_cam @ state.world_from_cam[:3, :3].T
    height = state.world_from_cam[2, 3]
    sea = surface == SURFACES.index("sea")
    assert sea.sum() > 1000, "this frame looks down on the sea"
    b = (EARTH_RADIUS_M + height) * d_world[..., 2]
    c = (EARTH_RADIUS_M + height) ** 2 - EARTH_RADIUS_M**2
    t = -b - np.sqrt(np.maximum(b * b - c, 0.0))
    steep = sea & (d_world[..., 2] < -0.1)  # 6 degrees or more below the horizontal
    np.testing.assert_allclose(depth[steep], (t * d_cam[..., 2])[steep], rtol=1e-3)
    hit = np.array([0.0, 0.0, EARTH_RADIUS_M + height]) + (depth / d_cam[..., 2])[..., None] * d_world
    sag = EARTH_CAP_SAG * np.hypot(hit[sea][:, 0], hit[sea][:, 1])
    assert (np.abs(np.linalg.norm(hit[sea], axis=-1) - EARTH_RADIUS_M) < sag + 1.0).all()
    # Rays that pass above the horizon (the earth's dip below the horizontal) and miss the
    # aircraft and the clouds hit nothing: infinite depth; cloud pixels have their layer's depth.
    sky = surface == SURFACES.index("sky")
    assert sky.sum() > 1000 and np.isinf(depth[sky]).all()
    assert (d_world[..., 2][sky] > -np.sin(dip_rad(height)) - 1e-3).all()
    cloud = surface == SURFACES.index("cloud")
    assert np.isfinite(depth[cloud]).all() and (depth[cloud] > 0).all()


def test_feature_visibility_sees_into_the_basket_only_from_behind() -> None:
    renderer, config = renderer_for("podcam15.yaml")
    state = frame_state(config, 0)
    state = dataclasses.replace(state, hose_points_world=state.hose_points_world + [0.0, 0.0, 5000.0])
    features = feature_table(config)
    centre = features.name.index("drogue.basket_centre")
    coupling = features.name.index("drogue.coupling_left")
    world_from_drogue = state.world_from_drogue
    results = {}
    for side, direction in (("behind", -1.0), ("ahead", 1.0)):
        eye = apply_transform(world_from_drogue, np.array([[direction * 3.0, 0.0, 0.3]]))[0]
        target = world_from_drogue[:3, 3]
        moved = dataclasses.replace(state, world_from_cam=body_from_cam_looking(eye, target - eye))
        renderer.pose(moved, draw_look(config, frame_rng(0, 0)))
        fraction, centre_seen = renderer.feature_visibility(moved, features)
        # Each fraction is the share of that feature's own points a ray reaches (padding aside).
        for f in (centre, coupling):
            points = apply_transform(world_from_drogue, features.point_set(f)) - eye
            origin = renderer.camera_render
            seen = visible(renderer.scene, origin, points + origin,
                           visibility_tolerance_m(np.linalg.norm(points, axis=1)))
            assert fraction[f] == seen.mean() and fraction[f] * features.n_points[f] % 1 == 0
        results[side] = (centre_seen[centre], fraction[coupling], centre_seen[coupling])
    # The basket centre is seen through the opening from behind, hidden by the
    # canopy from ahead; the coupling's outside is hidden behind the reception ring
    # from behind and in plain view from ahead.
    assert results["behind"][0] and not results["ahead"][0]
    assert results["ahead"][2] and not results["behind"][2]
    assert results["ahead"][1] > results["behind"][1]


def test_looks_are_drawn_from_the_frame_rng_within_the_config() -> None:
    config = load_config(ROOT / "scenes" / "wingcam55.yaml")
    a, b = (draw_look(config, frame_rng(55, 3)) for _ in range(2))
    c = draw_look(config, frame_rng(55, 4))
    assert a == b and a != c
    sky = config.randomization.sky
    assert sky.sun_elevation_deg[0] <= a.sun_elevation_deg <= sky.sun_elevation_deg[1]
    assert sky.turbidity[0] <= a.turbidity <= sky.turbidity[1]
    lo, hi = config.randomization.materials.paint_roughness
    assert all(lo <= m["paint"].roughness <= hi for m in a.materials.values())


#: A warm-up frame, then 24 frames over 23 approach chains (each a new weather, sea and
#: livery), their skies, lenses and sensor draws.
KERNEL_FRAMES: Final = (0, 1, 5, *(16 * k + (7 * k) % 16 for k in range(1, 23)))


def kernel_census(seed: int = 31, frames: tuple[int, ...] = KERNEL_FRAMES, name: str = "wingcam55",
                  frozen: bool | None = None) -> dict:
    """In this process (one thread, ``llvm_ad_rgb``), a tiny shipped config ``name`` with every world
    randomizer on, each frame made as a build makes it: per frame, the JIT kernels launched
    that no earlier frame launched (``new``); and the render kernel (the largest: hash,
    operation count) of one frame alone, and again with a second renderer of another
    config built and rendered beside it (``alone``, ``beside``). ``frozen``: the render
    recorded once and replayed or traced each frame (``render.frozen``; None: the default);
    ``recordings``: how many times it recorded."""
    import tempfile

    import drjit as dr

    from datagen.pipeline.writer import timed_frame

    use_variant("llvm_ad_rgb")
    set_threads(1)
    tiny = {"render.spp": 1, "camera.width": 32, "camera.height": 17, "labels.edge_margin_px": 1.0,
            "dataset.seed": seed, **({} if frozen is None else {"render.frozen": frozen})}
    config = override_config(load_config(ROOT / "scenes" / f"{name}.yaml"), tiny)
    assert all(getattr(config.randomization, name).enabled for name in ("clouds", "livery", "sensor"))
    scene, states = Scene.resolve(config), FrameStates(config)
    renderer = Renderer(scene)
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    out: dict = {"new": []}
    seen: set[str] = set()
    with tempfile.TemporaryDirectory() as tmp:
        def kernels(r, s, st, i) -> list[tuple[str, int]]:
            dr.kernel_history()
            timed_frame(s, r, st, i, Path(tmp) / "frame.png")
            return [(k["hash"], k["operation_count"]) for k in dr.kernel_history() if k["type"] == dr.KernelType.JIT]

        for i in frames:
            launched = kernels(renderer, scene, states, i)
            out["new"].append(len({h for h, _ in launched} - seen))
            seen |= {h for h, _ in launched}
        out["recordings"] = renderer.recordings
        out["cast_recordings"] = renderer.cast_recordings
        out["alone"] = max(kernels(renderer, scene, states, frames[1]), key=lambda k: k[1])
        other = override_config(load_config(ROOT / "scenes" / "podcam15.yaml"), {**tiny, "render.spp": 2})
        other_scene = Scene.resolve(other)
        second = Renderer(other_scene)
        kernels(second, other_scene, FrameStates(other), 0)
        out["beside"] = max(kernels(renderer, scene, states, frames[1]), key=lambda k: k[1])
        out["recordings_beside"] = renderer.recordings  # its scene rebuilt after the other renderer's
        out["cast_recordings_beside"] = renderer.cast_recordings
        assert second.config is other  # alive until here
    return out


def _census(frozen: bool) -> dict:
    """:func:`kernel_census` in a process of its own: Mitsuba objects other tests leave in
    this one would change the kernels."""
    code = ("import json; from tests.test_render import kernel_census; "
            f"print(json.dumps(kernel_census(frozen={frozen})))")
    done = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=600,
                          check=False)
    assert done.returncode == 0, done.stderr[-2000:]
    return json.loads(done.stdout.strip().splitlines()[-1])


@pytest.fixture(scope="module")
def frozen_census() -> dict:
    """:func:`_census` with the render frozen (the default)."""
    return _census(True)


@pytest.fixture(scope="module")
def traced_census() -> dict:
    """:func:`_census` with the render traced every frame."""
    return _census(False)


@pytest.mark.parametrize("mode", ["frozen", "traced"])
def test_frames_after_the_first_compile_no_kernel(mode: str, request) -> None:
    """Every per-frame value reaches the kernels as an opaque value (the sky's scales
    included), and nothing is left pending for a frozen render to evaluate in a kernel of
    its own (datagen.render.frozen.settle): after one frame, frames of other approaches,
    skies, clouds, seas, liveries and sensor draws compile nothing (each compile costs
    seconds, and memory), frozen or traced."""
    new = request.getfixturevalue(f"{mode}_census")["new"]
    assert new[0] > 0 and new[1:] == [0] * (len(new) - 1), f"new kernels per frame: {new}"


def test_a_frozen_render_records_once_over_twenty_three_approaches_and_a_rebuilt_scene(
        frozen_census, traced_census) -> None:
    """The frozen render (the frame's and the target pass's path tracing, in one recording),
    and the geometry pass's frozen ray cast, record at the first frame and replay every later frame of every
    approach (the films and samplers settled when the scene is built: datagen.render.frozen);
    its scene rebuilt after another renderer's, each replays its recording or records once
    more (measured: dashcam75 records the render again, and a rebuilt wingcam55 scene now and
    then). Traced, neither records."""
    assert frozen_census["recordings"] == frozen_census["cast_recordings"] == 1, frozen_census
    assert frozen_census["recordings_beside"] in (1, 2), frozen_census
    assert frozen_census["cast_recordings_beside"] in (1, 2), frozen_census
    assert traced_census["recordings"] == traced_census["recordings_beside"] == 0
    assert traced_census["cast_recordings"] == traced_census["cast_recordings_beside"] == 0


def test_the_render_kernel_is_the_same_with_another_renderer_alive(traced_census) -> None:
    """Dr.Jit compiles a call through a Mitsuba class for every live instance in the
    process: a second renderer's scene grew the render kernel (and on CUDA disabled its
    ray tracing). It is released while another renderer renders, so the kernel is the
    one a lone renderer compiles, operation for operation (traced: a replayed kernel is
    logged with the hash it recorded, whatever the scene beside it)."""
    assert traced_census["alone"] == traced_census["beside"]


def _placed(values: np.ndarray, on_boundary: bool) -> np.ndarray:
    """``values`` copied into numpy memory that starts on a 64-byte boundary, or one
    element past one (unaligned at any SIMD width)."""
    buffer = np.empty(values.size + 64, values.dtype)
    start = (-buffer.ctypes.data % 64) // values.dtype.itemsize + (0 if on_boundary else 1)
    out = buffer[start:start + values.size].reshape(values.shape)
    out[...] = values
    return out


def _jit_kernels(run) -> set[str]:
    """The hashes of the Dr.Jit kernels ``run()`` launches."""
    import drjit as dr

    dr.sync_thread()
    with dr.scoped_set_flag(dr.JitFlag.KernelHistory, True):
        dr.kernel_history()
        run()
        dr.sync_thread()
        return {k["hash"] for k in dr.kernel_history() if k["type"] == dr.KernelType.JIT}


@pytest.mark.parametrize("dtype", [np.float32, np.uint32, np.float64])
@pytest.mark.parametrize("shape", [(1,), (7,), (5, 3), (4, 4, 3)])
def test_aligned_copies_an_array_to_a_64_byte_boundary_unchanged(dtype, shape) -> None:
    from datagen.render.mitsuba import aligned

    values = _placed(np.arange(int(np.prod(shape)), dtype=dtype).reshape(shape), on_boundary=False)
    out = aligned(values, dtype)
    assert values.ctypes.data % 64 != 0 and out.ctypes.data % 64 == 0 and out.flags.c_contiguous
    assert out.dtype == dtype and out.shape == values.shape and np.array_equal(out, values)
    assert not np.shares_memory(out, values)


def test_a_mesh_from_numpy_memory_anywhere_compiles_the_same_ray_casting_kernels() -> None:
    """Dr.Jit maps numpy memory into kernels and compiles them for its alignment: a mesh
    set from numpy memory that happened not to start on a 64-byte boundary compiled other
    kernels than the same mesh elsewhere (by chance, per process: seconds each for a
    render kernel)."""
    import gc

    from datagen.render.mitsuba import aligned, mitsuba_mesh

    vertices = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], np.float32)
    faces = np.array([[0, 1, 2], [0, 2, 3]], np.uint32)
    uv = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], np.float32)
    xy = mi.Float(aligned(np.linspace(-0.9, 0.9, 64)))

    def cast(make):
        mesh = mitsuba_mesh("plate", make(vertices), make(faces), texcoords=make(uv))
        scene = mi.load_dict({"type": "scene", "plate": mesh}, optimize=False)
        si = scene.ray_intersect(mi.Ray3f(mi.Point3f(xy, xy, 1.0), mi.Vector3f(0.0, 0.0, -1.0)))
        out = {}
        return _jit_kernels(lambda: out.update(uv=np.array(si.uv), p=np.array(si.p))), out

    hashes_here, here = cast(lambda a: _placed(a, True))
    gc.collect()  # the first scene gone before the second is built
    hashes_there, there = cast(lambda a: _placed(a, False))
    assert hashes_here and hashes_here == hashes_there
    assert all(np.array_equal(here[k], there[k]) for k in here) and np.isfinite(here["uv"]).all()


def test_exr_has_linear_rgb_depth_and_object_ids(tmp_path: Path) -> None:
    import OpenEXR

    renderer, config = renderer_for("podcam15.yaml", spp=1)
    state = frame_state(config, 0)
    result = renderer.render(state, frame_look(config, state), render_seed(15, 0), geometry=True)
    path = tmp_path / "f.exr"
    write_exr(path, result.rgb, result.depth, result.object_id)
    with OpenEXR.File(str(path), separate_channels=True) as exr:
        channels = exr.channels()
        assert sorted(channels) == ["B", "G", "R", "Z", "object_id"]
        np.testing.assert_array_equal(channels["R"].pixels, result.rgb[..., 0])
        np.testing.assert_array_equal(channels["Z"].pixels, result.depth)
        assert channels["object_id"].pixels.dtype == np.uint32
        np.testing.assert_array_equal(channels["object_id"].pixels, result.object_id)
    assert [p.name for p in tmp_path.iterdir()] == ["f.exr"]


def test_srgb_transfer() -> None:
    out = to_srgb8(np.array([0.0, 0.0031308, 0.18, 0.5, 1.0, 3.0]))
    np.testing.assert_array_equal(out, [0, 10, 118, 188, 255, 255])


def test_missing_llvm_gets_an_install_hint(monkeypatch) -> None:
    from datagen.render import runtime

    monkeypatch.setattr(runtime, "has_backend", lambda name: False)
    with pytest.raises(DatagenError, match=r"apt-get install -y libllvm19"):
        runtime.use_variant("llvm_ad_rgb")


def test_render_command_writes_png_and_exr(tmp_path: Path) -> None:
    import subprocess
    import sys

    import cv2

    out = subprocess.run([sys.executable, "-m", "datagen", "render", "--config", "scenes/podcam15.yaml",
                          "--frames", "0-1", "--scale", "0.1", "--spp", "1", "--exr", "--out", str(tmp_path)],
                         cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    names = sorted(p.name for p in tmp_path.iterdir())
    assert names == ["podcam15-000000.exr", "podcam15-000000.png", "podcam15-000001.exr", "podcam15-000001.png"]
    image = cv2.imread(str(tmp_path / "podcam15-000000.png"), cv2.IMREAD_UNCHANGED)
    assert image.shape == (108, 205, 3) and image.dtype == np.uint8 and image.std() > 1.0
    bad = subprocess.run([sys.executable, "-m", "datagen", "render", "--config", "scenes/podcam15.yaml",
                          "--frames", "x"], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert bad.returncode == 2 and bad.stderr.strip().startswith("--frames: 'x' is not a list")


def test_a_visibility_threshold_excludes_occluded_features() -> None:
    from datagen.core.label_boxes import Exclusion, compute_labels

    renderer, config = renderer_for("podcam15.yaml")
    state = frame_state(config, 0)
    features = feature_table(config)
    renderer.pose(state, frame_look(config, state))
    fraction, _ = renderer.feature_visibility(state, features)
    cam_from_objects = np.stack([invert_rigid(state.world_from_cam) @ state.world_from(o) for o in features.objects])
    labels = compute_labels(features, cam_from_objects, renderer.intrinsics, edge_margin_px=2)
    assert labels.with_visibility(fraction, 0.0).exclusion.tolist() == labels.exclusion.tolist()
    strict = labels.with_visibility(fraction, 0.5)
    dropped = labels.labeled & (fraction < 0.5)
    assert dropped.any() and (labels.labeled & (fraction >= 0.5)).any()
    np.testing.assert_array_equal(strict.exclusion == Exclusion.OCCLUDED, dropped)
    np.testing.assert_array_equal(strict.labeled, labels.labeled & (fraction >= 0.5))


def test_scalar_fallback_agrees_with_the_vectorized_variant() -> None:
    config = load_config(ROOT / "scenes" / "podcam15.yaml")
    state = frame_state(config, 45)
    look = frame_look(config, state)
    features = feature_table(config)
    out = {}
    for name in ("scalar_rgb", "auto"):
        renderer = Renderer(Scene.resolve(config), variant=name, width=96, height=51, spp=1)
        renderer.pose(state, look)
        depth, ids, surface = renderer.geometry_pass()
        out[name] = (depth, ids, surface, *renderer.feature_visibility(state, features))
    use_variant("auto")
    (d_s, id_s, s_s, f_s, c_s), (d_v, id_v, s_v, f_v, c_v) = out["scalar_rgb"], out["auto"]
    assert len(set(id_v.ravel().tolist())) >= 3  # sea, drogue, hose and receiver in view
    assert (id_s == id_v).mean() > 0.998 and (s_s == s_v).mean() > 0.998
    both = np.isfinite(d_s) & np.isfinite(d_v)
    np.testing.assert_allclose(d_s[both], d_v[both], rtol=1e-4)
    np.testing.assert_array_equal(c_s, c_v)
    np.testing.assert_allclose(f_s, f_v)


def test_a_casts_hit_is_keyed_by_the_instance_met_or_else_the_top_level_shape() -> None:
    """The geometry pass's tables are keyed by :func:`~datagen.render.raycast.hit_key`: an
    instanced mesh's hit names its instance (each of two instances of one group its own),
    a top-level shape's names the shape, a miss 0 (Embree's preliminary intersection
    leaves the shape null on an instance's hit; keyed by the shape, all three instanced
    hits would be 0)."""
    import drjit as dr

    from datagen.render.raycast import hit_key

    if mi.variant().startswith("scalar"):
        pytest.skip("a vectorized variant's cast")
    rect = {"type": "rectangle", "to_world": mi.ScalarTransform4f().translate([0.0, 0.0, 5.0])}
    scene = mi.load_dict({"type": "scene", "top": dict(rect), "group": {"type": "shapegroup", "part": dict(rect)},
                          **{name: {"type": "instance", "shapegroup": {"type": "ref", "id": "group"},
                                    "to_world": mi.ScalarTransform4f().translate([x, 0.0, 0.0])}
                             for name, x in (("left", -3.0), ("right", 3.0))}}, optimize=False)
    registry = {s.id(): int(dr.reinterpret_array(mi.UInt32, mi.ShapePtr(s))[0]) for s in scene.shapes()}
    xs = [0.0, -3.0, 3.0, 8.0]  # the top-level shape, each instance, nothing
    si = scene.ray_intersect_preliminary(mi.Ray3f(mi.Point3f(mi.Float(xs), 0.0, 0.0), mi.Vector3f(0.0, 0.0, 1.0)))
    keys = np.asarray(hit_key(mi, dr, si)).tolist()
    assert keys == [registry["top"], registry["left"], registry["right"], 0]
    assert len({*keys[:3]}) == 3 and 0 not in keys[:3]


def test_denoise_off_leaves_the_path_tracers_image_unchanged(one_thread) -> None:
    """With render.denoise off a frame is Mitsuba's own render times the exposure, bit for
    bit (what every build wrote before denoising existed); the aircraft's lights, which are
    added after the render (tests/test_liveries.py), and the target pass's samples
    (tests/test_target.py) off."""
    from datagen.render.tonemap import exposure_scale

    config = override_config(load_config("wingcam55"), {"camera.width": 160, "camera.height": 84,
                                                        "render.spp": 2, "render.denoise": "off",
                                                        "randomization.sensor.enabled": False,
                                                        "randomization.livery.lights": False,
                                                        "render.target_spp": 0})
    renderer = Renderer(Scene.resolve(config))
    state = frame_state(config, 3)
    look = frame_look(config, state)
    result = renderer.render(state, look, render_seed(55, 3))
    raw = np.asarray(mi.render(renderer.scene, seed=render_seed(55, 3), spp=2), dtype=np.float32)
    assert raw.shape[-1] == 3 and result.denoise_s is None
    np.testing.assert_array_equal(result.rgb, raw * exposure_scale(look.exposure_ev))


def test_denoiser_guides_leave_the_beauty_channels_unchanged(one_thread) -> None:
    """The aov integrator that makes the albedo and normal guides renders the same beauty
    channels as the plain path tracer (same samples), so the guides cost no noise."""
    base = override_config(load_config("dashcam75"), {"camera.width": 160, "camera.height": 84, "render.spp": 2})
    state = frame_state(base, 5)
    look = frame_look(base, state)
    images = []
    for updates in ({"render.denoise": "off"}, {"render.denoise": "oidn", "render.denoise_guides": True}):
        renderer = Renderer(Scene.resolve(override_config(base, updates)))
        renderer.pose(state, look)
        images.append(np.asarray(mi.render(renderer.scene, seed=11, spp=2), dtype=np.float32))
    assert images[0].shape[-1] == 3 and images[1].shape[-1] == 9
    np.testing.assert_array_equal(images[1][..., :3], images[0])
    assert np.abs(images[1][..., 6:9]).max() <= 1.0 + 1e-6  # unit normals


def denoised_frame_digest() -> str:
    """In this process (one thread, ``llvm_ad_rgb``): a small denoised podcam15 frame's
    SHA-256 of its RGB bytes, and whether the denoiser ran."""
    import hashlib

    use_variant("llvm_ad_rgb")
    set_threads(1)
    config = override_config(load_config("podcam15"), {"camera.width": 160, "camera.height": 84,
                                                       "render.denoise": "oidn"})
    state = frame_state(config, 2)
    result = Renderer(Scene.resolve(config)).render(state, frame_look(config, state), 99)
    return f"{hashlib.sha256(np.ascontiguousarray(result.rgb).tobytes()).hexdigest()} {result.denoise_s > 0}"


def test_a_denoised_frame_is_the_same_bytes_in_two_processes_with_one_thread() -> None:
    code = "from tests.test_render import denoised_frame_digest; print(denoised_frame_digest())"
    digests = []
    for _ in range(2):
        done = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=600,
                              check=False)
        assert done.returncode == 0, done.stderr[-2000:]
        digests.append(done.stdout.strip().splitlines()[-1])
    assert digests[0].endswith(" True") and digests[0] == digests[1]


def test_a_missing_mitsuba_oidn_gets_one_line_saying_how_to_install_it(monkeypatch) -> None:
    import sys

    from datagen.render import denoise as denoise_module

    monkeypatch.setitem(sys.modules, "mitsuba_oidn", None)  # import mitsuba_oidn now fails
    denoise_module._oidn.cache_clear()
    try:
        config = override_config(load_config("podcam15"), {"render.denoise": "oidn"})
        with pytest.raises(DatagenError, match=r"pip install mitsuba-oidn") as info:
            Renderer(Scene.resolve(config), width=32, height=17)
        assert "\n" not in str(info.value) and "render.denoise" in str(info.value)
        Renderer(Scene.resolve(override_config(config, {"render.denoise": "off"})), width=32, height=17)
    finally:
        denoise_module._oidn.cache_clear()


def test_the_sun_glint_on_a_cox_munk_sea_is_still_there() -> None:
    """The rougher sea (the firefly fix) still mirrors the sun: around the point where a flat
    sea would reflect the sun into the camera, the sea reaches white and stands far above
    the rest of the sea, as the glitter path does in photographs."""
    from datagen.analysis.image_quality import luminance
    from datagen.scene.look import sun_direction_world

    # Clouds could shade the sun, the sensor would rescale the image, the air veil the
    # glint's far end (a low sun's mirror lies tens of kilometres out) and the approach's
    # ground be land: off; the waves stay.
    config = override_config(load_config("dashcam75"), {"camera.width": 256, "camera.height": 135,
                                                        "render.spp": 16, "render.denoise": "off",
                                                        **world_off("clouds", "sensor", "backlit sun", "haze",
                                                                    "ground")})
    assert config.randomization.sea.model == "cox_munk" and config.randomization.sea.waves
    frame, seed = 209, config.dataset.seed  # a low sun ahead: its mirror image lies in the view
    state = frame_state(config, frame)
    look = frame_look(config, state)
    sun = sun_direction_world(state, look)
    renderer = Renderer(Scene.resolve(config))
    u, v = project_points((state.cam_from_world[:3, :3] @ (sun * [1, 1, -1]))[None], renderer.intrinsics)[0]
    assert 0 < u < 256 and 0 < v < 135
    result = renderer.render(state, look, render_seed(seed, frame), geometry=True)
    lum = luminance(result.rgb)
    sea = (result.object_id == 0) & np.isfinite(result.depth)
    jj, ii = np.mgrid[0:135, 0:256]
    near = sea & (np.hypot(ii + 0.5 - u, jj + 0.5 - v) < 6)
    assert near.sum() > 20
    assert lum[near].max() >= 1.0 and lum[near].mean() > 5 * np.median(lum[sea])


def test_the_cox_munk_sea_removes_most_fireflies_from_the_tanker() -> None:
    """A low sun over a glassy sea puts caustic speckles all over the tanker (sunlight the
    sea mirrors onto it, which a path tracer finds by chance); over the Cox-Munk sea at
    the same spp, at least 5 times fewer pixels stand out of their neighbourhood."""
    from datagen.analysis.image_quality import fireflies

    # The sea's reflectance model alone: the world's randomizers (waves would roughen the glassy sea) off.
    base = override_config(load_config("wingcam55"), {"camera.width": 512, "camera.height": 270,
                                                      "render.spp": 64, "render.denoise": "off", **world_off(),
                                                      # the sun range the frame below was picked with
                                                      "randomization.sky.sun_elevation_deg": [15.0, 70.0]})
    frame, seed = 14, base.dataset.seed  # the tanker 12 m ahead, the sun 17 degrees high
    counts = {}
    for model in ("uniform", "cox_munk"):
        config = override_config(base, {"randomization.sea.model": model})
        state = frame_state(config, frame)
        look = frame_look(config, state)
        result = Renderer(Scene.resolve(config)).render(state, look, render_seed(seed, frame), geometry=True)
        counts[model] = int((fireflies(result.rgb) & (result.object_id == object_id("tanker"))).sum())
    assert counts["uniform"] > 20 and counts["cox_munk"] * 5 < counts["uniform"], counts


def test_another_aircraft_is_drawn_where_its_meshes_project_and_waits_hidden_without_one() -> None:
    from datagen.scene.traffic import world_from_traffic

    renderer, config = renderer_for("podcam25.yaml")
    k, states = renderer.intrinsics, FrameStates(config)
    for a in range(60):  # the first approach whose other aircraft is in view
        state = states(a * config.frames_per_chain + 3)
        look = frame_look(config, state)
        pose = world_from_traffic(state, look.other_aircraft_tanker_m, look.other_aircraft_heading_deg)
        if pose is None:
            continue
        mesh = load_mesh(object_paths(config, look.other_aircraft)[0], look.other_aircraft).combined
        points = apply_transform(invert_rigid(state.world_from_cam) @ pose, mesh.vertices)
        uv = project_points(points, k)
        box = np.array([*uv.min(axis=0), *uv.max(axis=0)])
        if (points[:, 2] > 0).all() and box[0] > 0 and box[1] > 0 and box[2] < k.width and box[3] < k.height:
            break
    else:
        pytest.fail("no approach of podcam25 shows another aircraft whole")
    renderer.pose(state, look)
    _, with_it, _ = renderer.geometry_pass()
    alone = dataclasses.replace(look, other_aircraft="none", other_aircraft_tanker_m=None,
                                other_aircraft_heading_deg=None)
    renderer.pose(state, alone)
    _, without, _ = renderer.geometry_pass()
    rows, cols = np.nonzero(with_it != without)
    assert len(rows) >= 10 and np.all(with_it[rows, cols] == OTHER_AIRCRAFT_ID)  # not the target's id
    assert cols.min() >= box[0] - 1 and cols.max() + 1 <= box[2] + 1
    assert rows.min() >= box[1] - 1 and rows.max() + 1 <= box[3] + 1


def test_a_cockpit_cameras_windscreen_frame_crosses_its_upper_corners_only_and_is_no_object() -> None:
    renderer, config = renderer_for("dashcam75.yaml")
    still = override_config(config, {"camera.mount_jitter.rotation_deg": 0.0, "camera.mount_jitter.translation_m": 0.0,
                                     **world_off("vibration")})
    state = FrameStates(still)(0)
    renderer.pose(state, frame_look(config, state))
    depth, ids, _ = renderer.geometry_pass()
    frame = depth < 1.0  # the frame is half a metre ahead; nothing else comes that close
    h, w = frame.shape
    assert frame[: h // 3, : w // 4].mean() > 0.05 and frame[: h // 3, -(w // 4):].mean() > 0.05
    assert not frame[h // 2:, w // 4: -(w // 4)].any()
    assert np.all(ids[frame] == 0)
    assert "windscreen_frame.to_world" in renderer.params
    wing, wing_config = renderer_for("wingcam55.yaml")  # a pod's camera: no frame
    wing_state = FrameStates(wing_config)(0)
    wing.pose(wing_state, frame_look(wing_config, wing_state))
    assert "windscreen_frame.to_world" not in wing.params
