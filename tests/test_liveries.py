"""Aircraft with surfaces (issue 57, item 2): procedural liveries band-limited to the pixel
(no texel), panels along each piece's structure, markings' roundels and numbers, soot behind
the exhausts, and the lights; the kernel paints what numpy paints."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from datagen.assets.liveries import (
    _SEGMENTS,
    DIGIT_SEGMENTS,
    LIGHTS,
    MAX_DIGITS,
    NUMBER_U,
    Livery,
    Markings,
    PaintPoint,
    _line,
    decal_uv,
    light_sites,
    structure_uv,
)
from datagen.assets.noise import FADE_LO, NUMPY
from datagen.core.conventions import SEALANT_PART, texture_part_rng
from tests.strategies import rotations

SCHEMES = ("grey_camouflage", "two_tone", "high_visibility", "bare_metal")


def _livery(scheme: str, seed: int = 3, **kw) -> Livery:
    return Livery.drawn(np.random.default_rng(seed), scheme, kw.pop("weathering", 0.4), length_m=40.0, span_m=40.0,
                        nose_x_m=20.0, **kw)


def _points(rng: np.random.Generator, n: int, footprint: float | np.ndarray = 0.005, nz=None) -> PaintPoint:
    s, t, x, y, z = (rng.uniform(-15.0, 15.0, n).astype(np.float32) for _ in range(5))
    f = np.broadcast_to(np.float32(footprint), (n,)).astype(np.float32)
    nz = rng.uniform(-1.0, 1.0, n).astype(np.float32) if nz is None else np.full(n, nz, np.float32)
    return PaintPoint(s, t, x, y, z, nz, f)


@settings(max_examples=60, deadline=None)
@given(width=st.floats(1e-4, 0.05), footprint=st.floats(1e-4, 0.05))
def test_a_lines_box_filtered_coverage_integrates_to_its_width_at_any_footprint(width: float, footprint: float) -> None:
    reach = width + footprint
    d = np.linspace(-reach, reach, 200_001)
    cover = _line(np.abs(d), np.float64(width), np.float64(footprint), NUMPY)
    assert np.all((cover >= 0.0) & (cover <= 1.0))
    assert np.trapezoid(cover, d) == pytest.approx(width, rel=2e-3)


@given(width=st.floats(1e-4, 0.01), ratio=st.floats(1.0, 50.0))
def test_a_line_narrower_than_a_pixel_darkens_it_by_the_share_it_covers(width: float, ratio: float) -> None:
    footprint = width * ratio
    assert _line(np.float64(0.0), np.float64(width), np.float64(footprint), NUMPY) == pytest.approx(1.0 / ratio)


def test_seams_a_pixel_cannot_resolve_fade_to_their_mean_and_sharp_ones_stay_lines() -> None:
    livery = _livery("grey_camouflage")
    rng = np.random.default_rng(1)
    coarse = livery._panels(_points(rng, 50_000, footprint=max(livery.panel_m) / FADE_LO), NUMPY)[0]
    mean = livery.seam_m / np.array(livery.panel_m)
    assert np.allclose(coarse, mean.sum() - mean.prod(), atol=1e-6)  # the two families' mean coverage
    fine = livery._panels(_points(rng, 50_000, footprint=1e-4), NUMPY)[0]
    assert fine.max() == pytest.approx(1.0) and np.median(fine) == 0.0


def _cylinder(rotation: np.ndarray, length: float, radius: float, n: int = 24, rings: int = 8):
    """A closed cylinder along the first axis of ``rotation``: vertices, faces (outward)."""
    phi = np.linspace(0.0, 2 * np.pi, n, endpoint=False)
    xs = np.linspace(-length / 2, length / 2, rings)
    ring = np.stack([np.repeat(xs, n), np.tile(radius * np.cos(phi), rings), np.tile(radius * np.sin(phi), rings)], -1)
    verts = np.concatenate([ring, [[-length / 2, 0, 0], [length / 2, 0, 0]]])
    faces = []
    for r in range(rings - 1):
        for j in range(n):
            a, b, c, d = r * n + j, r * n + (j + 1) % n, (r + 1) * n + j, (r + 1) * n + (j + 1) % n
            faces += [[a, b, d], [a, d, c]]
    first, last = len(verts) - 2, len(verts) - 1
    for j in range(n):
        faces += [[first, (j + 1) % n, j], [last, (rings - 1) * n + j, (rings - 1) * n + (j + 1) % n]]
    return verts @ rotation.T + np.array([3.0, -2.0, 1.0]), np.asarray(faces)


@settings(max_examples=30, deadline=None)
@given(rotation=rotations(), length=st.floats(4.0, 40.0), radius=st.floats(0.2, 1.0))
def test_structural_coordinates_run_along_a_pieces_longest_axis_and_every_face_is_right_handed(
        rotation: np.ndarray, length: float, radius: float) -> None:
    verts, faces = _cylinder(rotation, length, radius)
    out_v, _, uv = structure_uv(verts, faces)
    tri, st_ = out_v.reshape(-1, 3, 3).astype(np.float64), uv.reshape(-1, 3, 2).astype(np.float64)
    axis = rotation[:, 0]
    along = (tri - verts[:-2].mean(axis=0)) @ axis
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    side = np.abs(normal @ axis) < 1e-6 * np.linalg.norm(normal, axis=1)  # faces that are not the caps
    assert side.sum() > 0
    np.testing.assert_allclose(np.abs(st_[side][..., 0]), np.abs(along[side]), atol=1e-3 * length)
    e1, e2 = st_[:, 1] - st_[:, 0], st_[:, 2] - st_[:, 0]
    assert np.all(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0] > 0.0)


def test_each_piece_of_a_mesh_is_mapped_along_its_own_axis() -> None:
    sweep = np.radians(35.0)
    wing_axis = np.array([np.sin(sweep), np.cos(sweep), 0.0])
    wing_frame = np.column_stack([wing_axis, np.cross([0.0, 0.0, 1.0], wing_axis), [0.0, 0.0, 1.0]])
    fuselage, f1 = _cylinder(np.eye(3), 30.0, 1.5)
    wing, f2 = _cylinder(wing_frame, 14.0, 0.3)
    verts = np.concatenate([fuselage, wing])
    faces = np.concatenate([f1, f2 + len(fuselage)])
    out_v, _, uv = structure_uv(verts, faces)
    tri, st_ = out_v.reshape(-1, 3, 3).astype(np.float64), uv.reshape(-1, 3, 2).astype(np.float64)
    on_wing = np.arange(len(faces)) >= len(f1)
    for sel, axis in ((~on_wing, np.array([1.0, 0.0, 0.0])), (on_wing, wing_axis)):
        ds = st_[sel][:, 1, 0] - st_[sel][:, 0, 0]
        dp = (tri[sel][:, 1] - tri[sel][:, 0]) @ axis
        long_edges = np.abs(dp) > 0.5
        np.testing.assert_allclose(np.abs(ds[long_edges]), np.abs(dp[long_edges]), atol=1e-3)


@pytest.mark.render
@pytest.mark.parametrize("scheme", SCHEMES)
def test_the_kernel_paints_the_same_livery_as_numpy(scheme: str) -> None:
    mi = pytest.importorskip("mitsuba")
    import drjit as dr

    from datagen.render.procedural import body_texture_class
    from datagen.render.runtime import use_variant

    variant = use_variant("llvm_ad_rgb")
    livery = _livery(scheme, exhausts=((-10.0, 2.0, 0.0, 0.6),))
    rng = np.random.default_rng(5)
    n = 20_000
    x, y = rng.uniform(-15.0, 15.0, (2, n)).astype(np.float32)
    z = rng.uniform(2.0, 400.0, n).astype(np.float32)  # 2-400 m from the camera at the origin
    s, t = rng.uniform(-10.0, 10.0, (2, n)).astype(np.float32)
    pixel_rad = 1.0 / 2000.0
    texture = body_texture_class(variant)
    textures = {name: texture(pixel_rad=pixel_rad, colour=name != "roughness") for name in ("albedo", "roughness",
                                                                                          "normal")}
    textures["albedo"].shade = livery.albedo
    textures["roughness"].shade = lambda p, ops: livery.roughness(0.35, p, ops)
    textures["normal"].shade = livery.normal
    for tex in textures.values():
        tex.camera = (0.0, 0.0, 0.0)  # the point's body frame is the render frame here
    # Each point seen along the surface's normal from ``distance`` away: the footprint is the same both ways.
    si = dr.zeros(mi.SurfaceInteraction3f, n)
    si.p = mi.Point3f(mi.Float(x), mi.Float(y), mi.Float(z))
    si.uv = mi.Point2f(mi.Float(s), mi.Float(t))
    si.n = mi.Normal3f(0.0, 0.0, 1.0)
    si.wi = mi.Vector3f(0.0, 0.0, 1.0)
    footprint = (np.sqrt(x.astype(np.float64)**2 + y**2 + z**2) * pixel_rad).astype(np.float32)
    p = PaintPoint(s, t, x, y, z, np.ones(n, np.float32), footprint)
    expected = {"albedo": livery.albedo(p), "roughness": (livery.roughness(0.35, p),), "normal": livery.normal(p)}
    for name, tex in textures.items():
        got = tex.eval(si) if name != "roughness" else (tex.eval_1(si),)
        for kernel, numpy in zip(got, expected[name], strict=True):
            diff = np.abs(np.asarray(kernel) - numpy)
            # float32 roundings flip a point lying on a panel's or a seam's edge: rare, and bounded.
            assert np.mean(diff > 1e-4) < 2e-3 and diff.max() < 0.7, (name, float(np.mean(diff > 1e-4)))


@pytest.mark.render
def test_a_twins_hits_are_painted_in_its_own_body_frame_and_the_targets_in_the_targets() -> None:
    mi = pytest.importorskip("mitsuba")
    import drjit as dr

    from datagen.core.transforms import make_transform
    from datagen.render.procedural import body_texture_class
    from datagen.render.runtime import use_variant

    variant = use_variant("llvm_ad_rgb")
    livery = _livery("high_visibility", seed=11)
    texture = body_texture_class(variant)(pixel_rad=1.0 / 2000.0, colour=True)
    texture.shade = livery.albedo
    twin_shape = mi.load_dict({"type": "sphere"})
    texture.twin = int(dr.reinterpret_array(mi.UInt32, mi.ShapePtr(twin_shape))[0])
    offset = np.array([90.0, -40.0, 25.0])  # the twin flies here, the target at the render frame's origin
    texture.body_from_render = np.eye(4)
    texture.twin_body_from_render = np.linalg.inv(make_transform(np.eye(3), offset))
    rng = np.random.default_rng(8)
    n = 4_000
    body = rng.uniform(-15.0, 15.0, (n, 3))
    body[:, 2] = rng.uniform(-2.0, 2.0, n)
    on_twin = rng.uniform(size=n) < 0.5
    render = body + np.where(on_twin[:, None], offset, 0.0)
    si = dr.zeros(mi.SurfaceInteraction3f, n)
    si.p = mi.Point3f(*(mi.Float(c.astype(np.float32)) for c in render.T))
    si.uv = mi.Point2f(mi.Float(body[:, 0].astype(np.float32)), mi.Float(body[:, 1].astype(np.float32)))
    si.n = mi.Normal3f(0.0, 0.0, 1.0)
    si.wi = mi.Vector3f(0.0, 0.0, 1.0)
    twin_ptr = mi.UInt32(texture.twin)
    si.instance = dr.reinterpret_array(mi.ShapePtr, dr.select(mi.Bool(on_twin), twin_ptr, mi.UInt32(0)))
    texture.camera = (0.0, 0.0, 0.0)
    got = np.stack([np.asarray(c) for c in texture.eval(si)], axis=-1)
    distance = np.linalg.norm(render, axis=1)
    p = PaintPoint(*(body[:, :2].T.astype(np.float32)), *(body.T.astype(np.float32)), np.ones(n, np.float32),
                   (distance / 2000.0).astype(np.float32))
    expected = np.stack(livery.albedo(p), axis=-1)
    assert np.mean(np.abs(got - expected).max(axis=-1) > 1e-3) < 5e-3  # both painted where they are
    # The same points read in the target's frame wear other paint: the twin's frame made the difference.
    texture.twin = None
    target_frame = np.stack([np.asarray(c) for c in texture.eval(si)], axis=-1)
    assert np.mean(np.abs(target_frame[on_twin] - expected[on_twin]).max(axis=-1) > 1e-3) > 0.2


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**31), scheme=st.sampled_from(SCHEMES))
def test_a_panels_tone_and_gloss_are_one_value_over_the_whole_brick_panel_and_change_at_its_seams(
        seed: int, scheme: str) -> None:
    livery = _livery(scheme, seed=seed)
    ps, pt = livery.panel_m
    rng = np.random.default_rng(seed)
    row = int(rng.integers(-8, 8)) * 2 + 1  # an odd row: its panels sit half a panel along
    k = int(rng.integers(-8, 8))
    # Points spread over that panel's interior, away from its seams by 5% of a panel.
    s = ((k + 0.5) + rng.uniform(0.05, 0.95, 200)) * ps
    t = (row + rng.uniform(0.05, 0.95, 200)) * pt
    zero = np.zeros(200, np.float32)
    tiny = np.full(200, 1e-4, np.float32)

    def value(s, t):
        return livery._panel_value(PaintPoint(s.astype(np.float32), t.astype(np.float32), zero, zero, zero,
                                              zero + 1, tiny), NUMPY)

    inside = value(s, t)
    assert np.ptp(inside) == 0.0
    # Across the panel's seam along s the next panel has a value of its own: drawn over 16 panels, some differ.
    steps = [value(s + j * ps, t)[0] for j in range(1, 17)]
    assert len(set(np.round(steps, 6).tolist()) | {round(float(inside[0]), 6)}) > 4


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**31), scheme=st.sampled_from(SCHEMES))
def test_a_seam_is_edged_by_a_wider_band_of_sealant_that_darkens_the_paint_by_its_drawn_share(
        seed: int, scheme: str) -> None:
    livery = _livery(scheme, seed=seed, weathering=0.0)
    assert livery.seam_m < livery.sealant_m and 0.0 < livery.sealant_dark < 1.0
    ps, pt = livery.panel_m
    rng = np.random.default_rng(seed)
    row, k = int(rng.integers(-8, 8)) * 2, int(rng.integers(-8, 8))  # an even row: no brick offset
    s = np.full(2, (k + 0.5) * ps, np.float32)  # mid-panel along s, far from its seams and rivets
    # Beside the seam between rows: in the sealant, clear of the seam's gap and its rivet row; and
    # 10 cm into the same panel.
    t = np.array([row * pt + 0.0065, row * pt + 0.1], np.float32)
    zero, tiny = np.zeros(2, np.float32), np.full(2, 1e-4, np.float32)
    band, inside = np.stack(livery.albedo(PaintPoint(s, t, zero, zero, zero, zero + 1, tiny), NUMPY), -1)
    # A channel the panel's tone lifts past 1 is clipped there inside the panel, not in the band.
    unclipped = inside < np.float32(1.0)
    assert unclipped.any()
    assert band[unclipped] == pytest.approx(inside[unclipped] * (1.0 - livery.sealant_dark), rel=1e-4)


def test_the_sealant_is_drawn_from_the_liverys_own_seed_not_from_the_approachs_stream() -> None:
    """So that the markings and the other aircraft's livery, drawn after it, are what they were."""
    livery = Livery.drawn(np.random.default_rng(5), "grey_camouflage", 0.3, length_m=40.0, span_m=40.0,
                          nose_x_m=20.0)
    own = texture_part_rng(livery.seed, SEALANT_PART)
    assert livery.sealant_m == own.uniform(0.02, 0.04)
    assert livery.sealant_dark == own.uniform(0.12, 0.25) + 0.15 * 0.3


