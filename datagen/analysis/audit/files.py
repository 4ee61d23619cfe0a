"""The dataset's files: every file a manifest names exists and nothing else is there, the image
lists, the planned shards, and every image decodes to the dataset's size."""

from __future__ import annotations

import contextlib
import os
import stat
from pathlib import Path
from typing import Final

import numpy as np

from datagen.analysis.audit.check import MAX_OFFENDERS, Check
from datagen.core.camera import Intrinsics
from datagen.dataset.layout import MANIFEST_NAME
from datagen.dataset.reader import DatasetIndex, DatasetView, image_size
from datagen.files import is_temporary

#: Files Ultralytics writes into a dataset it trains on: label caches beside the label
#: folders (``labels/train/00000.cache``, and ``.cache.npy`` while it writes one) and
#: ``.npy`` image caches beside the images (``cache=disk``). They are not orphans.
ULTRALYTICS_SUFFIXES: Final = (".cache", ".cache.npy", ".npy")


def check_files(view: DatasetIndex | DatasetView) -> Check:
    check = Check("files", "every image, label and EXR a manifest names exists, no file in images/, labels/ "
                  "or exr/ is unnamed, no temporary file is left, and every planned shard is finished")
    root = view.root
    referenced = {p for paths in (view.image_path, view.label_path, view.pose_label_path, view.exr_path)
                  for p in paths if p}
    for rel in sorted(referenced):
        check.checked += 1
        if not (root / rel).is_file():
            check.fail(rel, "named in a manifest but missing")
    for tree in ("images", "labels", "exr", *(("pose/labels",) if view.label_format == "both" else ())):
        for dirpath, _, files in os.walk(root / tree):
            for name in files:
                rel = str((Path(dirpath) / name).relative_to(root))
                check.checked += 1
                if is_temporary(name):
                    check.fail(rel, "temporary file left by an interrupted writer")
                elif rel not in referenced and not name.endswith(ULTRALYTICS_SUFFIXES):
                    check.fail(rel, "orphan: no manifest names it")
    for name in sorted(os.listdir(root / "manifests")):
        if is_temporary(name):
            check.fail(f"manifests/{name}", "temporary file left by an interrupted writer")
        elif not MANIFEST_NAME.fullmatch(name):
            check.fail(f"manifests/{name}", "not a shard manifest ({split}-{shard:05d}.parquet): an orphan")
    rows = sorted(zip(view.frame_id.tolist(), view.split, view.image_path, strict=True))
    prefixes = ("", "pose/") if view.label_format == "both" else ("",)
    for split, prefix in ((s, p) for s in ("train", "val") for p in prefixes):  # what Ultralytics trains on
        want = [f"./{rel}" for _, s, rel in rows if s == split and rel]
        if not want:
            continue
        name = f"{prefix}{split}.txt"
        listed = root / name
        check.checked += 1
        try:
            have = listed.read_text().splitlines() if listed.is_file() else None
        except (OSError, UnicodeDecodeError):
            have = None
        if have is None:
            check.fail(name, f"missing or unreadable; it lists the {split} images for Ultralytics")
        elif have != want:
            extra = sorted(set(have) - set(want))[:1]
            what = (f"names {extra[0]!r}, which no manifest does" if extra
                    else "misses images or lists them out of order")
            check.fail(name, f"{what} ({len(have)} lines, {len(want)} {split} images)")
    ids, counts = np.unique(view.frame_id, return_counts=True)
    for frame in ids[counts > 1][:MAX_OFFENDERS]:
        rows = [view.manifest_file[b] for b in np.flatnonzero(view.frame_id == frame)]
        check.fail(rows[0], f"frame {frame} is in {len(rows)} manifest rows ({', '.join(sorted(set(rows)))}): a "
                   "manifest copied or renamed by hand")
    splits = view.doc.get("splits", {})
    for split, planned in (splits.items() if isinstance(splits, dict) else []):
        have = len({int(f) for f, s in zip(view.frame_id, view.split, strict=True) if s == split})
        want = planned.get("frames", have) if isinstance(planned, dict) else have
        check.checked += 1
        if have < want:
            check.fail("dataset.json", f"splits.{split}: {want} frames planned, {have} in the manifests "
                       "(an unfinished build: rerun it)")
        elif have > want:
            check.fail("dataset.json", f"splits.{split}: {want} frames planned, {have} in the manifests "
                       "(manifests from another build?)")
    return check


