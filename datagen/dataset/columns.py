"""Parquet schemas of a dataset: the per-frame manifests and the feature table.

The one place that knows the column names and types. ``manifests/README.md``
documents every column; a test checks that the two agree.

- ``manifests/{split}-{shard:05d}.parquet``: one row per frame (:func:`manifest_schema`).
  The schema metadata carries ``datagen.manifest_version`` and the shard's
  label counts (``datagen.shard_summary``, JSON).
- ``features.parquet``: one row per class (:func:`features_schema`): the 3D point
  set and true centre of every feature in its object's frame, which is all
  that PnP (and a label audit) needs besides the manifest poses.
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Final

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
from numpy.typing import NDArray

from datagen.atomic import write_parquet
from datagen.config.inputs import parse_json
from datagen.core.errors import DatagenError
from datagen.core.features import MAX_NAME_CHARS, FeatureTable, valid_name
from datagen.core.keypoints import keypoint_flags
from datagen.core.label_boxes import Exclusion
from datagen.paths import read_bytes

__all__ = [
    "APPEARANCE",
    "COLUMNS_SINCE",
    "IMAGE_STATISTICS",
    "MANIFEST_VERSION",
    "MEASURED_COLUMNS",
    "PIXEL_COLUMNS",
    "READABLE_MANIFEST_VERSIONS",
    "RUN_COLUMNS",
    "TEXEL_COLUMNS",
    "FeatureColumns",
    "feature_records",
    "features_schema",
    "manifest_schema",
    "matrix_field",
    "object_records",
    "read_features",
    "read_manifest_summary",
    "read_objects",
    "read_parquet",
    "stored_schema",
    "stored_type",
    "write_features",
    "write_manifest",
    "write_objects",
]

#: Version of the manifest and feature-table schemas (bumped on any incompatible change).
MANIFEST_VERSION: Final = "12"
#: The manifest versions this datagen reads: 7 stored fixed-size lists as they are
#: (:func:`stored_type`); a column added since a version is read as nulls from it
#: (:data:`COLUMNS_SINCE`).
READABLE_MANIFEST_VERSIONS: Final = ("7", "8", "9", "10", "11", MANIFEST_VERSION)
#: Columns added after version 7, with the version that added them.
COLUMNS_SINCE: Final = {"haze_scale_height_m": "9", "cloud_type": "10", "cloud_deck_thickness_m": "10",
                         "cloud_layer_thickness_m": "10", "ground_type": "10", "ground_seed": "10",
                         **dict.fromkeys(("camera_vibration_rms_deg", "camera_vibration_hz", "drogue_canopy",
                                          "drogue_tape", "hose_band_colour", "hose_band_spacing_m",
                                          "hose_band_width_m", "other_aircraft", "other_aircraft_tanker_m",
                                          "other_aircraft_heading_deg", "window_dirt", "window_droplets",
                                          "window_reflection", "window_seed", "sensor_lens_blur_px",
                                          "sensor_chromatic_aberration_px", "sensor_white_balance_k", "sensor_tint",
                                          "sensor_tone_gamma", "sensor_tone_shoulder", "sensor_video_crf",
                                          "sensor_readout_s", "cam_from_tanker_per_s", "cam_from_receiver_per_s",
                                          "cam_from_drogue_per_s", "drogue_luminance", "drogue_contrast"), "11"),
                         "aircraft_lights": "12", "aircraft_light_scale": "12"}

#: The image statistics a manifest records per rendered frame
#: (:func:`datagen.render.tonemap.image_statistics` measures them).
IMAGE_STATISTICS: Final = ("image_mean_luminance", "image_rms_contrast", "share_sky", "share_sea", "share_cloud",
                           "share_object", "drogue_luminance", "drogue_contrast")
#: The largest on-screen footprint (px) of a texel the frame sampled: of the world's textures
#: (the sea's wave normals; clouds are procedural, without texels) and of the aircraft's
#: liveries (:meth:`datagen.render.world.World.texel_footprint_px`); null where none is seen.
TEXEL_COLUMNS: Final = ("world_texel_px", "livery_texel_px")
#: Manifest columns that name a frame's files (relative to the dataset root; null when absent).
FILE_COLUMNS: Final = ("image_path", "label_path", "pose_label_path", "exr_path")
#: Manifest columns that describe the run rather than the frame: they differ between
#: two builds of the same config; every other column is identical.
RUN_COLUMNS: Final = ("render_s", "denoise_s", "frame_s", "worker", "worker_rss_mib")
#: Manifest columns measured on the rendered pixels, whose last bits depend on how many threads
#: Mitsuba renders with (the order in which a pixel's samples are summed): the promise of a
#: build is that the same config and seed give the same label files and the same manifests,
#: :data:`RUN_COLUMNS` aside, for any worker count; these columns (and the images) too when
#: every worker renders with the same number of threads (``--threads 1``: on any machine).
#: With the default threads (the cores divided among the workers) they differ in the last
#: bits, about 1e-7 relative.
PIXEL_COLUMNS: Final = ("auto_exposure_ev", "image_mean_luminance", "image_rms_contrast", "drogue_luminance",
                         "drogue_contrast")
#: Manifest columns measured on the rendered frame (the camera model's metering and motion,
#: the image statistics): null where the frame was not rendered (labels-only builds).
MEASURED_COLUMNS: Final = ("auto_exposure_ev", "motion_blur_px", "sun_in_view", *IMAGE_STATISTICS, *TEXEL_COLUMNS)
#: The appearance dimensions of a frame and their manifest columns, as the audit's appearance
#: section shows their coverage (a column is null in every row where its randomizer is off).
APPEARANCE: Final[dict[str, tuple[str, ...]]] = {
    "sun and sky": ("sun_elevation_deg", "sun_azimuth_deg", "sun_backlit", "turbidity", "sun_scale", "sky_scale",
                    "exposure_ev"),
    "atmosphere": ("haze_visibility_m", "haze_scale_height_m"),
    "clouds": ("cloud_type", "cloud_deck_coverage", "cloud_deck_altitude_m", "cloud_deck_thickness_m",
               "cloud_layer_coverage", "cloud_layer_altitude_m", "cloud_layer_thickness_m", "cloud_opacity",
               "cloud_albedo"),
    "ground": ("ground_type",),
    "sea": ("sea_wind_speed_mps", "sea_roughness", "sea_wind_direction_deg", "sea_wave_slope_variance",
            "sea_whitecap_fraction"),
    "livery": ("receiver_livery", "tanker_livery", "livery_weathering", "aircraft_lights", "aircraft_light_scale"),
    "drogue": ("drogue_canopy", "drogue_tape", "hose_band_spacing_m", "drogue_luminance", "drogue_contrast"),
    "camera": ("camera_vibration_rms_deg", "camera_vibration_hz", "motion_blur_px"),
    "window": ("window_dirt", "window_droplets", "window_reflection"),
    "traffic": ("other_aircraft",),
    "sensor": ("sensor_iso", "sensor_exposure_time_s", "sensor_vignetting", "sensor_glare", "sensor_jpeg_quality",
               "sensor_lens_blur_px", "sensor_chromatic_aberration_px", "sensor_white_balance_k", "sensor_tint",
               "sensor_tone_gamma", "sensor_tone_shoulder", "sensor_video_crf", "sensor_readout_s", "auto_exposure_ev",
               "sun_in_view"),
    "image": IMAGE_STATISTICS,
    "texels": TEXEL_COLUMNS,
}

_F64 = pa.float64()


def _vec(n: int) -> pa.DataType:
    return pa.list_(_F64, n)


#: A 4x4 homogeneous transform: four rows of four (row-major), so that every reader gets the
#: matrix back without reshaping (``np.array(row["cam_from_world"].tolist())`` in pandas).
MATRIX: Final = pa.list_(_vec(4), 4)

FEATURE_RECORD: Final = pa.struct([
    ("class_id", pa.int32()),
    ("center_px", _vec(2)),
    ("tight_xyxy", _vec(4)),
    ("corrected_xyxy", _vec(4)),
    ("label_xyxy", _vec(4)),
    ("labeled", pa.bool_()),
    ("exclusion", pa.string()),
    ("visible_fraction", _F64),
    ("center_visible", pa.bool_()),
    ("keypoint_flag", pa.int8()),
])

#: One labeled object of a frame as a pose instance (datagen.core.keypoints): the box of its
#: projected mesh (hull vertices), the label box after the size rule, and its exclusion.
OBJECT_RECORD: Final = pa.struct([
    ("object", pa.string()),
    ("class_id", pa.int32()),
    ("tight_xyxy", _vec(4)),
    ("label_xyxy", _vec(4)),
    ("labeled", pa.bool_()),
    ("exclusion", pa.string()),
])

MATERIAL_RECORD: Final = pa.struct([
    ("object", pa.string()),
    ("part_class", pa.string()),
    ("base_color", _vec(3)),
    ("roughness", _F64),
    ("metallic", _F64),
    ("specular", _F64),
])


def manifest_schema() -> pa.Schema:
    """The schema of a manifest shard (version in the metadata)."""
    fields = [
        pa.field("frame_id", pa.int64(), nullable=False),
        pa.field("split", pa.string(), nullable=False),
        pa.field("shard", pa.int32(), nullable=False),
        pa.field("image_path", pa.string()),
        pa.field("label_path", pa.string()),
        pa.field("pose_label_path", pa.string()),
        pa.field("exr_path", pa.string()),
        pa.field("width", pa.int32(), nullable=False),
        pa.field("height", pa.int32(), nullable=False),
        pa.field("fx", _F64, nullable=False),
        pa.field("fy", _F64, nullable=False),
        pa.field("cx", _F64, nullable=False),
        pa.field("cy", _F64, nullable=False),
        pa.field("cam_from_world", MATRIX, nullable=False),
        pa.field("world_from_tanker", MATRIX, nullable=False),
        pa.field("world_from_receiver", MATRIX, nullable=False),
        pa.field("world_from_drogue", MATRIX, nullable=False),
        pa.field("cam_from_tanker_per_s", MATRIX),
        pa.field("cam_from_receiver_per_s", MATRIX),
        pa.field("cam_from_drogue_per_s", MATRIX),
        pa.field("ptd_receiver_m", _vec(3), nullable=False),
        pa.field("distance_m", _F64, nullable=False),
        pa.field("seed", pa.int64(), nullable=False),
        pa.field("render_seed", pa.int64(), nullable=False),
        pa.field("spp", pa.int32()),
        pa.field("denoise", pa.string()),
        pa.field("mount", pa.string(), nullable=False),
        pa.field("approach_index", pa.int64(), nullable=False),
        pa.field("approach_number", pa.int32(), nullable=False),
        pa.field("time_s", _F64, nullable=False),
        pa.field("turbulence_intensity", _F64, nullable=False),
        pa.field("bank_deg", _F64, nullable=False),
        pa.field("sun_elevation_deg", _F64, nullable=False),
        pa.field("sun_azimuth_deg", _F64, nullable=False),
        pa.field("sun_direction_world", _vec(3), nullable=False),
        pa.field("turbidity", _F64, nullable=False),
        pa.field("sun_scale", _F64, nullable=False),
        pa.field("sky_scale", _F64, nullable=False),
        pa.field("exposure_ev", _F64, nullable=False),
        pa.field("sea_roughness", _F64, nullable=False),
        pa.field("sea_wind_speed_mps", _F64),
        pa.field("haze_visibility_m", _F64),
        pa.field("haze_scale_height_m", _F64),
        pa.field("materials", pa.list_(MATERIAL_RECORD), nullable=False),
        pa.field("sun_backlit", pa.bool_()),
        pa.field("cloud_type", pa.string()),
        pa.field("cloud_deck_coverage", _F64),
        pa.field("cloud_deck_altitude_m", _F64),
        pa.field("cloud_deck_thickness_m", _F64),
        pa.field("cloud_layer_coverage", _F64),
        pa.field("cloud_layer_altitude_m", _F64),
        pa.field("cloud_layer_thickness_m", _F64),
        pa.field("cloud_opacity", _F64),
        pa.field("cloud_albedo", _F64),
        pa.field("cloud_seed", pa.int64()),
        pa.field("sea_wind_direction_deg", _F64),
        pa.field("sea_wave_slope_variance", _F64),
        pa.field("sea_whitecap_fraction", _F64),
        pa.field("sea_colour", _vec(3)),
        pa.field("sea_seed", pa.int64()),
        pa.field("ground_type", pa.string()),
        pa.field("ground_seed", pa.int64()),
        pa.field("receiver_livery", pa.string()),
        pa.field("tanker_livery", pa.string()),
        pa.field("livery_weathering", _F64),
        pa.field("livery_seed", pa.int64()),
        pa.field("aircraft_lights", pa.bool_()),
        pa.field("aircraft_light_scale", _F64),
        pa.field("sensor_iso", _F64),
        pa.field("sensor_exposure_time_s", _F64),
        pa.field("sensor_vignetting", _F64),
        pa.field("sensor_glare", _F64),
        pa.field("sensor_distortion", _vec(5)),
        pa.field("sensor_jpeg_quality", pa.int32()),
        pa.field("sensor_seed", pa.int64()),
        pa.field("camera_vibration_rms_deg", _F64),
        pa.field("camera_vibration_hz", _F64),
        pa.field("drogue_canopy", pa.string()),
        pa.field("drogue_tape", pa.bool_()),
        pa.field("hose_band_colour", _vec(3)),
        pa.field("hose_band_spacing_m", _F64),
        pa.field("hose_band_width_m", _F64),
        pa.field("other_aircraft", pa.string()),
        pa.field("other_aircraft_tanker_m", _vec(3)),
        pa.field("other_aircraft_heading_deg", _F64),
        pa.field("window_dirt", _F64),
        pa.field("window_droplets", pa.int32()),
        pa.field("window_reflection", _F64),
        pa.field("window_seed", pa.int64()),
        pa.field("sensor_lens_blur_px", _F64),
        pa.field("sensor_chromatic_aberration_px", _F64),
        pa.field("sensor_white_balance_k", _F64),
        pa.field("sensor_tint", _F64),
        pa.field("sensor_tone_gamma", _F64),
        pa.field("sensor_tone_shoulder", _F64),
        pa.field("sensor_video_crf", pa.int32()),
        pa.field("sensor_readout_s", _F64),
        pa.field("auto_exposure_ev", _F64),
        pa.field("motion_blur_px", _F64),
        pa.field("sun_in_view", pa.bool_()),
        *(pa.field(name, _F64) for name in IMAGE_STATISTICS),
        *(pa.field(name, _F64) for name in TEXEL_COLUMNS),
        pa.field("n_labeled", pa.int32(), nullable=False),
        pa.field("features", pa.list_(FEATURE_RECORD), nullable=False),
        pa.field("objects", pa.list_(OBJECT_RECORD), nullable=False),
        pa.field("render_s", _F64),
        pa.field("denoise_s", _F64),
        pa.field("frame_s", _F64),
        pa.field("worker", pa.string()),
        pa.field("worker_rss_mib", _F64),
    ]
    return pa.schema(fields, metadata={"datagen.manifest_version": MANIFEST_VERSION})


def stored_type(t: pa.DataType) -> pa.DataType:
    """How a manifest column of type ``t`` is stored in parquet: every fixed-size list (at
    any depth) as a list, whose null rows every supported pyarrow writes and reads back
    (before pyarrow 26 a null fixed-size list row read back as an error); readers cast the
    columns back to :func:`manifest_schema`'s types."""
    if pa.types.is_fixed_size_list(t) or pa.types.is_list(t):
        return pa.list_(stored_type(t.value_type))
    if pa.types.is_struct(t):
        return pa.struct([pa.field(f.name, stored_type(f.type), f.nullable) for f in t])
    return t


