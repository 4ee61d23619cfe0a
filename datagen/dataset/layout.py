"""The dataset folder: its layout, its shard plan, its metadata files and its lock.

Layout (Ultralytics reads it as it is: a label's path is its image's path with
the last ``/images/`` replaced by ``/labels/`` and the extension by ``.txt``)::

    data.yaml  hyp.yaml  dataset.json  features.parquet  train.txt  val.txt
    images/{split}/{shard:05d}/{frame:08d}.png     8-bit sRGB training images
    labels/{split}/{shard:05d}/{frame:08d}.txt     YOLO lines (empty: no labeled feature)
    exr/{split}/{shard:05d}/{frame:08d}.exr        linear R, G, B, Z, object_id (with --exr)
    manifests/{split}-{shard:05d}.parquet          one row per frame (datagen.dataset.schema)
    .datagen.lock                                  held by the build that writes the folder

Every frame's split comes from the seed alone (:func:`datagen.core.conventions.split_uniform`);
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
import re
from collections.abc import Iterator
from dataclasses import dataclass
from importlib import metadata
from pathlib import Path
from typing import Final

import yaml

from datagen.core.camera import Intrinsics
from datagen.config.schema import Config
from datagen.core.conventions import OBJECT_NAMES, PIXEL_CONVENTION, split_uniform
from datagen.core.errors import DatagenError
from datagen.dataset.files import atomic_path, is_temporary
from datagen.dataset.schema import MANIFEST_VERSION
from datagen.core.training import TrainView, label_options

__all__ = [
    "DATASET_SCHEMA",
    "DATASET_SCHEMA_VERSION",
    "MANIFEST_NAME",
    "SPLITS",
    "DatasetLock",
    "Layout",
    "ShardJob",
    "asset_files",
    "check_folder",
    "config_fingerprint",
    "owned_files",
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
LOCK_NAME: Final = ".datagen.lock"
#: The name of a shard's manifest, ``{split}-{shard:05d}.parquet``; nothing else in manifests/ is one.
MANIFEST_NAME: Final = re.compile(r"(train|val)-[0-9]{5}\.parquet")


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
    from datagen.assets.files import RIGID_OBJECTS, object_paths

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
                     class_names: list[str], *, render: bool = True) -> dict:
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
        "render": render,
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
                        assets: dict, *, describe: bool, render: bool = True) -> None:
    """dataset.json (when ``describe``: a new dataset), then data.yaml, hyp.yaml and
    features.parquet, each atomically. dataset.json comes first so that a folder
    with any datagen file in it is recognisable as a dataset; the other three are
    pure functions of the config and are rewritten by every run."""
    from datagen.assets.files import feature_table
    from datagen.dataset.schema import write_features

    features = feature_table(config)
    names = list(features.name)
    root = layout.root
    if describe:
        document = dataset_document(config, jobs, fingerprint, assets, names, render=render)
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


def check_folder(layout: Layout) -> bool:
    """Whether ``layout.root`` may receive a build, looking only (nothing is created):
    False for a missing or empty folder, True for a datagen dataset; a folder that is
    not empty and holds no dataset is refused, with or without ``--overwrite`` (it
    may hold someone's data)."""
    root = layout.root
    if root.exists() and not root.is_dir():
        raise DatagenError(f"{root}: --out is a file, not a folder")
    try:
        # The lock and temporaries of an interrupted first run do not make a folder non-empty.
        entries = [p.name for p in root.iterdir() if p.name != LOCK_NAME and not is_temporary(p.name)] \
            if root.is_dir() else []
    except OSError as exc:
        raise DatagenError(f"{root}: cannot read the folder ({exc.strerror})") from None
    if not entries:
        return False
    if not layout.dataset_json.is_file():
        raise DatagenError(f"{root}: not empty and not a datagen dataset (no dataset.json); "
                           "choose an empty or new --out folder")
    return True


def prepare_folder(layout: Layout, fingerprint: str, config: Config, assets: dict, *, render: bool,
                   overwrite: bool) -> bool:
    """Decide what to do with the output folder; call with the lock held.

    Returns True when an earlier build of the same config is resumed. A folder
    that is not empty and holds no datagen dataset is refused (:func:`check_folder`);
    a dataset of another config, other assets or the other kind of build
    (rendered or labels-only) is refused unless ``overwrite``, which removes exactly
    what datagen wrote there (:func:`remove_owned`).
    """
    if not check_folder(layout):
        return False
    path = layout.dataset_json
    try:
        existing = json.loads(path.read_text())
        old_fingerprint, old_config = existing["fingerprint"], existing["config"]
    except (OSError, ValueError, KeyError, TypeError) as exc:
        if not overwrite:
            raise DatagenError(f"{path}: unreadable dataset description ({type(exc).__name__}); use --overwrite "
                               "to replace the dataset") from None
        existing, old_fingerprint, old_config = {}, None, {}
    if old_fingerprint == fingerprint:
        return True
    if not overwrite:
        changes = list(_differences(old_config, config.model_dump(mode="json")))
        if isinstance(existing.get("render"), bool) and existing["render"] != render:
            kind = "a labels-only build (--no-render)" if render else "a rendered build"
            changes.insert(0, f"render {json.dumps(existing['render'])} -> {json.dumps(render)}: the folder "
                              f"holds {kind}")
        old_assets = existing.get("assets") if isinstance(existing.get("assets"), dict) else {}
        for name, files in sorted(assets.items()):
            old = old_assets.get(name) if isinstance(old_assets.get(name), dict) else {}
            for kind in ("mesh", "features"):
                if old.get(f"{kind}_sha256") != files[f"{kind}_sha256"]:
                    changes.append(f"{name} {kind} file {files[kind]} changed")
        what = "; ".join(changes[:3]) + (f"; and {len(changes) - 3} more" if len(changes) > 3 else "")
        raise DatagenError(f"{path}: this folder holds a dataset of another config, assets or build "
                           f"({what or 'made by another datagen version'}); use --overwrite to replace it, or "
                           "choose another --out")
    remove_owned(layout, existing)
    return False


#: Report folders inside a dataset and the record each one's writer keeps of its files
#: (``files``: paths relative to the folder): what ``--overwrite`` may remove there.
REPORT_RECORDS: Final = {"audit": "report.json", "evaluation": "evaluation.json", "preview": "preview.json"}
#: Metadata files at the top of a dataset, in the order ``--overwrite`` removes them (dataset.json last).
METADATA: Final = ("data.yaml", "hyp.yaml", "train.txt", "val.txt", "features.parquet", "dataset.json")


def _inside(root: Path, rel: object) -> Path | None:
    """``root / rel`` for a relative path that stays inside ``root``, else None."""
    if not isinstance(rel, str) or not rel or rel.startswith("/") or "\0" in rel:
        return None
    parts = Path(rel).parts
    if ".." in parts:
        return None
    return root.joinpath(*parts)


def owned_files(layout: Layout, doc: dict) -> list[Path]:
    """Every file the dataset's own records say datagen wrote into ``layout.root``, in the
    order ``--overwrite`` removes them: manifests first (so that no shard counts as done
    if this is interrupted), then images, labels and EXRs, reports, metadata, and
    dataset.json last (so that the folder stays recognisable as a dataset until the end).

    The records: the shard plan of the config in dataset.json (every path a build of
    it writes), the paths each readable manifest names, and the ``files`` list of each
    report's own record (:data:`REPORT_RECORDS`)."""
    import pyarrow.parquet as pq

    root = layout.root
    manifests: list[Path] = []
    frames: list[str] = []
    try:
        config = Config.model_validate(doc.get("config", {}))
    except (ValueError, TypeError):
        config = None
    if config is not None:
        old = Layout(root, ".jpg" if config.render.image_format == "jpg" else ".png")
        for job in plan_shards(config):
            manifests.append(old.manifest(job))
            for i in job.frames:
                frames += [old.image_rel(job.split, job.shard, i), old.label_rel(job.split, job.shard, i),
                           old.exr_rel(job.split, job.shard, i)]
    named = sorted((root / "manifests").glob("*.parquet")) if (root / "manifests").is_dir() else []
    for path in named:
        if not MANIFEST_NAME.fullmatch(path.name):
            continue
        manifests.append(path)
        try:
            table = pq.read_table(path, columns=["image_path", "label_path", "exr_path"])
        except Exception:  # noqa: BLE001 (an unreadable manifest names nothing)
            continue
        for column in table.columns:
            frames += [p for p in column.to_pylist() if p]
    reports: list[Path] = []
    for folder, record in REPORT_RECORDS.items():
        path = root / folder / record
        try:
            listed = json.loads(path.read_text()).get("files", [])
        except (OSError, ValueError, AttributeError):
            listed = []
        reports += [p for rel in listed if isinstance(listed, list) and (p := _inside(root / folder, rel))]
        reports.append(path)
    ordered = manifests + [p for rel in frames if (p := _inside(root, rel))] + reports + [root / m for m in METADATA]
    return list(dict.fromkeys(ordered))


def _links_on_the_way(root: Path, paths: list[Path]) -> Path | None:
    """The first folder between ``root`` and any of ``paths`` that is a symbolic link."""
    checked: dict[Path, bool] = {}
    for path in paths:
        for parent in reversed(path.relative_to(root).parents[:-1]):
            folder = root / parent
            if folder not in checked:
                checked[folder] = folder.is_symlink()
            if checked[folder]:
                return folder
    return None


def remove_owned(layout: Layout, doc: dict) -> int:
    """Delete exactly the files :func:`owned_files` names (and datagen's temporaries beside
    them), never a folder with something else in it and never through a symbolic link:
    a linked folder on the way refuses the whole removal before anything is deleted.
    Folders left empty are removed. Returns how many files were deleted."""
    root = layout.root
    files = owned_files(layout, doc)
    link = _links_on_the_way(root, files)
    if link is not None:
        raise DatagenError(f"{link}: a symbolic link; --overwrite does not delete through links (remove the link "
                           "or its files yourself, or choose another --out)")
    folders = dict.fromkeys(p.parent for p in files)
    removed = 0
    for path in files:
        if path.is_file() and not path.is_symlink():
            path.unlink()
            removed += 1
    removed += sweep_temporaries(list(folders))
    for folder in sorted(folders, key=lambda p: len(p.parts), reverse=True):
        while folder != root and folder.is_relative_to(root):
            try:
                folder.rmdir()  # only when empty
            except OSError:
                break
            folder = folder.parent
    return removed


def sweep_temporaries(paths: list[Path]) -> int:
    """Remove datagen's own temporaries (:func:`datagen.dataset.files.is_temporary`) an interrupted
    writer left in these folders (not recursive); returns how many."""
    removed = 0
    for folder in paths:
        if not folder.is_dir() or folder.is_symlink():
            continue
        for entry in folder.iterdir():
            if is_temporary(entry.name) and entry.is_file() and not entry.is_symlink():
                entry.unlink(missing_ok=True)
                removed += 1
    return removed
