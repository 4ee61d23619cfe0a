"""The dataset folder as a place on disk: its lock, which folders a build may use, what
``--overwrite`` may remove, and the temporaries an interrupted writer leaves.

Nothing datagen did not write is ever removed or changed: a folder that is not a
dataset is refused before anything (the lock included) is created in it, and
``--overwrite`` removes exactly the files of the names datagen gives its own files
(:func:`owned_files`), found on disk, never by a path a file of the dataset names.
"""

from __future__ import annotations

import errno
import fcntl
import json
import os
import platform
import stat
from collections.abc import Iterator
from pathlib import Path
from typing import Final

from datagen.atomic import is_temporary
from datagen.config.inputs import read_json
from datagen.core.errors import ConfigError, DatagenError, shown
from datagen.dataset.layout import FRAME_FILE, FRAME_TREES, LOCK_NAME, MANIFEST_NAME, POSE_IMAGES_LINK, Layout
from datagen.dataset.limits import DATASET_JSON_BYTES
from datagen.dataset.reports import REPORTS, record_of
from datagen.paths import DatasetFolder, read_bytes
from datagen.pipeline.dataset_card import is_dataset_card
from datagen.scene.resolved import Scene

__all__ = [
    "METADATA",
    "DatasetLock",
    "check_folder",
    "owned_files",
    "prepare_folder",
    "remove_owned",
    "sweep_temporaries",
]

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
            fd = os.open(self.path, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW | os.O_NONBLOCK, 0o644)
        except OSError as exc:
            raise DatagenError(f"{exc.filename or self.path.parent}: cannot create the dataset folder's lock "
                               f"({exc.strerror})") from None
        info = os.fstat(fd)
        if not stat.S_ISREG(info.st_mode) or info.st_nlink != 1:
            os.close(fd)
            what = "not a regular file" if not stat.S_ISREG(info.st_mode) else \
                f"a file of {info.st_nlink} names (a hard link: another name of it may be outside the folder)"
            raise DatagenError(f"{self.path}: {what}; a build locks its folder with a file of its own and writes "
                               "nothing into this one (remove it)")
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError as exc:
            os.close(fd)
            if exc.errno not in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES):
                raise
            holder = _holder(self.path)
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


def _holder(path: Path) -> str:
    """Who holds the lock, as its file says (``pid N on HOST``), escaped and short."""
    try:
        text = read_bytes(path, "a lock", 256).decode("utf-8", "replace").strip()
    except DatagenError:
        text = ""
    return shown(text[:80]) or "another process"


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
    if entries and not layout.dataset_json.is_file():
        raise DatagenError(f"{root}: not empty and not a datagen dataset (no dataset.json); "
                           "choose an empty or new --out folder")
    if root.is_dir():  # a dataset, or a folder of nothing but a lock or a temporary: either may hold a link out
        for rel in DatasetFolder(root).links_out():
            raise DatagenError(f"{root / rel}: a symbolic link that leads outside the dataset; a build writes "
                               "only inside its folder (remove the link)")
    return bool(entries)


def prepare_folder(layout: Layout, fingerprint: str, scene: Scene, *, render: bool, overwrite: bool) -> bool:
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
        existing = read_json(path, "dataset description", DATASET_JSON_BYTES)
        old_fingerprint, old_config = existing["fingerprint"], existing["config"]
    except (DatagenError, KeyError, TypeError) as exc:
        if not overwrite:
            single = isinstance(exc, ConfigError) and len(exc.problems) == 1
            why = exc.problems[0].message if isinstance(exc, ConfigError) and single else type(exc).__name__
            raise DatagenError(f"{path}: unreadable dataset description ({shown(why)}); use --overwrite to replace "
                               "the dataset") from None
        existing, old_fingerprint, old_config = {}, None, {}
    if old_fingerprint == fingerprint:
        return True
    if not overwrite:
        changes = list(_differences(old_config, scene.config.model_dump(mode="json")))
        if isinstance(existing.get("render"), bool) and existing["render"] != render:
            kind = "a labels-only build (--no-render)" if render else "a rendered build"
            changes.insert(0, f"render {json.dumps(existing['render'])} -> {json.dumps(render)}: the folder "
                              f"holds {kind}")
        assets = existing.get("assets")
        old_assets: dict = assets if isinstance(assets, dict) else {}
        for name, files in sorted(scene.assets.items()):
            entry = old_assets.get(name)
            old: dict = entry if isinstance(entry, dict) else {}
            changes.extend(f"{name} {kind} file {files[kind]} changed" for kind in ("mesh", "features")
                           if old.get(f"{kind}_sha256") != files[f"{kind}_sha256"])
        what = "; ".join(changes[:3]) + (f"; and {len(changes) - 3} more" if len(changes) > 3 else "")
        raise DatagenError(f"{path}: this folder holds a dataset of another config, assets or build "
                           f"({what or 'made by another datagen version'}); use --overwrite to replace it, or "
                           "choose another --out")
    remove_owned(layout)
    return False


