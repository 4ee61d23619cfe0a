"""Read a built dataset back into arrays: the manifests, the feature table and the
metadata, for the audit and the previews.

Every frame of a dataset has the same feature list (one record per class, in
class-id order), so the per-feature manifest columns become ``(B, F, ...)``
arrays. Labels recomputed here use nothing but the manifest poses and
intrinsics and ``features.parquet``.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Final

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq
from numpy.typing import NDArray

from datagen.config.inputs import parse_yaml, read_json, read_text
from datagen.core.camera import FOCAL_BOUNDS_PX, MAX_IMAGE_PX, MAX_READOUT_S, Intrinsics, RollingShutter
from datagen.core.errors import DatagenError, shown
from datagen.core.features import FeatureTable
from datagen.core.label_boxes import FrameLabels
from datagen.core.labelling_context import Labelled, LabellingContext, LabelRules
from datagen.dataset.columns import (
    APPEARANCE,
    COLUMNS_SINCE,
    FILE_COLUMNS,
    INTRINSICS_COLUMNS,
    POSE_COLUMNS,
    RATE_COLUMNS,
    READABLE_MANIFEST_VERSIONS,
    ManifestColumn,
    ManifestColumns,
    flat_floats,
    manifest_schema,
    read_features,
    read_objects,
    read_parquet,
    stored_schema,
)
from datagen.dataset.layout import MANIFEST_NAME, SPLITS
from datagen.dataset.limits import (
    DATA_YAML_BYTES,
    DATASET_JSON_BYTES,
    MAX_DISTANCE_M,
    MAX_FRAMES,
    MAX_WORLD_M,
    TABLE_BYTES,
    TABLE_ROWS,
    ReadLimits,
)
from datagen.paths import NOT_INSIDE, DatasetFolder, named_inside, read_bytes

__all__ = ["DatasetIndex", "DatasetMeta", "DatasetSource", "DatasetView", "FrameOrder", "Shard", "image_size",
           "load_dataset", "open_dataset", "plan_gaps"]


@dataclass(frozen=True, eq=False)
class Shard:
    """One manifest's rows of a dataset (a loaded view is one shard of itself): the manifest
    (relative to the root; empty for a view) and each of its rows' position in the dataset's
    frame order (its rows sorted by frame id, as a view holds them)."""

    name: str
    positions: NDArray[np.int64]


@dataclass(frozen=True, eq=False)
class DatasetMeta(Labelled):
    """What every frame of a dataset shares: dataset.json, the data.yaml files, and what
    labelled its frames (the feature table, the intrinsics, the object hulls and the label
    rules, read by name through :class:`~datagen.core.labelling_context.Labelled`)."""

    root: Path
    doc: dict  # dataset.json
    data_yaml: dict  # the root's data.yaml: the detect set's, or the pose set's in a pose-only dataset
    pose_yaml: dict | None  # the pose set's data.yaml (pose/data.yaml with labels.format 'both')
    labelling: LabellingContext  # the build's own context, rebuilt from features.parquet, objects.parquet, dataset.json

    @property
    def corrected(self) -> bool:
        return bool(self.doc["corrected"])

    @functools.cached_property
    def folder(self) -> DatasetFolder:
        """The dataset folder as untrusted input: :meth:`~datagen.paths.DatasetFolder.file`
        is the only way a reader gets from a path the dataset names to a file."""
        return DatasetFolder(self.root)

    @property
    def edge_margin_px(self) -> float:
        return float(self.doc["edge_margin_px"])

    @functools.cached_property
    def limits(self) -> ReadLimits:
        """The largest file of each per-frame kind this dataset may hold
        (:class:`~datagen.dataset.limits.ReadLimits`: from dataset.json's resolution and plan)."""
        plan = self.doc.get("splits")
        splits: dict = plan if isinstance(plan, dict) else {}
        frames = {s: v["frames"] for s, v in splits.items() if s in SPLITS and isinstance(v, dict)
                  and isinstance(v.get("frames"), int)}
        if len(frames) != len(splits):  # a plan the readers refuse in their own words (plan_gaps)
            frames = {}
        shard = self.doc.get("shard_size")
        return ReadLimits.of(self.labelling, shard if isinstance(shard, int) else 100_000,
                             frames or {"train": MAX_FRAMES})

    @property
    def label_format(self) -> str:
        """``labels.format``: detect, pose or both."""
        return self.label_rules.format

    def frames(self, *, unique: bool = False) -> FrameOrder:
        """The small per-frame columns of every frame, in frame order (a view: itself; a
        source: every manifest's small columns, read once). ``unique``: refuse, in one line,
        a frame that several manifests hold."""
        raise NotImplementedError

    def shards(self) -> list[Shard]:
        """The dataset's shards, in manifest order (a view: one, itself)."""
        raise NotImplementedError

    def read(self, shard: Shard, *, checked: bool = True) -> DatasetView:
        """``shard``'s rows as a view (a view's own shard: the view); ``checked``: refuse
        (one line) rows whose camera is not dataset.json's (the audit, which reports them,
        reads them unchecked)."""
        raise NotImplementedError

    def walk(self, positions: NDArray[np.int64] | None = None, *, split: str | None = None,
             checked: bool = True) -> Iterator[tuple[DatasetView, NDArray[np.int64]]]:
        """The one way through a dataset's rows: ``(view, rows)`` runs of the frames at
        ``positions`` (in the dataset's frame order, :meth:`frames`; every frame when None),
        in the order given, of ``split`` alone when one is named; ``view.<column>[rows]`` are
        those frames'. A loaded view yields itself; a source reads each shard as the
        positions reach it and holds at most one a split (positions in frame order then read
        each shard once, however train and val frames interleave)."""
        order = self.frames()
        positions = np.arange(len(order), dtype=np.int64) if positions is None else np.asarray(positions, np.int64)
        if split is not None:
            positions = positions[np.array([order.split[p] == split for p in positions.tolist()], dtype=bool)]
        shards = self.shards()
        shard_of = np.zeros(len(order), dtype=np.int64)
        row_of = np.zeros(len(order), dtype=np.int64)
        for k, shard in enumerate(shards):
            shard_of[shard.positions] = k
            row_of[shard.positions] = np.arange(len(shard.positions))
        held: dict[str, tuple[int, DatasetView]] = {}  # split -> the shard held for it
        owner = shard_of[positions]
        starts = np.flatnonzero(np.r_[True, owner[1:] != owner[:-1]]) if len(positions) else np.zeros(0, np.int64)
        for start, end in zip(starts.tolist(), [*starts[1:].tolist(), len(positions)], strict=True):
            k = int(owner[start])
            key = order.split[int(positions[start])]
            if key not in held or held[key][0] != k:
                held[key] = (k, self.read(shards[k], checked=checked))
            yield held[key][1], row_of[positions[start:end]]


@dataclass(frozen=True, eq=False)
class _FrameRows:
    """The per-frame manifest columns every reader of a dataset's rows has (its ``columns``:
    :class:`~datagen.dataset.columns.ManifestColumns`), each under its column's name
    (:class:`~datagen.dataset.columns.ManifestColumn`)."""

    columns: ManifestColumns
    frame_id = ManifestColumn[NDArray[np.int64]]()
    split = ManifestColumn[list[str]]()
    image_path = ManifestColumn[list[str | None]]()
    label_path = ManifestColumn[list[str | None]]()  # the detection label file, None in a pose-only dataset
    pose_label_path = ManifestColumn[list[str | None]]()  # the pose label file, None without pose labels
    exr_path = ManifestColumn[list[str | None]]()
    approach_index = ManifestColumn[NDArray[np.int64]]()
    approach_number = ManifestColumn[NDArray[np.int64]]()
    world_texel_px = ManifestColumn[NDArray[np.float64]]()  # the largest world texel shown, NaN: none seen

    def __len__(self) -> int:
        return len(self.frame_id)

    @property
    def stems(self) -> list[str]:
        """Each row's file stem (the frame's image, or label, file name without extension)."""
        return [Path(next((p for p in paths if p), f"{int(frame):08d}")).stem
                for frame, *paths in zip(self.frame_id, self.image_path, self.label_path, self.pose_label_path,
                                         strict=True)]


@dataclass(frozen=True, eq=False)
class DatasetView(_FrameRows, DatasetMeta):
    """A dataset's metadata and manifest rows (all of them, or one shard's), per-feature
    columns as ``(B, F)`` arrays (rows sorted by frame id); every other manifest column is
    in ``columns``."""

    manifest_file: list[str]  # per row: the manifest it came from (relative to root)
    row_intrinsics: NDArray[np.float64]  # (B, 6): width, height, fx, fy, cx, cy
    world_from: dict[str, NDArray[np.float64]]  # object -> (B, 4, 4)
    class_id: NDArray[np.int64]  # (B, F)
    center_px: NDArray[np.float64]  # (B, F, 2)
    tight_xyxy: NDArray[np.float64]  # (B, F, 4)
    corrected_xyxy: NDArray[np.float64]  # (B, F, 4)
    label_xyxy: NDArray[np.float64]  # (B, F, 4) the box written to the label file, NaN where not labeled
    labeled: NDArray[np.bool_]  # (B, F)
    exclusion: NDArray[np.object_]  # (B, F) reason or None
    visible_fraction: NDArray[np.float64]  # (B, F), NaN where not rendered
    center_visible: NDArray[np.float64]  # (B, F) 1, 0 or NaN
    keypoint_flag: NDArray[np.int8]  # (B, F) the pose visibility flag (datagen.core.keypoints)
    object_tight_xyxy: NDArray[np.float64]  # (B, O, 4) box of each object's projected hull, NaN if not finite
    object_label_xyxy: NDArray[np.float64]  # (B, O, 4) its pose box, NaN where not labeled
    object_exclusion: NDArray[np.object_]  # (B, O) reason or None
    distortion: NDArray[np.float64]  # (B, 5) the lens's OpenCV coefficients, zeros for a pinhole frame
    readout_s: NDArray[np.float64]  # (B,) a rolling shutter's readout, 0 for a global shutter
    cam_from_per_s: dict[str, NDArray[np.float64]]  # object -> (B, 4, 4) d/dt cam_from_<object> (0: no shutter)
    cam_from_world = ManifestColumn[NDArray[np.float64]]()  # (B, 4, 4)
    distance_m = ManifestColumn[NDArray[np.float64]]()
    ptd_receiver_m = ManifestColumn[NDArray[np.float64]]()  # (B, 3)

    @property
    def appearance(self) -> dict[str, Any]:
        """Each column of :data:`~datagen.dataset.columns.APPEARANCE` the rows hold: its values."""
        return {c: self.columns[c] for cols in APPEARANCE.values() for c in cols if c in self.columns}

    def frames(self, *, unique: bool = False) -> DatasetView:
        return self  # (a view with duplicates was loaded asking for them)

    def shards(self) -> list[Shard]:
        return [Shard("", np.arange(len(self), dtype=np.int64))]

    def read(self, shard: Shard, *, checked: bool = True) -> DatasetView:
        return self

    @property
    def intrinsics_as_built(self) -> NDArray[np.bool_]:
        """``(B,)`` whether each row's camera is dataset.json's (to 1e-9 px)."""
        k = self.intrinsics
        expected = np.array([k.width, k.height, k.fx, k.fy, k.cx, k.cy])
        return np.isclose(self.row_intrinsics, expected, rtol=0, atol=1e-9).all(axis=1)

    def cam_from_objects(self) -> NDArray[np.float64]:
        """``(B, O, 4, 4)`` in the order of ``features.objects``."""
        return np.stack([self.cam_from_world @ self.world_from[o] for o in self.features.objects], axis=1)

    def shutter(self) -> RollingShutter | None:
        """The frames' rolling shutters (None when every frame's is global)."""
        if not self.readout_s.any():
            return None
        return RollingShutter(self.readout_s, np.stack([self.cam_from_per_s[o] for o in self.features.objects], axis=1))

    def recompute_objects(self) -> FrameLabels:
        """Every frame's pose boxes from the poses and objects.parquet alone."""
        return self.labelling.label_objects(self.cam_from_objects(),
                                            self.distortion if self.distortion.any() else None, self.shutter())

    def recompute(self) -> FrameLabels:
        """The labels of every frame from the poses and features.parquet alone (with the
        manifest's visibility for the optional occlusion rule)."""
        labels = self.labelling.label_features(self.cam_from_objects(),
                                               self.distortion if self.distortion.any() else None, self.shutter())
        return self.labelling.occlude(labels, self.visible_fraction)


@dataclass(frozen=True, eq=False)
class DatasetIndex(_FrameRows):
    """The small per-row columns of every manifest (:data:`INDEX_COLUMNS`), in frame order (as a
    :class:`DatasetView` of the whole dataset orders its rows): what the checks across shards need."""

    root: Path
    doc: dict
    label_format: str
    manifest_file: list[str]
    rank: dict[str, NDArray[np.int64]]  # manifest -> each of its rows' position in frame order (its rows sorted)
    limits: ReadLimits  # the dataset's (DatasetMeta.limits)

    @functools.cached_property
    def folder(self) -> DatasetFolder:
        """The dataset folder as untrusted input (:class:`~datagen.paths.DatasetFolder`)."""
        return DatasetFolder(self.root)


#: A dataset's frames in frame order with their small columns: a source's index, or a loaded
#: view (what :meth:`DatasetMeta.frames` gives).
FrameOrder = DatasetIndex | DatasetView


def plan_gaps(rows: FrameOrder, only: str | None = None) -> list[str]:
    """How the frames in the manifests differ from what dataset.json planned
    (``splits.SPLIT.frames``), one text per split that differs (none: as planned); ``only``:
    of that split alone."""
    splits = rows.doc.get("splits")
    if not isinstance(splits, dict):
        return ["splits: expected a mapping of each split to its planned frames"]
    gaps = [f"splits: no plan for the {s} frames in the manifests" for s in sorted(set(rows.split) - set(splits))
            if only in (None, s)]
    for split, planned in splits.items():
        if only not in (None, split):
            continue
        have = len({int(f) for f, s in zip(rows.frame_id, rows.split, strict=True) if s == split})
        want = planned.get("frames") if isinstance(planned, dict) else None
        if split not in SPLITS or not isinstance(want, int) or isinstance(want, bool) or want < 0:
            gaps.append(f"splits.{str(split)[:20]!r}: expected a split (train or val) with its planned frames")
        elif have < want:
            gaps.append(f"splits.{split}: {want} frames planned, {have} in the manifests (an unfinished build, or a "
                        "manifest removed: rerun the build)")
        elif have > want:
            gaps.append(f"splits.{split}: {want} frames planned, {have} in the manifests (manifests from another "
                        "build?)")
    return gaps


#: The columns of :class:`DatasetIndex`: those every reader of rows has (:class:`_FrameRows`).
INDEX_COLUMNS: Final = tuple(name for name, value in vars(_FrameRows).items() if isinstance(value, ManifestColumn))


@dataclass(frozen=True, eq=False)
class DatasetSource(DatasetMeta):
    """An opened dataset whose manifests are read one at a time (:meth:`read_shard`), so that
    what streams over them holds one shard, not the dataset."""

    manifests: tuple[str, ...]  # relative to root, sorted

    def read_manifest(self, name: str, columns: tuple[str, ...] | None = None) -> pa.Table:
        """One manifest, checked against the schema (one line naming it when it is not a
        manifest this datagen reads)."""
        return _read_manifest(self.root / name, self.limits, columns)

    def read_manifests(self, columns: tuple[str, ...] | None = None) -> list[pa.Table]:
        """Every manifest (its ``columns``, or all), in name order; one line once they hold
        more rows than twice the frames dataset.json plans (a copied manifest or two the
        audit names; thousands would grow a reader's memory without bound)."""
        tables, rows = [], 0
        for name in self.manifests:
            tables.append(self.read_manifest(name, columns))
            rows += tables[-1].num_rows
            if rows > 2 * self.limits.frames:
                raise DatagenError(f"{self.root / 'manifests'}: more rows than twice the {self.limits.frames:,} "
                                   f"frames dataset.json plans (at {name}): manifests copied in from elsewhere")
        return tables

    def frames(self, *, unique: bool = False) -> DatasetIndex:
        if unique:  # as load_dataset refuses them
            _refuse_duplicates(self.root, self._index.frame_id, self._index.manifest_file)
        return self._index


    def shards(self) -> list[Shard]:
        ranks = self.frames().rank
        return [Shard(name, ranks[name]) for name in self.manifests]

    def read(self, shard: Shard, *, checked: bool = True) -> DatasetView:
        return self.read_shard(shard.name, checked=checked)

    def read_shard(self, name: str, *, checked: bool = True) -> DatasetView:
        """One manifest's rows as a view; ``checked``: refuse (one line) rows whose camera is
        not dataset.json's (the audit, which reports them, reads them unchecked)."""
        return _view(self, [self.read_manifest(name)], [name], allow_duplicates=True, checked=checked)

    def read_frames(self, frames: list[int]) -> DatasetView:
        """The rows of the frame ids ``frames`` as a view, read from the manifests that hold
        them and no other; one line naming the first id that no manifest holds."""
        index = self.frames()
        where = dict(zip(index.frame_id.tolist(), index.manifest_file, strict=True))
        missing = [f for f in frames if f not in where]
        if missing:
            span = f"frames {int(index.frame_id.min())}-{int(index.frame_id.max())}" if len(index) else "no frames"
            raise DatagenError(f"--frames: frame {missing[0]} is not in {self.root} ({span})")
        names = sorted({where[f] for f in frames})
        return _view(self, [self.read_manifest(n) for n in names], names, allow_duplicates=False, checked=True)

    @functools.cached_property
    def _index(self) -> DatasetIndex:
        """Every manifest's small columns (:data:`INDEX_COLUMNS`), rows in frame order, read
        once (:meth:`frames`); rows of a frame that several manifests hold are kept (the audit
        names them)."""
        tables = self.read_manifests(INDEX_COLUMNS)
        names = [name for name, t in zip(self.manifests, tables, strict=True) for _ in range(t.num_rows)]
        stored = _FrameRows(ManifestColumns(pa.concat_tables(tables)))
        frame_ids = stored.frame_id
        _check_splits(self.root, stored.split, names, frame_ids)
        order = np.argsort(frame_ids, kind="stable")
        rank = np.empty(len(order), dtype=np.int64)
        rank[order] = np.arange(len(order))
        ranks, start = {}, 0
        for name, t in zip(self.manifests, tables, strict=True):
            mine = rank[start:start + t.num_rows]
            ranks[name] = mine[np.argsort(frame_ids[start:start + t.num_rows], kind="stable")]
            start += t.num_rows
        return DatasetIndex(columns=ManifestColumns(stored.columns.table.take(pa.array(order))), root=self.root,
                            doc=self.doc, label_format=self.label_format, manifest_file=[names[i] for i in order],
                            rank=ranks, limits=self.limits)


def _read_json(path: Path) -> dict:
    if not path.exists():
        raise DatagenError(f"{path}: no such file; not a datagen dataset folder")
    data = read_json(path, "dataset description", DATASET_JSON_BYTES)  # ConfigError: one line, a DatagenError
    if not isinstance(data, dict):
        raise DatagenError(f"{path}: expected a JSON object")
    return data


def _check_document(doc: dict, path: Path) -> None:
    """The keys of dataset.json the readers use, with their types (one line per the first problem)."""
    def number(value: object) -> bool:
        return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)

    for key in ("intrinsics", "image_width", "image_height", "edge_margin_px", "corrected", "config"):
        if key not in doc:
            raise DatagenError(f"{path}: {key}: missing")
    for key in ("image_width", "image_height"):
        value = doc[key]
        if not isinstance(value, int) or isinstance(value, bool) or not 0 < value <= MAX_IMAGE_PX:
            raise DatagenError(f"{path}: {key}: value {str(value)[:40]!r}: expected an image size in pixels")
    k = doc["intrinsics"]
    for key in ("fx", "fy", "cx", "cy"):
        if not isinstance(k, dict) or key not in k:
            raise DatagenError(f"{path}: intrinsics.{key}: missing")
        size = doc["image_width"] if key in ("fx", "cx") else doc["image_height"]
        lo, hi = FOCAL_BOUNDS_PX if key in ("fx", "fy") else (0.0, size)
        what = "a focal length a camera can be made with, px" if key in ("fx", "fy") else "a point of the image"
        if not number(k[key]) or not lo <= k[key] <= hi:
            raise DatagenError(f"{path}: intrinsics.{key}: value {str(k[key])[:40]!r}: expected a number from {lo:g} "
                               f"to {hi:g} ({what})")
    if not number(doc["edge_margin_px"]) or not isinstance(doc["corrected"], bool):
        raise DatagenError(f"{path}: edge_margin_px or corrected: expected a number and true or false")
    if not isinstance(doc["config"], dict):
        raise DatagenError(f"{path}: config: expected a mapping")
    seed = doc.get("seed", 0)
    if not isinstance(seed, int) or isinstance(seed, bool) or seed < 0:
        raise DatagenError(f"{path}: seed: value {str(seed)[:40]!r}: expected the dataset's seed, an integer from 0")
    shard = doc.get("shard_size", 1)
    if not isinstance(shard, int) or isinstance(shard, bool) or not 1 <= shard <= 100_000:
        raise DatagenError(f"{path}: shard_size: value {str(shard)[:40]!r}: expected the frames of a shard, an "
                           "integer from 1 to 100000")
    splits = doc.get("splits", {})
    for split, plan in (splits.items() if isinstance(splits, dict) else ()):
        frames = plan.get("frames") if isinstance(plan, dict) else None  # other shapes: plan_gaps names them
        if split in SPLITS and isinstance(frames, int) and not isinstance(frames, bool) \
                and not 0 <= frames <= MAX_FRAMES:
            raise DatagenError(f"{path}: splits.{split}.frames: value {str(frames)[:40]!r}: expected the frames "
                               f"planned, an integer from 0 to {MAX_FRAMES}")


