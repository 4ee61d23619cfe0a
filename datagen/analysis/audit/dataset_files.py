"""The dataset's files: every file a manifest names exists and nothing else is there, the image
lists, the planned shards, and how an image is decoded (its size read from its header first)."""

from __future__ import annotations

import contextlib
import os
import stat
from pathlib import Path
from typing import Final

import numpy as np

from datagen.analysis.audit.check import MAX_OFFENDERS, Check
from datagen.atomic import is_temporary
from datagen.config.inputs import parse_yaml, read_text
from datagen.core.camera import Intrinsics
from datagen.core.errors import DatagenError
from datagen.dataset.layout import DATA_YAML_KEYS, HYP_PATH_KEYS, MANIFEST_NAME
from datagen.dataset.reader import DatasetIndex, DatasetMeta, DatasetView, image_size, plan_gaps

#: Files Ultralytics writes into a dataset it trains on: label caches beside the label
#: folders (``labels/train/00000.cache``, and ``.cache.npy`` while it writes one) and
#: ``.npy`` image caches beside the images (``cache=disk``). They are not orphans.
ULTRALYTICS_SUFFIXES: Final = (".cache", ".cache.npy", ".npy")


def check_files(view: DatasetIndex | DatasetView) -> Check:
    check = Check("files", "every image, label and EXR a manifest names exists inside the dataset, no "
                  "symbolic link leads out of it, no file in images/, labels/ or exr/ is unnamed, no temporary "
                  "file is left, and every planned shard is finished")
    root, folder = view.root, view.folder
    referenced = {p for paths in (view.image_path, view.label_path, view.pose_label_path, view.exr_path)
                  for p in paths if p}
    for rel in sorted(referenced):
        check.checked += 1
        problem = folder.problem(rel)
        if problem:
            check.fail(rel, problem)
        elif not (root / rel).is_file():
            check.fail(rel, "named in a manifest but missing")
    for rel in folder.links_out():
        check.checked += 1
        check.fail(rel, "a symbolic link that leads outside the dataset: no reader follows it")
    for tree in ("images", "labels", "exr", *(("pose/labels",) if view.label_format == "both" else ())):
        if folder.problem(tree):
            continue  # a link out of the dataset: named above, not walked
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
            have = listed.read_text().splitlines() if listed.is_file() and not folder.problem(name) else None
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
    check.checked += len(splits) if isinstance(splits, dict) else 0
    for gap in plan_gaps(view):
        check.fail("dataset.json", gap)
    return check


def check_recipe(meta: DatasetMeta) -> Check:
    """data.yaml and hyp.yaml (and the pose set's) hold only what datagen writes there: the
    image lists of this dataset, no ``path`` or ``download`` (Ultralytics resolves the one
    and runs the other), and no setting that names a file, model or command."""
    check = Check("training_recipe", "data.yaml and hyp.yaml name only this dataset's image lists and no other "
                  "file, folder, model or command (what Ultralytics reads and runs when it trains)")
    sets = ["", "pose/"] if meta.label_format == "both" else [""]
    for prefix in sets:
        data = meta.pose_yaml if prefix else meta.data_yaml
        name = f"{prefix}data.yaml"
        check.checked += 1
        for key in sorted(set(map(str, data)) - set(DATA_YAML_KEYS)):
            check.fail(name, f"{key[:40]!r}: not a key datagen writes ({', '.join(DATA_YAML_KEYS)})")
        for key in ("train", "val"):
            if data.get(key) not in ("train.txt", "val.txt"):
                check.fail(name, f"{key}: {str(data.get(key))[:60]!r}; expected train.txt or val.txt, the image "
                           "lists beside it")
        hyp = f"{prefix}hyp.yaml"
        check.checked += 1
        try:
            doc = parse_yaml(read_text(meta.folder.file(hyp), "hyp.yaml"), meta.root / hyp)
        except DatagenError as exc:
            check.fail(hyp, " ".join(str(exc).split())[:160])
            continue
        if not isinstance(doc, dict):
            check.fail(hyp, "expected a mapping of Ultralytics settings")
            continue
        for key, value in doc.items():
            if str(key) in HYP_PATH_KEYS:
                check.fail(hyp, f"{str(key)[:40]!r}: names a file, folder, model or command; datagen writes none")
            elif not isinstance(value, (int, float, bool)) and not (isinstance(value, str) and value.isalnum()):
                check.fail(hyp, f"{str(key)[:40]!r}: {str(value)[:40]!r} is not a number, a flag or a word")
    return check


#: Bytes read to find an image's size in its header (a JPEG's frame header may follow its EXIF).
_HEADER_BYTES: Final = 65536
#: The largest on-screen footprint a world texel may have (px): above about 1.5 px a texture's
#: grid starts to show.
MAX_WORLD_TEXEL_PX: Final = 1.5


def check_texels(view: DatasetIndex | DatasetView) -> Check:
    """No rendered frame shows a world texture's texel larger than :data:`MAX_WORLD_TEXEL_PX`
    on screen (the manifest's ``world_texel_px``; 0 for the procedural sea and clouds)."""
    check = Check("world_texels", f"no rendered frame shows a world texel over {MAX_WORLD_TEXEL_PX:g} px "
                  "(the sea and clouds are procedural: 0)")
    values = np.array([np.nan if v is None else v for v in view.world_texel_px], dtype=np.float64)
    seen = np.isfinite(values)
    check.checked = int(seen.sum())
    check.applicable = check.checked > 0
    check.worst = float(values[seen].max()) if check.checked else None
    for b in np.flatnonzero(seen & (values > MAX_WORLD_TEXEL_PX)):
        check.fail(f"{view.manifest_file[b]} frame {view.frame_id[b]}", f"a world texel spans {values[b]:.2f} px",
                   float(values[b]), row=int(b))
    return check



def decode_image(path: Path, k: Intrinsics) -> tuple[np.ndarray | None, str | None]:
    """The image at ``path`` decoded (BGR, uint8), or why not: its header must state the
    dataset's size (``k``) before anything is decoded, and it must decode fully to 8-bit
    colour. A missing file is ``(None, None)``: the files check names it. Call it inside
    :func:`quiet_stderr` (libpng speaks of a damaged file on the process's stderr)."""
    import cv2

    # A decoded frame is at most its raw size; a file far larger than that is not one.
    max_bytes = 4 * k.width * k.height * 3 + (1 << 20)
    try:
        info = path.stat()
        if not stat.S_ISREG(info.st_mode):
            return None, "not a regular file"
        if info.st_size > max_bytes:
            return None, f"{info.st_size:,} bytes, more than a {k.width}x{k.height} image can take"
        data = path.read_bytes()
    except FileNotFoundError:
        return None, None
    except OSError as exc:
        return None, f"unreadable ({exc.strerror})"
    found = image_size(data[:_HEADER_BYTES])
    if found is None:
        return None, "not a PNG or JPEG image"
    if found != (k.width, k.height):
        return None, f"{found[0]}x{found[1]} px, dataset.json says {k.width}x{k.height}"
    image = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
    if image is None:
        return None, "does not decode (truncated or corrupt)"
    if image.dtype != np.uint8 or image.shape != (k.height, k.width, 3):
        return None, f"decodes to {image.dtype} {image.shape}, expected uint8 ({k.height}, {k.width}, 3)"
    return image, None


@contextlib.contextmanager
def quiet_stderr():
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