def test_counter_shading_paints_the_underside_lighter_than_the_top() -> None:
    livery = _livery("two_tone", weathering=0.0)
    rng = np.random.default_rng(2)
    top = np.mean(livery.paint(_points(rng, 20_000, nz=1.0))[1])
    below = np.mean(livery.paint(_points(rng, 20_000, nz=-1.0))[1])
    dark, light = livery.colours[0][1], livery.colours[1][1]
    assert top < dark + 0.2 * (light - dark) and below > light - 0.2 * (light - dark)


def test_high_visibility_bands_cross_the_fuselage_where_drawn() -> None:
    livery = _livery("high_visibility", seed=11)
    centre = livery.bands[0]
    n = 1000
    pts = [PaintPoint(*(np.full(n, v, np.float32) for v in (0.0, 0.0, x, 0.0, 0.0, 1.0, 0.001))) for x in
           (centre, centre + 2.0 * livery.band_width_m + 0.5)]
    inside, outside = (livery.paint(p)[1][0] for p in pts)
    assert inside == pytest.approx(livery.colours[1][1], rel=1e-4)
    assert outside != pytest.approx(inside, abs=1e-3)


def test_soot_darkens_the_skin_behind_an_exhaust_and_not_ahead_of_it() -> None:
    livery = _livery("bare_metal", weathering=0.5, exhausts=((0.0, 0.0, 0.0, 0.5),))
    n = 400
    y = np.linspace(-0.3, 0.3, n).astype(np.float32)

    def at(x: float) -> float:
        p = PaintPoint(y * 0 + 1.0, y * 0 + 1.0, np.full(n, x, np.float32), y, y * 0, y * 0, y * 0 + 0.01)
        return float(livery._weather(p, NUMPY)[1].mean())

    assert at(-1.0) > 0.3 * livery.soot and at(-3.0) > at(-7.0) and at(3.0) == 0.0