def _floats(array: pa.Array, shape: tuple[int, ...]) -> NDArray[np.float64]:
    """A float column, or (nested) fixed-size lists of floats, as an array of ``shape``, NaN
    where a value or a list is null."""
    return flat_floats(array).reshape(shape)


def load_dataset(root: str | Path, *, allow_duplicates: bool = False, checked: bool = True) -> DatasetView:
    """Read ``root``'s dataset.json, data.yaml, features.parquet and every manifest.

    ``allow_duplicates``: keep rows of a frame that several manifests hold (the audit
    names them); otherwise they are refused, as they would count the frame twice.
    ``checked``: refuse rows whose camera is not dataset.json's (the audit names them).

    Raises:
        DatagenError: one line naming the file and what is wrong with it.
    """
    source = open_dataset(root)
    tables = source.read_manifests()
    return _view(source, tables, list(source.manifests), allow_duplicates=allow_duplicates,
                 checked=checked)


def open_dataset(root: str | Path) -> DatasetSource:
    """Read ``root``'s dataset.json, data.yaml, features.parquet and objects.parquet, and
    list its manifests (read them with :meth:`DatasetSource.read_shard`).

    Raises:
        DatagenError: one line naming the file and what is wrong with it.
    """
    root = Path(root)
    if not root.is_dir():
        raise DatagenError(f"{root}: no such dataset folder")
    folder = DatasetFolder(root)
    for name in ("dataset.json", "data.yaml", "features.parquet", "objects.parquet", "manifests"):
        folder.file(name)  # none of them may lead out of the dataset
    doc = _read_json(root / "dataset.json")
    data_yaml = parse_yaml(read_text(root / "data.yaml", "data.yaml", max_bytes=DATA_YAML_BYTES), root / "data.yaml")
    _check_document(doc, root / "dataset.json")
    if not isinstance(data_yaml, dict):
        raise DatagenError(f"{root / 'data.yaml'}: expected a mapping with train, val, nc and names")
    try:
        rules = LabelRules.from_mapping(doc["config"].get("labels", {}))
    except ValueError as exc:
        raise DatagenError(f"{root / 'dataset.json'}: config.labels.{exc}") from None
    pose_yaml = data_yaml if rules.format == "pose" else None
    if rules.format == "both":
        pose_yaml = parse_yaml(read_text(folder.file("pose/data.yaml"), "data.yaml", max_bytes=DATA_YAML_BYTES),
                               root / "pose" / "data.yaml")
        if not isinstance(pose_yaml, dict):
            raise DatagenError(f"{root / 'pose' / 'data.yaml'}: expected a mapping with train, val, nc, names and "
                               "kpt_shape")
    features, hulls = _read_tables(root)
    k = doc["intrinsics"]
    intrinsics = Intrinsics(doc["image_width"], doc["image_height"], float(k["fx"]), float(k["fy"]),
                            float(k["cx"]), float(k["cy"]))
    return DatasetSource(root=root, doc=doc, data_yaml=data_yaml, pose_yaml=pose_yaml,
                         labelling=LabellingContext(features, intrinsics, hulls, rules),
                         manifests=_manifest_names(folder))