def stored_schema(schema: pa.Schema) -> pa.Schema:
    """``schema`` with each column's :func:`stored_type`."""
    return pa.schema([f.with_type(stored_type(f.type)) for f in schema], metadata=schema.metadata)


def write_manifest(path: Path, rows: Sequence[dict], summary: dict) -> Path:
    """Write one shard's manifest atomically (its columns as :func:`stored_type` says);
    ``summary`` (label counts, JSON-able) goes into the schema metadata."""
    schema = stored_schema(manifest_schema())
    meta = dict(schema.metadata)
    meta[b"datagen.shard_summary"] = json.dumps(summary, sort_keys=True).encode()
    index = schema.get_field_index("features")
    scalars = pa.Table.from_pylist([{k: v for k, v in row.items() if k != "features"} for row in rows],
                                   schema=schema.remove(index))
    table = scalars.add_column(index, schema.field("features"), _features_column([r["features"] for r in rows]))
    return write_parquet(path, table.replace_schema_metadata(meta), compression="zstd")


def read_manifest_summary(path: Path, max_bytes: int) -> dict:
    """The label counts a shard's manifest carries in its metadata (no row is read; a file
    over ``max_bytes`` is not read at all): a mapping, or one line saying why not."""
    data = read_bytes(path, "a shard's manifest", max_bytes)
    try:
        meta = pq.read_schema(pa.BufferReader(data)).metadata or {}
    except (OSError, pa.ArrowException) as exc:
        raise DatagenError(f"{path}: unreadable manifest ({type(exc).__name__})") from None
    summary = parse_json(meta.get(b"datagen.shard_summary", b"{}").decode("utf-8", "replace"), path)
    if not isinstance(summary, dict):
        raise DatagenError(f"{path}: datagen.shard_summary: expected a mapping of label counts")
    return summary


