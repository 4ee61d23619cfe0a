"""The dataset folder: its layout, its shard plan, its metadata files and its lock.

Layout (Ultralytics reads it as it is: a label's path is its image's path with
the last ``/images/`` replaced by ``/labels/`` and the extension by ``.txt``)::

    data.yaml  hyp.yaml  dataset.json  features.parquet  train.txt  val.txt
    images/{split}/{shard:05d}/{frame:08d}.png     8-bit sRGB training images
    labels/{split}/{shard:05d}/{frame:08d}.txt     YOLO lines (empty: no labeled feature)
    exr/{split}/{shard:05d}/{frame:08d}.exr        linear R, G, B, Z, object_id (with --exr)
    manifests/{split}-{shard:05d}.parquet          one row per frame (datagen.manifest)
    .datagen.lock                                  held by the build that writes the folder

Every frame's split comes from the seed alone (:func:`datagen.conventions.split_uniform`);
each split's frames, in frame order, are cut into shards of ``shard_size``. A
shard is the unit of work and of resumption: it is done exactly when its
manifest exists, and the manifest is written last, after every image and label
of the shard is in place.
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import hashlib
import json
import os
import platform
import shutil
from collections.abc import Iterator
from dataclasses import dataclass
from importlib import metadata
from pathlib import Path
from typing import Final

import yaml

from datagen.camera import Intrinsics
from datagen.config import Config
from datagen.conventions import OBJECT_NAMES, PIXEL_CONVENTION, split_uniform
from datagen.errors import DatagenError
from datagen.files import atomic_path
from datagen.manifest import MANIFEST_VERSION
from datagen.training import TrainView, label_options

__all__ = [
    "DATASET_SCHEMA",
    "DATASET_SCHEMA_VERSION",
    "SPLITS",
    "DatasetLock",
    "Layout",
    "ShardJob",
    "asset_files",
    "config_fingerprint",
    "frame_split",
    "plan_shards",
    "prepare_folder",
    "remove_owned",
    "sweep_temporaries",
    "write_dataset_files",
    "write_image_lists",
]

DATASET_SCHEMA: Final = "datagen.dataset"
#: Version of dataset.json's layout (bumped on any incompatible change).
DATASET_SCHEMA_VERSION: Final = 1
SPLITS: Final = ("train", "val")
#: Everything datagen writes at the top of a dataset folder (``--overwrite`` removes these only).
OWNED: Final = ("manifests", "images", "labels", "exr", "audit", "preview", "evaluation", "data.yaml",
                "hyp.yaml", "train.txt", "val.txt", "features.parquet", "dataset.json")
LOCK_NAME: Final = ".datagen.lock"


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


def frame_split(config: Config, frame_index: int, seed: int | None = None) -> str:
    """``train`` or ``val``, decided by the seed for the frame (or its approach chain)."""
    d = config.dataset
    seed = d.seed if seed is None else seed
    unit = frame_index if d.split_by == "frame" else frame_index // config.approach.frames_per_approach
    return "val" if split_uniform(seed, unit) < d.val_fraction else "train"


def plan_shards(config: Config) -> list[ShardJob]:
    """Every shard of the dataset, train first: a pure function of the config."""
    d = config.dataset
    frames: dict[str, list[int]] = {s: [] for s in SPLITS}
    for i in range(d.frames):
        frames[frame_split(config, i)].append(i)
    return [
        ShardJob(split, n, tuple(indices[start:start + d.shard_size]))
        for split, indices in frames.items()
        for n, start in enumerate(range(0, len(indices), d.shard_size))
    ]


@dataclass(frozen=True)
class Layout:
    """Paths inside a dataset folder; ``*_rel`` are relative to the root (as in manifests)."""

    root: Path
    image_ext: str = ".png"

    def _rel(self, tree: str, split: str, shard: int, frame: int, ext: str) -> str:
        return f"{tree}/{split}/{shard:05d}/{frame:08d}{ext}"

    def image_rel(self, split: str, shard: int, frame: int) -> str:
        return self._rel("images", split, shard, frame, self.image_ext)

    def label_rel(self, split: str, shard: int, frame: int) -> str:
        return self._rel("labels", split, shard, frame, ".txt")

    def exr_rel(self, split: str, shard: int, frame: int) -> str:
        return self._rel("exr", split, shard, frame, ".exr")

    def manifest(self, job: ShardJob) -> Path:
        return self.root / "manifests" / f"{job.name}.parquet"

    def image_list(self, split: str) -> Path:
        """``train.txt`` or ``val.txt``: the split's images, one ``./images/...`` path per line."""
        return self.root / f"{split}.txt"

    def shard_dirs(self, job: ShardJob) -> list[Path]:
        return [self.root / tree / job.split / f"{job.shard:05d}" for tree in ("images", "labels", "exr")]

    @property
    def dataset_json(self) -> Path:
        return self.root / "dataset.json"


