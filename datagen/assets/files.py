"""Meshes and feature files: the built-in assets, a user's own, and their validation.

Files
    ``assets/meshes/{object}.glb``: one GLB per object in its body frame
    (metres), one named geometry per part (``paint``, ``glass``, ``metal``...).
    A user may give any OBJ, PLY or GLB instead; its geometry names become part
    names.

    ``assets/features/{object}.json``: the object's feature sets, format
    ``datagen.features/1``::

        {"format": "datagen.features/1", "object": "receiver", "small_radius_m": 0.06,
         "variants": {"baseline": [FEATURE, ...], "small": [...], ...}}

    where each FEATURE is ``{"class_id", "name", "object", "size", "internal",
    "center_m", "points_m"}``: class ids count 0..n-1 within a variant,
    ``points_m`` is the feature's 3D point set (at least 3 points, model frame,
    metres), ``center_m`` its true centre (optional: default the centroid;
    it must lie inside the points' convex hull), ``size`` one of small, medium,
    large, and ``internal`` marks a centre that is not on the surface (a ring
    centre). A dataset's class ids follow ``features.objects``: the first
    object's features, then the next object's, and so on.

:func:`build_assets` regenerates the built-in files from :mod:`datagen.assets.models`
byte for byte; the committed files are exactly its output.
"""

from __future__ import annotations

import functools
import json
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Final

import numpy as np
import trimesh
from numpy.typing import NDArray
from scipy.optimize import nnls

from datagen.core.conventions import random_features_rng
from datagen.core.errors import ConfigError, Problem
from datagen.core.features import FeatureTable
from datagen.dataset.files import atomic_path
from datagen.config.inputs import parse_json, read_text
from datagen.assets.models import SIZE_SCALE, FeatureAnchor, Model
from datagen.assets.models.drogue import build_drogue
from datagen.assets.models.receiver import build_receiver
from datagen.assets.models.tanker import build_tanker

if TYPE_CHECKING:
    from datagen.config.schema import Config

__all__ = [
    "BUILTIN_DIR",
    "FEATURE_FORMAT",
    "RIGID_OBJECTS",
    "STORED_VARIANTS",
    "Feature",
    "ObjectMesh",
    "build_assets",
    "check_assets",
    "builtin_paths",
    "feature_table",
    "load_features",
    "load_mesh",
    "load_object_features",
    "object_features",
    "random_features",
]

#: The built-in assets, beside the package in the source tree.
BUILTIN_DIR: Final = Path(__file__).resolve().parents[2] / "assets"
FEATURE_FORMAT: Final = "datagen.features/1"
#: Objects with a mesh and feature file (the hose is made per frame).
RIGID_OBJECTS: Final = ("tanker", "receiver", "drogue")
#: Variants stored in feature files; "random" (paper model I) is generated from the mesh.
STORED_VARIANTS: Final = ("baseline", "small", "medium", "large")
SIZES: Final = tuple(SIZE_SCALE)
#: A centre may lie this far outside its points' convex hull (rounding), metres.
HULL_TOLERANCE_M: Final = 1e-4
#: Most points a feature may have, and most features a variant may list.
MAX_FEATURE_POINTS: Final = 1024
MAX_FEATURES: Final = 1000
#: Longest feature name, characters.
MAX_NAME_CHARS: Final = 100
#: A point set is degenerate (cannot make a box in every view) when its second-largest
#: spread is below this share of its largest: coincident or collinear points.
DEGENERATE_SPREAD: Final = 1e-6
#: Largest mesh file read, bytes.
MAX_MESH_BYTES: Final = 1 << 30
#: Points of a feature ring (besides the snapped anchor).
RING_POINTS: Final = 8
#: Coordinates in feature files are rounded to micrometres.
COORD_DECIMALS: Final = 6
MESH_SUFFIXES: Final = (".glb", ".gltf", ".obj", ".ply", ".stl", ".off")

_BUILDERS: Final = {"tanker": build_tanker, "receiver": build_receiver, "drogue": build_drogue}


