"""``datagen export``: a built dataset in the formats other tools read, from its manifests,
``features.parquet``, ``objects.parquet``, images and (for masks) EXR object ids.

- **COCO keypoints** (:func:`export_coco`): ``OUT/annotations/{split}.json`` and the images
  under ``OUT/images/...`` (hard links where the file system allows, else copies). One
  category per labeled object, its ``keypoints`` the names of its features in class-id order
  (no skeleton); one annotation per labeled object (the pose instance of
  :mod:`datagen.core.keypoints`): ``bbox`` its box, ``keypoints`` ``x, y, v`` per feature
  with COCO's visibility flags (0 not labeled, 1 labeled but hidden, 2 visible), and
  ``num_keypoints``. Keypoint coordinates follow COCO's pixel-index convention (integer
  coordinates at pixel centres: :func:`datagen.core.conventions.index_px`); boxes span the
  continuous pixels they cover.
- **BOP** (:func:`export_bop`, the format of ``bop_toolkit/docs/bop_datasets_format.md``):
  ``models/obj_{id:06d}.ply`` in millimetres with ``models_info.json``; one scene per shard,
  ``{split}/{shard:06d}/`` with ``rgb/``, ``mask/`` (the object alone, by ray casting),
  ``mask_visib/`` (its pixels in the EXR object-id pass), ``scene_camera.json`` (``cam_K``
  in the pixel-index convention, as calibrated OpenCV cameras are), ``scene_gt.json``
  (``cam_R_m2c``, ``cam_t_m2c`` in mm, ``obj_id`` of :func:`datagen.core.conventions.object_id`)
  and ``scene_gt_info.json`` (``bbox_obj`` from the projected hull, or from the silhouette
  when the object reaches behind the camera, ``bbox_visib``, pixel
  counts and ``visib_fract``). BOP cameras are pinholes: a dataset with lens distortion is refused.

The output folder must not exist (or be empty); everything is written under a hidden
temporary folder beside it, renamed into place when complete.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import stat
from collections.abc import Callable
from pathlib import Path
from typing import Final

import numpy as np
from numpy.typing import NDArray

from datagen.atomic import link_or_copy, write_image, write_text
from datagen.core.conventions import index_px, object_id
from datagen.core.errors import DatagenError
from datagen.core.label_boxes import FrameLabels
from datagen.dataset.limits import ReadLimits
from datagen.dataset.reader import DatasetView
from datagen.paths import opened_file, read_bytes, regular_file

__all__ = ["EXPORT_FORMATS", "export_bop", "export_coco", "export_dataset"]

EXPORT_FORMATS: Final = ("coco", "bop")
#: BOP stores lengths in millimetres.
MM_PER_M: Final = 1000.0


def export_dataset(view: DatasetView, out: Path, fmt: str, progress: Callable[[int], None] | None = None) -> Path:
    """Write ``view`` as ``fmt`` (``coco`` or ``bop``) into the new folder ``out``."""
    if fmt not in EXPORT_FORMATS:
        raise DatagenError(f"--format: {fmt!r}: choose {' or '.join(EXPORT_FORMATS)}")
    missing = [i for i, p in enumerate(view.image_path) if not p]
    if missing:
        raise DatagenError(f"{view.root / view.manifest_file[missing[0]]}: frame {view.frame_id[missing[0]]} has no "
                           f"image (a --no-render build): a {fmt.upper()} export needs the images")
    if fmt == "bop":
        if any(not p for p in view.exr_path):
            raise DatagenError(f"{view.root}: the BOP export needs the EXR object ids for its masks: build the "
                               "dataset with --exr")
        if view.distortion.any():
            b = int(np.flatnonzero(view.distortion.any(axis=1))[0])
            raise DatagenError(f"{view.root / view.manifest_file[b]}: frame {view.frame_id[b]} has lens distortion; "
                               "BOP's cameras are pinholes (build with randomization.sensor.distortion off)")
        if view.readout_s.any():
            b = int(np.flatnonzero(view.readout_s)[0])
            raise DatagenError(f"{view.root / view.manifest_file[b]}: frame {view.frame_id[b]} has a rolling shutter; "
                               "BOP's poses are one instant's (build with randomization.sensor.rolling_shutter off)")
    for rel in view.image_path:  # nothing outside the dataset, nothing but the dataset's images
        _check_image(view, rel)
    for rel in view.exr_path if fmt == "bop" else []:
        if not rel or not regular_file(view.folder.file(rel)):
            raise DatagenError(f"{view.root / (rel or '')}: missing or not a regular file")
    out = Path(os.path.abspath(out))
    if out.is_symlink():
        raise DatagenError(f"--out: {out}: a symbolic link; an export is written only into a new real folder")
    if out.exists() and (not out.is_dir() or any(out.iterdir())):
        raise DatagenError(f"--out: {out}: exists and is not an empty folder; choose a new one")
    if out.exists() and not out.stat().st_mode & stat.S_IWUSR:
        raise DatagenError(f"--out: {out}: a read-only folder; make it writable or choose a new one")
    if out.resolve().is_relative_to(view.folder.real_root):
        raise DatagenError(f"--out: {out}: inside the dataset {view.root}; choose a folder outside it")
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
    except (FileExistsError, NotADirectoryError):
        raise DatagenError(f"--out: {out.parent}: a file is in the way of the folder; choose another") from None
    tmp = out.parent / f".{out.name}.datagen-export-{os.getpid()}"
    if tmp.is_symlink() or tmp.is_file():
        tmp.unlink()
    shutil.rmtree(tmp, ignore_errors=True)
    try:
        tmp.mkdir()
        (export_coco if fmt == "coco" else export_bop)(view, tmp, progress or (lambda n: None))
        if out.exists():  # the user's empty folder (checked above) stays, the export moves into it
            for entry in sorted(tmp.iterdir()):
                entry.rename(out / entry.name)
            tmp.rmdir()
        else:
            tmp.rename(out)
    except OSError as exc:  # the file it is about, named in the export, not in the hidden folder it is written in
        shutil.rmtree(tmp, ignore_errors=True)
        where = os.fsdecode(exc.filename) if exc.filename is not None else str(out)
        if Path(where).is_relative_to(tmp):
            where = str(out / Path(where).relative_to(tmp))
        raise DatagenError(f"{where}: {exc.strerror or 'cannot be written'}") from None
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)  # only the temporary folder this export made
        raise
    return out


def _check_image(view: DatasetView, rel: str | None) -> Path:
    """The dataset's image ``rel``, once it is a regular file inside the dataset of at most
    :attr:`~datagen.dataset.limits.ReadLimits.image_bytes`, whose header says it is a PNG or
    JPEG (as its suffix says) of the dataset's size: an export links only the dataset's own
    frames beside annotations that state their size."""
    from datagen.analysis.audit.dataset_files import HEADER_BYTES, image_header_problem

    if not rel:
        raise DatagenError(f"{view.root}: a frame without an image (a --no-render build)")
    path = view.folder.file(rel)
    head = read_bytes(path, "an image", view.limits.image_bytes, head=HEADER_BYTES)
    problem = image_header_problem(head, path, view.limits)
    if problem:
        raise DatagenError(f"{path}: {problem}")
    return path


def _json(doc: object, **options) -> str:
    """``doc`` as strict JSON (a value that is not a finite number is refused: other
    tools' readers take no ``NaN``)."""
    try:
        return json.dumps(doc, allow_nan=False, **options)
    except ValueError as exc:
        raise DatagenError(f"a value of the export is not a finite number ({exc})") from None


def _xywh(xyxy: NDArray[np.float64]) -> list[float]:
    x0, y0, x1, y1 = (float(v) for v in xyxy)
    return [x0, y0, x1 - x0, y1 - y0]


# --- COCO ----------------------------------------------------------------------------------------
def coco_document(view: DatasetView, rows: list[int], objects: FrameLabels) -> dict:
    """The COCO keypoints document of the manifest rows ``rows`` (image paths as in the dataset);
    ``objects``: the dataset's pose boxes (:meth:`DatasetView.recompute_objects`)."""
    layout = view.pose_layout
    k = view.intrinsics
    names = layout.names(view.features)
    categories = [{"id": c + 1, "name": name, "supercategory": "aircraft", "keypoints": names[c], "skeleton": []}
                  for c, name in enumerate(layout.objects)]
    images: list[dict] = []
    annotations: list[dict] = []
    for b in rows:
        image_id = int(view.frame_id[b])
        images.append({"id": image_id, "file_name": view.image_path[b], "width": k.width, "height": k.height})
        for c in np.flatnonzero(objects.labeled[b]):
            members = layout.feature_at[c][layout.feature_at[c] >= 0]
            flags = view.keypoint_flag[b, members].astype(int)
            uv = np.where((flags > 0)[:, None], index_px(view.center_px[b, members]), 0.0)
            keypoints = np.column_stack([uv, flags]).ravel()
            box = _xywh(objects.label_xyxy[b, c])
            annotations.append({"id": len(annotations) + 1, "image_id": image_id, "category_id": int(c) + 1,
                                "bbox": box, "area": box[2] * box[3], "iscrowd": 0,
                                "keypoints": [float(v) if i % 3 < 2 else int(v) for i, v in enumerate(keypoints)],
                                "num_keypoints": int((flags > 0).sum())})
    info = {"description": f"datagen {view.doc.get('name', view.root.name)}: pose instances of "
                           f"{', '.join(layout.objects)}, keypoints at the true feature centres",
            "keypoint_convention": "pixel indices: integer coordinates at pixel centres (continuous - 0.5)",
            "bbox_convention": "continuous pixels: [x, y, w, h] of the area covered, the image spans [0, W] x [0, H]"}
    return {"info": info, "images": images, "annotations": annotations, "categories": categories}


def export_coco(view: DatasetView, out: Path, progress: Callable[[int], None]) -> None:
    """COCO keypoint files per split, with the images linked under ``out``."""
    (out / "annotations").mkdir()
    objects = view.recompute_objects()
    for split in ("train", "val"):
        rows = [b for b in range(len(view)) if view.split[b] == split]
        if not rows:
            continue
        for b in rows:
            rel = view.image_path[b] or ""
            link_or_copy(_check_image(view, rel), out / rel)
            progress(1)
        doc = coco_document(view, rows, objects)
        write_text(out / "annotations" / f"{split}.json", _json(doc))


# --- BOP -----------------------------------------------------------------------------------------
def _ply(vertices_mm: NDArray[np.float64], normals: NDArray[np.float64], faces: NDArray[np.int64]) -> str:
    """An ASCII PLY of a triangle mesh with vertex normals (what bop_toolkit's ``inout.load_ply`` reads)."""
    head = (f"ply\nformat ascii 1.0\ncomment datagen: millimetres, body frame (x forward, y left, z up)\n"
            f"element vertex {len(vertices_mm)}\nproperty float x\nproperty float y\nproperty float z\n"
            "property float nx\nproperty float ny\nproperty float nz\n"
            f"element face {len(faces)}\nproperty list uchar int vertex_indices\nend_header\n")
    verts = "\n".join(" ".join(f"{v:.6f}" for v in row) for row in np.hstack([vertices_mm, normals]))
    tris = "\n".join(f"3 {a} {b} {c}" for a, b, c in faces)
    return head + verts + "\n" + tris + "\n"


def _models(view: DatasetView, out: Path) -> dict[str, tuple[NDArray, NDArray]]:
    """Write ``models/`` (PLY in mm, models_info.json); return each object's mesh in metres."""
    from datagen.assets.loader import load_mesh

    (out / "models").mkdir()
    info, meshes = {}, {}
    for name in view.features.objects:
        mesh = load_mesh(_recorded_mesh(view, name), name).combined
        vertices, faces = np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.faces, dtype=np.int64)
        meshes[name] = (vertices, faces)
        mm = vertices * MM_PER_M
        obj = object_id(name)
        write_text(out / "models" / f"obj_{obj:06d}.ply", _ply(mm, np.asarray(mesh.vertex_normals), faces))
        hull = view.hulls[name] * MM_PER_M
        diameter = float(max(np.linalg.norm(hull - p, axis=1).max() for p in hull))
        lo, hi = mm.min(axis=0), mm.max(axis=0)
        info[str(obj)] = {"diameter": diameter, "min_x": lo[0], "min_y": lo[1], "min_z": lo[2],
                          "size_x": hi[0] - lo[0], "size_y": hi[1] - lo[1], "size_z": hi[2] - lo[2]}
    write_text(out / "models" / "models_info.json",
               _json({k: {f: float(v) for f, v in d.items()} for k, d in info.items()}, indent=1))
    return meshes