# --- identity of a build --------------------------------------------------------------------
def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def asset_files(config: Config) -> dict[str, dict[str, str]]:
    """Mesh and feature files of every object, with their SHA-256."""
    from datagen.assets import RIGID_OBJECTS, object_paths

    out = {}
    for name in RIGID_OBJECTS:
        mesh, features = object_paths(config, name)
        out[name] = {"mesh": str(mesh), "mesh_sha256": _sha256(mesh),
                     "features": str(features), "features_sha256": _sha256(features)}
    return out


def config_fingerprint(config: Config, assets: dict, *, render: bool = True) -> str:
    """SHA-256 of everything that decides a dataset's content: the resolved config
    (paths of built-in assets excluded), the bytes of every asset file and whether
    images are rendered."""
    doc = {
        "config": config.model_dump(mode="json"),
        "render": render,
        "assets": {name: [a["mesh_sha256"], a["features_sha256"]] for name, a in assets.items()},
    }
    return hashlib.sha256(json.dumps(doc, sort_keys=True).encode()).hexdigest()


def _versions() -> dict[str, str]:
    import datagen

    out = {"datagen": datagen.__version__, "python": platform.python_version()}
    for dist in ("mitsuba", "drjit", "numpy", "pyarrow", "trimesh", "opencv-python-headless"):
        with contextlib.suppress(metadata.PackageNotFoundError):
            out[dist] = metadata.version(dist)
    return out


# --- metadata files ---------------------------------------------------------------------------
def dataset_document(config: Config, jobs: list[ShardJob], fingerprint: str, assets: dict,
                     class_names: list[str]) -> dict:
    """The content of ``dataset.json``."""
    cam = config.camera
    k = Intrinsics.from_hfov_deg(cam.width, cam.height, cam.hfov_deg)
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
        "versions": _versions(),
        "image_width": cam.width,
        "image_height": cam.height,
        "intrinsics": {"fx": k.fx, "fy": k.fy, "cx": k.cx, "cy": k.cy},
        "edge_margin_px": config.labels.edge_margin_px,
        "corrected": config.labels.corrected,
        "label_size": {"train_imgsz": config.labels.train_imgsz, "min_box_px": config.labels.min_box_px,
                       "small_boxes": config.labels.small_boxes,
                       "min_label_size_px": list(label_options(config.labels, cam.width, cam.height)["min_size_px"])},
        "pixel_convention": PIXEL_CONVENTION,
        "camera_frame": "opencv: x right, y down, z forward",
        "body_frame": "x forward, y left, z up",
        "objects": objects,
        "features": {"file": "features.parquet", "classes": len(class_names),
                     "variant": config.features.variant, "objects": list(config.features.objects)},
        "seed": config.dataset.seed,
        "shard_size": config.dataset.shard_size,
        "splits": splits,
        "assets": assets,
        "config": config.model_dump(mode="json"),
    }


def _commands(root: Path, imgsz: int) -> str:
    """Train, predict and evaluate commands that work offline from any folder."""
    return f"""\
# Train (offline, from any folder; yolo11s.yaml builds the network from scratch, a local .pt file works too):
#   yolo detect train data={root / 'data.yaml'} cfg={root / 'hyp.yaml'} model=yolo11s.yaml project={root.parent / 'runs'} name={root.name}
# Predict the validation frames (keeping low-confidence detections) and score the PtD vectors
# that PnP makes of the detections at or above --conf:
#   yolo detect predict model={root.parent / 'runs' / root.name / 'weights' / 'best.pt'} source={root / 'val.txt'} imgsz={imgsz} conf=0.001 save_txt=True save_conf=True project={root.parent / 'runs'} name={root.name}-predict
#   datagen evaluate {root} --predictions {root.parent / 'runs' / (root.name + '-predict') / 'labels'} --conf 0.25
"""


