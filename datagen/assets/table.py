"""A config's objects: which mesh and feature file each uses, and the dataset's feature table.

A dataset's class ids follow ``features.objects``: the first object's features,
then the next object's; names are qualified by object (``receiver.probe_tip``).
"""

from __future__ import annotations

import sys
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from datagen.assets.loader import (
    Feature,
    ObjectMesh,
    builtin_paths,
    degenerate,
    load_features,
    load_mesh,
    read_feature_file,
)
from datagen.core.conventions import RIGID_OBJECTS, random_features_rng
from datagen.core.errors import ConfigError, Problem
from datagen.core.features import SIZE_SCALE, FeatureTable

if TYPE_CHECKING:
    from datagen.config import Config

__all__ = [
    "check_assets",
    "describe_features",
    "feature_table",
    "load_object_features",
    "object_features",
    "object_paths",
]

# --- the dataset's feature table ------------------------------------------------------
def object_paths(config: Config, object_name: str) -> tuple[Path, Path]:
    """(mesh, feature file) the config uses for an object: its own or the built-in."""
    spec = getattr(config.objects, object_name)
    mesh, features = builtin_paths(object_name)
    return spec.mesh or mesh, spec.features or features


def object_features(config: Config, object_name: str, mesh: ObjectMesh | None = None) -> list[Feature]:
    """One object's features under the config's variant, files and seed (``mesh``: the
    object's mesh where it is already loaded)."""
    mesh_path, features_path = object_paths(config, object_name)
    return load_object_features(object_name, config.features.variant, mesh_path=mesh_path,
                                features_path=features_path, seed=config.dataset.seed,
                                random_count=config.features.random_per_object, mesh=mesh)


def load_object_features(object_name: str, variant: str, *, mesh_path: Path | None = None,
                         features_path: Path | None = None, seed: int = 0,
                         random_count: int = 40, mesh: ObjectMesh | None = None) -> list[Feature]:
    """One object's features: a stored variant from its feature file, or
    ``random_count`` random surface features of its mesh (``mesh``, or read from
    ``mesh_path``) seeded by ``seed``. Paths default to the built-in assets."""
    builtin_mesh, builtin_features = builtin_paths(object_name)
    mesh_path, features_path = mesh_path or builtin_mesh, features_path or builtin_features
    if variant != "random":
        return load_features(features_path, object_name, variant)
    mesh = mesh or load_mesh(mesh_path, object_name)
    radius = _random_radius(features_path, mesh)
    from datagen.assets.generate import random_features  # trimesh: only when random features are asked for

    features = random_features(mesh, random_count, random_features_rng(seed, object_name), radius)
    bad = [(f, why) for f in features if (why := degenerate(f.points_m))]
    if bad:
        raise ConfigError([Problem(mesh_path, "", f"random feature {f.name}: {why} (the surface around it is too "
                                   "thin to hold a feature ring)") for f, why in bad[:3]])
    return features


def _random_radius(features_path: Path, mesh: ObjectMesh) -> float:
    """Ring radius of random features: the medium size of the feature file's
    ``small_radius_m`` when it gives one, else 1% of the mesh's diagonal."""
    if features_path.is_file():
        data = read_feature_file(features_path)
        small = data.get("small_radius_m") if isinstance(data, dict) else None
        if isinstance(small, (int, float)) and small > 0:
            return float(small) * SIZE_SCALE["medium"]
    return 0.01 * float(np.linalg.norm(mesh.combined.extents))


def feature_table(config: Config, meshes: Mapping[str, ObjectMesh] | None = None) -> FeatureTable:
    """Every labeled feature of the config, class ids in ``features.objects`` order (``meshes``:
    the objects' meshes where they are already loaded).

    Names are qualified by object (``receiver.probe_tip``).
    """
    meshes = meshes or {}
    features = [f for obj in config.features.objects for f in object_features(config, obj, meshes.get(obj))]
    return FeatureTable.from_point_sets(
        [f.points_m for f in features],
        objects=[f.object for f in features],
        names=[f"{f.object}.{f.name}" for f in features],
        centers=[f.center_m for f in features],
        sizes=[f.size for f in features],
    )


def check_assets(config: Config) -> tuple[FeatureTable, dict[str, ObjectMesh]]:
    """Load every mesh and the labeled features a config uses (each file read once); all
    problems are raised together. Returns the dataset's feature table and the meshes.

    A mesh's warnings (:attr:`ObjectMesh.warnings`: a mesh that names no parts is painted
    all over) go to stderr, one line each, once per file: ``datagen validate`` and
    ``datagen build`` say them without failing."""
    problems: list[Problem] = []
    meshes: dict[str, ObjectMesh] = {}
    for name in RIGID_OBJECTS:
        try:
            meshes[name] = load_mesh(object_paths(config, name)[0], name)
        except ConfigError as exc:
            problems += exc.problems
    for line in dict.fromkeys(line for mesh in meshes.values() for line in mesh.warnings):
        print(line, file=sys.stderr, flush=True)
    try:
        table = feature_table(config, meshes)
    except ConfigError as exc:
        problems += exc.problems
    if problems:
        unique = {str(p): p for p in problems}  # a file shared by two objects is reported once
        raise ConfigError(list(unique.values()))
    return table, meshes


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