def _read_tables(root: Path) -> tuple[FeatureTable, dict[str, NDArray[np.float64]]]:
    """features.parquet's table and objects.parquet's hulls, one per labeled object (one line
    when either is missing or wrong)."""
    tables = []
    for path, read in ((root / "features.parquet", read_features), (root / "objects.parquet", read_objects)):
        data = read_bytes(path, "a table of the dataset", TABLE_BYTES)
        try:
            rows = pq.ParquetFile(pa.BufferReader(data)).metadata.num_rows
            if not 0 < rows <= TABLE_ROWS:
                raise DatagenError(f"{path}: {rows} rows; expected from 1 to {TABLE_ROWS:,}")
            tables.append(read(pa.BufferReader(data)))
        except DatagenError:
            raise
        except Exception as exc:
            raise DatagenError(f"{path}: unreadable ({type(exc).__name__}: "
                               f"{' '.join(str(exc).split())[:120]})") from None
    features, hulls = tables
    assert isinstance(features, FeatureTable) and isinstance(hulls, dict)
    if tuple(hulls) != tuple(features.objects) or any(len(h) == 0 or not np.isfinite(h).all()
                                                      for h in hulls.values()):
        raise DatagenError(f"{root / 'objects.parquet'}: objects {', '.join(hulls) or 'none'} with their hull "
                           f"points; features.parquet labels {', '.join(features.objects)}")
    return features, hulls