# --- features.parquet ----------------------------------------------------------------
def features_schema() -> pa.Schema:
    return pa.schema([
        pa.field("class_id", pa.int32(), nullable=False),
        pa.field("name", pa.string(), nullable=False),
        pa.field("object", pa.string(), nullable=False),
        pa.field("points_m", pa.list_(_vec(3)), nullable=False),
        pa.field("center_m", _vec(3), nullable=False),
        pa.field("size", pa.string(), nullable=False),
    ], metadata={"datagen.manifest_version": MANIFEST_VERSION})


def write_features(path: Path, features: FeatureTable) -> Path:
    """One row per class: the point set (unpadded) and true centre in its object's frame."""
    rows = [
        {
            "class_id": int(features.class_id[i]),
            "name": features.name[i],
            "object": features.objects[features.object_index[i]],
            "points_m": features.point_set(i).tolist(),
            "center_m": features.center_model[i].tolist(),
            "size": features.size[i],
        }
        for i in range(len(features))
    ]
    return write_parquet(path, pa.Table.from_pylist(rows, schema=features_schema()))


#: The farthest a feature point or hull vertex may lie from its object's origin, metres.
MAX_BODY_M: Final = 10_000.0


def _body_points(values: object, what: str) -> NDArray[np.float64]:
    """``(N, 3)`` points of an object's body frame, finite and within :data:`MAX_BODY_M`
    (ValueError naming ``what`` otherwise)."""
    points = np.asarray(values, dtype=np.float64).reshape(-1, 3)
    if not len(points) or not (np.isfinite(points) & (np.abs(points) <= MAX_BODY_M)).all():
        raise ValueError(f"{what}: expected points of finite metres within {MAX_BODY_M:g} of the object's origin")
    return points