def _recorded_mesh(view: DatasetView, name: str) -> Path:
    """The mesh file the dataset's object ``name`` was built with (dataset.json's
    ``assets.NAME.mesh``), once its bytes are those of ``assets.NAME.mesh_sha256``: a
    dataset names a file outside itself here, so nothing but its digest is read before it
    is known to be that mesh."""
    from datagen.assets.loader import MAX_MESH_BYTES

    where = f"{view.root / 'dataset.json'}: assets.{name}"
    assets = view.doc.get("assets")
    record = assets.get(name) if isinstance(assets, dict) else None
    if not isinstance(record, dict) or not isinstance(record.get("mesh"), str) or not record["mesh"] \
            or not isinstance(record.get("mesh_sha256"), str):
        raise DatagenError(f"{where}: expected a mapping with the mesh's path and mesh_sha256 (the BOP export writes "
                           "the object's model from the mesh the dataset was built with)")
    path = Path(record["mesh"])
    try:
        info = path.stat()
        if not stat.S_ISREG(info.st_mode) or info.st_size > MAX_MESH_BYTES:
            raise DatagenError(f"{where}.mesh: {path}: not a mesh file")
        digest = hashlib.sha256()
        with open(path, "rb") as f:
            for block in iter(lambda: f.read(1 << 20), b""):
                digest.update(block)
        sha256 = digest.hexdigest()
    except OSError as exc:
        raise DatagenError(f"{where}.mesh: {path}: {exc.strerror or 'unreadable'} (the BOP export writes the "
                           "object's model from the mesh the dataset was built with)") from None
    if sha256 != record["mesh_sha256"]:
        raise DatagenError(f"{where}.mesh: {path}: its bytes are not those the dataset was built with "
                           "(mesh_sha256 differs): the mesh was changed or swapped")
    return path


