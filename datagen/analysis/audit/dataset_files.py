"""The dataset's files: every file a manifest names exists and nothing else is there, the image
lists, the planned shards, and how an image is decoded (its size read from its header first)."""

from __future__ import annotations

import contextlib
import os
from pathlib import Path
from typing import Final

import numpy as np

from datagen.analysis.audit.check import MAX_OFFENDERS, Check
from datagen.atomic import is_temporary
from datagen.config.inputs import parse_yaml, read_text
from datagen.core.errors import DatagenError, shown
from datagen.dataset.layout import DATA_YAML_KEYS, MANIFEST_NAME, SPLITS
from datagen.dataset.limits import HYP_YAML_BYTES, ReadLimits
from datagen.dataset.reader import DatasetMeta, FrameOrder, image_size, plan_gaps
from datagen.dataset.training_run import recipe_problems
from datagen.paths import Unreadable, read_bytes, regular_file

#: Files Ultralytics writes into a dataset it trains on: label caches beside the label
#: folders (``labels/train/00000.cache``, and ``.cache.npy`` while it writes one) and
#: ``.npy`` image caches beside the images (``cache=disk``). They are not orphans.
ULTRALYTICS_SUFFIXES: Final = (".cache", ".cache.npy", ".npy")


def check_files(view: FrameOrder) -> Check:
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
        elif not regular_file(root / rel):
            check.fail(rel, "named in a manifest but missing" if not os.path.lexists(root / rel)
                       else "named in a manifest but not a regular file, or in a folder that cannot be read")
    for rel in folder.links_out():
        check.checked += 1
        check.fail(rel, "a symbolic link that leads outside the dataset: no reader follows it")
    for tree in ("images", "labels", "exr", *(("pose/labels",) if view.label_format == "both" else ())):
        if folder.problem(tree) or not os.path.isdir(root / tree):
            continue  # a link out of the dataset (named above, not walked), or no such tree
        def unreadable(exc: OSError) -> None:
            check.fail(os.path.relpath(os.fsdecode(exc.filename), root), f"a folder that cannot be read "
                       f"({exc.strerror}): its files are not checked")

        for dirpath, _, files in os.walk(root / tree, onerror=unreadable):
            for name in files:
                rel = str((Path(dirpath) / name).relative_to(root))
                check.checked += 1
                if is_temporary(name):
                    check.fail(rel, "temporary file left by an interrupted writer")
                elif rel not in referenced and not name.endswith(ULTRALYTICS_SUFFIXES):
                    check.fail(rel, "orphan: no manifest names it")
    for name in sorted(os.listdir(root / "manifests")):  # read by open_dataset already
        if is_temporary(name):
            check.fail(f"manifests/{name}", "temporary file left by an interrupted writer")
        elif not MANIFEST_NAME.fullmatch(name):
            check.fail(f"manifests/{name}", "not a shard manifest ({split}-{shard:05d}.parquet): an orphan")
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


def image_list_problems(index: FrameOrder) -> list[tuple[str, str]]:
    """``(file, problem)`` of the image lists Ultralytics trains on (``train.txt``,
    ``val.txt``, and the pose set's): each must list exactly the manifests' images of its
    split, in frame order, and each image listed must be a regular file inside the dataset
    (a line naming a file elsewhere would make Ultralytics read it and write its caches
    beside it; a FIFO would block it). Each list is read within
    :meth:`~datagen.dataset.limits.ReadLimits.image_list_bytes`."""
    root, folder = index.root, index.folder
    rows = sorted(zip(index.frame_id.tolist(), index.split, index.image_path, strict=True))
    prefixes = ("", "pose/") if index.label_format == "both" else ("",)
    problems = []
    limits = index.limits
    for split, prefix in ((s, p) for s in SPLITS for p in prefixes):
        want = [f"./{rel}" for _, s, rel in rows if s == split and rel]
        if not want:
            continue
        name = f"{prefix}{split}.txt"
        try:
            have = read_bytes(folder.file(name), "an image list", limits.image_list_bytes(split)) \
                .decode("utf-8").splitlines()
        except (DatagenError, UnicodeDecodeError) as exc:
            why = exc.problem if isinstance(exc, Unreadable) else "not UTF-8 text" \
                if isinstance(exc, UnicodeDecodeError) else str(exc)
            problems.append((name, f"{why}; it lists the {split} images for Ultralytics"))
            continue
        if have != want:
            extra = sorted(set(have) - set(want))[:1]
            what = (f"names {shown(extra[0][:120])!r}, which no manifest does" if extra
                    else "misses images or lists them out of order")
            problems.append((name, f"{what} ({len(have)} lines, {len(want)} {split} images)"))
            continue
        for line in have:
            rel = line.removeprefix("./")
            wrong = folder.problem(rel) or (None if regular_file(root / rel) else "missing or not a regular file")
            if wrong:
                problems.append((name, f"{shown(line[:120])}: {wrong}"))
                break
    return problems


