"""Meshes and feature files: reading and validating the built-in assets and a user's own.

Files (package data under :data:`BUILTIN_DIR`, found through ``importlib.resources``)
    ``meshes/{object}.glb``: one GLB per object in its body frame
    (metres), one named geometry per part (``paint``, ``glass``, ``metal``...).
    A user may give any OBJ, PLY or GLB instead: a GLB's geometry names, an OBJ's
    materials (``usemtl``) become part names, and a part's name gives its material
    class (:func:`datagen.assets.models.material_class`; anything unknown is paint).
    A mesh that names no parts (an OBJ without materials, a PLY, a GLB of unnamed
    meshes) is one painted part: :attr:`ObjectMesh.warnings` says so.

    ``features/{object}.json``: the object's feature sets, format
    ``datagen.features/1``::

        {"format": "datagen.features/1", "object": "receiver", "small_radius_m": 0.06,
         "variants": {"baseline": [FEATURE, ...], "small": [...], ...}}

    where each FEATURE is ``{"class_id", "name", "object", "size", "internal",
    "center_m", "points_m"}``: class ids count 0..n-1 within a variant,
    ``points_m`` is the feature's 3D point set (at least 3 points that span an
    area, model frame, metres), ``center_m`` its true centre (optional: default
    the centroid; it must lie inside the points' convex hull), ``size`` one of
    :data:`datagen.core.features.SIZE_SCALE`, and ``internal`` marks a centre that
    is not on the surface (a ring centre).

Every problem is reported as a :class:`~datagen.core.errors.Problem` naming the
file and the key; files are read with the bounds of :mod:`datagen.config.inputs`.
"""

from __future__ import annotations

import functools
import hashlib
import io
import re
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import TYPE_CHECKING, Final

import numpy as np
from numpy.typing import NDArray

from datagen.config.inputs import parse_json, read_text
from datagen.core.conventions import RIGID_OBJECTS
from datagen.core.errors import ConfigError, Problem
from datagen.core.features import MAX_NAME_CHARS, SIZE_SCALE, valid_name

if TYPE_CHECKING:  # trimesh takes most of a second to import: only where meshes are read
    import trimesh

__all__ = [
    "BUILTIN_DIR",
    "FEATURE_FORMAT",
    "MAX_FEATURES",
    "MAX_FEATURE_POINTS",
    "Feature",
    "ObjectMesh",
    "builtin_paths",
    "concatenated",
    "degenerate",
    "hull_distance",
    "load_features",
    "load_mesh",
    "parse_features",
    "read_feature_file",
]

#: The built-in meshes and feature files: package data of datagen.assets.
BUILTIN_DIR: Final = Path(str(resources.files("datagen.assets") / "builtin"))


FEATURE_FORMAT: Final = "datagen.features/1"


#: A centre may lie this far outside its points' convex hull (rounding), metres.
HULL_TOLERANCE_M: Final = 1e-4


#: Most points a feature may have, and most features a variant may list.
MAX_FEATURE_POINTS: Final = 1024


MAX_FEATURES: Final = 1000


#: A point set is degenerate (cannot make a box in every view) when its second-largest
#: spread is below this share of its largest: coincident or collinear points.
DEGENERATE_SPREAD: Final = 1e-6


#: Largest mesh file read, bytes.
MAX_MESH_BYTES: Final = 1 << 30


MESH_SUFFIXES: Final = (".glb", ".gltf", ".obj", ".ply", ".stl", ".off")


#: Formats that hold one unnamed mesh: no part names, no materials.
UNNAMED_SUFFIXES: Final = (".ply", ".stl", ".off")


#: The names trimesh gives a GLB's unnamed meshes.
_PLACEHOLDER_NAME: Final = re.compile(r"geometry(_\d+)?")


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
    sha256: str  # of the file's bytes, as read for the parts
    #: One line each, naming the file: what will not render as the file's author may
    #: expect (a mesh that names no parts is painted all over); nothing fails on them.
    warnings: tuple[str, ...] = ()

    @functools.cached_property
    def combined(self) -> trimesh.Trimesh:
        return concatenated(list(self.parts.values()))


def builtin_paths(object_name: str, root: Path = BUILTIN_DIR) -> tuple[Path, Path]:
    """(mesh, feature file) of a built-in object."""
    return root / "meshes" / f"{object_name}.glb", root / "features" / f"{object_name}.json"