def test_each_digit_lights_exactly_its_seven_segments() -> None:
    cell = 2.0 / MAX_DIGITS
    for digit in range(10):
        markings = Markings(rings=((0.0,) * 3,) * 3, ink=(0.0, 0.0, 0.0), digits=(digit,))
        # A one-digit number is right-aligned: the last cell's segment centres in decal units.
        sx, centre = min(cell * 0.4, 0.6 * 0.8), 1.0 - cell / 2
        for j, (cx, cy, _, _) in enumerate(_SEGMENTS):
            u = np.float32(NUMBER_U + centre + cx * sx)
            v = np.float32(cy * 0.8)
            colour = markings.colour(u, v, np.float32(1e-3), (np.float32(1.0),) * 3)
            lit = (DIGIT_SEGMENTS[digit] >> j) & 1
            assert colour[0] == pytest.approx(0.0 if lit else 1.0), (digit, "abcdefg"[j])


def test_a_roundels_rings_run_inner_middle_outer() -> None:
    rings = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))
    markings = Markings(rings=rings, ink=(0.0, 0.0, 0.0), digits=(1, 2))
    for r, expected in ((0.9, rings[0]), (0.5, rings[1]), (0.1, rings[2])):
        u, v = np.float32(r * 0.6), np.float32(r * 0.8)
        got = markings.colour(u, v, np.float32(1e-3), (np.float32(0.5),) * 3)
        assert tuple(float(c) for c in got) == pytest.approx(expected)


