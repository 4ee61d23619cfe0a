"""What a dataset is: the content of ``dataset.json`` (written once, when a dataset is new)
and the fingerprint that decides whether a rerun resumes the same dataset."""

from __future__ import annotations

import contextlib
import hashlib
import json
import platform
from importlib import metadata
from typing import Final

from datagen.core.conventions import OBJECT_NAMES, PIXEL_CONVENTION
from datagen.dataset.columns import MANIFEST_VERSION
from datagen.dataset.layout import SPLITS, ShardJob
from datagen.scene.resolved import Scene

__all__ = [
    "DATASET_SCHEMA",
    "DATASET_SCHEMA_VERSION",
    "config_fingerprint",
    "dataset_document",
]


DATASET_SCHEMA: Final = "datagen.dataset"


#: Version of dataset.json's layout (bumped on any incompatible change).
DATASET_SCHEMA_VERSION: Final = 1


def config_fingerprint(scene: Scene, *, render: bool = True) -> str:
    """SHA-256 of everything that decides a dataset's content: the resolved config,
    the bytes of every asset file and whether images are rendered."""
    doc = {
        "config": scene.config.model_dump(mode="json"),
        "render": render,
        "assets": {name: [a["mesh_sha256"], a["features_sha256"]] for name, a in scene.assets.items()},
    }
    return hashlib.sha256(json.dumps(doc, sort_keys=True).encode()).hexdigest()


def _versions() -> dict[str, str]:
    out = {"python": platform.python_version()}
    for dist in ("datagen", "mitsuba", "drjit", "mitsuba-oidn", "numpy", "pyarrow", "trimesh",
                 "opencv-python-headless"):
        with contextlib.suppress(metadata.PackageNotFoundError):
            out[dist] = metadata.version(dist)
    return out


def _images(config) -> dict:
    """How the images were made: what a user needs to compare two datasets' pixels."""
    r = config.render
    return {"spp": r.spp, "max_depth": r.max_depth,
            "target_spp": r.target_spp, "target_window": r.target_window if r.target_spp else None,
            "denoise": r.denoise,
            "denoise_guides": r.denoise_guides if r.denoise != "off" else None,
            "denoise_quality": r.denoise_quality if r.denoise != "off" else None,
            "sea_model": config.randomization.sea.model, "format": r.image_format,
            "exr": "linear radiance x exposure (denoised when denoise is on), Z, object_id" if r.exr else None}


def dataset_document(scene: Scene, jobs: list[ShardJob], fingerprint: str, *, render: bool = True) -> dict:
    """The content of ``dataset.json``."""
    config, assets, k = scene.config, scene.assets, scene.intrinsics
    cam = config.camera
    class_names = list(scene.features.name)
    splits = {s: {"frames": sum(len(j.frames) for j in jobs if j.split == s),
                  "shards": sum(1 for j in jobs if j.split == s)} for s in SPLITS}
    objects = [{"id": i + 1, "name": name, "mesh": assets[name]["mesh"] if name in assets else None,
                "mesh_sha256": assets[name]["mesh_sha256"] if name in assets else None}
               for i, name in enumerate(OBJECT_NAMES)]
    return {
        "schema": DATASET_SCHEMA,
        "schema_version": DATASET_SCHEMA_VERSION,
        "manifest_version": MANIFEST_VERSION,
        "name": config.name,
        "fingerprint": fingerprint,
        "render": render,
        "images": _images(config) if render else None,
        "versions": _versions(),
        "image_width": cam.width,
        "image_height": cam.height,
        "intrinsics": {"fx": k.fx, "fy": k.fy, "cx": k.cx, "cy": k.cy},
        "edge_margin_px": config.labels.edge_margin_px,
        "corrected": config.labels.corrected,
        "label_size": {"train_imgsz": config.labels.train_imgsz, "min_box_px": config.labels.min_box_px,
                       "small_boxes": config.labels.small_boxes,
                       "min_label_size_px": list(scene.labelling.min_size_px)},
        "pixel_convention": PIXEL_CONVENTION,
        "camera_frame": "opencv: x right, y down, z forward",
        "body_frame": "x forward, y left, z up",
        "objects": objects,
        "features": {"file": "features.parquet", "classes": len(class_names),
                     "variant": config.features.variant, "objects": list(config.features.objects)},
        "seed": config.dataset.seed,
        "approach_model": config.approach.model,
        "shard_size": config.frames_per_shard,
        "splits": splits,
        "assets": assets,
        "config": config.model_dump(mode="json"),
    }