def _manifest_names(folder: DatasetFolder) -> tuple[str, ...]:
    """The shards' manifests, relative to the dataset's root (a dataset without one is refused)."""
    manifests, root = [], folder.root
    for path in sorted((root / "manifests").glob("*.parquet")):
        if not MANIFEST_NAME.fullmatch(path.name):
            continue  # not a shard's manifest (the audit names it)
        rel = str(path.relative_to(root))
        folder.file(rel)
        if not path.is_file():
            raise DatagenError(f"{path}: not a regular file")
        manifests.append(rel)
    if not manifests:
        raise DatagenError(f"{root / 'manifests'}: no manifest; the dataset has no finished shard")
    return tuple(manifests)


def _read_manifest(path: Path, limits: ReadLimits, columns: tuple[str, ...] | None = None) -> pa.Table:
    """A manifest checked against :func:`datagen.dataset.columns.manifest_schema` (its
    ``columns``, or all): read once, within ``limits`` (its bytes, rows and uncompressed
    size judged from its footer before any row is read), and its values in their ranges
    (:func:`_check_values`)."""
    expected = manifest_schema()
    if columns is not None:
        expected = pa.schema([expected.field(c) for c in columns])
    data = read_bytes(path, "a shard's manifest", limits.manifest_bytes)
    try:
        footer = pq.ParquetFile(pa.BufferReader(data)).metadata
        rows, schema = footer.num_rows, footer.schema.to_arrow_schema()
        unpacked = sum(footer.row_group(i).total_byte_size for i in range(footer.num_row_groups))
        version = (schema.metadata or {}).get(b"datagen.manifest_version", b"?")
    except (OSError, pa.ArrowException) as exc:
        raise DatagenError(f"{path}: unreadable manifest ({type(exc).__name__})") from None
    if not 0 < rows <= limits.shard_rows:
        raise DatagenError(f"{path}: {rows} rows; a shard's manifest holds from 1 to {limits.shard_rows} frames "
                           "(dataset.json's shard_size)")
    if unpacked > limits.manifest_bytes:
        raise DatagenError(f"{path}: {unpacked:,} bytes uncompressed, more than {rows} frames' rows may take "
                           f"({limits.manifest_bytes:,})")
    version = version.decode(errors="replace")[:20]
    if version not in READABLE_MANIFEST_VERSIONS:
        raise DatagenError(f"{path}: manifest version {shown(version)}, this datagen reads "
                           f"{' and '.join(READABLE_MANIFEST_VERSIONS)}")
    try:
        table = read_parquet(pa.BufferReader(data), [c for c in expected.names if c in schema.names])
    except (OSError, pa.ArrowException) as exc:
        raise DatagenError(f"{path}: unreadable manifest ({type(exc).__name__})") from None
    stored = expected if version == READABLE_MANIFEST_VERSIONS[0] else stored_schema(expected)
    for field in stored:  # a column added since the shard's version: nulls
        if field.name not in table.schema.names and int(COLUMNS_SINCE.get(field.name, "0")) > int(version):
            table = table.append_column(field, pa.nulls(rows, field.type))
    for field in stored:
        have = table.schema.field(field.name) if field.name in table.schema.names else None
        if have is None or not have.type.equals(field.type):
            what = "missing" if have is None else f"type {have.type}, expected {field.type}"
            raise DatagenError(f"{path}: column {field.name}: {what}")
    for field in expected:
        if not field.nullable and table.column(field.name).null_count:
            raise DatagenError(f"{path}: column {field.name}: null values, which it may not hold")
    try:
        table = table.select(expected.names).cast(expected)
    except (pa.ArrowException, ValueError) as exc:  # a list of the wrong length
        raise DatagenError(f"{path}: a column's lists are not the lengths its type fixes "
                           f"({' '.join(str(exc).split())[:120]})") from None
    _check_values(table, path, limits)
    return table


