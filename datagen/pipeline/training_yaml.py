"""How Ultralytics trains on a dataset: ``data.yaml`` (the splits, classes and keypoints) and
``hyp.yaml`` (the recipe), with the commands their comments give."""

from __future__ import annotations

from pathlib import Path
from typing import Final

import yaml

from datagen.core.keypoints import PoseLayout
from datagen.core.training import TRAIN_BATCH
from datagen.dataset.layout import SPLITS
from datagen.dataset.training_run import TrainingRun
from datagen.scene.resolved import Scene

__all__ = [
    "data_yaml",
    "hyp_yaml",
    "pose_hyp_yaml",
    "split_lists",
]


def split_lists(splits: tuple[str, ...]) -> dict[str, str]:
    """The image list Ultralytics reads for each split: ``train.txt`` and ``val.txt``, where
    a split without frames (``val_fraction: 0``, or a small build) borrows the other's
    (Ultralytics needs both). ``splits``: the splits that have frames."""
    have = [s for s in SPLITS if s in splits] or ["train"]
    return {s: f"{s if s in have else have[0]}.txt" for s in SPLITS}


def _commands(root: Path, imgsz: int, splits: tuple[str, ...], task: str = "detect",
              dataset: Path | None = None) -> str:
    """Train, predict and evaluate commands that work offline from any shell. ``root``: the
    folder of the set's data.yaml; ``dataset``: the dataset's root, when that is another;
    ``splits``: those with frames (the predictions are of the validation list)."""
    run = TrainingRun(root, dataset or root, task)
    train, predict = run.yolo_commands(imgsz, split_lists(splits)["val"])
    return f"""\
# Train {run.network} from scratch (offline) and predict the validation frames, keeping
# low-confidence detections (needs the train extra: pip install 'datagen[train]'):
#   {run.train_command()}
# which runs Ultralytics' own commands (pass another model= to either, a local .pt file too):
#   {train}
#   {predict}
# Score the PtD vectors that PnP makes of the {'detections' if task == 'detect' else 'keypoints'} at or above --conf:
#   {run.evaluate_command()}
"""


def data_yaml(root: Path, class_names: list[str], splits: tuple[str, ...] = SPLITS, *, imgsz: int = 864,
              pose: PoseLayout | None = None, dataset: Path | None = None) -> str:
    """Ultralytics' dataset file. ``train`` and ``val`` are the image lists ``train.txt``
    and ``val.txt`` (written when the build finishes). No ``path:``: Ultralytics then
    resolves them against the folder of data.yaml itself, so the dataset can move.
    ``splits`` are the splits that have frames: Ultralytics needs both, so a split
    without frames (``val_fraction: 0``, or a tiny build) borrows the other's.
    With ``pose`` (then ``class_names`` are the objects) it is the pose set's file:
    ``kpt_shape`` and, where one exists, ``flip_idx``."""
    lists = split_lists(splits)
    note = "".join(f"# no {s} frames in this build: {s} uses {lists[s]}\n" for s in SPLITS if lists[s] != f"{s}.txt")
    doc = {"train": lists["train"], "val": lists["val"],
           "nc": len(class_names), "names": dict(enumerate(class_names))}
    task = "detect"
    if pose is not None:
        task = "pose"
        doc["kpt_shape"] = [pose.kpt_count, 3]
        if pose.flip_idx is not None:
            doc["flip_idx"] = list(pose.flip_idx)
        else:
            note += f"# no flip_idx: {pose.flip_problem} (hyp.yaml keeps fliplr off)\n"
    return (f"# Ultralytics {task} dataset (datagen); train.txt and val.txt list the images of each split.\n"
            + _commands(root, imgsz, splits, task, dataset) + note + yaml.safe_dump(doc, sort_keys=False))


