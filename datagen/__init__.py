"""datagen: physically based synthetic training data for vision-based aerial refueling.

The public API is re-exported here; modules whose names start with an
underscore, and anything not in ``__all__``, are private.
"""

from datagen.config import Config, load_config
from datagen.core.camera import Intrinsics, in_front, project_points
from datagen.core.errors import ConfigError, DatagenError, Problem
from datagen.core.features import FeatureTable
from datagen.core.label_boxes import Exclusion, FrameLabels, boxes_from_uv, compute_labels
from datagen.core.transforms import (
    Transform,
    apply_transform,
    invert_rigid,
    make_transform,
    rotation_from_ypr,
)
from datagen.dataset.yolo import yolo_lines

__version__ = "0.1.0"

__all__ = [
    "Config",
    "ConfigError",
    "DatagenError",
    "Exclusion",
    "FeatureTable",
    "FrameLabels",
    "Intrinsics",
    "Problem",
    "Transform",
    "__version__",
    "apply_transform",
    "boxes_from_uv",
    "compute_labels",
    "in_front",
    "invert_rigid",
    "load_config",
    "make_transform",
    "project_points",
    "rotation_from_ypr",
    "yolo_lines",
]