#: The largest entry of a recorded pose rate, per second (a rotation at 1e3 rad/s, a speed of
#: 1e4 m/s: far beyond any aircraft's).
MAX_RATE_PER_S: Final = 1.0e4


def _check_values(table: pa.Table, path: Path, limits: ReadLimits) -> None:
    """Every number a reader computes with lies in its range (one line naming the manifest,
    the frame, the column and the value of the first that does not): frame ids below the
    frames planned, approach counters from 0, distances and the PtD vector finite and within
    :data:`~datagen.dataset.limits.MAX_DISTANCE_M`, poses rigid transforms within
    :data:`~datagen.dataset.limits.MAX_WORLD_M`, keypoint flags 0, 1 or 2, visible
    fractions from 0 to 1. ``table``'s columns that are checked are checked; others are not
    there to check."""
    names = set(table.column_names)
    frame = np.asarray(table.column("frame_id"), dtype=np.int64) if "frame_id" in names else None

    def refuse(column: str, bad: NDArray[np.bool_], value: list, expected: str) -> None:
        b = int(np.flatnonzero(bad)[0])
        where = f"frame {frame[b]}" if frame is not None and 0 <= frame[b] < limits.frames else f"row {b}"
        shown_value = repr(value[b])
        shown_value = shown_value if len(shown_value) <= 80 else shown_value[:77] + "..."
        raise DatagenError(f"{path}: {where}: {column}: value {shown_value}: expected {expected}")

    if frame is not None:
        bad = (frame < 0) | (frame >= limits.frames)
        if bad.any():
            refuse("frame_id", bad, frame.tolist(), f"a frame id from 0 to {limits.frames - 1} (dataset.json's splits)")
    for column in ("approach_index", "approach_number"):
        if column in names:
            values = np.asarray(table.column(column), dtype=np.int64)
            if (values < 0).any():
                refuse(column, values < 0, values.tolist(), "a count from 0")
    if "distance_m" in names:
        d = np.asarray(table.column("distance_m"), dtype=np.float64)
        bad = ~(np.isfinite(d) & (d >= 0) & (d <= MAX_DISTANCE_M))
        if bad.any():
            refuse("distance_m", bad, d.tolist(), f"a distance from 0 to {MAX_DISTANCE_M:g} m")
    if "ptd_receiver_m" in names:
        v = _floats(table.column("ptd_receiver_m").combine_chunks(), (table.num_rows, 3))
        bad = ~np.all(np.isfinite(v) & (np.abs(v) <= MAX_DISTANCE_M), axis=1)
        if bad.any():
            refuse("ptd_receiver_m", bad, v.tolist(), f"a vector of finite metres within {MAX_DISTANCE_M:g}")
    for column in ("cam_from_world", *POSE_COLUMNS.values()):
        if column in names:
            m = _floats(table.column(column).combine_chunks(), (table.num_rows, 4, 4))
            bad = ~_rigid(m)
            if bad.any():
                refuse(column, bad, m.tolist(), f"a rigid transform (a rotation, a translation within "
                       f"{MAX_WORLD_M:g} m, last row 0 0 0 1)")
    if "sensor_readout_s" in names:
        r = flat_floats(table.column("sensor_readout_s").combine_chunks())
        bad = ~(np.isnan(r) | ((r >= 0.0) & (r <= MAX_READOUT_S)))
        if bad.any():
            refuse("sensor_readout_s", bad, r.tolist(), f"null or a readout from 0 to {MAX_READOUT_S:g} s")
    for column in RATE_COLUMNS.values():
        if column in names:
            arr = table.column(column).combine_chunks()
            m = _floats(arr, (table.num_rows, 4, 4))
            null = np.asarray(arr.is_null().to_numpy(zero_copy_only=False), dtype=bool)
            ok = (np.isfinite(m) & (np.abs(m) <= MAX_RATE_PER_S)).all(axis=(1, 2)) & (m[:, 3] == 0.0).all(axis=1)
            bad = ~(null | ok)
            if bad.any():
                refuse(column, bad, m.tolist(), f"null or the rate of a transform (finite, each entry within "
                       f"{MAX_RATE_PER_S:g} a second, last row 0 0 0 0)")
    if "features" in names:
        flat = table.column("features").combine_chunks().flatten()
        rows = np.repeat(np.arange(table.num_rows), np.asarray(pc.list_value_length(
            table.column("features").combine_chunks())))
        flags = np.asarray(flat.field("keypoint_flag").to_numpy(zero_copy_only=False), dtype=np.int64)
        bad = ~np.isin(flags, (0, 1, 2))
        if bad.any():
            refuse("features.keypoint_flag", np.isin(np.arange(table.num_rows), rows[bad]),
                   [flags[rows == r].tolist() for r in range(table.num_rows)], "Ultralytics' keypoint flags 0, 1 or 2")
        seen = flat_floats(flat.field("visible_fraction"))
        bad = ~(np.isnan(seen) | ((seen >= 0) & (seen <= 1)))
        if bad.any():
            refuse("features.visible_fraction", np.isin(np.arange(table.num_rows), rows[bad]),
                   [seen[rows == r].tolist() for r in range(table.num_rows)], "fractions from 0 to 1 (or null)")