def _bbox_of_mask(mask: NDArray[np.bool_]) -> list[int]:
    """BOP's ``[x, y, w, h]`` of a mask's pixels, ``[-1, -1, -1, -1]`` when empty."""
    ys, xs = np.nonzero(mask)
    if not len(xs):
        return [-1, -1, -1, -1]
    return [int(xs.min()), int(ys.min()), int(xs.max() - xs.min() + 1), int(ys.max() - ys.min() + 1)]


def _bbox_of_box(xyxy: NDArray[np.float64]) -> list[int]:
    """The pixels a continuous box covers as BOP's ``[x, y, w, h]`` (may reach outside the image)."""
    if not np.isfinite(xyxy).all():
        return [-1, -1, -1, -1]
    x0, y0 = int(np.floor(xyxy[0])), int(np.floor(xyxy[1]))
    x1, y1 = int(np.ceil(xyxy[2])) - 1, int(np.ceil(xyxy[3])) - 1
    return [x0, y0, x1 - x0 + 1, y1 - y0 + 1]


def read_object_ids(path: Path, limits: ReadLimits) -> NDArray[np.uint32]:
    """The ``object_id`` channel of a datagen EXR (:func:`datagen.atomic.write_exr`), which
    must be a regular file of at most :attr:`~datagen.dataset.limits.ReadLimits.exr_bytes`
    whose header states the dataset's image size (read before any pixel is decoded)."""
    import OpenEXR

    shape = (limits.height, limits.width)
    with opened_file(path, "a frame's EXR", limits.exr_bytes) as name:
        try:
            low, high = OpenEXR.File(name, header_only=True).header()["dataWindow"]
            size = (int(high[1]) - int(low[1]) + 1, int(high[0]) - int(low[0]) + 1)
        except Exception as exc:
            raise DatagenError(f"{path}: unreadable EXR header ({type(exc).__name__})") from None
        if size != shape:
            raise DatagenError(f"{path}: an EXR of {size[1]}x{size[0]} px, the dataset's images are "
                               f"{shape[1]}x{shape[0]}")
        try:
            with OpenEXR.File(name, separate_channels=True) as exr:
                ids = np.asarray(exr.channels()["object_id"].pixels, dtype=np.uint32)
        except Exception as exc:
            raise DatagenError(f"{path}: unreadable EXR or no object_id channel ({type(exc).__name__})") from None
    if ids.shape != tuple(shape):
        raise DatagenError(f"{path}: object ids of {ids.shape[1::-1]} px, the dataset's images are "
                           f"{shape[1]}x{shape[0]}")
    return ids


