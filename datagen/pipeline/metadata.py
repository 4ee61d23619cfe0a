"""The metadata files of a dataset: ``dataset.json``, ``data.yaml``, ``hyp.yaml``,
``features.parquet`` and the image lists ``train.txt`` / ``val.txt``.

``dataset.json`` says what the dataset is (written once, when a dataset is new);
the others are pure functions of the resolved scene and are rewritten by every
run. The fingerprint decides whether a rerun resumes the same dataset.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import platform
from importlib import metadata
from pathlib import Path
from typing import Final

import yaml

from datagen.atomic import link_or_copy, symlink_folder, write_image, write_text
from datagen.core.conventions import OBJECT_NAMES, PIXEL_CONVENTION
from datagen.core.errors import DatagenError
from datagen.core.keypoints import PoseLayout
from datagen.core.training import TRAIN_BATCH
from datagen.dataset.columns import MANIFEST_VERSION, write_features, write_objects
from datagen.dataset.layout import POSE_IMAGES_LINK, SPLITS, Layout, ShardJob
from datagen.paths import regular_file
from datagen.scene.resolved import Scene

__all__ = [
    "CARD_MARK",
    "DATASET_SCHEMA",
    "DATASET_SCHEMA_VERSION",
    "config_fingerprint",
    "data_yaml",
    "dataset_card",
    "dataset_document",
    "hyp_yaml",
    "is_dataset_card",
    "pose_hyp_yaml",
    "write_dataset_card",
    "write_dataset_files",
    "write_image_lists",
    "write_placeholder_images",
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


def _rendered(config) -> str:
    r = config.render
    denoised = ", denoised with Intel Open Image Denoise" if r.denoise == "oidn" else ""
    return f"rendered with Mitsuba 3 at {r.spp} spp{denoised}"


def _images(config) -> dict:
    """How the images were made: what a user needs to compare two datasets' pixels."""
    r = config.render
    return {"spp": r.spp, "max_depth": r.max_depth, "denoise": r.denoise,
            "denoise_guides": r.denoise_guides if r.denoise != "off" else None,
            "denoise_quality": r.denoise_quality if r.denoise != "off" else None,
            "sea_model": config.randomization.sea.model, "format": r.image_format,
            "exr": "linear radiance x exposure (denoised when denoise is on), Z, object_id" if r.exr else None}


# --- metadata files ---------------------------------------------------------------------------
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
        "shard_size": config.dataset.shard_size,
        "splits": splits,
        "assets": assets,
        "config": config.model_dump(mode="json"),
    }


def _commands(root: Path, imgsz: int, task: str = "detect", dataset: Path | None = None) -> str:
    """Train, predict and evaluate commands that work offline from any folder. ``root``: the
    folder of the set's data.yaml; ``dataset``: the dataset's root, when that is another."""
    model = "yolo11s.yaml" if task == "detect" else "yolo11s-pose.yaml"
    dataset = dataset or root
    runs = dataset.parent / "runs"
    name = dataset.name if dataset == root else f"{dataset.name}-{task}"
    return f"""\
# Train (offline, from any folder; {model} builds the network from scratch, a local .pt file works too):
#   yolo {task} train data={root / 'data.yaml'} cfg={root / 'hyp.yaml'} model={model} project={runs} name={name}
# Predict the validation frames (keeping low-confidence detections) and score the PtD vectors
# that PnP makes of the {'detections' if task == 'detect' else 'keypoints'} at or above --conf:
#   yolo {task} predict model={runs / name / 'weights' / 'best.pt'} source={root / 'val.txt'} imgsz={imgsz} conf=0.001 save_txt=True save_conf=True project={runs} name={name}-predict
#   datagen evaluate {dataset} --predictions {runs / (name + '-predict') / 'labels'} --conf 0.25
"""  # noqa: E501 (text the user reads, one line per sentence)