#: Bytes read to find an image's size in its header (a JPEG's frame header may follow its EXIF).
_HEADER_BYTES: Final = 65536
#: The largest on-screen footprint a world texel may have (px): above about 1.5 px a texture's
#: grid starts to show.
MAX_WORLD_TEXEL_PX: Final = 1.5


def check_texels(view: DatasetIndex | DatasetView) -> Check:
    """No rendered frame shows a world texture's texel (the sea's wave normals) larger than
    :data:`MAX_WORLD_TEXEL_PX` on screen (the manifest's ``world_texel_px``)."""
    check = Check("world_texels", f"no rendered frame shows a world texel over {MAX_WORLD_TEXEL_PX:g} px "
                  "(clouds are procedural; the sea's wave normals are a texture)")
    values = np.array([np.nan if v is None else v for v in view.world_texel_px], dtype=np.float64)
    seen = np.isfinite(values)
    check.checked = int(seen.sum())
    check.applicable = check.checked > 0
    check.worst = float(values[seen].max()) if check.checked else None
    for b in np.flatnonzero(seen & (values > MAX_WORLD_TEXEL_PX)):
        check.fail(f"{view.manifest_file[b]} frame {view.frame_id[b]}", f"a world texel spans {values[b]:.2f} px",
                   float(values[b]), row=int(b))
    return check



def check_images(view: DatasetIndex | DatasetView, k: Intrinsics) -> Check:
    """Open every image a manifest names: its header states the dataset's size (``k``), and
    it decodes fully (a truncated file or one that is not an image fails). Missing files
    are the ``files`` check's."""
    import cv2

    check = Check("images", f"every image a manifest names decodes fully, {k.width}x{k.height} 8-bit colour as "
                  "dataset.json states")
    paths = [p for p in view.image_path if p]
    # A decoded frame is at most its raw size; a file far larger than that is not one.
    max_bytes = 4 * k.width * k.height * 3 + (1 << 20)

    def one(rel: str) -> str | None:
        path = view.root / rel
        try:
            info = path.stat()
            size = info.st_size
            if not stat.S_ISREG(info.st_mode):
                return "not a regular file"
            if size > max_bytes:
                return f"{size:,} bytes, more than a {k.width}x{k.height} image can take"
            data = path.read_bytes()
        except FileNotFoundError:
            return None
        except OSError as exc:
            return f"unreadable ({exc.strerror})"
        found = image_size(data[:_HEADER_BYTES])
        if found is None:
            return "not a PNG or JPEG image"
        if found != (k.width, k.height):
            return f"{found[0]}x{found[1]} px, dataset.json says {k.width}x{k.height}"
        image = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
        if image is None:
            return "does not decode (truncated or corrupt)"
        if image.dtype != np.uint8 or image.shape != (k.height, k.width, 3):
            return f"decodes to {image.dtype} {image.shape}, expected uint8 ({k.height}, {k.width}, 3)"
        return None

    from concurrent.futures import ThreadPoolExecutor

    with _quiet_stderr(), ThreadPoolExecutor(max(1, os.cpu_count() or 1)) as pool:  # OpenCV decodes without the GIL
        for rel, problem in zip(paths, pool.map(one, paths), strict=True):
            check.checked += 1
            if problem:
                check.fail(rel, problem)
    return check


@contextlib.contextmanager
def _quiet_stderr():
    """Silence what libpng prints to the process's stderr about a damaged file (the check
    names the file itself)."""
    try:
        saved = os.dup(2)
    except OSError:
        yield
        return
    try:
        with open(os.devnull, "wb") as null:
            os.dup2(null.fileno(), 2)
        yield
    finally:
        os.dup2(saved, 2)
        os.close(saved)