def _rigid(m: NDArray[np.float64]) -> NDArray[np.bool_]:
    """``(B,)`` whether each ``(4, 4)`` is a rigid transform: finite, a rotation (orthonormal
    to 1e-6, determinant 1), a translation within :data:`MAX_WORLD_M`, last row 0 0 0 1."""
    finite = np.all(np.isfinite(m), axis=(1, 2)) & np.all(np.abs(m[:, :3, :3]) <= 1.0 + 1e-6, axis=(1, 2))
    m = np.where(finite[:, None, None], m, 0.0)  # a rotation's entries lie in [-1, 1]
    r = m[:, :3, :3]
    orthonormal = np.abs(r @ np.swapaxes(r, 1, 2) - np.eye(3)).max(axis=(1, 2)) <= 1e-6
    proper = np.linalg.det(r) > 0
    near = (np.abs(m[:, :3, 3]) <= MAX_WORLD_M).all(axis=1)
    last = (m[:, 3] == np.array([0.0, 0.0, 0.0, 1.0])).all(axis=1)
    return finite & orthonormal & proper & near & last


def _view(meta: DatasetMeta, tables: list[pa.Table], manifests: list[str], *, allow_duplicates: bool,
          checked: bool) -> DatasetView:
    """The rows of ``tables`` (read from ``manifests``) as one view, sorted by frame id;
    ``checked``: every row's camera must be dataset.json's."""
    root, features = meta.root, meta.features
    names = [name for name, t in zip(manifests, tables, strict=True) for _ in range(t.num_rows)]
    try:
        stored = _FrameRows(ManifestColumns(pa.concat_tables(tables)))
    except pa.ArrowException as exc:
        raise DatagenError(f"{root / 'manifests'}: manifests with different schemas ({exc})") from None
    if not allow_duplicates:
        _refuse_duplicates(root, stored.frame_id, names)
    order = np.argsort(stored.frame_id, kind="stable")
    rows = _FrameRows(ManifestColumns(stored.columns.table.take(pa.array(order))))
    table = rows.columns.table
    names = [names[i] for i in order]
    b, f = table.num_rows, len(features)
    _check_splits(root, rows.split, names, rows.frame_id)
    flat = _records(table, "features", f, f"feature records, features.parquet has {f} classes", root, names)
    for column in FILE_COLUMNS:
        for i, rel in enumerate(rows.columns[column]):
            if rel is not None and not named_inside(rel):
                raise DatagenError(f"{root / names[i]}: frame {rows.frame_id[i]}: {column} {rel[:80]!r} {NOT_INSIDE}")

    exclusion = np.array(flat.field("exclusion").to_pylist(), dtype=object).reshape(b, f)
    n_obj = len(features.objects)
    objects = _records(table, "objects", n_obj, f"object records, features.parquet has {n_obj} objects", root,
                       names)
    cols = rows.columns
    view = DatasetView(
        root=root,
        doc=meta.doc,
        data_yaml=meta.data_yaml,
        pose_yaml=meta.pose_yaml,
        labelling=meta.labelling,
        columns=cols,
        manifest_file=names,
        row_intrinsics=np.stack([np.asarray(cols[c], dtype=np.float64) for c in INTRINSICS_COLUMNS], axis=1),
        world_from={o: cols[c] for o, c in POSE_COLUMNS.items()},
        class_id=np.asarray(flat.field("class_id"), dtype=np.int64).reshape(b, f),
        center_px=_floats(flat.field("center_px"), (b, f, 2)),
        tight_xyxy=_floats(flat.field("tight_xyxy"), (b, f, 4)),
        corrected_xyxy=_floats(flat.field("corrected_xyxy"), (b, f, 4)),
        label_xyxy=_floats(flat.field("label_xyxy"), (b, f, 4)),
        labeled=np.asarray(flat.field("labeled").to_numpy(zero_copy_only=False), dtype=bool).reshape(b, f),
        exclusion=exclusion,
        visible_fraction=_floats(flat.field("visible_fraction"), (b, f)),
        center_visible=_floats(pc.cast(flat.field("center_visible"), pa.float64()), (b, f)),
        keypoint_flag=np.asarray(flat.field("keypoint_flag").to_numpy(zero_copy_only=False),
                                 dtype=np.int8).reshape(b, f),
        object_tight_xyxy=_floats(objects.field("tight_xyxy"), (b, n_obj, 4)),
        object_label_xyxy=_floats(objects.field("label_xyxy"), (b, n_obj, 4)),
        object_exclusion=np.array(objects.field("exclusion").to_pylist(), dtype=object).reshape(b, n_obj),
        distortion=_nulls_as_zero(cols, "sensor_distortion"),  # zeros: a pinhole
        readout_s=_nulls_as_zero(cols, "sensor_readout_s"),
        cam_from_per_s={o: _nulls_as_zero(cols, c) for o, c in RATE_COLUMNS.items()},
    )
    if checked and not view.intrinsics_as_built.all():
        b = int(np.argmin(view.intrinsics_as_built))
        raise DatagenError(f"{root / 'dataset.json'}: intrinsics differ from those of {names[b]} frame "
                           f"{view.frame_id[b]} ({view.row_intrinsics[b].tolist()}): dataset.json or the manifest "
                           "was changed; datagen audit names every such frame")
    return view


