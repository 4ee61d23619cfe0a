"""A config resolved once into everything the stages of a build need.

:meth:`Scene.resolve` checks the assets a config names and derives, in one place,
the feature table, the camera intrinsics, the label rules at the training size,
the asset files with their SHA-256, the labeled objects' convex hulls (their pose
boxes, :mod:`datagen.core.keypoints`) and the image format. Every stage (labels,
rendering, the dataset writer, the executors' workers) receives this frozen
object; none derives any of it again.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass
from pathlib import Path

from datagen.assets.loader import mesh_hull
from datagen.assets.table import check_assets, object_paths
from datagen.config.schema import Config
from datagen.core.camera import Intrinsics
from datagen.core.conventions import RIGID_OBJECTS
from datagen.core.labelling_context import Labelled, LabellingContext

__all__ = ["Scene"]


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


@dataclass(frozen=True, eq=False)
class Scene(Labelled):
    """A config and what it resolves to (frozen; pickles to worker processes)."""

    config: Config
    labelling: LabellingContext  # features, intrinsics, hulls and label rules: what labels a frame
    assets: dict[str, dict[str, str]]  # object -> mesh, mesh_sha256, features, features_sha256

    @classmethod
    def resolve(cls, config: Config) -> Scene:
        """Load and check every mesh and feature file ``config`` uses (all problems at once,
        :class:`~datagen.core.errors.ConfigError`) and derive the rest."""
        features, meshes = check_assets(config)
        cam = config.camera
        assets = {}
        for name in RIGID_OBJECTS:
            mesh, feature_file = object_paths(config, name)
            assets[name] = {"mesh": str(mesh), "mesh_sha256": meshes[name].sha256,
                            "features": str(feature_file), "features_sha256": _sha256(feature_file)}
        hulls = {name: mesh_hull(meshes[name]) for name in features.objects}
        labelling = LabellingContext(features, Intrinsics.from_hfov_deg(cam.width, cam.height, cam.hfov_deg), hulls,
                                     config.labels.rules())
        return cls(config=config, labelling=labelling, assets=assets)

    @property
    def name(self) -> str:
        return self.config.name

    @property
    def image_suffix(self) -> str:
        return self.config.render.image_suffix

    def mesh_path(self, name: str) -> Path:
        """The mesh file of object ``name``."""
        return Path(self.assets[name]["mesh"])