@dataclass(frozen=True, eq=False)
class Feature:
    """One feature of one object, as read from a feature file (``class_id`` local to it)."""

    class_id: int
    name: str
    object: str
    points_m: NDArray[np.float64]
    center_m: NDArray[np.float64]
    size: str
    internal: bool = False


@dataclass(frozen=True, eq=False)
class ObjectMesh:
    """An object's mesh: triangles by part name, in its body frame."""

    name: str
    path: Path
    parts: dict[str, trimesh.Trimesh]

    @functools.cached_property
    def combined(self) -> trimesh.Trimesh:
        return trimesh.util.concatenate(list(self.parts.values()))


def builtin_paths(object_name: str, root: Path = BUILTIN_DIR) -> tuple[Path, Path]:
    """(mesh, feature file) of a built-in object."""
    return root / "meshes" / f"{object_name}.glb", root / "features" / f"{object_name}.json"


# --- meshes ---------------------------------------------------------------------------
def load_mesh(path: Path, object_name: str) -> ObjectMesh:
    """Read a mesh file into parts; raises :class:`ConfigError` naming the file on bad input."""
    path = Path(path)

    def fail(message: str) -> ConfigError:
        return ConfigError([Problem(path, "", message)])

    if not path.is_file():
        raise fail("mesh file not found")
    if path.suffix.lower() not in MESH_SUFFIXES:
        raise fail(f"unsupported mesh format {path.suffix!r} (use OBJ, PLY or GLB)")
    try:
        size = path.stat().st_size
    except OSError as exc:
        raise fail(f"cannot read mesh: {exc.strerror}") from None
    if size > MAX_MESH_BYTES:
        raise fail(f"{size:,} bytes: larger than the {MAX_MESH_BYTES:,} bytes a mesh file may have")
    try:
        scene = trimesh.load(path, force="scene", process=False)
    except Exception as exc:  # trimesh raises many kinds on a malformed file
        raise fail(f"cannot read mesh: {exc}") from None
    parts: dict[str, list[trimesh.Trimesh]] = {}
    for node in scene.graph.nodes_geometry:
        transform, geometry_name = scene.graph[node]
        geometry = scene.geometry[geometry_name]
        if not isinstance(geometry, trimesh.Trimesh) or len(geometry.faces) == 0:
            continue
        mesh = geometry.copy()
        mesh.apply_transform(transform)
        parts.setdefault(str(geometry_name), []).append(mesh)
    if not parts:
        raise fail("mesh contains no triangles")
    merged = {name: trimesh.util.concatenate(meshes) for name, meshes in sorted(parts.items())}
    for name, mesh in merged.items():
        if not np.isfinite(mesh.vertices).all():
            raise fail(f"part {name!r} has non-finite vertex coordinates")
    return ObjectMesh(object_name, path, merged)


# --- feature files --------------------------------------------------------------------
def load_features(path: Path, object_name: str, variant: str) -> list[Feature]:
    """Read and validate one variant of an object's feature file.

    Every problem found is reported, one line each, naming the file and the key.
    """
    path = Path(path)
    data = _read_json(path)
    problems: list[Problem] = []

    def problem(key: str, message: str, value: object = None, has_value: bool = False) -> None:
        problems.append(Problem(path, key, message, value=value, has_value=has_value))

    if not isinstance(data, dict):
        raise ConfigError([Problem(path, "", "expected a JSON object at the top level")])
    if data.get("format") != FEATURE_FORMAT:
        problem("format", f"expected {FEATURE_FORMAT!r}", data.get("format"), "format" in data)
    variants = data.get("variants")
    if not isinstance(variants, dict):
        raise ConfigError([*problems, Problem(path, "variants", "required mapping of variant name to features")])
    if variant not in variants:
        have = ", ".join(sorted(variants)) or "none"
        raise ConfigError([*problems, Problem(path, f"variants.{variant}",
                                              f"variant {variant!r} not in this file (it has: {have})")])
    records = variants[variant]
    if not isinstance(records, list) or not records:
        raise ConfigError([*problems, Problem(path, f"variants.{variant}", "expected a non-empty list of features")])
    if len(records) > MAX_FEATURES:
        raise ConfigError([*problems, Problem(path, f"variants.{variant}",
                                              f"{len(records)} features; a variant may have at most {MAX_FEATURES}")])
    features = []
    seen_ids: dict[int, int] = {}
    seen_names: dict[str, int] = {}
    for i, record in enumerate(records):
        key = f"variants.{variant}[{i}]"
        feature = _parse_feature(record, key, object_name, problem)
        if feature is None:
            continue
        if feature.class_id in seen_ids:
            problem(f"{key}.class_id", f"duplicate class id (also at [{seen_ids[feature.class_id]}])",
                    feature.class_id, True)
        seen_ids.setdefault(feature.class_id, i)
        if feature.name in seen_names:
            problem(f"{key}.name", f"duplicate feature name (also at [{seen_names[feature.name]}])", feature.name, True)
        seen_names.setdefault(feature.name, i)
        features.append(feature)
    if not problems:
        missing = sorted(set(range(len(records))) - set(seen_ids))
        if missing:
            problem(f"variants.{variant}", f"class ids must run 0..{len(records) - 1}; missing {missing[:5]}")
    if problems:
        raise ConfigError(problems)
    return sorted(features, key=lambda f: f.class_id)