def _plate(centre, normal_axis: int, sign: float, size=(1.2, 0.3)) -> tuple[np.ndarray, np.ndarray]:
    """A flat rectangle (two triangles) at ``centre``, facing ``sign`` along ``normal_axis``, long along x."""
    a, b = size[0] / 2, size[1] / 2
    other = next(i for i in range(3) if i not in (0, normal_axis))
    corners = np.zeros((4, 3))
    corners[:, 0] = [-a, a, a, -a]
    corners[:, other] = [-b, -b, b, b]
    return corners + np.asarray(centre, dtype=np.float64), np.array([[0, 1, 2], [0, 2, 3]])


def test_a_number_reads_left_to_right_and_upright_seen_from_outside_on_either_side() -> None:
    for side in (1.0, -1.0):  # a decal on the left (+y) and on the right (-y) of a body centred at the origin
        verts, faces = _plate((0.0, side * 1.5, 0.5), 1, side)
        out_v, _, uv = decal_uv(verts, faces, body_centre=np.zeros(3))
        u = uv[:, 0] - NUMBER_U
        assert np.all(np.abs(u) <= 1.0 + 1e-6) and np.all(np.abs(uv[:, 1]) <= 1.0 + 1e-6)
        # Seen from outside (from +y on the left), the viewer's right is cross(view, up) with view = -normal.
        right = np.cross([0.0, -side, 0.0], [0.0, 0.0, 1.0])
        order = np.argsort(out_v @ right)
        assert u[order[0]] < u[order[-1]]
        assert np.corrcoef(uv[:, 1], out_v[:, 2])[0, 1] > 0.99  # v runs up


