"""The metadata files of a dataset, written by every run: ``dataset.json`` (when the dataset
is new), ``data.yaml`` and ``hyp.yaml`` (for the detect and the pose set), ``features.parquet``
and ``objects.parquet``."""

from __future__ import annotations

import json
import os

from datagen.atomic import symlink_folder, write_text
from datagen.core.errors import DatagenError
from datagen.dataset.columns import write_features, write_objects
from datagen.dataset.layout import POSE_IMAGES_LINK, Layout, ShardJob
from datagen.pipeline.dataset_document import dataset_document
from datagen.pipeline.training_yaml import data_yaml, hyp_yaml, pose_hyp_yaml
from datagen.scene.resolved import Scene

__all__ = [
    "write_dataset_files",
]


def write_dataset_files(layout: Layout, scene: Scene, jobs: list[ShardJob], fingerprint: str, *, describe: bool,
                        render: bool = True) -> None:
    """dataset.json (when ``describe``: a new dataset), then data.yaml, hyp.yaml and
    features.parquet, each atomically. dataset.json comes first so that a folder
    with any datagen file in it is recognisable as a dataset; the other three are
    pure functions of the scene and are rewritten by every run."""
    names = list(scene.features.name)
    root = layout.root
    if describe:
        write_text(layout.dataset_json,
                   json.dumps(dataset_document(scene, jobs, fingerprint, render=render), indent=2) + "\n")
    splits = tuple(sorted({job.split for job in jobs}))
    imgsz = scene.config.labels.train_imgsz
    if layout.detect:
        write_text(root / "data.yaml", data_yaml(root, names, splits, imgsz=imgsz))
        write_text(root / "hyp.yaml", hyp_yaml(scene, root, splits))
    if layout.pose:
        pose_root = layout.pose_root
        if pose_root != root:
            link, target = root / POSE_IMAGES_LINK[0], POSE_IMAGES_LINK[1]
            if link.is_symlink() and os.readlink(link) == target:
                pass
            elif link.exists() or link.is_symlink():
                raise DatagenError(f"{link}: exists and is not datagen's link to {target} (the pose set reaches the "
                                   "images through it); move it away or choose another --out")
            else:
                symlink_folder(link, target)
        write_text(pose_root / "data.yaml", data_yaml(pose_root, list(scene.features.objects), splits, imgsz=imgsz,
                                                      pose=scene.pose_layout, dataset=root))
        write_text(pose_root / "hyp.yaml", pose_hyp_yaml(scene, pose_root, root, splits))
    write_features(root / "features.parquet", scene.features)
    write_objects(root / "objects.parquet", scene.features.objects, scene.hulls)