def export_bop(view: DatasetView, out: Path, progress: Callable[[int], None]) -> None:
    """The BOP folder layout: models, then one scene per shard of each split."""
    from datagen.render.masks import Silhouettes

    meshes = _models(view, out)
    k = view.intrinsics
    silhouettes = Silhouettes(meshes, k)
    cam_from_objects = view.cam_from_objects()
    objects = view.recompute_objects()
    ik = index_px(np.array([k.cx, k.cy]))
    cam_k = [k.fx, 0.0, float(ik[0]), 0.0, k.fy, float(ik[1]), 0.0, 0.0, 1.0]
    scenes: dict[tuple[str, int], list[int]] = {}
    for b in range(len(view)):
        shard = int(view.manifest_file[b].rsplit("-", 1)[1].split(".")[0])
        scenes.setdefault((view.split[b], shard), []).append(b)
    for (split, shard), rows in scenes.items():
        folder = out / split / f"{shard:06d}"
        camera: dict[str, dict] = {}
        gt: dict[str, list] = {}
        gt_info: dict[str, list] = {}
        for b in rows:
            im = int(view.frame_id[b])
            source = _check_image(view, view.image_path[b])
            link_or_copy(source, folder / "rgb" / f"{im:06d}{source.suffix}")
            ids = read_object_ids(view.folder.file(view.exr_path[b] or ""), view.limits)
            camera[str(im)] = {"cam_K": cam_k, "depth_scale": 1.0}
            gt[str(im)], gt_info[str(im)] = [], []
            for o, name in enumerate(view.features.objects):
                m = cam_from_objects[b, o]
                gt[str(im)].append({"cam_R_m2c": m[:3, :3].ravel().tolist(),
                                    "cam_t_m2c": (m[:3, 3] * MM_PER_M).tolist(), "obj_id": object_id(name)})
                full = silhouettes.mask(name, m)
                visible = ids == object_id(name)
                n_all, n_visib = int(full.sum()), int(visible.sum())
                # The projected hull's box, which may reach beyond the image; for an object that
                # reaches behind the camera (no such box), the box of its silhouette in the image.
                box = objects.tight_xyxy[b, o]
                bbox_obj = _bbox_of_box(box) if np.isfinite(box).all() else _bbox_of_mask(full)
                gt_info[str(im)].append({"bbox_obj": bbox_obj,
                                         "bbox_visib": _bbox_of_mask(visible), "px_count_all": n_all,
                                         "px_count_valid": n_all, "px_count_visib": n_visib,
                                         "visib_fract": min(1.0, n_visib / n_all) if n_all else 0.0})
                index = len(gt[str(im)]) - 1
                for kind, mask in (("mask", full), ("mask_visib", visible)):
                    path = folder / kind / f"{im:06d}_{index:06d}.png"
                    path.parent.mkdir(parents=True, exist_ok=True)
                    write_image(path, (mask * np.uint8(255)))
            progress(1)
        for name, doc in (("scene_camera", camera), ("scene_gt", gt), ("scene_gt_info", gt_info)):
            write_text(folder / f"{name}.json", _json(doc, indent=1))
    write_text(out / "camera.json", _json({"cx": cam_k[2], "cy": cam_k[5], "fx": k.fx, "fy": k.fy,
                                                "width": k.width, "height": k.height, "depth_scale": 1.0}))