def _read_json(path: Path) -> object:
    return parse_json(read_text(path, "feature file"), path)


def _parse_feature(record: object, key: str, object_name: str, problem) -> Feature | None:
    if not isinstance(record, dict):
        problem(key, "expected a feature mapping")
        return None
    allowed = {"class_id", "name", "object", "points_m", "center_m", "size", "internal"}
    for extra in sorted(set(record) - allowed):
        problem(f"{key}.{extra}", f"unknown key (allowed: {', '.join(sorted(allowed))})")
    ok = True
    for required in ("class_id", "name", "object", "points_m"):
        if required not in record:
            problem(f"{key}.{required}", "required key is missing")
            ok = False
    if not ok:
        return None
    class_id, name, obj = record["class_id"], record["name"], record["object"]
    if not isinstance(class_id, int) or isinstance(class_id, bool) or class_id < 0:
        problem(f"{key}.class_id", "must be a non-negative integer", class_id, True)
        ok = False
    if not isinstance(name, str) or not name or len(name) > MAX_NAME_CHARS or not name.isprintable():
        problem(f"{key}.name", f"must be a non-empty printable string of at most {MAX_NAME_CHARS} characters",
                name, True)
        ok = False
    if obj not in RIGID_OBJECTS:
        problem(f"{key}.object", f"unknown object (known: {', '.join(RIGID_OBJECTS)})", obj, True)
        ok = False
    elif obj != object_name:
        problem(f"{key}.object", f"feature of {obj!r} in the feature file of {object_name!r}", obj, True)
        ok = False
    size = record.get("size", "medium")
    if size not in SIZES:
        problem(f"{key}.size", f"must be one of {', '.join(SIZES)}", size, True)
        ok = False
    internal = record.get("internal", False)
    if not isinstance(internal, bool):
        problem(f"{key}.internal", "must be true or false", internal, True)
        ok = False
    points = _coords(record["points_m"], f"{key}.points_m", problem, rows=True)
    if points is not None and len(points) < 3:
        problem(f"{key}.points_m", f"a point set needs at least 3 points, got {len(points)}")
        points = None
    elif points is not None and len(points) > MAX_FEATURE_POINTS:
        problem(f"{key}.points_m", f"{len(points)} points; a feature may have at most {MAX_FEATURE_POINTS}")
        points = None
    elif points is not None and (degenerate := _degenerate(points)):
        problem(f"{key}.points_m", f"{degenerate}: a feature needs points that span an area, or its box can "
                "have no width or height")
        points = None
    center = None
    if record.get("center_m") is not None:
        center = _coords(record["center_m"], f"{key}.center_m", problem, rows=False)
    if points is None or (record.get("center_m") is not None and center is None) or not ok:
        return None
    if center is None:
        center = points.mean(axis=0)
    else:
        gap = hull_distance(points, center)
        if gap > HULL_TOLERANCE_M:
            problem(f"{key}.center_m", f"centre lies {gap:.4g} m outside the convex hull of points_m",
                    record["center_m"], True)
            return None
    return Feature(class_id, name, obj, points, center, size, internal)