def data_yaml(root: Path, class_names: list[str], splits: tuple[str, ...] = SPLITS, *, imgsz: int = 864) -> str:
    """Ultralytics' dataset file. ``train`` and ``val`` are the image lists ``train.txt``
    and ``val.txt`` (written when the build finishes). No ``path:``: Ultralytics then
    resolves them against the folder of data.yaml itself, so the dataset can move.
    ``splits`` are the splits that have frames: Ultralytics needs both, so a split
    without frames (``val_fraction: 0``, or a tiny build) borrows the other's."""
    have = [s for s in SPLITS if s in splits] or ["train"]
    lists = {s: f"{s if s in have else have[0]}.txt" for s in SPLITS}
    note = "".join(f"# no {s} frames in this build: {s} uses {lists[s]}\n" for s in SPLITS if s not in have)
    doc = {"train": lists["train"], "val": lists["val"],
           "nc": len(class_names), "names": dict(enumerate(class_names))}
    return ("# Ultralytics dataset (datagen); train.txt and val.txt list the images of each split.\n"
            + _commands(root, imgsz) + note + yaml.safe_dump(doc, sort_keys=False))


def hyp_yaml(config: Config, root: Path) -> str:
    """A training recipe that keeps corrected centres and left/right classes intact."""
    imgsz = config.labels.train_imgsz
    scale = min(TrainView(config.camera.width, config.camera.height, imgsz).scale)
    margin = config.labels.edge_margin_px * scale
    return f"""\
# Ultralytics training recipe for a datagen dataset ({config.name}).
{_commands(root, imgsz)}# Corrected boxes are centred on the projection of a feature's true 3D centre, and
# many classes come in left/right pairs. Augmentations that clip boxes at a crop
# border (mosaic, translate, scale) move the box centre off the true centre, and a
# horizontal flip turns a left-wing feature into a right-wing one without changing
# its class: all are off. Photometric (HSV) augmentation is harmless and stays.
# Label boxes are at least {config.labels.min_box_px:g} px at this imgsz (labels.min_box_px), so that every
# label survives the trainer's 2 px rule and holds an anchor centre (datagen audit: learnable).
imgsz: {imgsz}  # labels.train_imgsz; the {config.labels.edge_margin_px:g} px edge margin is {margin:.1f} px at this size
mosaic: 0.0
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
"""


def write_image_lists(layout: Layout, jobs: list[ShardJob]) -> list[Path]:
    """``train.txt`` and ``val.txt``: every image of each split in frame order, one
    ``./images/...`` path per line (Ultralytics resolves ``./`` against the list's
    folder, for training and for ``yolo predict source=``). Written when every shard
    is done, so that a list never names a missing image."""
    written = []
    for split in SPLITS:
        lines = [f"./{layout.image_rel(job.split, job.shard, i)}\n"
                 for job in jobs if job.split == split for i in job.frames]
        if lines:
            with atomic_path(layout.image_list(split)) as tmp:
                tmp.write_text("".join(lines))
            written.append(layout.image_list(split))
    return written


def write_dataset_files(layout: Layout, config: Config, jobs: list[ShardJob], fingerprint: str,
                        assets: dict, *, describe: bool) -> None:
    """dataset.json (when ``describe``: a new dataset), then data.yaml, hyp.yaml and
    features.parquet, each atomically. dataset.json comes first so that a folder
    with any datagen file in it is recognisable as a dataset; the other three are
    pure functions of the config and are rewritten by every run."""
    from datagen.assets import feature_table
    from datagen.manifest import write_features

    features = feature_table(config)
    names = list(features.name)
    root = layout.root
    if describe:
        document = dataset_document(config, jobs, fingerprint, assets, names)
        with atomic_path(layout.dataset_json) as tmp:
            tmp.write_text(json.dumps(document, indent=2) + "\n")
    splits = tuple(sorted({job.split for job in jobs}))
    imgsz = config.labels.train_imgsz
    for name, text in (("data.yaml", data_yaml(root, names, splits, imgsz=imgsz)),
                       ("hyp.yaml", hyp_yaml(config, root))):
        with atomic_path(root / name) as tmp:
            tmp.write_text(text)
    write_features(root / "features.parquet", features)