def test_the_lights_sit_red_on_the_left_wingtip_green_on_the_right_and_white_at_the_tail() -> None:
    rng = np.random.default_rng(4)
    body = rng.uniform([-10, -1, -1], [10, 1, 1], (500, 3))
    wing = rng.uniform([-2, -12, -0.2], [2, 12, 0.2], (500, 3))
    sites = light_sites(np.concatenate([body, wing]), centre_y_m=0.0)
    colours = {name: colour for name, colour, _ in LIGHTS}
    assert sites["port"][1] == pytest.approx(np.concatenate([body, wing])[:, 1].max())
    assert sites["starboard"][1] == pytest.approx(np.concatenate([body, wing])[:, 1].min())
    assert colours["port"][0] > 10 * colours["port"][1] and colours["starboard"][1] > 10 * colours["starboard"][0]
    assert sites["tail"][0] == pytest.approx(body[:, 0].min()) and min(colours["tail"]) == 1.0
    assert sites["beacon_top"][2] > 0.9 and sites["beacon_bottom"][2] < -0.9


def test_a_livery_is_the_same_draw_for_the_same_seed_and_another_for_another() -> None:
    assert _livery("grey_camouflage", seed=7) == _livery("grey_camouflage", seed=7)
    assert _livery("grey_camouflage", seed=7) != _livery("grey_camouflage", seed=8)


