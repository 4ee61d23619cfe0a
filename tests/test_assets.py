"""Built-in meshes and feature sets, a user's own assets, and bad asset input."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import trimesh
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from datagen.assets.generate import asset_documents
from datagen.assets.loader import BUILTIN_DIR, builtin_paths, hull_distance, load_features, load_mesh
from datagen.assets.models import material_class
from datagen.assets.models.drogue import HOSE_RADIUS_M, hose_faces, hose_mesh, hose_vertices
from datagen.assets.rig import HOSE_PORT_TANKER_M, MOUNTS
from datagen.assets.table import feature_table, load_object_features
from datagen.config import load_config
from datagen.core.conventions import RIGID_OBJECTS
from datagen.core.errors import ConfigError
from datagen.core.features import STORED_VARIANTS

from .strategies import finite

ROOT = Path(__file__).resolve().parents[1]
SCENES = sorted((ROOT / "scenes").glob("*.yaml"))


@pytest.fixture(scope="module")
def meshes():
    return {name: load_mesh(builtin_paths(name)[0], name) for name in RIGID_OBJECTS}


def surface_distance(mesh: trimesh.Trimesh, points: np.ndarray) -> np.ndarray:
    _, distance, _ = trimesh.proximity.closest_point(mesh, points)
    return distance


# --- the built-in assets ------------------------------------------------------------
def _glb_float_words(data: bytes) -> np.ndarray:
    """Which 4-byte words of a GLB file hold float32 accessor values (bool per word)."""
    length = int.from_bytes(data[12:16], "little")
    document = json.loads(data[20:20 + length])
    binary = 20 + length + 8
    floats = np.zeros(len(data) // 4, dtype=bool)
    for accessor in document["accessors"]:
        if accessor["componentType"] == 5126:  # FLOAT
            view = document["bufferViews"][accessor["bufferView"]]
            start = binary + view.get("byteOffset", 0) + accessor.get("byteOffset", 0)
            floats[start // 4:(start + view["byteLength"]) // 4] = True
    return floats


def same_document(committed: bytes, fresh: bytes, path: Path) -> bool:
    """Byte for byte, except that a GLB's float32 vertex data may differ by one unit in the
    last place: numpy's vectorized sine and cosine round differently on CPUs with other
    vector units (an AMD EPYC VM rebuilt the tanker with 5 of 152,504 bytes one ulp off)."""
    if committed == fresh or path.suffix != ".glb" or len(committed) != len(fresh) or len(fresh) % 4:
        return committed == fresh
    a, b = np.frombuffer(committed, np.int32), np.frombuffer(fresh, np.int32)
    differ = a != b
    return bool(np.all(_glb_float_words(fresh)[differ]) and np.all(np.abs(a[differ] - b[differ]) <= 1))


def test_committed_assets_are_what_assets_build_writes_to_a_float32_ulp(tmp_path: Path) -> None:
    documents = asset_documents(tmp_path)
    assert len(documents) == 2 * len(RIGID_OBJECTS)
    for path, data in documents.items():
        committed = BUILTIN_DIR / path.relative_to(tmp_path)
        assert same_document(committed.read_bytes(), data, path), f"{committed} differs from a fresh build"
    out = subprocess.run([sys.executable, "-m", "datagen", "assets", "build", "--out", str(tmp_path)],
                         capture_output=True, text=True, timeout=300, cwd=ROOT)
    assert out.returncode == 0, out.stderr
    assert {p: p.read_bytes() for p in tmp_path.rglob("*") if p.is_file()} == documents
    assert not [p for p in tmp_path.rglob(".*")], "temporary files left behind"


def test_the_asset_comparison_allows_one_float32_ulp_and_nothing_else() -> None:
    path = builtin_paths("tanker")[0]
    data = path.read_bytes()
    floats = np.flatnonzero(_glb_float_words(data))
    others = np.flatnonzero(~_glb_float_words(data))
    words = np.frombuffer(data, np.int32).copy()

    def changed(word: int, by: int) -> bytes:
        out = words.copy()
        out[word] += by
        return out.tobytes()

    assert same_document(data, changed(floats[100], 1), path)
    assert not same_document(data, changed(floats[100], 2), path)
    assert not same_document(data, changed(others[-1], 1), path)  # an index, not a coordinate
    assert not same_document(data[:-4], data[:-4] + b"\0", path)


@pytest.mark.parametrize("name", RIGID_OBJECTS)
@pytest.mark.parametrize("variant", STORED_VARIANTS)
def test_feature_points_lie_on_the_mesh_surface(meshes, name: str, variant: str) -> None:
    surface = meshes[name].combined
    for f in load_features(builtin_paths(name)[1], name, variant):
        assert surface_distance(surface, f.points_m).max() < 0.01, f.name
        if not f.internal:
            assert surface_distance(surface, f.center_m[None])[0] < 0.01, f.name
        assert hull_distance(f.points_m, f.center_m) < 1e-4, f.name


def test_default_feature_counts() -> None:
    counts = {n: len(load_features(builtin_paths(n)[1], n, "baseline")) for n in RIGID_OBJECTS}
    assert counts["receiver"] == 40 and counts["tanker"] == 40 and counts["drogue"] >= 16
    table = feature_table(load_config(ROOT / "scenes" / "wingcam55.yaml"))
    assert len(table) == 80 and table.objects == ("receiver", "tanker")


@pytest.mark.parametrize("scene", SCENES, ids=lambda p: p.stem)
def test_class_ids_are_unique_and_contiguous_per_dataset(scene: Path) -> None:
    config = load_config(scene)
    table = feature_table(config)
    np.testing.assert_array_equal(table.class_id, np.arange(len(table)))
    assert len(set(table.name)) == len(table)
    # Classes follow features.objects: every object's features form one block, in order.
    blocks = [table.objects[i] for i in table.object_index]
    assert [b for i, b in enumerate(blocks) if i == 0 or b != blocks[i - 1]] == list(config.features.objects)


def test_size_variants_are_colocated_and_grow_fourfold_in_area() -> None:
    for name in RIGID_OBJECTS:
        path = builtin_paths(name)[1]
        by_size = {v: load_features(path, name, v) for v in ("small", "medium", "large")}
        radii = {}
        for v, features in by_size.items():
            rows = [f for f in features if not f.internal]
            radii[v] = np.array([np.linalg.norm(f.points_m - f.center_m, axis=1).max() for f in rows])
            assert [f.name for f in features] == [f.name for f in by_size["small"]]
        for a, b in zip(by_size["small"], by_size["large"], strict=True):
            np.testing.assert_allclose(a.center_m, b.center_m, atol=0.01 * (1 + 3 * (not a.internal)))
        # Ring radius doubles from one size to the next (four times the area), up
        # to the snapping of ring points onto a curved surface.
        for smaller, larger in (("small", "medium"), ("medium", "large")):
            ratio = np.median(radii[larger] / radii[smaller])
            assert 1.7 < ratio < 2.3, (name, smaller, larger, ratio)


def test_dimensions_are_real_scale(meshes) -> None:
    tanker = meshes["tanker"].combined.extents
    assert 40.0 <= tanker[0] <= 50.0 and 40.0 <= tanker[1] <= 50.0, tanker
    receiver = meshes["receiver"]
    airframe = trimesh.util.concatenate([m for p, m in receiver.parts.items() if p != "probe"])
    length, span, height = airframe.extents
    assert 16.0 <= length <= 18.5 and 11.0 <= span <= 13.5 and 3.5 <= height <= 5.0, airframe.extents
    rim = meshes["drogue"].parts["tape"].extents  # the ring at the canopy's rim
    assert 0.6 <= rim[1] <= 0.8 and 0.6 <= rim[2] <= 0.8, rim


def test_models_sit_on_the_rig(meshes) -> None:
    # The receiver's probe tip is its origin, the wingcam is outside the airframe
    # and the hose port is on the tanker's surface.
    receiver = meshes["receiver"].combined
    assert surface_distance(receiver, np.zeros((1, 3)))[0] < 1e-4
    for mount in ("wingcam", "dashcam"):
        cam = np.array([MOUNTS[mount].position_m])
        assert not receiver.contains(cam)[0], mount
    assert surface_distance(meshes["receiver"].parts["pod"], np.array([MOUNTS["wingcam"].position_m]))[0] < 0.1
    assert surface_distance(meshes["tanker"].combined, HOSE_PORT_TANKER_M[None])[0] < 0.1
    assert not meshes["tanker"].combined.contains(np.array([MOUNTS["podcam"].position_m]))[0]


def test_parts_are_named_for_materials(meshes) -> None:
    for name, mesh in meshes.items():
        classes = {material_class(p) for p in mesh.parts}
        assert {"metal", "markings"} <= classes and classes & {"paint", "fabric"}, name
    assert {"glass", "dark"} <= {material_class(p) for p in meshes["receiver"].parts}
    assert {"glass", "dark"} <= {material_class(p) for p in meshes["tanker"].parts}
    assert material_class("Canopy_Glass.001") == "glass" and material_class("fuselage") == "paint"


@pytest.mark.render
def test_meshes_load_in_mitsuba(meshes) -> None:
    import mitsuba as mi

    from datagen.render.mitsuba import mitsuba_mesh
    from datagen.render.runtime import use_variant

    use_variant("auto")
    for mesh in meshes.values():
        shapes = {p: mitsuba_mesh(p, m.vertices, m.faces) for p, m in mesh.parts.items()}
        scene = mi.load_dict({"type": "scene", **shapes}, optimize=False)
        assert len(scene.shapes()) == len(mesh.parts)
        bbox = scene.bbox()
        np.testing.assert_allclose([list(bbox.min), list(bbox.max)], mesh.combined.bounds, atol=1e-4)


# --- random features (model I) ------------------------------------------------------
def test_random_features_are_seeded_and_on_the_surface(meshes) -> None:
    a = load_object_features("tanker", "random", seed=7, random_count=25)
    b = load_object_features("tanker", "random", seed=7, random_count=25)
    c = load_object_features("tanker", "random", seed=8, random_count=25)
    assert len(a) == 25 and [f.class_id for f in a] == list(range(25))
    assert all(np.array_equal(x.points_m, y.points_m) for x, y in zip(a, b, strict=True))
    assert not all(np.array_equal(x.center_m, y.center_m) for x, y in zip(a, c, strict=True))
    surface = meshes["tanker"].combined
    assert max(surface_distance(surface, f.points_m).max() for f in a) < 0.01
    centres = np.array([f.center_m for f in a])
    gaps = np.linalg.norm(centres[:, None] - centres[None], axis=-1) + np.eye(25) * 1e9
    assert gaps.min() > 1.0  # spread out, not clumped


# --- the hose -------------------------------------------------------------------------
def test_hose_is_a_closed_tube_of_fixed_topology() -> None:
    s = np.linspace(0.0, 1.0, 48)
    straight = np.column_stack([-20 * s, np.zeros_like(s), -3 * s**2])
    bent = straight + np.column_stack([np.zeros_like(s), np.sin(3 * s), np.zeros_like(s)])
    a, b = hose_mesh(straight), hose_mesh(bent)
    assert a.is_watertight and a.is_winding_consistent and a.volume > 0
    np.testing.assert_array_equal(a.faces, b.faces)
    np.testing.assert_array_equal(hose_faces(48), a.faces)
    assert len(hose_vertices(bent)) == len(b.vertices)
    # About 7 cm across: ring points are one radius from the curve.
    ring = hose_vertices(straight)[48 * 12 // 2: 48 * 12 // 2 + 12]
    centre = straight[24]
    np.testing.assert_allclose(np.linalg.norm(ring - centre, axis=1), HOSE_RADIUS_M, rtol=1e-6)
    assert 0.06 <= 2 * HOSE_RADIUS_M <= 0.08


@given(a=arrays(np.float64, (5, 3), elements=st.floats(-1e3, 1e3, **finite)),
       b=arrays(np.float64, (5, 3), elements=st.floats(-1e3, 1e3, **finite)))
def test_the_lofts_cross_product_is_numpys_bit_for_bit(a, b) -> None:
    from datagen.assets.models.loft import _cross

    assert np.array_equal(_cross(a, b), np.cross(a, b))


@given(steps=arrays(np.float64, (12, 3), elements=st.floats(-3.0, 3.0, **finite)),
       radius=st.floats(0.01, 2.0))
def test_a_tubes_rings_are_circles_of_its_radius_square_to_the_path(steps, radius) -> None:
    """Each ring of ``tube_rings`` lies at the radius from its path point, in the plane square
    to the path's tangent there, its points evenly around it."""
    from datagen.assets.models.loft import tube_rings

    path = np.cumsum(steps + np.array([1.0, 0.0, 0.0]) * 4.0, axis=0)  # moving on along x
    rings = tube_rings(path, radius, 8)
    tangents = np.gradient(path, axis=0)
    tangents /= np.linalg.norm(tangents, axis=1, keepdims=True)
    offsets = rings - path[:, None, :]
    np.testing.assert_allclose(np.linalg.norm(offsets, axis=2), radius, rtol=1e-9)
    np.testing.assert_allclose(np.einsum("rpk,rk->rp", offsets, tangents), 0.0, atol=1e-9 * radius)
    np.testing.assert_allclose(np.linalg.norm(offsets[:, 1] - offsets[:, 0], axis=1),
                               2 * radius * np.sin(np.pi / 8), rtol=1e-9)