#: The optimizer lines of both recipes (detect and pose).
_OPTIMIZER: Final = f"""\
# SGD at Ultralytics' lr0 from the first step, one optimizer step per batch (nbs = batch).
# Ultralytics' defaults (optimizer 'auto', nbs 64) pick AdamW at lr0 0.002 * 5 / (4 + classes)
# below 10,000 iterations and accumulate 64 / batch batches per step: a detector trained
# from scratch on a small datagen set then takes a step every few epochs. Memorizing 24
# frames (yolo11n): nbs 64, 0% of features found after 40 epochs; AdamW ('auto'), 64% after
# 100; these lines, 82% after 42 and 99% after 100. Epochs: Ultralytics' default (100).
optimizer: SGD
lr0: 0.01
batch: {TRAIN_BATCH}
nbs: {TRAIN_BATCH}  # keep equal to batch when you change it
"""


def hyp_yaml(scene: Scene, root: Path, splits: tuple[str, ...] = SPLITS) -> str:
    """The training recipe: an optimizer that steps on small datasets too, and augmentations
    that keep corrected centres and left/right classes intact."""
    config = scene.config
    imgsz = config.labels.train_imgsz
    scale = min(scene.train_view.scale)
    margin = config.labels.edge_margin_px * scale
    return f"""\
# Ultralytics training recipe for a datagen dataset ({config.name}).
{_commands(root, imgsz, splits)}# Corrected boxes are centred on the projection of a feature's true 3D centre, and
# many classes come in left/right pairs. Augmentations that clip boxes at a crop
# border (mosaic, translate, scale) move the box centre off the true centre, and a
# horizontal flip turns a left-wing feature into a right-wing one without changing
# its class: all are off. Photometric (HSV) augmentation is harmless and stays.
# Label boxes are at least {config.labels.min_box_px:g} px at this imgsz (labels.min_box_px): smaller ones
# teach nothing, because Ultralytics' task-aligned assigner weighs a box by its overlap with
# the untrained head's first guesses (about 15 strides wide), and datagen audit's
# learnable check says so. The box's centre is the true centre whatever its size.
imgsz: {imgsz}  # labels.train_imgsz; the {config.labels.edge_margin_px:g} px edge margin is {margin:.1f} px at this size
{_OPTIMIZER}mosaic: 0.0
close_mosaic: 0
mixup: 0.0
cutmix: 0.0
copy_paste: 0.0
fliplr: 0.0
flipud: 0.0
degrees: 0.0
translate: 0.0
scale: 0.0
shear: 0.0
perspective: 0.0
hsv_h: 0.015
hsv_s: 0.7
hsv_v: 0.4
"""  # noqa: E501 (text the user reads, one line per sentence)


def pose_hyp_yaml(scene: Scene, root: Path, dataset: Path | None = None, splits: tuple[str, ...] = SPLITS) -> str:
    """The pose set's training recipe: keypoints move exactly with every geometric
    augmentation, so mosaic, translate and scale are on, and fliplr where a flip_idx exists."""
    config = scene.config
    imgsz = config.labels.train_imgsz
    layout = scene.pose_layout
    if layout.flip_idx is not None:
        flip = ("# flip_idx (data.yaml) swaps every left/right pair of keypoints, so a horizontal flip\n"
                "# keeps each keypoint on its feature.\nfliplr: 0.5\n")
    else:
        flip = (f"# No flip_idx: {layout.flip_problem}; a flip would move keypoints onto the wrong features.\n"
                "fliplr: 0.0\n")
    return f"""\
# Ultralytics pose training recipe for a datagen dataset ({config.name}).
{_commands(root, imgsz, splits, "pose", dataset)}# Each object is an instance whose keypoints are its features' true centre projections
# (datagen.core.keypoints). Ultralytics moves keypoints exactly with mosaic, translation and
# scaling (a keypoint leaving the crop becomes invisible), so these stay on. Rotation, shear
# and perspective also move keypoints exactly but loosen the object boxes: off.
imgsz: {imgsz}  # labels.train_imgsz
{_OPTIMIZER}mosaic: 1.0
close_mosaic: 10
translate: 0.1
scale: 0.5
{flip}flipud: 0.0
degrees: 0.0
shear: 0.0
perspective: 0.0
mixup: 0.0
cutmix: 0.0
copy_paste: 0.0
hsv_h: 0.015
hsv_s: 0.7
hsv_v: 0.4
"""  # noqa: E501 (text the user reads, one line per sentence)
