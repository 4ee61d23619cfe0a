"""How much a reader takes from a dataset folder, and which values it accepts: every file a
command reads is bounded in size before it is read, and every number the readers compute
with is range-checked where it is read. The bounds are stated here once; those of the
per-frame files follow from the dataset's own plan and resolution (dataset.json), so that
a sparse, huge or crafted file costs no more memory than a real file of the dataset could,
and a tampered value is one line, not a histogram of ten million bins.

Measured ceilings of each command on hostile folders: the bad-input page of the docs.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Final

from datagen.core.labelling_context import LabellingContext

__all__ = [
    "DATASET_JSON_BYTES",
    "DATA_YAML_BYTES",
    "HYP_YAML_BYTES",
    "MAX_DETECTIONS",
    "MAX_DISTANCE_M",
    "MAX_FRAMES",
    "MAX_WORLD_M",
    "TABLE_BYTES",
    "TABLE_ROWS",
    "ReadLimits",
]

_KIB: Final = 1024
_MIB: Final = 1024 * 1024

#: dataset.json: the build's config and its records (a shipped scene's is about 9 KB).
DATASET_JSON_BYTES: Final = 1 * _MIB
#: data.yaml (and pose/data.yaml): the image lists and class names (80 classes: about 3.4 KB).
DATA_YAML_BYTES: Final = 256 * _KIB
#: hyp.yaml (and pose/hyp.yaml): the training recipe (about 2.5 KB).
HYP_YAML_BYTES: Final = 64 * _KIB
#: features.parquet and objects.parquet: a point set per class, a hull per object.
TABLE_BYTES: Final = 64 * _MIB
#: Rows of features.parquet or objects.parquet.
TABLE_ROWS: Final = 100_000
#: Frames a dataset may plan (the config's ``dataset.frames`` allows no more).
MAX_FRAMES: Final = 10_000_000
#: The longest value of a label or prediction line, characters (``0.1234567`` has 9; a
#: class id at most 6), with its separator.
_TOKEN_CHARS: Final = 16
#: Detections a prediction file may hold: Ultralytics writes at most ``max_det`` per image
#: (300 unless told otherwise).
MAX_DETECTIONS: Final = 3000
#: A manifest row's bytes, uncompressed, beyond its feature records (measured: 12.8 KB a row
#: with 80 features, materials and appearance draws included).
_ROW_BYTES: Final = 64 * _KIB
#: A manifest row's bytes per feature record (measured: about 120).
_FEATURE_RECORD_BYTES: Final = 1 * _KIB
#: A file's footer, headers and slack beyond its content, bytes.
_SLACK: Final = 1 * _MIB
#: The largest distance a manifest may record, metres (``approach.range_m`` allows 10 km).
MAX_DISTANCE_M: Final = 100_000.0
#: The largest world coordinate a pose may hold, metres (the Earth's radius is 6.4e6).
MAX_WORLD_M: Final = 1.0e8


@dataclass(frozen=True)
class ReadLimits:
    """The largest file of each per-frame kind a dataset may hold: from its resolution,
    its feature table and its plan."""

    width: int
    height: int
    features: int
    objects: int
    keypoints: int  # the most keypoints of a pose instance
    shard_rows: int  # the most frames of a shard
    split_frames: Mapping[str, int]  # frames planned per split

    @classmethod
    def of(cls, labelling: LabellingContext, shard_rows: int, split_frames: Mapping[str, int]) -> ReadLimits:
        """The limits of a dataset labelled by ``labelling`` (a build's scene, a dataset's
        metadata), in shards of at most ``shard_rows`` frames, ``split_frames`` planned."""
        k = labelling.intrinsics
        return cls(k.width, k.height, len(labelling.features), len(labelling.features.objects),
                   labelling.pose_layout.kpt_count, shard_rows, dict(split_frames))

    @property
    def frames(self) -> int:
        """Frames planned in all: every frame id lies below."""
        return min(MAX_FRAMES, sum(self.split_frames.values()))

    @property
    def label_bytes(self) -> int:
        """A label file: a detection line per feature and a pose line per object."""
        values = 5 * self.features + (5 + 3 * self.keypoints) * self.objects
        return values * _TOKEN_CHARS + 4 * _KIB

    @property
    def image_bytes(self) -> int:
        """A training image: a PNG is at most its raw pixels and headers (a frame of noise
        compresses to about its raw size)."""
        return 4 * self.width * self.height * 3 + _SLACK

    @property
    def exr_bytes(self) -> int:
        """A frame's EXR: five 32-bit channels, uncompressed at worst."""
        return 2 * self.width * self.height * 5 * 4 + _SLACK

    def image_list_bytes(self, split: str) -> int:
        """``{split}.txt``: one ``./images/{split}/{shard}/{frame}.png`` line per planned frame."""
        return 64 * self.split_frames.get(split, 0) + 4 * _KIB

    @property
    def manifest_bytes(self) -> int:
        """A shard's manifest, on disk and uncompressed."""
        return self.shard_rows * (_ROW_BYTES + _FEATURE_RECORD_BYTES * (self.features + self.objects)) + _SLACK

    @property
    def prediction_bytes(self) -> int:
        """A prediction file: :data:`MAX_DETECTIONS` lines of a box, its keypoints and a confidence."""
        return MAX_DETECTIONS * (6 + 3 * self.keypoints) * _TOKEN_CHARS + 4 * _KIB