# --- convex hull test ---------------------------------------------------------------
@given(
    points=arrays(np.float64, (6, 3), elements=st.floats(-5, 5, **finite)),
    weights=arrays(np.float64, 6, elements=st.floats(0.0, 1.0, **finite)),
)
def test_hull_distance_is_zero_for_convex_combinations(points, weights) -> None:
    if weights.sum() < 1e-3:
        weights = np.ones(6)
    inside = points.T @ (weights / weights.sum())
    assert hull_distance(points, inside) < 1e-6 * (1 + np.ptp(points))


@given(
    points=arrays(np.float64, (5, 3), elements=st.floats(-1, 1, **finite)),
    direction=arrays(np.float64, 3, elements=st.floats(-1, 1, **finite)),
    gap=st.floats(0.01, 10.0),
)
def test_hull_distance_measures_points_outside(points, direction, gap) -> None:
    n = np.linalg.norm(direction)
    if n < 1e-3:
        direction, n = np.array([1.0, 0.0, 0.0]), 1.0
    u = direction / n
    # Beyond the farthest point along u by ``gap``: at least ``gap`` from the hull,
    # and no farther than from the nearest point.
    outside = points[np.argmax(points @ u)] + gap * u
    d = hull_distance(points, outside)
    assert d >= gap - 1e-6
    assert d <= np.linalg.norm(points - outside, axis=1).min() + 1e-6