def read_parquet(source: str | Path | pa.BufferReader, columns: list[str] | None = None) -> pa.Table:
    """A whole parquet table (a path or a buffer), read on the calling thread. pyarrow's
    ``read_table``, and ``ParquetFile`` given a path, start Arrow's I/O thread pool even with
    ``use_threads=False``; a worker of that pool still starting when the interpreter exits
    aborts the process ("terminate called without an active exception", exit -6), so a
    refusal's one line could end in a crash. A buffer read by ``ParquetFile`` starts none."""
    if not isinstance(source, pa.BufferReader):
        source = pa.BufferReader(Path(source).read_bytes())
    return pq.ParquetFile(source).read(columns=columns, use_threads=False)


def read_features(source) -> FeatureTable:
    """The :class:`FeatureTable` a dataset was labeled with, from its ``features.parquet``
    (a path or a buffer); ValueError for a point that is not finite metres."""
    table = read_parquet(source).to_pylist()
    table.sort(key=lambda r: r["class_id"])
    for r in table:
        for key in ("name", "object"):
            if not valid_name(r[key]):
                raise ValueError(f"class {r['class_id']} {key}: not a name of 1 to {MAX_NAME_CHARS} printable "
                                 "characters")
    return FeatureTable.from_point_sets(
        [_body_points(r["points_m"], f"class {r['class_id']} points_m") for r in table],
        objects=[r["object"] for r in table],
        class_ids=[r["class_id"] for r in table],
        names=[r["name"] for r in table],
        centers=[_body_points(r["center_m"], f"class {r['class_id']} center_m")[0] for r in table],
        sizes=[r["size"] for r in table],
    )


