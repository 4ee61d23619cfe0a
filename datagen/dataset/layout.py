"""The dataset folder: its layout (the paths of its files) and its shards.

Layout (Ultralytics reads it as it is: a label's path is its image's path with
the last ``/images/`` replaced by ``/labels/`` and the extension by ``.txt``)::

    data.yaml  hyp.yaml  dataset.json  features.parquet  objects.parquet  train.txt  val.txt
    images/{split}/{shard:05d}/{frame:08d}.png     8-bit sRGB training images
    labels/{split}/{shard:05d}/{frame:08d}.txt     YOLO lines (empty: no labeled feature), detect
                                                   or pose as labels.format says
    pose/data.yaml  pose/hyp.yaml  pose/train.txt  pose/val.txt
    pose/images -> ../images                       with labels.format 'both': the pose set beside
    pose/labels/{split}/{shard:05d}/{frame:08d}.txt  the detect set (a relative link to the images)
    exr/{split}/{shard:05d}/{frame:08d}.exr        linear R, G, B, Z, object_id (with --exr)
    manifests/{split}-{shard:05d}.parquet          one row per frame (datagen.dataset.columns)
    .datagen.lock                                  held by the build that writes the folder

Each split's frames, in frame order, are cut into shards (the build's plan:
:func:`datagen.pipeline.plan.plan_shards`). A shard is the unit of work and of
resumption: it is done exactly when its manifest exists, and the manifest is written
last, after every image and label of the shard is in place.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path
from typing import Final

__all__ = [
    "DATA_YAML_KEYS",
    "FRAME_FILE",
    "FRAME_TREES",
    "LOCK_NAME",
    "MANIFEST_NAME",
    "POSE_IMAGES_LINK",
    "SPLITS",
    "Layout",
    "ShardJob",
]

SPLITS: Final = ("train", "val")


LOCK_NAME: Final = ".datagen.lock"
#: With labels.format 'both', the pose set reaches the images through this relative link
#: (Ultralytics finds a label by replacing the last /images/ of the image's path).
POSE_IMAGES_LINK: Final = ("pose/images", "../images")


#: The keys of a data.yaml datagen writes (Ultralytics' dataset file): no ``path``, no
#: ``download`` (Ultralytics runs a ``download`` command when a split's images are missing).
DATA_YAML_KEYS: Final = ("train", "val", "nc", "names", "kpt_shape", "flip_idx")
#: The name of a shard's manifest, ``{split}-{shard:05d}.parquet``; nothing else in manifests/ is one.
MANIFEST_NAME: Final = re.compile(r"(train|val)-[0-9]{5}\.parquet")
#: The path of a frame's file (relative to the root) in the form :class:`Layout` gives it:
#: ``{tree}/{split}/{shard:05d}/{frame:08d}{ext}``, each tree with its own extensions.
FRAME_FILE: Final = re.compile(r"(images/(train|val)/[0-9]{5}/[0-9]{8}\.(png|jpg)"
                               r"|(pose/)?labels/(train|val)/[0-9]{5}/[0-9]{8}\.txt"
                               r"|exr/(train|val)/[0-9]{5}/[0-9]{8}\.exr)")
#: The folders that hold the frames' files.
FRAME_TREES: Final = ("images", "labels", "pose/labels", "exr")


# --- plan -------------------------------------------------------------------------------
@dataclass(frozen=True)
class ShardJob:
    """One shard: consecutive frames (in frame order) of one split."""

    split: str
    shard: int
    frames: tuple[int, ...]

    @property
    def name(self) -> str:
        return f"{self.split}-{self.shard:05d}"


@dataclass(frozen=True)
class Layout:
    """Paths inside a dataset folder; ``*_rel`` are relative to the root (as in manifests)."""

    root: Path
    image_suffix: str = ".png"
    label_format: str = "detect"  # labels.format: detect, pose or both

    @property
    def detect(self) -> bool:
        """Whether the dataset has detection labels (in ``labels/``)."""
        return self.label_format in ("detect", "both")

    @property
    def pose(self) -> bool:
        """Whether the dataset has pose labels."""
        return self.label_format in ("pose", "both")

    @property
    def pose_root(self) -> Path:
        """The folder of the pose set's data.yaml: the root, or ``pose/`` beside the detect set."""
        return self.root / "pose" if self.label_format == "both" else self.root

    def _rel(self, tree: str, split: str, shard: int, frame: int, ext: str) -> str:
        return f"{tree}/{split}/{shard:05d}/{frame:08d}{ext}"

    def image_rel(self, split: str, shard: int, frame: int) -> str:
        return self._rel("images", split, shard, frame, self.image_suffix)

    def label_rel(self, split: str, shard: int, frame: int) -> str | None:
        """The detection label file, None without detection labels."""
        return self._rel("labels", split, shard, frame, ".txt") if self.detect else None

    def pose_label_rel(self, split: str, shard: int, frame: int) -> str | None:
        """The pose label file, None without pose labels."""
        if not self.pose:
            return None
        tree = "pose/labels" if self.label_format == "both" else "labels"
        return self._rel(tree, split, shard, frame, ".txt")

    def exr_rel(self, split: str, shard: int, frame: int) -> str:
        return self._rel("exr", split, shard, frame, ".exr")

    def manifest(self, job: ShardJob) -> Path:
        return self.root / "manifests" / f"{job.name}.parquet"

    def image_list(self, split: str) -> Path:
        """``train.txt`` or ``val.txt``: the split's images, one ``./images/...`` path per line."""
        return self.root / f"{split}.txt"

    def shard_dirs(self, job: ShardJob) -> list[Path]:
        trees = ("images", "labels", "exr", *(("pose/labels",) if self.label_format == "both" else ()))
        return [self.root / tree / job.split / f"{job.shard:05d}" for tree in trees]

    @property
    def dataset_json(self) -> Path:
        return self.root / "dataset.json"
