"""Read a built dataset back into arrays: the manifests, the feature table and the
metadata, for the audit and the previews.

Every frame of a dataset has the same feature list (one record per class, in
class-id order), so the per-feature manifest columns become ``(B, F, ...)``
arrays. Labels recomputed here use nothing but the manifest poses and
intrinsics and ``features.parquet``.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq
import yaml
from numpy.typing import NDArray

from datagen.camera import Intrinsics
from datagen.config import LabelsConfig
from datagen.errors import DatagenError
from datagen.features import FeatureTable
from datagen.labels import FrameLabels, compute_labels
from datagen.manifest import MANIFEST_VERSION, manifest_schema, read_features
from datagen.training import TrainView, label_options

__all__ = ["DatasetView", "load_dataset"]


@dataclass(frozen=True, eq=False)
class DatasetView:
    """A dataset's metadata and manifest rows, per-feature columns as ``(B, F)`` arrays
    (rows sorted by frame id)."""

    root: Path
    doc: dict  # dataset.json
    data_yaml: dict
    features: FeatureTable
    intrinsics: Intrinsics
    manifest_file: list[str]  # per row: the manifest it came from (relative to root)
    frame_id: NDArray[np.int64]
    split: list[str]
    image_path: list[str | None]
    label_path: list[str]
    exr_path: list[str | None]
    row_intrinsics: NDArray[np.float64]  # (B, 6): width, height, fx, fy, cx, cy
    cam_from_world: NDArray[np.float64]  # (B, 4, 4)
    world_from: dict[str, NDArray[np.float64]]  # object -> (B, 4, 4)
    distance_m: NDArray[np.float64]
    ptd_receiver_m: NDArray[np.float64]  # (B, 3)
    approach_index: NDArray[np.int64]
    approach_number: NDArray[np.int64]
    class_id: NDArray[np.int64]  # (B, F)
    center_px: NDArray[np.float64]  # (B, F, 2)
    tight_xyxy: NDArray[np.float64]  # (B, F, 4)
    corrected_xyxy: NDArray[np.float64]  # (B, F, 4)
    label_xyxy: NDArray[np.float64]  # (B, F, 4) the box written to the label file, NaN where not labeled
    labeled: NDArray[np.bool_]  # (B, F)
    exclusion: NDArray[np.object_]  # (B, F) reason or None
    visible_fraction: NDArray[np.float64]  # (B, F), NaN where not rendered
    center_visible: NDArray[np.float64]  # (B, F) 1, 0 or NaN

    def __len__(self) -> int:
        return len(self.frame_id)

    @property
    def corrected(self) -> bool:
        return bool(self.doc["corrected"])

    @property
    def edge_margin_px(self) -> float:
        return float(self.doc["edge_margin_px"])

    @property
    def label_rules(self) -> LabelsConfig:
        """The ``labels`` section of the config the dataset was built with."""
        return LabelsConfig.model_validate(self.doc["config"]["labels"])

    @property
    def train_view(self) -> TrainView:
        """How Ultralytics' trainer sees this dataset's images (``labels.train_imgsz``)."""
        return TrainView(self.intrinsics.width, self.intrinsics.height, self.label_rules.train_imgsz)

    def cam_from_objects(self) -> NDArray[np.float64]:
        """``(B, O, 4, 4)`` in the order of ``features.objects``."""
        return np.stack([self.cam_from_world @ self.world_from[o] for o in self.features.objects], axis=1)

    def recompute(self) -> FrameLabels:
        """The labels of every frame from the poses and features.parquet alone (with the
        manifest's visibility for the optional occlusion rule)."""
        rules = self.label_rules
        labels = compute_labels(self.features, self.cam_from_objects(), self.intrinsics,
                                **label_options(rules, self.intrinsics.width, self.intrinsics.height))
        threshold = rules.min_visible_fraction
        if threshold > 0:
            fraction = np.where(np.isnan(self.visible_fraction), 1.0, self.visible_fraction)
            labels = labels.with_visibility(fraction, threshold)
        return labels


def _read_json(path: Path) -> dict:
    try:
        return json.loads(path.read_text())
    except FileNotFoundError:
        raise DatagenError(f"{path}: no such file; not a datagen dataset folder") from None
    except (OSError, ValueError) as exc:
        raise DatagenError(f"{path}: unreadable ({exc})") from None


def _floats(array: pa.Array, shape: tuple[int, ...]) -> NDArray[np.float64]:
    """A float column (or fixed-size lists of floats) as an array of ``shape``, NaN where null."""
    if pa.types.is_fixed_size_list(array.type):
        n = array.type.list_size
        values = _floats(array.values.slice(array.offset * n, len(array) * n), (len(array), n))
        null = np.asarray(array.is_null())
        if null.any():
            values = values.copy()
            values[null] = np.nan  # a null list hides its (arbitrary) values
        return values.reshape(shape)
    return np.asarray(pc.fill_null(array, float("nan")).to_numpy(zero_copy_only=False),
                      dtype=np.float64).reshape(shape)


def load_dataset(root: str | Path) -> DatasetView:
    """Read ``root``'s dataset.json, data.yaml, features.parquet and every manifest.

    Raises:
        DatagenError: one line naming the file and what is wrong with it.
    """
    root = Path(root)
    if not root.is_dir():
        raise DatagenError(f"{root}: no such dataset folder")
    doc = _read_json(root / "dataset.json")
    for key in ("intrinsics", "image_width", "image_height", "edge_margin_px", "corrected", "config"):
        if key not in doc:
            raise DatagenError(f"{root / 'dataset.json'}: {key}: missing")
    try:
        LabelsConfig.model_validate(doc["config"]["labels"])
    except (KeyError, TypeError, ValueError) as exc:
        first = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise DatagenError(f"{root / 'dataset.json'}: config.labels: invalid ({first})") from None
    try:
        data_yaml = yaml.safe_load((root / "data.yaml").read_text()) or {}
    except (OSError, yaml.YAMLError) as exc:
        raise DatagenError(f"{root / 'data.yaml'}: unreadable ({exc})") from None
    try:
        features = read_features(root / "features.parquet")
    except (OSError, pa.ArrowException, KeyError, ValueError) as exc:
        raise DatagenError(f"{root / 'features.parquet'}: unreadable ({exc})") from None
    k = doc["intrinsics"]
    missing = [key for key in ("fx", "fy", "cx", "cy") if not isinstance(k, dict) or key not in k]
    if missing:
        raise DatagenError(f"{root / 'dataset.json'}: intrinsics.{missing[0]}: missing")
    intrinsics = Intrinsics(int(doc["image_width"]), int(doc["image_height"]), k["fx"], k["fy"], k["cx"], k["cy"])
    expected = manifest_schema()
    tables, names = [], []
    for path in sorted((root / "manifests").glob("*.parquet")):
        try:
            table = pq.read_table(path)
        except (OSError, pa.ArrowException) as exc:
            raise DatagenError(f"{path}: unreadable manifest ({type(exc).__name__})") from None
        version = (table.schema.metadata or {}).get(b"datagen.manifest_version", b"?").decode()
        if version != MANIFEST_VERSION:
            raise DatagenError(f"{path}: manifest version {version}, this datagen reads {MANIFEST_VERSION}")
        for field in expected:
            have = table.schema.field(field.name) if field.name in table.schema.names else None
            if have is None or not have.type.equals(field.type):
                what = "missing" if have is None else f"type {have.type}, expected {field.type}"
                raise DatagenError(f"{path}: column {field.name}: {what}")
        tables.append(table.select(expected.names).cast(expected))
        names += [str(path.relative_to(root))] * table.num_rows
    if not tables:
        raise DatagenError(f"{root / 'manifests'}: no manifest; the dataset has no finished shard")
    try:
        table = pa.concat_tables(tables)
    except pa.ArrowException as exc:
        raise DatagenError(f"{root / 'manifests'}: manifests with different schemas ({exc})") from None
    order = np.argsort(np.asarray(table.column("frame_id")), kind="stable")
    table = table.take(pa.array(order))
    names = [names[i] for i in order]
    b, f = table.num_rows, len(features)
    lists = table.column("features").combine_chunks()
    lengths = np.asarray(pc.list_value_length(lists))
    if not np.all(lengths == f):
        bad = int(np.argmax(lengths != f))
        raise DatagenError(f"{root / names[bad]}: frame {table.column('frame_id')[bad]}: {lengths[bad]} feature "
                           f"records, features.parquet has {f} classes")
    flat = lists.flatten()

    def matrices(name: str) -> NDArray[np.float64]:
        return _floats(table.column(name).combine_chunks(), (b, 4, 4))

    exclusion = np.array(flat.field("exclusion").to_pylist(), dtype=object).reshape(b, f)
    return DatasetView(
        root=root,
        doc=doc,
        data_yaml=data_yaml,
        features=features,
        intrinsics=intrinsics,
        manifest_file=names,
        frame_id=np.asarray(table.column("frame_id"), dtype=np.int64),
        split=table.column("split").to_pylist(),
        image_path=table.column("image_path").to_pylist(),
        label_path=table.column("label_path").to_pylist(),
        exr_path=table.column("exr_path").to_pylist(),
        row_intrinsics=np.stack([np.asarray(table.column(c), dtype=np.float64)
                                 for c in ("width", "height", "fx", "fy", "cx", "cy")], axis=1),
        cam_from_world=matrices("cam_from_world"),
        world_from={o: matrices(f"world_from_{o}") for o in ("tanker", "receiver", "drogue")},
        distance_m=np.asarray(table.column("distance_m"), dtype=np.float64),
        ptd_receiver_m=_floats(table.column("ptd_receiver_m").combine_chunks(), (b, 3)),
        approach_index=np.asarray(table.column("approach_index"), dtype=np.int64),
        approach_number=np.asarray(table.column("approach_number"), dtype=np.int64),
        class_id=np.asarray(flat.field("class_id"), dtype=np.int64).reshape(b, f),
        center_px=_floats(flat.field("center_px"), (b, f, 2)),
        tight_xyxy=_floats(flat.field("tight_xyxy"), (b, f, 4)),
        corrected_xyxy=_floats(flat.field("corrected_xyxy"), (b, f, 4)),
        label_xyxy=_floats(flat.field("label_xyxy"), (b, f, 4)),
        labeled=np.asarray(flat.field("labeled").to_numpy(zero_copy_only=False), dtype=bool).reshape(b, f),
        exclusion=exclusion,
        visible_fraction=_floats(flat.field("visible_fraction"), (b, f)),
        center_visible=_floats(pc.cast(flat.field("center_visible"), pa.float64()), (b, f)),
    )