# --- objects.parquet ----------------------------------------------------------------
def objects_schema() -> pa.Schema:
    return pa.schema([
        pa.field("class_id", pa.int32(), nullable=False),
        pa.field("object", pa.string(), nullable=False),
        pa.field("hull_points_m", pa.list_(_vec(3)), nullable=False),
    ], metadata={"datagen.manifest_version": MANIFEST_VERSION})


def write_objects(path: Path, objects: Sequence[str], hulls: Mapping[str, NDArray[np.float64]]) -> Path:
    """One row per labeled object (its pose class): the convex-hull vertices of its mesh in
    its body frame, which bound its projection (:mod:`datagen.core.keypoints`)."""
    rows = [{"class_id": c, "object": name, "hull_points_m": np.asarray(hulls[name]).tolist()}
            for c, name in enumerate(objects)]
    return write_parquet(path, pa.Table.from_pylist(rows, schema=objects_schema()))


def read_objects(source) -> dict[str, NDArray[np.float64]]:
    """Object name -> hull vertices ``(H, 3)``, in pose-class order, from ``objects.parquet``
    (a path or a buffer); ValueError for a vertex that is not finite metres."""
    rows = sorted(read_parquet(source).to_pylist(), key=lambda r: r["class_id"])
    return {r["object"]: _body_points(r["hull_points_m"], f"object {r['object']} hull_points_m") for r in rows}