def _coords(value: object, key: str, problem, *, rows: bool) -> NDArray[np.float64] | None:
    """``[[x, y, z], ...]`` (rows) or ``[x, y, z]`` as a finite float array, else a problem."""
    shape = "a list of [x, y, z] points" if rows else "[x, y, z]"
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        arr = None
    good = arr is not None and (arr.ndim == 2 and arr.shape[1] == 3 if rows else arr.shape == (3,))
    if not good or isinstance(value, str):
        problem(key, f"must be {shape}", value, True)
        return None
    if not np.isfinite(arr).all():
        problem(key, "coordinates must be finite numbers", value, True)
        return None
    return arr


def _degenerate(points: NDArray[np.float64]) -> str | None:
    """Why a point set cannot make a box in every view, or None: all its points coincide,
    or they lie on one line (the spreads of the centred points, largest first)."""
    spread = np.linalg.svd(points - points.mean(axis=0), compute_uv=False)
    if spread[0] <= 1e-9:
        return "all points coincide"
    if spread[1] <= DEGENERATE_SPREAD * spread[0]:
        return "the points lie on one line"
    return None


def hull_distance(points: NDArray[np.float64], center: NDArray[np.float64]) -> float:
    """Distance from ``center`` to the convex hull of ``points`` (0 inside), robust to
    flat or collinear point sets: the nearest convex combination by non-negative
    least squares with the sum-to-one row weighted heavily."""
    both = np.vstack([points, center])
    origin = both.mean(axis=0)
    scale = max(float(np.ptp(both, axis=0).max()), 1e-12)
    weight = 1e3
    a = np.vstack([(points - origin).T / scale, np.full(len(points), weight)])
    b = np.concatenate([(center - origin) / scale, [weight]])
    w, _ = nnls(a, b, maxiter=50 * len(points))
    if w.sum() <= 0:
        return float(np.linalg.norm(points - center, axis=1).min())
    w = w / w.sum()
    return float(np.linalg.norm(points.T @ w - center))