# --- bring your own -------------------------------------------------------------------
def write_user_assets(folder: Path, features: list[dict] | None = None) -> tuple[Path, Path]:
    body = trimesh.creation.box(extents=(4.0, 1.0, 1.0))
    glass = trimesh.creation.icosphere(radius=0.3)
    glass.apply_translation((1.0, 0.0, 0.5))
    scene = trimesh.Scene()
    scene.add_geometry(body, geom_name="fuselage")
    scene.add_geometry(glass, geom_name="canopy_glass")
    mesh = folder / "drogue.glb"
    scene.export(mesh)
    corner = [[2.0, 0.5, 0.5], [2.0, 0.3, 0.5], [1.8, 0.5, 0.5], [2.0, 0.5, 0.3]]
    if features is None:
        features = [
            {"class_id": 0, "name": "nose_corner", "object": "drogue", "size": "small", "points_m": corner},
            {"class_id": 1, "name": "tail_face", "object": "drogue", "points_m":
                [[-2.0, 0.4, 0.4], [-2.0, -0.4, 0.4], [-2.0, -0.4, -0.4], [-2.0, 0.4, -0.4]],
             "center_m": [-2.0, 0.0, 0.0], "internal": False},
        ]
    doc = {"format": "datagen.features/1", "object": "drogue", "variants": {"baseline": features}}
    path = folder / "drogue-features.json"
    path.write_text(json.dumps(doc, indent=1))
    return mesh, path


