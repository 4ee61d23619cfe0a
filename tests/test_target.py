"""The target pass (:mod:`datagen.render.target`): where its window goes, that its sensor sees
the frame's own pixels there, and how its samples are merged into the frame's."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from datagen.core.camera import Intrinsics
from datagen.core.conventions import OTHER_AIRCRAFT_ID, object_id, pixel_centres, target_render_seed
from datagen.render.target import (
    FEATHER,
    PLACEMENT_STRIDE_PX,
    TargetWindow,
    target_size,
    target_window,
)


def _grid_ids(width: int, height: int, boxes: list[tuple[float, float, float, float, int]]) -> np.ndarray:
    """Object ids at the placement grid's block centres: each box ``(u0, v0, u1, v1, id)`` (pixels)
    over those before it."""
    uu, vv = pixel_centres(width, height, PLACEMENT_STRIDE_PX)
    ids = np.zeros(uu.shape, np.uint32)
    for u0, v0, u1, v1, i in boxes:
        ids[(uu >= u0) & (uu < u1) & (vv >= v0) & (vv < v1)] = i
    return ids


@settings(max_examples=200, deadline=None)
@given(st.integers(40, 300), st.integers(30, 200), st.floats(0.2, 1.0), st.data())
def test_the_window_holds_every_object_sample_that_fits_in_it_and_is_centred_on_them_where_it_can_be(
        width, height, share, data) -> None:
    tw, th = target_size(Intrinsics.from_hfov_deg(width, height, 55.0), share)
    # An object's box that fits with a placement step to spare, another aircraft and the
    # background around it, and smaller boxes of other objects inside it.
    w = data.draw(st.floats(0.5, max(0.5, tw - PLACEMENT_STRIDE_PX)))
    h = data.draw(st.floats(0.5, max(0.5, th - PLACEMENT_STRIDE_PX)))
    u, v = data.draw(st.floats(0.0, width - w)), data.draw(st.floats(0.0, height - h))
    boxes = [(0.0, 0.0, width, height, OTHER_AIRCRAFT_ID) if data.draw(st.booleans()) else (0, 0, 0, 0, 0),
             (u, v, u + w, v + h, object_id("tanker"))]
    for name in data.draw(st.lists(st.sampled_from(["receiver", "drogue", "hose"]), max_size=3)):
        a, b = sorted(data.draw(st.lists(st.floats(u, u + w), min_size=2, max_size=2)))
        c, d = sorted(data.draw(st.lists(st.floats(v, v + h), min_size=2, max_size=2)))
        boxes.append((a, c, b, d, object_id(name)))
    ids = _grid_ids(width, height, boxes)
    window = target_window(ids, (tw, th), (width, height))
    assert (window.width, window.height) == (tw, th)
    assert 0 <= window.u0 <= width - tw and 0 <= window.v0 <= height - th
    uu, vv = pixel_centres(width, height, PLACEMENT_STRIDE_PX)
    seen = (ids >= 1) & (ids < OTHER_AIRCRAFT_ID)
    if not seen.any():  # the box fell between the grid's samples: the image's centre
        assert (window.u0, window.v0) == ((width - tw) // 2, (height - th) // 2)
        return
    cols, rows = uu[seen], vv[seen]
    assert window.u0 <= cols.min() and cols.max() < window.u0 + tw
    assert window.v0 <= rows.min() and rows.max() < window.v0 + th
    # Centred on the objects' samples unless the image's border stops it (within the grid).
    for lo, size, first, last, image in ((window.u0, tw, cols.min(), cols.max(), width),
                                         (window.v0, th, rows.min(), rows.max(), height)):
        want = (first + last) / 2 - size / 2
        if 0 < want < image - size:
            assert abs(lo - want) <= PLACEMENT_STRIDE_PX, (lo, want)


def test_the_window_is_centred_where_only_the_background_another_aircraft_or_nothing_is_in_view() -> None:
    centred = TargetWindow(25, 15, 50, 30, 100, 60)
    assert target_window(_grid_ids(100, 60, []), (50, 30), (100, 60)) == centred
    assert target_window(_grid_ids(100, 60, [(0, 0, 100, 60, OTHER_AIRCRAFT_ID)]), (50, 30), (100, 60)) == centred
    ids = _grid_ids(100, 60, [(0, 0, 100, 60, OTHER_AIRCRAFT_ID), (80, 40, 84, 44, object_id("drogue"))])
    window = target_window(ids, (50, 30), (100, 60))
    assert window.u0 <= 80 and window.u0 + 50 >= 84 and window.v0 <= 40 and window.v0 + 30 >= 44


def test_a_window_over_objects_larger_than_it_holds_as_many_of_their_samples_as_any_grid_position() -> None:
    rng = np.random.default_rng(3)
    uu, vv = pixel_centres(200, 120, PLACEMENT_STRIDE_PX)
    ids = _grid_ids(200, 120, [(20, 30, 150, 100, object_id("tanker")), (140, 5, 190, 60, object_id("receiver"))])
    ids[rng.random(ids.shape) < 0.1] = object_id("hose")
    objects = ids > 0
    window = target_window(ids, (64, 40), (200, 120))

    def held(u: int, v: int) -> int:
        return int((objects & (uu >= u) & (uu < u + 64) & (vv >= v) & (vv < v + 40)).sum())

    grid = [(u, v) for v in [*range(0, 81, 4), 80] for u in [*range(0, 137, 4), 136]]
    assert held(window.u0, window.v0) == max(held(u, v) for u, v in grid)


@pytest.mark.render
@settings(max_examples=40, deadline=None)
@given(st.integers(16, 120), st.integers(10, 80), st.floats(0.15, 1.0), st.data())
def test_the_windows_sensor_casts_the_frames_own_rays_through_its_pixels(width, height, share, data) -> None:
    """The second sensor (its principal point moved) and the frame's sensor give the same ray
    through the same continuous pixel of the frame."""
    pytest.importorskip("mitsuba")
    import mitsuba as mi

    from datagen.render.mitsuba import sensor_dict
    from datagen.render.runtime import use_variant

    use_variant("llvm_ad_rgb")
    k = Intrinsics.from_hfov_deg(width, height, data.draw(st.floats(20.0, 120.0)))
    tw, th = target_size(k, share)
    window = TargetWindow(data.draw(st.integers(0, width - tw)), data.draw(st.integers(0, height - th)), tw, th,
                          width, height)
    pose = np.eye(4)
    frame = mi.load_dict(sensor_dict(k, pose, 1))
    crop = mi.load_dict(sensor_dict(k, pose, 1, size=(tw, th)))
    params = mi.traverse(crop)
    params["principal_point_offset_x"], params["principal_point_offset_y"] = window.principal_point_offset
    params.update()
    x = np.array(data.draw(st.lists(st.floats(0.0, 1.0), min_size=3, max_size=3))) * tw
    y = np.array(data.draw(st.lists(st.floats(0.0, 1.0), min_size=3, max_size=3))) * th
    ray_crop, _ = crop.sample_ray(0.0, 0.5, mi.Point2f(x / tw, y / th), mi.Point2f(0.5))
    ray_frame, _ = frame.sample_ray(0.0, 0.5, mi.Point2f((x + window.u0) / width, (y + window.v0) / height),
                                    mi.Point2f(0.5))
    np.testing.assert_allclose(np.array(ray_crop.d), np.array(ray_frame.d), atol=2e-6)


@pytest.mark.render
def test_the_merge_is_the_sample_weighted_mean_inside_feathered_at_inner_edges_and_leaves_the_rest() -> None:
    pytest.importorskip("mitsuba")
    import drjit as dr
    import mitsuba as mi

    from datagen.render.runtime import use_variant
    from datagen.render.target import merge_target, window_offsets

    use_variant("llvm_ad_rgb")
    rng = np.random.default_rng(5)
    frame = rng.random((30, 40, 3)).astype(np.float32)
    extra = rng.random((16, 24, 3)).astype(np.float32)
    window = TargetWindow(16, 0, 24, 16, 40, 30)  # on the top and right borders
    image = mi.TensorXf(frame)
    merge_target(mi, dr, image, mi.TensorXf(extra), window_offsets(mi, dr, window), spp=4, target_spp=12)
    out = np.array(image)
    outside = np.ones((30, 40), bool)
    outside[0:16, 16:40] = False
    np.testing.assert_array_equal(out[outside], frame[outside])
    inner = frame[0:16, 16:40]
    # Far from the inner edges (left, bottom): the 4 + 12 samples' mean.
    deep = slice(0, 16 - int(np.ceil(FEATHER * 16))), slice(int(np.ceil(FEATHER * 24)), 24)
    np.testing.assert_allclose(out[0:16, 16:40][deep], ((4 * inner + 12 * extra) / 16)[deep], rtol=1e-5)
    # At the inner edges the window's weight falls towards 0; on the image's borders it does not.
    weight = (out[0:16, 16:40] - inner) / (extra - inner)  # its share: 12 w / (4 + 12 w)
    share = np.median(weight, axis=-1)
    assert share[8, 0] < share[8, 1] < share[8, 4] <= 0.75 + 1e-4
    assert share[15, 12] < share[12, 12]
    assert share[0, 23] == pytest.approx(0.75, abs=1e-4)


def test_the_target_pass_seed_is_another_stream_than_the_frames() -> None:
    seeds = [target_render_seed(s) for s in range(1000)]
    assert len(set(seeds)) == 1000 and all(t != s for s, t in enumerate(seeds))
    assert target_render_seed(7) == target_render_seed(7)


@pytest.mark.render
def test_a_renderers_target_pass_renders_the_frames_own_pixels_in_its_window() -> None:
    """podcam15 at 96x51 without the denoiser: the target pass's image of the window, at as
    many samples as the frame, matches the frame there pixel for pixel (up to their noise),
    and a window one pixel off does not."""
    pytest.importorskip("mitsuba")
    import mitsuba as mi

    from datagen.config import load_config, override_config
    from datagen.pipeline.frame import draw_frame
    from datagen.render.renderer import Renderer
    from datagen.render.target import TARGET_SENSOR
    from datagen.scene.approach import FrameStates
    from datagen.scene.resolved import Scene

    config = override_config(load_config("podcam15"), {
        "camera.width": 96, "camera.height": 51, "render.spp": 64, "render.target_spp": 64,
        "render.denoise": "off", "randomization.sensor.enabled": False})
    scene = Scene.resolve(config)
    draws = draw_frame(scene, FrameStates(config), 3)
    renderer = Renderer(scene)
    renderer.render(draws.state, draws.look, draws.render_seed)  # posed
    frame = np.array(renderer.path_trace(11), dtype=np.float64)[..., :3]  # no window: the frame's alone
    window = TargetWindow(20, 10, *renderer._target_size, 96, 51)
    renderer.aim_target(window)
    crop = np.array(mi.render(renderer.scene, sensor=TARGET_SENSOR, seed=12, spp=64), dtype=np.float64)[..., :3]

    def error(du: int) -> float:
        seen = frame[window.v0:window.v0 + window.height, window.u0 + du:window.u0 + du + window.width]
        return float(np.mean(np.abs(seen - crop)) / np.mean(crop))

    assert crop.shape[:2] == (window.height, window.width) and crop.mean() > 0
    assert error(0) < 0.5 * min(error(-1), error(1)), (error(-1), error(0), error(1))


@pytest.mark.render
@pytest.mark.parametrize("variant", ["llvm_ad_rgb", "scalar_rgb"])
def test_the_grids_object_ids_are_the_geometry_pass_at_the_grids_stride_whatever_the_pass_stride(variant) -> None:
    """The target pass's window is placed from ids the geometry pass's cast finds on a grid of
    block centres: the same ids as the pass at that stride, for a pass at stride 1 or 2."""
    pytest.importorskip("mitsuba")
    from datagen.config import load_config, override_config
    from datagen.render.renderer import Renderer
    from datagen.scene.approach import frame_state
    from datagen.scene.look import frame_look
    from datagen.scene.resolved import Scene

    config = override_config(load_config("podcam15"), {"camera.width": 40, "camera.height": 21,
                                                      "labels.edge_margin_px": 1.0, "render.variant": variant})
    renderer = Renderer(Scene.resolve(config))
    state = frame_state(config, 3)
    renderer.pose(state, frame_look(config, state))
    _, coarse, _ = renderer.geometry_pass(PLACEMENT_STRIDE_PX)
    want = coarse[::PLACEMENT_STRIDE_PX, ::PLACEMENT_STRIDE_PX]
    assert (want > 0).any()
    for stride in (1, 2):
        _, _, grid = renderer.geometry_and_cast(stride, np.zeros((1, 3), np.float32), grid=PLACEMENT_STRIDE_PX)
        np.testing.assert_array_equal(grid, want)