# --- generating features from a mesh -------------------------------------------------
def ring_points(surface: trimesh.Trimesh, anchor: NDArray[np.float64], radius: float,
                n: int = RING_POINTS) -> NDArray[np.float64]:
    """The anchor snapped to the surface, then ``n`` surface points around it: a ring
    of ``radius`` in the tangent plane, each point snapped to the surface."""
    snapped, _, tri = trimesh.proximity.closest_point(surface, anchor[None])
    normal = surface.face_normals[tri[0]]
    helper = np.array([0.0, 0.0, 1.0]) if abs(normal[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    e1 = np.cross(normal, helper)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(normal, e1)
    t = np.linspace(0.0, 2 * np.pi, n, endpoint=False)
    ring = snapped[0] + radius * (np.outer(np.cos(t), e1) + np.outer(np.sin(t), e2))
    ring_snapped, _, _ = trimesh.proximity.closest_point(surface, ring)
    return np.concatenate([snapped, ring_snapped])


def _anchor_feature(surface: trimesh.Trimesh, anchor: FeatureAnchor, radius: float, size: str,
                    class_id: int, object_name: str) -> Feature:
    points = ring_points(surface, np.asarray(anchor.anchor_m), radius)
    return Feature(class_id, anchor.name, object_name, points, points[0].copy(), size)


def random_features(mesh: ObjectMesh, count: int, rng: np.random.Generator,
                    radius: float) -> list[Feature]:
    """``count`` features centred on random surface points (paper model I): area-
    weighted over the outer parts, kept at least two ring diameters apart where
    the surface allows, each with a ring of ``radius``."""
    outer = [m for name, m in mesh.parts.items() if "inlet" not in name and "exhaust" not in name]
    surface = trimesh.util.concatenate(outer or list(mesh.parts.values()))
    areas = surface.area_faces
    candidates = 30 * count
    tri = rng.choice(len(areas), size=candidates, p=areas / areas.sum())
    uv = rng.random((candidates, 2))
    flip = uv.sum(axis=1) > 1
    uv[flip] = 1 - uv[flip]
    corners = surface.triangles[tri]
    samples = corners[:, 0] + uv[:, :1] * (corners[:, 1] - corners[:, 0]) + uv[:, 1:] * (corners[:, 2] - corners[:, 0])
    chosen: list[NDArray[np.float64]] = []
    spacing = 4 * radius
    for p in samples:
        if all(np.linalg.norm(p - q) >= spacing for q in chosen):
            chosen.append(p)
            if len(chosen) == count:
                break
    for p in samples:  # a small mesh may not fit them all apart: fill up regardless
        if len(chosen) == count:
            break
        if not any(p is q for q in chosen):
            chosen.append(p)
    return [
        _anchor_feature(surface, FeatureAnchor.at(f"random_{i:03d}", p), radius, "medium", i, mesh.name)
        for i, p in enumerate(chosen)
    ]


def model_features(model: Model, variant: str) -> list[Feature]:
    """A built-in model's features for one stored variant: the baseline keeps each
    anchor's own size; small, medium and large give every anchor that size,
    co-located (same centres). Internal features keep their own point sets."""
    surface = model.combined()
    features = []
    for anchor in model.anchors:
        size = anchor.size if variant == "baseline" else variant
        radius = model.small_radius_m * SIZE_SCALE[size]
        features.append(_anchor_feature(surface, anchor, radius, size, len(features), model.name))
    for internal in model.internal:
        features.append(Feature(len(features), internal.name, model.name, np.array(internal.points_m),
                                np.array(internal.center_m), internal.size, internal=True))
    return features


# --- the dataset's feature table ------------------------------------------------------
def object_paths(config: Config, object_name: str) -> tuple[Path, Path]:
    """(mesh, feature file) the config uses for an object: its own or the built-in."""
    spec = getattr(config.objects, object_name)
    mesh, features = builtin_paths(object_name)
    return spec.mesh or mesh, spec.features or features


def object_features(config: Config, object_name: str) -> list[Feature]:
    """One object's features under the config's variant, files and seed."""
    mesh_path, features_path = object_paths(config, object_name)
    return load_object_features(object_name, config.features.variant, mesh_path=mesh_path,
                                features_path=features_path, seed=config.dataset.seed,
                                random_count=config.features.random_per_object)


def load_object_features(object_name: str, variant: str, *, mesh_path: Path | None = None,
                         features_path: Path | None = None, seed: int = 0,
                         random_count: int = 40) -> list[Feature]:
    """One object's features: a stored variant from its feature file, or
    ``random_count`` random surface features of its mesh seeded by ``seed``.
    Paths default to the built-in assets."""
    builtin_mesh, builtin_features = builtin_paths(object_name)
    mesh_path, features_path = mesh_path or builtin_mesh, features_path or builtin_features
    if variant != "random":
        return load_features(features_path, object_name, variant)
    mesh = load_mesh(mesh_path, object_name)
    radius = _random_radius(features_path, mesh)
    features = random_features(mesh, random_count, random_features_rng(seed, object_name), radius)
    bad = [(f, why) for f in features if (why := _degenerate(f.points_m))]
    if bad:
        raise ConfigError([Problem(mesh_path, "", f"random feature {f.name}: {why} (the surface around it is too "
                                   "thin to hold a feature ring)") for f, why in bad[:3]])
    return features


def _random_radius(features_path: Path, mesh: ObjectMesh) -> float:
    """Ring radius of random features: the medium size of the feature file's
    ``small_radius_m`` when it gives one, else 1% of the mesh's diagonal."""
    if features_path.is_file():
        data = _read_json(features_path)
        small = data.get("small_radius_m") if isinstance(data, dict) else None
        if isinstance(small, (int, float)) and small > 0:
            return float(small) * SIZE_SCALE["medium"]
    return 0.01 * float(np.linalg.norm(mesh.combined.extents))


def feature_table(config: Config) -> FeatureTable:
    """Every labeled feature of the config, class ids in ``features.objects`` order.

    Names are qualified by object (``receiver.probe_tip``).
    """
    features = [f for obj in config.features.objects for f in object_features(config, obj)]
    return FeatureTable.from_point_sets(
        [f.points_m for f in features],
        objects=[f.object for f in features],
        names=[f"{f.object}.{f.name}" for f in features],
        centers=[f.center_m for f in features],
        sizes=[f.size for f in features],
    )


def check_assets(config: Config) -> FeatureTable:
    """Load every mesh and the labeled features a config uses; all problems are
    raised together. Returns the dataset's feature table."""
    problems: list[Problem] = []
    for name in RIGID_OBJECTS:
        try:
            load_mesh(object_paths(config, name)[0], name)
        except ConfigError as exc:
            problems += exc.problems
    try:
        table = feature_table(config)
    except ConfigError as exc:
        problems += exc.problems
    if problems:
        unique = {str(p): p for p in problems}  # a file shared by two objects is reported once
        raise ConfigError(list(unique.values()))
    return table


# --- building the built-in assets -----------------------------------------------------
def _round(values: NDArray[np.float64]) -> list:
    return np.round(values, COORD_DECIMALS).tolist()


def _feature_record(feature: Feature) -> dict:
    return {
        "class_id": feature.class_id,
        "name": feature.name,
        "object": feature.object,
        "size": feature.size,
        "internal": feature.internal,
        "center_m": _round(feature.center_m),
        "points_m": _round(feature.points_m),
    }


def features_document(model: Model) -> str:
    """The feature file of a built-in model: one feature per line, stable bytes."""
    lines = ["{", f'  "format": "{FEATURE_FORMAT}",', f'  "object": "{model.name}",',
             f'  "small_radius_m": {model.small_radius_m},', '  "variants": {']
    for v, variant in enumerate(STORED_VARIANTS):
        records = [json.dumps(_feature_record(f)) for f in model_features(model, variant)]
        lines.append(f'    "{variant}": [')
        lines.extend(f"      {r}{',' if i < len(records) - 1 else ''}" for i, r in enumerate(records))
        lines.append("    ]" + ("," if v < len(STORED_VARIANTS) - 1 else ""))
    lines += ["  }", "}", ""]
    return "\n".join(lines)


def mesh_document(model: Model) -> bytes:
    """The GLB of a built-in model: one named geometry and node per part."""
    scene = trimesh.Scene()
    for name, mesh in model.parts.items():
        scene.add_geometry(mesh, geom_name=name, node_name=name)
    return scene.export(file_type="glb")


def build_model(object_name: str) -> Model:
    return _BUILDERS[object_name]()


def build_assets(root: Path = BUILTIN_DIR, objects: Sequence[str] = RIGID_OBJECTS) -> list[Path]:
    """Regenerate the meshes and feature files of ``objects`` under ``root``; each
    file is written atomically. Returns the paths written."""
    written = []
    for name in objects:
        model = build_model(name)
        mesh_path, features_path = builtin_paths(name, root)
        for path, payload in ((mesh_path, mesh_document(model)),
                              (features_path, features_document(model).encode())):
            path.parent.mkdir(parents=True, exist_ok=True)
            with atomic_path(path) as tmp:
                tmp.write_bytes(payload)
            written.append(path)
    return written


def describe_features(features: Sequence[Feature]) -> str:
    """A fixed-width table of features: id, name, size, points, centre, spread."""
    header = f"{'id':>3}  {'name':<30} {'size':<6} {'pts':>3}  {'centre x, y, z (m)':<30} {'radius_m':>8}"
    rows = [header, "-" * len(header)]
    for f in features:
        radius = float(np.linalg.norm(f.points_m - f.center_m, axis=1).max())
        centre = ", ".join(f"{v:8.3f}" for v in f.center_m)
        mark = "*" if f.internal else ""
        rows.append(f"{f.class_id:>3}  {f.name + mark:<30} {f.size:<6} {len(f.points_m):>3}  {centre:<30} "
                    f"{radius:>8.3f}")
    if any(f.internal for f in features):
        rows.append("* internal: the centre is not on the surface")
    return "\n".join(rows)
