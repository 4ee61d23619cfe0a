"""The dataset folder as a place on disk: its lock, which folders a build may use, what
``--overwrite`` may remove, and the temporaries an interrupted writer leaves.

Nothing datagen did not write is ever removed or changed: a folder that is not a
dataset is refused before anything (the lock included) is created in it, and
``--overwrite`` removes exactly the files the dataset's own records name.
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
from datagen.config.load import stored_config
from datagen.core.errors import DatagenError
from datagen.dataset.columns import FILE_COLUMNS
from datagen.dataset.layout import LOCK_NAME, MANIFEST_NAME, POSE_IMAGES_LINK, Layout
from datagen.paths import DatasetFolder, regular_file
from datagen.pipeline.dataset_card import is_dataset_card
from datagen.pipeline.plan import dataset_layout, plan_shards
from datagen.scene.resolved import Scene

__all__ = [
    "METADATA",
    "REPORT_RECORDS",
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
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            os.close(fd)
            raise DatagenError(f"{self.path}: not a regular file; a build locks its folder with it (remove it)")
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
        changes = list(_differences(old_config, scene.config.model_dump(mode="json")))
        if isinstance(existing.get("render"), bool) and existing["render"] != render:
            kind = "a labels-only build (--no-render)" if render else "a rendered build"
            changes.insert(0, f"render {json.dumps(existing['render'])} -> {json.dumps(render)}: the folder "
                              f"holds {kind}")
        old_assets = existing.get("assets") if isinstance(existing.get("assets"), dict) else {}
        for name, files in sorted(scene.assets.items()):
            old = old_assets.get(name) if isinstance(old_assets.get(name), dict) else {}
            changes.extend(f"{name} {kind} file {files[kind]} changed" for kind in ("mesh", "features")
                           if old.get(f"{kind}_sha256") != files[f"{kind}_sha256"])
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
METADATA: Final = ("pose/data.yaml", "pose/hyp.yaml", "pose/train.txt", "pose/val.txt", "data.yaml", "hyp.yaml",
                   "train.txt", "val.txt", "features.parquet", "objects.parquet", "dataset.json")


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
        config = stored_config(doc.get("config", {}))
    except (ValueError, TypeError):
        config = None
    if config is not None:
        old = dataset_layout(root, config)
        for job in plan_shards(config):
            manifests.append(old.manifest(job))
            for i in job.frames:
                frames += [p for p in (old.image_rel(job.split, job.shard, i), old.label_rel(job.split, job.shard, i),
                                       old.pose_label_rel(job.split, job.shard, i),
                                       old.exr_rel(job.split, job.shard, i)) if p]
    named = sorted((root / "manifests").glob("*.parquet")) if (root / "manifests").is_dir() else []
    for path in named:
        if not MANIFEST_NAME.fullmatch(path.name):
            continue
        manifests.append(path)
        if not regular_file(path):
            continue
        try:
            table = pq.read_table(path, columns=[c for c in FILE_COLUMNS if c in pq.read_schema(path).names])
        except Exception:
            continue
        for column in table.columns:
            frames += [p for p in column.to_pylist() if p]
    reports: list[Path] = []
    for folder, record in REPORT_RECORDS.items():
        path = root / folder / record
        try:
            listed = json.loads(path.read_text()).get("files", []) if regular_file(path) else []
        except (OSError, ValueError, AttributeError):
            listed = []
        reports += [p for rel in listed if isinstance(listed, list) and (p := _inside(root / folder, rel))]
        reports.append(path)
    card = [root / "README.md"] if is_dataset_card(root / "README.md") else []  # a user's README stays
    ordered = (manifests + [p for rel in frames if (p := _inside(root, rel))] + reports + card
               + [root / m for m in METADATA])
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