def _check_splits(root: Path, splits: list, names: list[str], frame_ids: Sequence[int] | NDArray[np.int64]) -> None:
    """Each row's split is the split its manifest's name says (a split names folders that
    readers and exports write to)."""
    for split, name, frame in zip(splits, names, frame_ids, strict=True):
        if split not in SPLITS or not Path(name).name.startswith(f"{split}-"):
            raise DatagenError(f"{root / name}: frame {frame}: split {str(split)[:40]!r}; a row of {Path(name).name} "
                               f"is of split {Path(name).name.split('-')[0]}")


def _refuse_duplicates(root: Path, frame_ids: NDArray[np.int64], names: list[str]) -> None:
    """One line naming the manifests of the first frame that several rows hold (they would
    count it twice)."""
    if len(np.unique(frame_ids)) == len(frame_ids):
        return
    ids, counts = np.unique(frame_ids, return_counts=True)
    frame = int(ids[np.argmax(counts > 1)])
    where = sorted({names[i] for i in np.flatnonzero(frame_ids == frame)})
    raise DatagenError(f"{root / where[0]}: frame {frame} is in {len(where)} manifests ({', '.join(where)}): a "
                       "manifest copied or renamed by hand; datagen audit names every such frame")


def _records(table: pa.Table, column: str, count: int, what: str, root: Path, names: list[str]) -> pa.Array:
    """The flattened records of a list column whose every row must hold ``count`` of them
    (one line naming the manifest and frame of the first row that does not)."""
    lists = table.column(column).combine_chunks()
    lengths = np.asarray(pc.list_value_length(lists))
    if not np.all(lengths == count):
        bad = int(np.argmax(lengths != count))
        raise DatagenError(f"{root / names[bad]}: frame {table.column('frame_id')[bad]}: {lengths[bad]} {what}")
    return lists.flatten()