def test_the_shipped_aircraft_get_lights_exhausts_and_decals_from_their_meshes() -> None:
    from datagen.assets.loader import builtin_paths, load_mesh
    from datagen.render.paintwork import Airframe

    for obj in ("receiver", "tanker"):
        mesh = load_mesh(builtin_paths(obj)[0], obj)
        frame = Airframe.of(mesh)
        assert frame.exhausts and set(frame.lights) == {name for name, _, _ in LIGHTS}
        assert frame.lights["port"][1] > frame.centre[1] > frame.lights["starboard"][1]
        _, _, uv = decal_uv(mesh.parts["markings"].vertices, mesh.parts["markings"].faces, np.array(frame.centre))
        kinds = {round(u / NUMBER_U) for u in uv[:, 0]}
        assert kinds == {0, 1}  # roundels and numbers


def test_a_lights_spot_adds_its_radiance_times_the_solid_angle_it_subtends() -> None:
    from datagen.render.paintwork import LIGHT_RADIUS_M, add_light_spots

    rgb = np.zeros((64, 80, 3), np.float32)
    radiance = np.array([[3.0, 0.1, 0.05]])
    add_light_spots(rgb, np.array([[40.3, 30.7]]), np.array([50.0]), radiance, fx=2000.0)
    r_px = LIGHT_RADIUS_M * 2000.0 / 50.0
    np.testing.assert_allclose(rgb.sum(axis=(0, 1)), np.pi * r_px**2 * radiance[0], rtol=1e-5)
    peak = np.unravel_index(np.argmax(rgb[..., 0]), rgb.shape[:2])
    assert peak == (30, 40)  # the pixel the light's centre falls in
    edge = np.zeros_like(rgb)
    add_light_spots(edge, np.array([[-40.0, 30.0]]), np.array([50.0]), radiance, fx=2000.0)
    assert not edge.any()  # wholly off the image: nothing