def check_recipe(meta: DatasetMeta) -> Check:
    """What Ultralytics reads and runs when it trains: data.yaml and hyp.yaml (and the pose
    set's) hold only what datagen writes there, the image lists of this dataset (no ``path``
    or ``download``: Ultralytics resolves the one and runs the other), and settings of the
    recipe's table in their ranges (:data:`~datagen.dataset.training_run.RECIPE_SETTINGS`:
    none that names a file, model or command, or writes without bound); and the image lists
    themselves (:func:`image_list_problems`)."""
    check = Check("training_recipe", "data.yaml, hyp.yaml and the image lists name only this dataset's images and "
                  "settings of datagen's recipe in their ranges: no other file, folder, model or command, and "
                  "nothing that writes without bound (what Ultralytics reads and runs when it trains)")
    sets = ["", "pose/"] if meta.label_format == "both" else [""]
    for prefix in sets:
        data = (meta.pose_yaml if prefix else meta.data_yaml) or {}
        name = f"{prefix}data.yaml"
        check.checked += 1
        for key in sorted(set(map(str, data)) - set(DATA_YAML_KEYS)):
            check.fail(name, f"{shown(key[:40])!r}: not a key datagen writes ({', '.join(DATA_YAML_KEYS)})")
        for key in ("train", "val"):
            if data.get(key) not in ("train.txt", "val.txt"):
                check.fail(name, f"{key}: {shown(str(data.get(key))[:60])!r}; expected train.txt or val.txt, the "
                           "image lists beside it")
        hyp = f"{prefix}hyp.yaml"
        check.checked += 1
        try:
            doc = parse_yaml(read_text(meta.folder.file(hyp), "hyp.yaml", max_bytes=HYP_YAML_BYTES), meta.root / hyp)
        except DatagenError as exc:
            check.fail(hyp, " ".join(str(exc).split())[:160])
            continue
        for problem in recipe_problems(doc):
            check.fail(hyp, problem)
    check.checked += len(sets) * len(SPLITS)
    for name, problem in image_list_problems(meta.frames()):
        check.fail(name, problem)
    return check


#: Bytes read to find an image's size in its header (a JPEG's frame header may follow its EXIF).
HEADER_BYTES: Final = 65536
#: The largest on-screen footprint a world texel may have (px): above about 1.5 px a texture's
#: grid starts to show.
MAX_WORLD_TEXEL_PX: Final = 1.5


def check_texels(view: FrameOrder) -> Check:
    """No rendered frame shows a world texture's texel larger than :data:`MAX_WORLD_TEXEL_PX`
    on screen (the manifest's ``world_texel_px``; 0 for the procedural sea and clouds)."""
    check = Check("world_texels", f"no rendered frame shows a world texel over {MAX_WORLD_TEXEL_PX:g} px "
                  "(the sea and clouds are procedural: 0)")
    values = np.asarray(view.world_texel_px, dtype=np.float64)  # NaN (or None) where no sea or cloud was seen
    seen = np.isfinite(values)
    check.checked = int(seen.sum())
    check.applicable = check.checked > 0
    check.worst = float(values[seen].max()) if check.checked else None
    for b in np.flatnonzero(seen & (values > MAX_WORLD_TEXEL_PX)):
        check.fail(f"{view.manifest_file[b]} frame {view.frame_id[b]}", f"a world texel spans {values[b]:.2f} px",
                   float(values[b]), row=int(b))
    return check



def image_header_problem(data: bytes, path: Path, limits: ReadLimits) -> str | None:
    """Why the first bytes of an image file are not those of a frame of the dataset, or
    None: a PNG or JPEG (as its suffix says) whose header states the dataset's size."""
    found = image_size(data[:HEADER_BYTES])
    if found is None:
        return "not a PNG or JPEG image"
    kind = "png" if data[:4] == b"\x89PNG" else "jpg"
    if path.suffix.lower().lstrip(".").replace("jpeg", "jpg") != kind:
        return f"a {kind.upper()} image named {path.suffix or 'without a suffix'}"
    if found != (limits.width, limits.height):
        return f"{found[0]}x{found[1]} px, dataset.json says {limits.width}x{limits.height}"
    return None


def decode_image(path: Path, limits: ReadLimits) -> tuple[np.ndarray | None, str | None]:
    """The image at ``path`` decoded (BGR, uint8), or why not: at most
    :attr:`~datagen.dataset.limits.ReadLimits.image_bytes`, its header must state the
    dataset's size before anything is decoded (:func:`image_header_problem`), and it must
    decode fully to 8-bit colour. A missing file is ``(None, None)``: the files check names
    it. Call it inside :func:`quiet_stderr` (libpng speaks of a damaged file on the
    process's stderr)."""
    import cv2

    try:
        data = read_bytes(path, "an image", limits.image_bytes)
    except Unreadable as exc:
        return None, None if exc.problem == "no such file" else exc.problem
    problem = image_header_problem(data, path, limits)
    if problem:
        return None, problem
    image = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
    if image is None:
        return None, "does not decode (truncated or corrupt)"
    if image.dtype != np.uint8 or image.shape != (limits.height, limits.width, 3):
        return None, f"decodes to {image.dtype} {image.shape}, expected uint8 ({limits.height}, {limits.width}, 3)"
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