def data_yaml(root: Path, class_names: list[str], splits: tuple[str, ...] = SPLITS, *, imgsz: int = 864,
              pose: PoseLayout | None = None, dataset: Path | None = None) -> str:
    """Ultralytics' dataset file. ``train`` and ``val`` are the image lists ``train.txt``
    and ``val.txt`` (written when the build finishes). No ``path:``: Ultralytics then
    resolves them against the folder of data.yaml itself, so the dataset can move.
    ``splits`` are the splits that have frames: Ultralytics needs both, so a split
    without frames (``val_fraction: 0``, or a tiny build) borrows the other's.
    With ``pose`` (then ``class_names`` are the objects) it is the pose set's file:
    ``kpt_shape`` and, where one exists, ``flip_idx``."""
    have = [s for s in SPLITS if s in splits] or ["train"]
    lists = {s: f"{s if s in have else have[0]}.txt" for s in SPLITS}
    note = "".join(f"# no {s} frames in this build: {s} uses {lists[s]}\n" for s in SPLITS if s not in have)
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
            + _commands(root, imgsz, task, dataset) + note + yaml.safe_dump(doc, sort_keys=False))


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


def hyp_yaml(scene: Scene, root: Path) -> str:
    """The training recipe: an optimizer that steps on small datasets too, and augmentations
    that keep corrected centres and left/right classes intact."""
    config = scene.config
    imgsz = config.labels.train_imgsz
    scale = min(scene.train_view.scale)
    margin = config.labels.edge_margin_px * scale
    return f"""\
# Ultralytics training recipe for a datagen dataset ({config.name}).
{_commands(root, imgsz)}# Corrected boxes are centred on the projection of a feature's true 3D centre, and
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


def pose_hyp_yaml(scene: Scene, root: Path, dataset: Path | None = None) -> str:
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
{_commands(root, imgsz, "pose", dataset)}# Each object is an instance whose keypoints are its features' true centre projections
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


def write_image_lists(layout: Layout, jobs: list[ShardJob]) -> list[Path]:
    """``train.txt`` and ``val.txt``: every image of each split in frame order, one
    ``./images/...`` path per line (Ultralytics resolves ``./`` against the list's
    folder, for training and for ``yolo predict source=``). Written when every shard
    is done, so that a list never names a missing image."""
    written = []
    roots = [layout.root] + ([layout.pose_root] if layout.pose_root != layout.root else [])
    for split in SPLITS:
        lines = [f"./{layout.image_rel(job.split, job.shard, i)}\n"
                 for job in jobs if job.split == split for i in job.frames]
        if lines:
            written += [write_text(root / layout.image_list(split).name, "".join(lines)) for root in roots]
    return written


def write_placeholder_images(layout: Layout, jobs: list[ShardJob], width: int, height: int) -> list[Path]:
    """One grey image at every frame's image path (the first written, the others hard links
    to it), then the image lists: a labels-only build that Ultralytics' dataloader reads
    (the labels do not depend on the pixels). For tests and benchmarks, not datasets."""
    import numpy as np

    first = None
    for job in jobs:
        for i in job.frames:
            path = layout.root / layout.image_rel(job.split, job.shard, i)
            if first is None:
                first = write_image(path, np.full((height, width, 3), 90, np.uint8))
            else:
                link_or_copy(first, path)
    return write_image_lists(layout, jobs)


#: The first line of a dataset card datagen wrote; a README.md without it is the user's and is never touched.
CARD_MARK: Final = "<!-- datagen dataset card: rewritten by every finished build -->"


def dataset_card(scene: Scene, jobs: list[ShardJob], *, render: bool, labels: int,
                 excluded: dict[str, int]) -> str:
    """``README.md``: the dataset card. Its front matter tells Hugging Face ``datasets``
    which parquet files hold each split (``load_dataset(DIR)`` returns the manifests);
    its text says what the dataset is and how it was made."""
    config = scene.config
    frames = {split: sum(len(j.frames) for j in jobs if j.split == split) for split in SPLITS}
    front = {"configs": [{"config_name": "default", "data_files": [
        {"split": split, "path": f"manifests/{split}-*.parquet"} for split in SPLITS if frames[split]]}],
        "pretty_name": f"datagen {config.name}", "tags": ["synthetic", "object-detection", "keypoint-detection",
                                                          "aerial-refueling", "pnp"]}
    k, cam = scene.intrinsics, config.camera
    model = f" (paper model {config.paper_model})" if config.paper_model else ""
    lo, hi = config.approach.range_m
    rules = scene.labelling.rules
    reasons = ", ".join(f"{n:,} {r}" for r, n in excluded.items() if n) or "none"
    boxes = ("YOLO boxes in `labels/`" if config.labels.format != "pose"
             else "labeled features (no detection label files: the pose keypoints below)")
    return f"""---
{yaml.safe_dump(front, sort_keys=False).strip()}
---
{CARD_MARK}
# {config.name}{model}