def user_config(folder: Path, mesh: Path, features: Path) -> Path:
    config = folder / "user.yaml"
    config.write_text(
        "name: user\ncamera: {mount: podcam, hfov_deg: 25}\ndataset: {frames: 4, seed: 3}\n"
        "features: {objects: [receiver, drogue]}\n"
        f"objects: {{drogue: {{mesh: {mesh.name}, features: {features.name}}}}}\n"
    )
    return config


def test_a_config_can_use_a_users_mesh_and_features(tmp_path: Path) -> None:
    mesh_path, features_path = write_user_assets(tmp_path)
    config = load_config(user_config(tmp_path, mesh_path, features_path))
    table = feature_table(config)
    assert len(table) == 42
    assert table.name[40:] == ("drogue.nose_corner", "drogue.tail_face")
    np.testing.assert_allclose(table.center_model[41], [-2.0, 0.0, 0.0])
    np.testing.assert_allclose(table.center_model[40], np.mean([[2.0, 0.5, 0.5], [2.0, 0.3, 0.5],
                                                                [1.8, 0.5, 0.5], [2.0, 0.5, 0.3]], axis=0))
    mesh = load_mesh(mesh_path, "drogue")
    assert len(mesh.parts) == 2 and "paint" != material_class(next(p for p in mesh.parts if "glass" in p))
    random = load_object_features("drogue", "random", mesh_path=mesh_path, features_path=features_path,
                                  seed=1, random_count=5)
    assert len(random) == 5
    assert max(surface_distance(mesh.combined, f.points_m).max() for f in random) < 0.01