def matrix_field(m: np.ndarray) -> list[list[float]]:
    """A 4x4 transform as the four rows of a manifest column."""
    return np.asarray(m, dtype=np.float64).reshape(4, 4).tolist()


@dataclass(frozen=True)
class FeatureColumns:
    """The ``features`` column of one frame as arrays (``F`` records, class-id order):
    a manifest row carries this until its shard is written in one columnar pass."""

    class_id: NDArray[np.int64]
    center_px: NDArray[np.float64]  # (F, 2)
    tight_xyxy: NDArray[np.float64]  # (F, 4)
    corrected_xyxy: NDArray[np.float64]  # (F, 4)
    label_xyxy: NDArray[np.float64]  # (F, 4) the box written to the label file (null where not labeled)
    exclusion: NDArray[np.int8]  # Exclusion codes
    visible_fraction: NDArray[np.float64] | None  # None: not rendered
    center_visible: NDArray[np.bool_] | None
    keypoint_flag: NDArray[np.int8]  # Ultralytics' pose visibility (datagen.core.keypoints.keypoint_flags)

    @property
    def labeled(self) -> NDArray[np.bool_]:
        return self.exclusion == 0

    def exclusion_counts(self) -> dict[str, int]:
        codes, counts = np.unique(self.exclusion[self.exclusion != 0], return_counts=True)
        return {Exclusion(int(c)).reason: int(n) for c, n in zip(codes, counts, strict=True)}