#: Metadata files at the top of a dataset, in the order ``--overwrite`` removes them (dataset.json last).
METADATA: Final = ("pose/data.yaml", "pose/hyp.yaml", "pose/train.txt", "pose/val.txt", "data.yaml", "hyp.yaml",
                   "train.txt", "val.txt", "features.parquet", "objects.parquet", "dataset.json")


def owned_files(layout: Layout) -> list[Path]:
    """Every file in ``layout.root`` that datagen writes there by its own plan, in the order
    ``--overwrite`` removes them: manifests first (so that no shard counts as done if this
    is interrupted), then the frames' images, labels and EXRs, the reports, the metadata,
    and dataset.json last (so that the folder stays recognisable as a dataset until the end).

    Found by walking the folder (never following a link), never from a path a file of the
    dataset names: a manifest's name (:data:`~datagen.dataset.layout.MANIFEST_NAME`), a
    frame's file of the layout's own form (:data:`~datagen.dataset.layout.FRAME_FILE`), the
    files each report's record lists of its writer's own form
    (:data:`~datagen.dataset.reports.REPORTS`), the dataset card and the metadata. A
    user's file among them, of another name, stays."""
    root = layout.root
    manifests = [root / "manifests" / name for name in _names(root / "manifests") if MANIFEST_NAME.fullmatch(name)]
    frames: list[Path] = []
    for tree in FRAME_TREES:
        top = root / tree
        if top.is_symlink() or not top.is_dir():
            continue
        for dirpath, dirnames, filenames in os.walk(top):
            dirnames[:] = sorted(d for d in dirnames if not os.path.islink(os.path.join(dirpath, d)))
            for name in sorted(filenames):
                path = Path(dirpath) / name
                if FRAME_FILE.fullmatch(path.relative_to(root).as_posix()):
                    frames.append(path)
    reports: list[Path] = []
    for kind in REPORTS.values():
        folder = root / kind.folder
        listed = record_of(kind, folder)
        if listed is not None:  # a record of datagen's: its files and itself
            reports += [folder / rel for rel in listed] + [folder / kind.record]
    card = [root / "README.md"] if is_dataset_card(root / "README.md") else []  # a user's README stays
    return list(dict.fromkeys(manifests + frames + reports + card + [root / m for m in METADATA]))


def _names(folder: Path) -> list[str]:
    """The names in ``folder``, sorted; none where it is missing or a link."""
    if folder.is_symlink() or not folder.is_dir():
        return []
    return sorted(os.listdir(folder))


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


def remove_owned(layout: Layout) -> int:
    """Delete exactly the files :func:`owned_files` names (and datagen's temporaries beside
    them), never a folder with something else in it and never through a symbolic link:
    a linked folder on the way refuses the whole removal before anything is deleted.
    Folders left empty are removed. Returns how many files were deleted."""
    root = layout.root
    files = owned_files(layout)
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
    link, target = root / POSE_IMAGES_LINK[0], POSE_IMAGES_LINK[1]
    if link.is_symlink() and os.readlink(link) == target:  # the pose set's link, never what it points to
        link.unlink()
        folders.setdefault(link.parent)
    for folder in sorted(folders, key=lambda p: len(p.parts), reverse=True):
        while folder != root and folder.is_relative_to(root):
            try:
                folder.rmdir()  # only when empty
            except OSError:
                break
            folder = folder.parent
    return removed


def sweep_temporaries(paths: list[Path]) -> int:
    """Remove datagen's own temporaries (:func:`datagen.atomic.is_temporary`) an interrupted
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