Synthetic frames of vision-based aerial refueling made by datagen from the scene config
`{config.name}` (root seed {config.dataset.seed}): Monte Carlo refueling approaches over {lo:g}-{hi:g} m
seen by the {cam.mount} camera ({cam.hfov_deg:g} deg hFOV, {k.width}x{k.height}, pinhole, fx = fy = {k.fx:.3f} px,
cx = {k.cx:g}, cy = {k.cy:g}), {_rendered(config) if render else "labels only (no images)"}.

- **Frames**: {frames['train']:,} train, {frames['val']:,} val; {len(scene.features)} classes (the
  {config.features.variant} features of {' and '.join(config.features.objects)}).
- **Labels**: {labels:,} {boxes}, each centred exactly on the projection of its feature's
  true 3D centre ({'corrected' if rules.corrected else 'tight (uncorrected)'} boxes, at least
  {config.labels.min_box_px:g} px at imgsz {config.labels.train_imgsz}, {rules.edge_margin_px:g} px edge
  margin); excluded feature-frames: {reasons}.
{_pose_card(scene)}- **Tables**: `manifests/{{split}}-{{shard}}.parquet`, one row per frame (poses as 4x4 matrices, intrinsics,
  seeds, every appearance draw, and per feature its true centre, boxes, exclusion and visibility; missing
  values are nulls), `features.parquet` (each class's 3D points and centre). The columns are documented in
  datagen's `manifests/README.md`; `datasets.load_dataset(this folder)` reads the manifests.
- **Training**: `data.yaml` and `hyp.yaml` for Ultralytics YOLO; their comments give the train, predict and
  evaluate commands. `dataset.json` records the resolved config, the software versions and the asset hashes.
"""  # noqa: E501 (text the user reads, one line per sentence)


def _pose_card(scene: Scene) -> str:
    """The card's line on pose labels (empty without them)."""
    labels = scene.config.labels
    if labels.format == "detect":
        return ""
    where = "`pose/` (its own data.yaml and hyp.yaml)" if labels.format == "both" else "`labels/`"
    layout = scene.pose_layout
    flip = "with a `flip_idx`" if layout.flip_idx is not None else f"without `flip_idx` ({layout.flip_problem})"
    return (f"- **Pose labels** in {where}: one instance per object ({', '.join(layout.objects)}), its keypoints the "
            f"true centre projections of its features, `kpt_shape: [{layout.kpt_count}, 3]`, {flip}; truncated "
            f"objects: {labels.truncated_objects}.\n")


def write_dataset_card(layout: Layout, scene: Scene, jobs: list[ShardJob], *, render: bool, labels: int,
                       excluded: dict[str, int]) -> Path | None:
    """Write the card of a finished build, unless a README.md that datagen did not write is there."""
    path = layout.root / "README.md"
    if path.exists() and not is_dataset_card(path):
        return None
    return write_text(path, dataset_card(scene, jobs, render=render, labels=labels, excluded=excluded))


def is_dataset_card(path: Path) -> bool:
    """Whether ``path`` is a card datagen wrote (it carries :data:`CARD_MARK`)."""
    if not regular_file(path):  # a FIFO would block the read
        return False
    try:
        with open(path, encoding="utf-8", errors="replace") as f:
            return CARD_MARK in f.read(4096)
    except OSError:
        return False


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
        write_text(root / "hyp.yaml", hyp_yaml(scene, root))
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
        write_text(pose_root / "hyp.yaml", pose_hyp_yaml(scene, pose_root, root))
    write_features(root / "features.parquet", scene.features)
    write_objects(root / "objects.parquet", scene.features.objects, scene.hulls)