# --- the folder: lock, refusal, overwrite, leftovers --------------------------------------
class DatasetLock:
    """An exclusive ``flock`` on ``.datagen.lock``: held by one build at a time and
    released by the kernel when its process ends, however it ends."""

    def __init__(self, root: Path) -> None:
        self.path = root / LOCK_NAME
        self._fd: int | None = None

    def acquire(self) -> None:
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
        except OSError as exc:
            raise DatagenError(f"{exc.filename or self.path.parent}: cannot create the dataset folder "
                               f"({exc.strerror})") from None
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError as exc:
            os.close(fd)
            if exc.errno not in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES):
                raise
            holder = self.path.read_text().strip() or "another process"
            raise DatagenError(f"{self.path.parent}: another datagen build ({holder}) is writing this "
                               "dataset; wait for it to finish or choose another --out") from None
        os.ftruncate(fd, 0)
        os.write(fd, f"pid {os.getpid()} on {platform.node()}".encode())
        self._fd = fd

    def release(self) -> None:
        if self._fd is not None:
            os.close(self._fd)  # closing the descriptor drops the lock
            self._fd = None

    def __enter__(self) -> DatasetLock:
        self.acquire()
        return self

    def __exit__(self, *exc) -> None:
        self.release()


def _differences(old: object, new: object, key: str = "") -> Iterator[str]:
    if isinstance(old, dict) and isinstance(new, dict):
        for k in sorted(set(old) | set(new)):
            yield from _differences(old.get(k), new.get(k), f"{key}.{k}" if key else k)
    elif old != new:
        yield f"{key} {json.dumps(old)} -> {json.dumps(new)}"


def prepare_folder(layout: Layout, fingerprint: str, config: Config, *, overwrite: bool) -> bool:
    """Decide what to do with the output folder; call with the lock held.

    Returns True when an earlier build of the same config is resumed. A folder
    that is not empty and holds no datagen dataset is refused, even with
    ``overwrite`` (it may hold someone's data); a dataset of another config is
    refused unless ``overwrite``, which removes what datagen wrote there.
    """
    root = layout.root
    # The lock and temporaries of an interrupted first run do not make a folder non-empty.
    entries = [p.name for p in root.iterdir() if p.name != LOCK_NAME and not _temporary(p.name)] \
        if root.is_dir() else []
    if not entries:
        return False
    path = layout.dataset_json
    if not path.is_file():
        raise DatagenError(f"{root}: not empty and not a datagen dataset (no dataset.json); "
                           "choose an empty or new --out folder")
    try:
        existing = json.loads(path.read_text())
        old_fingerprint, old_config = existing["fingerprint"], existing["config"]
    except (OSError, ValueError, KeyError, TypeError) as exc:
        if not overwrite:
            raise DatagenError(f"{path}: unreadable dataset description ({exc}); use --overwrite to "
                               "replace the dataset") from None
        old_fingerprint, old_config = None, {}
    if old_fingerprint == fingerprint:
        return True
    if not overwrite:
        changes = list(_differences(old_config, config.model_dump(mode="json")))
        what = "; ".join(changes[:3]) + (f"; and {len(changes) - 3} more" if len(changes) > 3 else "")
        raise DatagenError(f"{path}: this folder holds a dataset of another config or assets "
                           f"({what or 'asset files changed'}); use --overwrite to replace it, or "
                           "choose another --out")
    remove_owned(root)
    return False


def _temporary(name: str) -> bool:
    return name.startswith(".") and name.endswith(".tmp")


def remove_owned(root: Path) -> None:
    """Delete what datagen wrote in ``root``: manifests first (so that no shard counts
    as done if this is interrupted), dataset.json last (so the folder stays
    recognisable as a dataset until the end)."""
    for name in OWNED:
        path = root / name
        if path.is_dir():
            shutil.rmtree(path)
        elif path.exists():
            path.unlink()


def sweep_temporaries(paths: list[Path]) -> int:
    """Remove the hidden temporary files (``.NAME.PID.tmp``) an interrupted writer
    left in these folders (not recursive); returns how many."""
    removed = 0
    for folder in paths:
        if not folder.is_dir():
            continue
        for entry in folder.iterdir():
            if _temporary(entry.name) and entry.is_file():
                entry.unlink(missing_ok=True)
                removed += 1
    return removed