def test_beacons_flash_a_fifth_of_the_time_and_the_steady_lights_always_shine() -> None:
    from types import SimpleNamespace

    from datagen.config import load_config
    from datagen.render.paintwork import BEACON_HZ, BEACON_ON, Airframe, Paintwork

    paintwork = Paintwork(load_config("wingcam55").randomization.livery, pixel_rad=1e-3)
    box = np.array([[-10.0, -8.0, -1.0], [10.0, 8.0, 2.0]])
    mesh = SimpleNamespace(parts={"paint": SimpleNamespace(vertices=box, faces=np.zeros((0, 3), int))})
    paintwork._airframes = {"receiver": Airframe.of(mesh)}
    look = SimpleNamespace(aircraft_lights=True, aircraft_light_scale=1.0)
    daylight = (np.array([100.0, 100.0, 100.0]), np.zeros(3))
    counts = [len(paintwork.light_spots(look, {"receiver": np.eye(4)}, t, daylight))
              for t in np.arange(0.0, 10.0, 0.01 / BEACON_HZ)]
    steady = sum(not flashing for _, _, flashing in LIGHTS)
    assert min(counts) == steady and max(counts) == len(LIGHTS)
    assert np.mean(np.array(counts) == len(LIGHTS)) == pytest.approx(BEACON_ON, abs=0.02)
    dark = SimpleNamespace(aircraft_lights=False, aircraft_light_scale=1.0)
    assert paintwork.light_spots(dark, {"receiver": np.eye(4)}, 0.0, daylight) == []


@pytest.mark.render
def test_a_frames_lights_are_drawn_where_they_project_and_change_nothing_else() -> None:
    pytest.importorskip("mitsuba")
    from datagen.config import load_config, override_config
    from datagen.render.renderer import Renderer
    from datagen.scene.approach import FrameStates
    from datagen.scene.look import frame_look
    from datagen.scene.resolved import Scene

    base = override_config(load_config("wingcam55"), {"render.denoise": "off", "randomization.sensor.enabled": False,
                                                      "randomization.livery.lights_share": 1.0,
                                                      "randomization.livery.light_scale": (50.0, 50.0)})
    images = {}
    for lights in (True, False):
        config = override_config(base, {"randomization.livery.lights": lights})
        renderer = Renderer(Scene.resolve(config), spp=1, width=256, height=135)
        state = FrameStates(config)(14)
        result = renderer.render(state, frame_look(config, state), 7, geometry=True)
        images[lights] = result
    changed = np.any(images[True].rgb != images[False].rgb, axis=-1)
    np.testing.assert_array_equal(images[True].object_id, images[False].object_id)  # no geometry
    assert 0 < changed.sum() < 200  # a few spots, nothing else
    assert (images[True].rgb >= images[False].rgb).all()  # light only adds
