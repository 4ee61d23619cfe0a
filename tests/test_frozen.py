"""The frozen render (:mod:`datagen.render.frozen`): replayed frames are the traced frames."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("mitsuba")
pytestmark = pytest.mark.render

#: Frames of three approach chains at wingcam55's defaults (7 frames a chain): each later
#: chain's sky, clouds, sea, ground, liveries and sensor draws are all new (its cloud layers
#: reshaped and facing the camera anew), and its frames replay a recording made with the
#: first chain's values.
FRAMES = (0, 1, 2, 7, 8, 9, 10, 14)


def _frames(frozen: bool) -> tuple[list[tuple[np.ndarray, ...]], tuple[int, int, int, int], int]:
    from datagen.config import load_config, override_config
    from datagen.pipeline.frame import draw_frame
    from datagen.render.renderer import Renderer
    from datagen.render.runtime import set_threads, use_variant
    from datagen.scene.approach import FrameStates
    from datagen.scene.resolved import Scene

    use_variant("llvm_ad_rgb")
    set_threads(1)
    config = override_config(load_config("wingcam55"), {
        "camera.width": 48, "camera.height": 26, "render.spp": 1, "render.denoise": "off",
        "render.frozen": frozen})  # on is the default
    scene = Scene.resolve(config)
    states, renderer = FrameStates(config), Renderer(scene)
    images, before = [], (0, 0)
    for k, i in enumerate(FRAMES):
        if k == len(FRAMES) - 1:
            before = renderer.recordings, renderer.cast_recordings
            renderer.release()  # the last frame's scene built anew (as after another renderer's)
        draws = draw_frame(scene, states, i)
        out = renderer.render(draws.state, draws.look, draws.render_seed)
        images.append((out.rgb, out.depth, out.object_id, out.surface))  # the image, and the geometry pass's
    recordings = (before[0], renderer.recordings, before[1], renderer.cast_recordings)
    refused = renderer.refused_recordings
    renderer.release()
    return images, recordings, refused


def test_frozen_frames_are_the_traced_frames_bit_for_bit_over_three_approaches_and_a_rebuilt_scene() -> None:
    """Every randomizer on; the last frame's scene is built anew and its frame is the traced
    one too."""
    replayed, (recordings, after_rebuild, casts, casts_after), refused = _in_own_process(_frames, True)
    traced, none, _ = _in_own_process(_frames, False)
    assert none == (0, 0, 0, 0)
    # The first frame records the render (the frame's path tracing and the target pass's, in
    # one recording) and the geometry pass's cast; no later frame or approach records again or is refused. The
    # scene built anew replays the recordings or records once more (measured: one run in
    # three to six records the render and the cast again there; what decides it is not found:
    # not the hash seed, nor the new shapes' registry ids, nor a collection before the build).
    assert recordings == 1 and casts == 1 and refused == 0, (recordings, casts, refused)
    assert after_rebuild in (1, 2) and casts_after in (1, 2), (after_rebuild, casts_after)
    for i, a, b in zip(FRAMES, replayed, traced, strict=True):
        for name, x, y in zip(("image", "depth", "object ids", "surfaces"), a, b, strict=True):
            assert x is not None and np.array_equal(x, y), f"frame {i}: {name}"


def test_a_texture_notes_its_values_again_only_when_its_shade_computes_something_else() -> None:
    import functools

    import mitsuba as mi

    from datagen.render.procedural import texture_class
    from datagen.render.runtime import use_variant

    use_variant("llvm_ad_rgb")

    def shade(gain: float, offset, x, y, footprint_m, ops):
        return x * ops.param_f32(gain) + ops.param_f32(offset[0])

    texture = texture_class(mi.variant())()
    offset = [0.25]
    texture.shade = functools.partial(shade, 2.0, offset)
    texture.prepare()
    notes = texture._book
    assert len(notes["f32"]) == 2 and [float(v[0]) for v in notes["f32"]] == [2.0, 0.25]
    texture.shade = functools.partial(shade, 2.0, offset)  # set again each frame: the same computation
    texture.prepare()
    assert texture._book is notes
    texture.shade = functools.partial(shade, 3.0, offset)  # another number: noted again
    texture.prepare()
    assert texture._book is not notes and [float(v[0]) for v in texture._book["f32"]] == [3.0, 0.25]
    notes = texture._book
    texture.shade = functools.partial(shade, 3.0, [0.25])  # an equal but other object: noted again
    texture.prepare()
    assert texture._book is not notes


def test_a_texture_shows_a_frozen_functions_walk_nothing_and_gives_its_device_values_as_inputs() -> None:
    """A frozen render walks a texture once for every object holding it, at every call: the
    texture holds its attributes where that walk passes at once, and hands its device values
    (the camera's three, each noted value) over in :meth:`inputs`, which the renderer passes
    to its frozen functions."""
    import functools

    import drjit as dr
    import mitsuba as mi

    from datagen.render.procedural import texture_class
    from datagen.render.runtime import use_variant

    use_variant("llvm_ad_rgb")

    def shade(gains, x, y, footprint_m, ops):
        total = x * 0.0
        for g in gains:
            total = total + ops.param_f32(g)
        return total

    texture = texture_class(mi.variant())()
    texture.shade = functools.partial(shade, [float(i) for i in range(300)])
    texture.prepare()
    assert set(vars(texture)) == {"_host"} and dr.detail.collect_indices(texture) == []
    assert len(dr.detail.collect_indices(texture.inputs())) == 3 + 300
    assert texture.pixel_rad > 0.0 and not texture.colour  # (its attributes, where they are held)


def test_a_texture_whose_kernel_reads_other_values_than_it_noted_is_refused() -> None:
    import drjit as dr
    import mitsuba as mi

    from datagen.render.procedural import texture_class
    from datagen.render.runtime import use_variant

    use_variant("llvm_ad_rgb")
    extra = []

    def shade(x, y, footprint_m, ops):  # asks for one more value each time it is traced
        extra.append(1.0)
        return x * sum((ops.param_f32(v) for v in extra), ops.f32(0.0))

    texture = texture_class(mi.variant())()
    texture.shade = shade
    texture.prepare()
    with pytest.raises(RuntimeError, match="read"):
        texture.eval_1(dr.zeros(mi.SurfaceInteraction3f, 4))


def _textures_not_varying() -> list[tuple[str, float | None]]:
    """Every procedural texture of wingcam55's world and paintwork that tells Mitsuba it does
    not vary over its surface: the cloud layer whose emitter's radiance it is, and that
    emitter's sampling weight (None: no cloud layer's)."""
    from datagen.config import load_config
    from datagen.render.renderer import Renderer
    from datagen.render.runtime import use_variant
    from datagen.scene.resolved import Scene

    use_variant("llvm_ad_rgb")
    renderer = Renderer(Scene.resolve(load_config("wingcam55")))
    renderer._build(8)
    world = renderer.world
    radiance = {id(texture): (name, world.cloud_meshes[name].emitter().sampling_weight())
                for name, texture in zip(world.cloud_meshes, world.cloud_radiances(), strict=True)}
    out = [radiance.get(id(t), ("", None)) for t in (*renderer.world.textures(), *renderer.paintwork.textures())
           if not t.is_spatially_varying()]
    assert len(renderer.world.cloud_meshes) == 2
    renderer.release()
    return out


def test_only_the_cloud_layers_radiance_says_it_does_not_vary_and_their_emitters_are_never_sampled() -> None:
    """A texture that tells Mitsuba it does not vary gets a wrong emission pdf; Mitsuba
    multiplies that pdf by the emitter's sampling weight, so the image is right only while it
    is 0. Telling the truth costs a scene per layer that Mitsuba rebuilds inside the render
    (a frozen render's recordings were refused, and its replays crashed)."""
    found = _in_own_process(_textures_not_varying)
    assert sorted(found) == [("cloud_deck", 0.0), ("cloud_layer", 0.0)], found


@pytest.mark.parametrize("message", [
    "record(): error encountered while recording a frozen function (see above).",
    "replay(): error encountered while re-recording a function (see above).",
])
def test_a_refused_recording_traces_its_frame_and_a_new_frozen_render_replaces_the_old(message, monkeypatch) -> None:
    """Dr.Jit's refusals to record (a first recording, or a recording again after a failed
    dry run of a replay) trace that frame; the frozen render whose cache may hold the refused
    entry is dropped, its recordings still counted. Other errors are raised."""
    import types

    import datagen.render.renderer as renderer_module
    from datagen.render.frozen import Frozen

    class Refusing:
        n_recordings = 3

        def __call__(self, *args):
            raise RuntimeError(message) from RuntimeError("record(): validate(): ...")

    fresh = types.SimpleNamespace(n_recordings=0)
    made = iter([Refusing(), fresh])
    traced = []

    def trace(scene, seed, target_seed, offsets, textures=()):
        traced.append((scene, seed, offsets))
        return "image"

    r = types.SimpleNamespace(
        _frozen=Frozen(lambda: next(made)), scene="scene", trace=trace, _textures=lambda: (),
        _dr=types.SimpleNamespace(opaque=lambda cls, v: v), _mi=types.SimpleNamespace(UInt32=int))
    assert renderer_module.Renderer.path_trace(r, 7) == "image" and traced == [("scene", 7, None)]
    assert r._frozen.refused == 1 and r._frozen.function is fresh
    assert renderer_module.Renderer.recordings.fget(r) == 3

    class Failing:
        def __call__(self, *args):
            raise RuntimeError("a kernel failed")

    r._frozen = Frozen(Failing)
    with pytest.raises(RuntimeError, match="a kernel failed"):
        renderer_module.Renderer.path_trace(r, 7)


def test_a_refused_recording_of_the_ray_cast_traces_it_and_a_new_frozen_cast_replaces_the_old(monkeypatch) -> None:
    """As the render's: the geometry pass's cast is traced where Dr.Jit refuses to record it,
    the frozen cast is replaced, and its recordings still count; other errors are raised."""
    import types

    import drjit as dr
    import mitsuba as mi

    import datagen.render.raycast as raycast
    from datagen.render.frozen import Frozen
    from datagen.render.renderer import Renderer
    from datagen.render.runtime import use_variant

    use_variant("llvm_ad_rgb")

    class Refusing:
        n_recordings = 2

        def __call__(self, *args):
            raise RuntimeError("replay(): ... re-recording ...")

    fresh = types.SimpleNamespace(n_recordings=0)
    made = iter([Refusing(), fresh])
    traced = []
    monkeypatch.setattr(raycast, "cast_kernel", lambda *args: traced.append(args) or "cast")
    r = types.SimpleNamespace(
        _mi=mi, _dr=dr, _camera_render=np.zeros(3), _id_table=mi.UInt32([0, 1]),
        _background_codes=mi.Int32([-1, 0, 1]), scene="scene", _frozen=None, _frozen_cast=Frozen(lambda: next(made)),
        world=types.SimpleNamespace(cloud_layer=lambda name: None, cloud_opacities=lambda: (), pixel_rad=1e-3))
    d = mi.Vector3f(dr.zeros(mi.Float, 4), dr.zeros(mi.Float, 4), dr.ones(mi.Float, 4))
    assert raycast.RayCasting._cast_on_device(r, d) == "cast" and len(traced) == 1
    assert Renderer.refused_recordings.fget(r) == 1 and r._frozen_cast.function is fresh
    assert Renderer.cast_recordings.fget(r) == 2

    class Failing:
        def __call__(self, *args):
            raise RuntimeError("a kernel failed")

    r._frozen_cast = Frozen(Failing)
    with pytest.raises(RuntimeError, match="a kernel failed"):
        raycast.RayCasting._cast_on_device(r, d)


def _in_own_process(fn, *args):
    """``fn(*args)`` in a fresh process, as a build's worker is: Mitsuba objects other tests
    left alive in this one are calls a recording cannot follow (it records again or refuses)."""
    import concurrent.futures
    import multiprocessing

    with concurrent.futures.ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn")) as pool:
        return pool.submit(fn, *args).result()


def _table_replays() -> tuple[list[bool], int]:
    """A frozen render of a texture that gathers from a :func:`scene_array` table in a loop
    (as the noise series do), the table replaced between calls: per call whether the replay
    is the traced render, and the recordings made."""
    import drjit as dr
    import mitsuba as mi

    from datagen.render.mitsuba import scene_array
    from datagen.render.runtime import set_threads, use_variant

    use_variant("llvm_ad_rgb")
    set_threads(1)

    class Table(mi.Texture):
        def __init__(self):
            super().__init__(mi.Properties())
            self.table = scene_array(mi.Float, np.full(4, 0.5))

        def eval(self, si, active=True):
            def body(i, total):
                return i + 1, total + dr.gather(mi.Float, self.table, i)

            _, total = dr.while_loop((mi.UInt32(si.uv.x * 0.0), si.uv.x * 0.0), lambda i, t: i < 3, body)
            return mi.Color3f(total / 3.0)

        def eval_1(self, si, active=True):
            return self.eval(si, active).x

        def mean(self):
            return 0.5

    texture = Table()
    placed = mi.ScalarTransform4f().translate([0, 0, 2]) @ mi.ScalarTransform4f().rotate([1, 0, 0], 180)
    scene = mi.load_dict({
        "type": "scene", "integrator": {"type": "path"},
        "sensor": {"type": "perspective", "film": {"type": "hdrfilm", "width": 8, "height": 8}},
        "light": {"type": "constant"},
        "wall": {"type": "rectangle", "to_world": placed, "bsdf": {"type": "diffuse", "reflectance": texture}},
    }, optimize=False)
    frozen = dr.freeze(lambda s, seed: mi.render(s, seed=seed, spp=1))
    seed = dr.opaque(mi.UInt32, 0)
    kept, same = [], []  # the tables replaced stay alive: a replay reading one would see its old values
    for value in (0.5, 0.9, 0.1, 0.7):
        kept.append(texture.table)
        texture.table = scene_array(mi.Float, np.full(4, value))
        traced, replayed = np.array(mi.render(scene, seed=seed, spp=1)), np.array(frozen(scene, seed))
        same.append(bool(np.array_equal(traced, replayed)))
    return same, frozen.n_recordings


def test_a_frozen_render_reads_the_arrays_scene_array_made_after_it_recorded() -> None:
    """Dr.Jit replays an array mapped from numpy memory at the memory it recorded;
    :func:`~datagen.render.mitsuba.scene_array` gives it arrays in its own memory."""
    same, recordings = _in_own_process(_table_replays)
    assert recordings == 1  # one recording, three replays
    assert all(same), same