# --- meshes ---------------------------------------------------------------------------
def load_mesh(path: Path, object_name: str) -> ObjectMesh:
    """Read a mesh file into parts; raises :class:`ConfigError` naming the file on bad input."""
    import trimesh

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
        data = path.read_bytes()
    except OSError as exc:
        raise fail(f"cannot read mesh: {exc.strerror}") from None
    try:
        scene = trimesh.load(io.BytesIO(data), file_type=path.suffix.lower()[1:], force="scene", process=False,
                             resolver=trimesh.resolvers.FilePathResolver(str(path.parent)))
    except Exception as exc:  # trimesh raises many kinds on a malformed file
        raise fail(f"cannot read mesh: {exc}") from None
    if not isinstance(scene, trimesh.Scene):
        raise fail(f"cannot read mesh: trimesh read a {type(scene).__name__}, not a scene")
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
    merged = {name: concatenated(meshes) for name, meshes in sorted(parts.items())}
    for name, mesh in merged.items():
        if not np.isfinite(mesh.vertices).all():
            raise fail(f"part {name!r} has non-finite vertex coordinates")
    why = _no_materials(path, data, merged)
    warnings = () if why is None else (
        f"{path}: warning: {why}: the whole mesh is painted with the livery (or the default paint), with no glass, "
        "metal or dark engine inlets; name each part for its material (glass, metal, engine_inlets...: an OBJ's "
        "usemtl names, a GLB's mesh names)",)
    return ObjectMesh(object_name, path, merged, hashlib.sha256(data).hexdigest(), warnings)


def concatenated(meshes: list[trimesh.Trimesh]) -> trimesh.Trimesh:
    """``meshes`` as one mesh."""
    import trimesh

    out = trimesh.util.concatenate(meshes)
    assert isinstance(out, trimesh.Trimesh)  # (of meshes: a mesh)
    return out


def _no_materials(path: Path, data: bytes, parts: dict[str, trimesh.Trimesh]) -> str | None:
    """Why a mesh file names none of its parts, or None: an OBJ without materials (trimesh
    then merges its objects and groups into one part), or whose materials did not reach its
    parts (its .mtl missing), a format without parts, a GLB whose meshes have no names."""
    suffix = path.suffix.lower()
    if suffix in UNNAMED_SUFFIXES:
        return f"{'an' if suffix in ('.stl', '.off') else 'a'} {suffix[1:].upper()} file has no materials or part names"
    if suffix == ".obj":
        named = [m.decode("utf-8", "replace").strip() for m in re.findall(rb"(?m)^[ \t]*usemtl[ \t]+([^\r\n]+)", data)]
        materials = {*named, *(m.split()[0] for m in named if m)}
        if not materials:
            return "no materials (no usemtl lines)"
        if not materials & set(parts):
            return "its materials did not reach its parts (is the .mtl file of its mtllib line beside it?)"
        return None
    if all(_PLACEHOLDER_NAME.fullmatch(name) for name in parts):
        return "its meshes have no names"
    return None


def mesh_hull(mesh: ObjectMesh) -> NDArray[np.float64]:
    """The vertices of the convex hull of an object's mesh, ``(H, 3)`` in its body frame: the
    points whose projection bounds the projected mesh (:mod:`datagen.core.keypoints`)."""
    combined = mesh.combined
    try:
        return np.asarray(combined.convex_hull.vertices, dtype=np.float64)
    except Exception:
        return np.unique(np.asarray(combined.vertices, dtype=np.float64), axis=0)


# --- feature files --------------------------------------------------------------------
def load_features(path: Path, object_name: str, variant: str) -> list[Feature]:
    """Read and validate one variant of an object's feature file.

    Every problem found is reported, one line each, naming the file and the key.
    """
    path = Path(path)
    return parse_features(read_feature_file(path), path, object_name, variant)


def parse_features(data: object, path: Path, object_name: str, variant: str) -> list[Feature]:
    """Validate one variant of a feature file's JSON ``data`` (problems name ``path``):
    what :func:`load_features` does once the file is read."""
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


def read_feature_file(path: Path) -> object:
    """The JSON data of a feature file (bounded: :mod:`datagen.config.inputs`)."""
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
    if not valid_name(name):
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
    if size not in SIZE_SCALE:
        problem(f"{key}.size", f"must be one of {', '.join(SIZE_SCALE)}", size, True)
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
    elif points is not None and (why := degenerate(points)):
        problem(f"{key}.points_m", f"{why}: a feature needs points that span an area, or its box can "
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
    assert arr is not None  # (good)
    if not np.isfinite(arr).all():
        problem(key, "coordinates must be finite numbers", value, True)
        return None
    return arr


def degenerate(points: NDArray[np.float64]) -> str | None:
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
    from scipy.optimize import nnls

    w, _ = nnls(a, b, maxiter=50 * len(points))
    if w.sum() <= 0:
        return float(np.linalg.norm(points - center, axis=1).min())
    w = w / w.sum()
    return float(np.linalg.norm(points.T @ w - center))