BAD_FEATURES = {
    "unknown object": (
        lambda f: f[0].update(object="boom"), "variants.baseline[0].object", "unknown object"),
    "another object": (
        lambda f: f[0].update(object="tanker"), "variants.baseline[0].object", "feature file of 'drogue'"),
    "duplicate class id": (
        lambda f: f[1].update(class_id=0), "variants.baseline[1].class_id", "duplicate class id"),
    "too few points": (
        lambda f: f[0].update(points_m=[[0, 0, 0], [1, 0, 0]]), "variants.baseline[0].points_m",
        "at least 3 points"),
    "centre outside the hull": (
        lambda f: f[1].update(center_m=[-2.5, 0, 0]), "variants.baseline[1].center_m",
        "outside the convex hull"),
    "class ids with a gap": (
        lambda f: f[1].update(class_id=5), "variants.baseline", "class ids must run 0..1"),
    "missing points": (lambda f: f[0].pop("points_m"), "variants.baseline[0].points_m", "required key"),
    "bad size": (lambda f: f[0].update(size="huge"), "variants.baseline[0].size", "must be one of"),
}


@pytest.mark.parametrize("case", BAD_FEATURES, ids=str)
def test_bad_feature_files_get_one_line_naming_file_and_key(tmp_path: Path, case: str) -> None:
    mutate, key, message = BAD_FEATURES[case]
    _, features_path = write_user_assets(tmp_path)
    doc = json.loads(features_path.read_text())
    mutate(doc["variants"]["baseline"])
    features_path.write_text(json.dumps(doc))
    with pytest.raises(ConfigError) as err:
        load_features(features_path, "drogue", "baseline")
    lines = err.value.lines()
    assert len(lines) == 1, lines
    assert lines[0].startswith(f"{features_path}: {key}:") and message in lines[0], lines[0]


def test_bad_json_and_missing_variant_are_named(tmp_path: Path) -> None:
    _, features_path = write_user_assets(tmp_path)
    with pytest.raises(ConfigError, match=r"drogue-features.json: variants.large: variant 'large' not in"):
        load_features(features_path, "drogue", "large")
    features_path.write_text('{"format": "datagen.features/1",\n "variants": {,}}')
    with pytest.raises(ConfigError, match=r"drogue-features.json:2: invalid JSON"):
        load_features(features_path, "drogue", "baseline")


def test_obj_parts_come_from_its_materials(tmp_path: Path) -> None:
    (tmp_path / "m.mtl").write_text("newmtl paint\nKd 0.5 0.5 0.5\nnewmtl canopy_glass\nKd 0 0 0\n")
    obj = tmp_path / "m.obj"
    obj.write_text("mtllib m.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\n"
                   "usemtl paint\nf 1 2 3\nusemtl canopy_glass\nf 1 2 4\n")
    mesh = load_mesh(obj, "drogue")
    assert sorted(mesh.parts) == ["canopy_glass", "paint"]
    assert material_class("canopy_glass") == "glass"


def test_bad_meshes_are_named(tmp_path: Path) -> None:
    garbage = tmp_path / "broken.glb"
    garbage.write_bytes(b"not a mesh at all")
    with pytest.raises(ConfigError, match=r"broken.glb: cannot read mesh"):
        load_mesh(garbage, "drogue")
    with pytest.raises(ConfigError, match=r"model.fbx: unsupported mesh format '.fbx'"):
        (tmp_path / "model.fbx").write_text("x")
        load_mesh(tmp_path / "model.fbx", "drogue")
    empty = tmp_path / "empty.obj"
    empty.write_text("# nothing\nv 0 0 0\n")
    with pytest.raises(ConfigError, match=r"empty.obj: mesh contains no triangles"):
        load_mesh(empty, "drogue")


def test_every_material_class_has_a_preview_colour() -> None:
    from datagen.assets.models import MATERIAL_CLASSES
    from datagen.render.views import _COLORS

    assert set(MATERIAL_CLASSES.values()) <= set(_COLORS)