def _nulls_as_zero(columns: ManifestColumns, column: str) -> NDArray[np.float64]:
    """A float column (or fixed-size lists of floats), zeros where a row is null (a row's
    values as they are otherwise)."""
    values = np.array(columns[column], dtype=np.float64)
    values[columns.null(column)] = 0.0
    return values


def image_size(head: bytes) -> tuple[int, int] | None:
    """``(width, height)`` from the first bytes of a PNG or JPEG file (its header alone, so
    that a file claiming a huge size is refused before it is decoded), or None."""
    if head[:8] == b"\x89PNG\r\n\x1a\n" and head[12:16] == b"IHDR" and len(head) >= 24:
        return int.from_bytes(head[16:20], "big"), int.from_bytes(head[20:24], "big")
    if head[:2] != b"\xff\xd8":
        return None
    i = 2
    while i + 9 < len(head):
        if head[i] != 0xFF:
            return None
        marker = head[i + 1]
        if marker == 0xFF:  # fill byte
            i += 1
            continue
        length = int.from_bytes(head[i + 2:i + 4], "big")
        if 0xC0 <= marker <= 0xCF and marker not in (0xC4, 0xC8, 0xCC):  # a start-of-frame segment
            return int.from_bytes(head[i + 7:i + 9], "big"), int.from_bytes(head[i + 5:i + 7], "big")
        i += 2 + length
    return None