def feature_records(labels, class_ids, visible_fraction=None, center_visible=None) -> FeatureColumns:
    """The ``features`` column of one frame from its :class:`~datagen.core.label_boxes.FrameLabels`."""
    return FeatureColumns(
        class_id=np.asarray(class_ids, dtype=np.int64),
        center_px=np.asarray(labels.center_px, dtype=np.float64),
        tight_xyxy=np.asarray(labels.tight_xyxy, dtype=np.float64),
        corrected_xyxy=np.asarray(labels.corrected_xyxy, dtype=np.float64),
        label_xyxy=np.asarray(labels.label_xyxy, dtype=np.float64),
        exclusion=np.asarray(labels.exclusion, dtype=np.int8),
        visible_fraction=None if visible_fraction is None else np.asarray(visible_fraction, dtype=np.float64),
        center_visible=None if center_visible is None else np.asarray(center_visible, dtype=bool),
        keypoint_flag=keypoint_flags(labels.exclusion, center_visible),
    )


def object_records(labels, objects: Sequence[str]) -> list[dict]:
    """The ``objects`` column of one frame: each labeled object's pose box
    (:func:`datagen.core.keypoints.object_table` labels), null where not finite or not labeled."""
    def box(values, keep: bool) -> list[float] | None:
        return [float(v) for v in values] if keep and np.isfinite(values).all() else None

    return [{"object": name, "class_id": c, "tight_xyxy": box(labels.tight_xyxy[c], True),
             "label_xyxy": box(labels.label_xyxy[c], bool(labels.labeled[c])), "labeled": bool(labels.labeled[c]),
             "exclusion": Exclusion(int(labels.exclusion[c])).reason} for c, name in enumerate(objects)]


def _features_column(frames: Sequence[FeatureColumns]) -> pa.Array:
    """One ``list<struct>`` column from per-frame arrays, without a Python object per record."""
    counts = np.array([len(f.class_id) for f in frames], dtype=np.int32)
    offsets = pa.array(np.concatenate([[0], np.cumsum(counts)]).astype(np.int32))
    n = int(counts.sum())

    def cat(name: str, width: int = 0) -> NDArray:
        arrays = [getattr(f, name) for f in frames]
        if not arrays:
            return np.zeros((0, width) if width else 0)
        return np.concatenate(arrays) if width == 0 else np.concatenate(arrays).reshape(-1, width)

    def fixed(values: NDArray, width: int, mask: NDArray | None = None) -> pa.Array:
        """Lists of ``width`` values (stored as lists: :func:`stored_type`), null where a value
        is not finite (a point behind the camera has no projection: a null, which every table
        tool skips, not a NaN that poisons a mean) or ``mask``; a null list holds no values."""
        missing = ~np.isfinite(values).all(axis=1)
        if mask is not None:
            missing |= mask
        offsets = np.concatenate([[0], np.cumsum(np.where(missing, 0, width))]).astype(np.int32)
        return pa.ListArray.from_arrays(pa.array(offsets), pa.array(values[~missing].reshape(-1), _F64),
                                        mask=pa.array(missing))

    def optional(name: str, dtype) -> pa.Array:
        values = np.zeros(n, dtype=dtype)
        mask = np.ones(n, dtype=bool)
        start = 0
        for f, c in zip(frames, counts, strict=True):
            v = getattr(f, name)
            if v is not None:
                values[start:start + c] = v
                mask[start:start + c] = False
            start += c
        return pa.array(values, mask=mask)

    reasons = np.array([None] + [e.reason for e in list(Exclusion)[1:]], dtype=object)
    codes = cat("exclusion").astype(np.int64)
    struct = pa.StructArray.from_arrays(
        [
            pa.array(cat("class_id").astype(np.int32)),
            fixed(cat("center_px", 2), 2),
            fixed(cat("tight_xyxy", 4), 4),
            fixed(cat("corrected_xyxy", 4), 4),
            fixed(cat("label_xyxy", 4), 4, mask=codes != 0),
            pa.array(codes == 0),
            pa.array(reasons[codes].tolist(), pa.string()),
            optional("visible_fraction", np.float64),
            optional("center_visible", bool),
            pa.array(cat("keypoint_flag").astype(np.int8)),
        ],
        fields=list(stored_type(FEATURE_RECORD)),
    )
    return pa.ListArray.from_arrays(offsets, struct).cast(stored_type(pa.list_(FEATURE_RECORD)))
