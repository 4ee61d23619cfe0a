"""Parquet schemas of a dataset: the per-frame manifests and the feature table.

The one place that knows the column names and types. The manifest's columns are one table
(:data:`MANIFEST_COLUMNS`: name, type, nullability, meaning, version, group) from which the
Arrow schema and ``manifests/README.md``'s table of columns are derived; a test checks that
the page holds that table as derived.

- ``manifests/{split}-{shard:05d}.parquet``: one row per frame (:func:`manifest_schema`).
  The schema metadata carries ``datagen.manifest_version`` and the shard's
  label counts (``datagen.shard_summary``, JSON).
- ``features.parquet``: one row per class (:func:`features_schema`): the 3D point
  set and true centre of every feature in its object's frame, which is all
  that PnP (and a label audit) needs besides the manifest poses.
"""

from __future__ import annotations

import json
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Final, Generic, TypeVar, overload

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
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
    "COLUMNS",
    "COLUMNS_SINCE",
    "IMAGE_STATISTICS",
    "MANIFEST_VERSION",
    "MEASURED_COLUMNS",
    "PIXEL_COLUMNS",
    "READABLE_MANIFEST_VERSIONS",
    "RUN_COLUMNS",
    "TEXEL_COLUMNS",
    "FeatureColumns",
    "ManifestColumn",
    "ManifestColumns",
    "column_values",
    "feature_records",
    "features_schema",
    "manifest_record",
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


@dataclass(frozen=True)
class Column:
    """A manifest column: its name, Arrow type and meaning (as ``manifests/README.md``'s table
    of columns gives it; empty: the column shares the row of the one before it), whether it
    is never null (``required``: the schema says so), or is nullable in the schema but always
    written (``filled``), the manifest version that added it, its unit (empty: none, or a
    name, a count or a share), and the group that names it
    together (:data:`IMAGE_STATISTICS`, :data:`TEXEL_COLUMNS`, :data:`FILE_COLUMNS`,
    :data:`INTRINSICS_COLUMNS`, :data:`POSE_COLUMNS`, :data:`RATE_COLUMNS`, :data:`RUN_COLUMNS`)."""

    name: str
    type: pa.DataType
    meaning: str = ""
    required: bool = False
    filled: bool = False
    since: str = "7"
    group: str = ""
    unit: str = ""

    @property
    def field(self) -> pa.Field:
        """Its Arrow field."""
        return pa.field(self.name, self.type, nullable=not self.required)

    @property
    def type_text(self) -> str:
        """Its type as the table of columns gives it: ``int64``, ``3 float64``, ``4 x 4
        float64``, ``list of struct``, ``... or null``."""
        t = self.type
        if pa.types.is_fixed_size_list(t):
            inner = t.value_type
            text = (f"{t.list_size} x {inner.list_size} float64" if pa.types.is_fixed_size_list(inner)
                    else f"{t.list_size} float64")
        elif pa.types.is_list(t):
            text = "list of struct"
        else:
            text = {"double": "float64"}.get(str(t), str(t))
        return text if self.required or self.filled else f"{text} or null"


#: Every manifest column, in the schema's order: the one table from which the Arrow schema
#: (:func:`manifest_schema`), the versions that added columns (:data:`COLUMNS_SINCE`), the
#: named groups and ``manifests/README.md``'s table of columns (:func:`manifest_table`) are
#: derived. Adding a column is one line here plus its computation (and a version).
MANIFEST_COLUMNS: Final[tuple[Column, ...]] = (
    Column("frame_id", pa.int64(), "frame index; with `seed`, it fixes every draw of the frame", required=True),
    Column("split", pa.string(), "`train` or `val`", required=True),
    Column("shard", pa.int32(), "shard number within the split", required=True),
    Column("image_path", pa.string(), "training image (null in a `--no-render` build)", group="files"),
    Column("label_path", pa.string(), "YOLO detection label file (null with `labels.format: pose`)", group="files"),
    Column("pose_label_path", pa.string(), "YOLO pose label file (null with `labels.format: detect`)", group="files"),
    Column("exr_path", pa.string(), "linear EXR, when written", group="files"),
    Column("width", pa.int32(), "image size, pixels", required=True, group="intrinsics", unit="px"),
    Column("height", pa.int32(), required=True, group="intrinsics", unit="px"),
    Column("fx", _F64, "pinhole intrinsics, pixels", required=True, group="intrinsics", unit="px"),
    Column("fy", _F64, required=True, group="intrinsics", unit="px"),
    Column("cx", _F64, required=True, group="intrinsics", unit="px"),
    Column("cy", _F64, required=True, group="intrinsics", unit="px"),
    Column("cam_from_world", MATRIX, "world to OpenCV camera", required=True, unit="m (translation)"),
    Column("world_from_tanker", MATRIX,
           "tanker body frame (origin: the average drogue centre) to world", required=True, group="poses",
           unit="m (translation)"),
    Column("world_from_receiver", MATRIX, "receiver body frame (origin: the probe tip) to world", required=True,
           group="poses", unit="m (translation)"),
    Column("world_from_drogue", MATRIX, "drogue body frame (origin: the drogue centre) to world", required=True,
           group="poses", unit="m (translation)"),
    Column("cam_from_tanker_per_s", MATRIX,
           "the time derivative of `cam_from_world @ world_from_<object>` at the frame's time, per "
           "second (by finite difference over 1 ms): with `sensor_readout_s`, each label point is "
           "where `(M + rate t) X` projects at its row's time t (null without a rolling shutter; "
           "version 11)", since="11", group="rates", unit="per s"),
    Column("cam_from_receiver_per_s", MATRIX, since="11", group="rates", unit="per s"),
    Column("cam_from_drogue_per_s", MATRIX, since="11", group="rates", unit="per s"),
    Column("ptd_receiver_m", _vec(3), "probe-to-drogue vector in the receiver frame, metres", required=True, unit="m"),
    Column("distance_m", _F64, "its length", required=True, unit="m"),
    Column("seed", pa.int64(), "the dataset's root seed", required=True),
    Column("render_seed", pa.int64(),
           "Mitsuba sampler seed of the frame (derived from `seed`, `frame_id`)", required=True),
    Column("spp", pa.int32(), "samples per pixel (null without rendering)", unit="samples"),
    Column("denoise", pa.string(), "denoiser applied to the linear image: `off` or `oidn` (null without rendering)"),
    Column("mount", pa.string(), "camera mount: `wingcam`, `dashcam` or `podcam`", required=True),
    Column("approach_index", pa.int64(), "approach chain the frame comes from", required=True),
    Column("approach_number", pa.int32(),
           "approach within the chain (0 unless 'time' sampling passed a contact)", required=True),
    Column("time_s", _F64, "time since the chain started, seconds", required=True, unit="s"),
    Column("turbulence_intensity", _F64, "turbulence multiplier of the approach", required=True),
    Column("bank_deg", _F64, "tanker bank angle, degrees (0: straight and level)", required=True, unit="deg"),
    Column("sun_elevation_deg", _F64, "sun draw (azimuth from the tanker's heading)", required=True, unit="deg"),
    Column("sun_azimuth_deg", _F64, required=True, unit="deg"),
    Column("sun_direction_world", _vec(3), "unit vector towards the sun, world frame", required=True),
    Column("turbidity", _F64, "sky draws (Mitsuba `sunsky`)", required=True),
    Column("sun_scale", _F64, required=True),
    Column("sky_scale", _F64, required=True),
    Column("exposure_ev", _F64, "exposure compensation, stops", required=True, unit="EV"),
    Column("sea_roughness", _F64, "principled roughness of the sea surface", required=True),
    Column("sea_wind_speed_mps", _F64, "wind speed the roughness follows (Cox-Munk), m/s; null when drawn uniformly",
           unit="m/s"),
    Column("haze_visibility_m", _F64,
           "the approach's meteorological visibility at sea level, metres (Koschmieder, 550 nm), when"
           " aerial perspective is on", unit="m"),
    Column("haze_scale_height_m", _F64,
           "the approach's aerosol scale height, metres, when aerial perspective is on (version 9; "
           "null in rows read from older versions)", since="9", unit="m"),
    Column("materials", pa.list_(MATERIAL_RECORD),
           "per object and part class: `object`, `part_class`, `base_color` (linear RGB), "
           "`roughness`, `metallic`, `specular`", required=True),
    Column("sun_backlit", pa.bool_(),
           "the sun was put within `randomization.sky.backlit_azimuth_deg` of the camera's forward "
           "azimuth (null: `backlit_fraction` 0)"),
    Column("cloud_type", pa.string(),
           "the deck's form: `cumulus`, `stratocumulus` or `overcast` (version 10; null: clouds off, "
           "or rows read from older versions)", since="10"),
    Column("cloud_deck_coverage", _F64, "share of the cloud deck's area that is cloud (null: clouds off)"),
    Column("cloud_deck_altitude_m", _F64, "the deck's altitude above sea level, m", unit="m"),
    Column("cloud_deck_thickness_m", _F64,
           "how thick the deck's thickest cells are, m (its body: slopes, self-shadowing, bases; "
           "version 10)", since="10", unit="m"),
    Column("cloud_layer_coverage", _F64, "share of the scattered layer's area that is cloud"),
    Column("cloud_layer_altitude_m", _F64,
           "the scattered layer's altitude above sea level, m (above or below the tanker; constant "
           "over an approach)", unit="m"),
    Column("cloud_layer_thickness_m", _F64,
           "how thick the scattered layer's thickest cells are, m (version 10)", since="10", unit="m"),
    Column("cloud_opacity", _F64, "opacity of a cloud's thick core"),
    Column("cloud_albedo", _F64, "diffuse reflectance of the clouds"),
    Column("cloud_seed", pa.int64(), "seed of the layers' noise fields"),
    Column("sea_wind_direction_deg", _F64,
           "direction the wind blows towards, degrees counter-clockwise from world x (null: waves "
           "off)", unit="deg"),
    Column("sea_wave_slope_variance", _F64,
           "mean square slope the wave trains carry where a pixel resolves them all (the microfacet "
           "roughness keeps the rest of the sea's)"),
    Column("sea_whitecap_fraction", _F64, "share of the sea under whitecaps (Monahan 1980; null: whitecaps off)"),
    Column("sea_colour", _vec(3), "the sea's body colour, linear RGB (null: colour off)"),
    Column("sea_seed", pa.int64(), "seed of the wave phases and whitecaps"),
    Column("ground_type", pa.string(),
           "the approach's ground: `sea`, `coast`, `farmland`, `desert`, `snow` or `mountains` "
           "(version 10; null: ground off, open sea)", since="10"),
    Column("ground_seed", pa.int64(), "seed of the land's fields (shore, detail, relief, fields)", since="10"),
    Column("receiver_livery", pa.string(), "the receiver's livery scheme (null: liveries off)"),
    Column("tanker_livery", pa.string(), "the tanker's livery scheme"),
    Column("livery_weathering", _F64, "grime, streaks, soot and fading strength, 0-1"),
    Column("livery_seed", pa.int64(),
           "seed of the liveries' draws (colours, pattern, panels, markings; "
           "`datagen.render.paintwork`)"),
    Column("aircraft_lights", pa.bool_(),
           "the aircraft's navigation lights and beacons are on this approach (version 12; null: "
           "lights off, or rows read from older versions)", since="12"),
    Column("aircraft_light_scale", _F64,
           "a steady light's radiance over that of a white diffuser in the frame's daylight (beacons "
           "3x; version 12)", since="12"),
    Column("sensor_iso", _F64, "sensor gain, ISO (null: camera model or its noise off)", unit="ISO"),
    Column("sensor_exposure_time_s", _F64, "exposure time, s: the length of the motion blur (null: motion blur off)",
           unit="s"),
    Column("sensor_vignetting", _F64, "corner light falloff, 0-1"),
    Column("sensor_glare", _F64, "strength of the sun's veiling glare and ghosts"),
    Column("sensor_distortion", _vec(5),
           "OpenCV lens distortion `k1, k2, p1, p2, k3` the image and the labels went through (null: "
           "pinhole)"),
    Column("sensor_jpeg_quality", pa.int32(),
           "quality of the JPEG round trip (null: off, or the frame went through H.264: "
           "`sensor_video_crf`)"),
    Column("sensor_seed", pa.int64(), "seed of the sensor noise"),
    Column("camera_vibration_rms_deg", _F64,
           "the approach's camera vibration: RMS pointing angle, degrees (version 11; null: vibration"
           " off, or rows read from older versions)", since="11", unit="deg"),
    Column("camera_vibration_hz", _F64, "its power-weighted mean frequency, Hz (version 11)", since="11", unit="Hz"),
    Column("drogue_canopy", pa.string(),
           "the approach's canopy scheme (`datagen.assets.drogues.CANOPIES`; its parts' colours are "
           "in `materials`; version 11; null: drogue draws off)", since="11"),
    Column("drogue_tape", pa.bool_(), "the canopy's rim carries reflective tape (version 11)", since="11"),
    Column("hose_band_colour", _vec(3),
           "linear RGB of the hose's marker bands (version 11; null: no bands)", since="11"),
    Column("hose_band_spacing_m", _F64, "distance between the hose's marker bands, m (version 11)", since="11",
           unit="m"),
    Column("hose_band_width_m", _F64, "length of each marker band along the hose, m (version 11)", since="11",
           unit="m"),
    Column("other_aircraft", pa.string(),
           "another aircraft flying in formation with the tanker in the camera's field of view: "
           "`none`, `receiver` or `tanker`; drawn, never labeled (version 11; null: traffic off)", since="11"),
    Column("other_aircraft_tanker_m", _vec(3), "its place in the tanker frame, m (null: none)", since="11", unit="m"),
    Column("other_aircraft_heading_deg", _F64, "its heading off the tanker's, degrees (null: none)", since="11",
           unit="deg"),
    Column("window_dirt", _F64,
           "strength of the dirt on the camera's window, 0-1 (version 11; null: window off)", since="11"),
    Column("window_droplets", pa.int32(),
           "water droplets on a pod camera's window (0 on a dry approach; null: a windscreen, or "
           "window off; version 11)", since="11"),
    Column("window_reflection", _F64,
           "strength of a cockpit windscreen's reflection of the cockpit, a share of the image's mean"
           " light (null: a pod's window; version 11)", since="11"),
    Column("window_seed", pa.int64(),
           "seed of the window's dirt and reflection fields and its droplets (version 11)", since="11"),
    Column("sensor_lens_blur_px", _F64,
           "standard deviation of the lens's Gaussian blur, px (version 11; null: lens off)", since="11", unit="px"),
    Column("sensor_chromatic_aberration_px", _F64,
           "red-blue separation at the image's farthest corner, px (version 11)", since="11", unit="px"),
    Column("sensor_white_balance_k", _F64,
           "the daylight temperature the camera is white-balanced for (the scene's white is D65), K "
           "(version 11; null: colour off)", since="11", unit="K"),
    Column("sensor_tint", _F64, "the white balance's green gain offset (version 11)", since="11"),
    Column("sensor_tone_gamma", _F64, "exponent of the tone curve on display-linear values (version 11)", since="11"),
    Column("sensor_tone_shoulder", _F64,
           "strength of the tone curve's highlight shoulder, 0-1 (0: hard clip; version 11)", since="11"),
    Column("sensor_video_crf", pa.int32(),
           "x264's constant rate factor of the frame's H.264 round trip, which replaced its JPEG one "
           "(null: none; version 11)", since="11"),
    Column("sensor_readout_s", _F64,
           "a rolling shutter's top-to-bottom readout, seconds: row v was exposed (v / height - 1/2) "
           "times it after the frame's time (null: a global shutter; version 11)", since="11", unit="s"),
    Column("auto_exposure_ev", _F64, "measured: the auto-exposure's correction against the fixed exposure, stops",
           unit="EV"),
    Column("motion_blur_px", _F64, "measured: the longest image motion over the exposure, px", unit="px"),
    Column("sun_in_view", pa.bool_(), "measured: the sun's direction projects inside the image"),
    Column("image_mean_luminance", _F64,
           "measured: mean Rec. 709 luma of the final 8-bit image, 0-1", group="image statistics"),
    Column("image_rms_contrast", _F64, "measured: standard deviation of that luma", group="image statistics"),
    Column("share_sky", _F64, "measured: share of pixels whose ray meets nothing (sky)", group="image statistics"),
    Column("share_sea", _F64, "measured: share of pixels whose ray meets the sea", group="image statistics"),
    Column("share_cloud", _F64,
           "measured: share of pixels whose ray meets a cloud's opaque part", group="image statistics"),
    Column("share_object", _F64,
           "measured: share of pixels whose ray meets an aircraft, the drogue or the hose", group="image statistics"),
    Column("drogue_luminance", _F64,
           "measured: mean Rec. 709 luma of the drogue's pixels in the final image, 0-1 (version 11; "
           "null: fewer than 16 of them)", since="11", group="image statistics"),
    Column("drogue_contrast", _F64,
           "measured: (L_drogue - L_background) / (L_drogue + L_background), the background being the"
           " pixels of no object within the drogue's box grown by half its size (negative: darker "
           "than behind; version 11)", since="11", group="image statistics"),
    Column("world_texel_px", _F64,
           "measured: the largest on-screen size of a world texture's texel the frame shows (0: the "
           "sea and the clouds are procedural, no texels), px; the audit fails a frame over 1.5 px; "
           "null where no sea or cloud is seen", group="texels", unit="px"),
    Column("livery_texel_px", _F64,
           "measured: the same for the aircraft's liveries, px (0 from version 12: procedural, "
           "band-limited to the pixel); null where no livery is seen", group="texels", unit="px"),
    Column("n_labeled", pa.int32(), "labeled features: the lines of the detection label file", required=True),
    Column("features", pa.list_(FEATURE_RECORD), "one record per class, in class-id order (below)", required=True),
    Column("objects", pa.list_(OBJECT_RECORD),
           "one record per labeled object, in pose-class order (below)", required=True),
    Column("render_s", _F64, "seconds inside `mi.render` (null: not rendered by this run)", group="run", unit="s"),
    Column("denoise_s", _F64, "seconds in the denoiser (null: not denoised by this run)", group="run", unit="s"),
    Column("frame_s", _F64, "seconds for the whole frame in its worker", filled=True, group="run", unit="s"),
    Column("worker", pa.string(), "the process that wrote the frame, `host:pid`", filled=True, group="run"),
    Column("worker_rss_mib", _F64, "resident memory of the worker after the frame, MiB", filled=True, group="run",
           unit="MiB"),
)


#: Each manifest column by its name.
COLUMNS: Final[Mapping[str, Column]] = {c.name: c for c in MANIFEST_COLUMNS}


def _group(name: str) -> tuple[str, ...]:
    """The names of :data:`MANIFEST_COLUMNS` of group ``name``, in the schema's order."""
    return tuple(c.name for c in MANIFEST_COLUMNS if c.group == name)


#: Columns added after version 7, with the version that added them.
COLUMNS_SINCE: Final = {c.name: c.since for c in MANIFEST_COLUMNS if c.since != "7"}
#: The image statistics a manifest records per rendered frame
#: (:func:`datagen.render.tonemap.image_statistics` measures them).
IMAGE_STATISTICS: Final = _group("image statistics")
#: The largest on-screen footprint (px) of a texel the frame sampled: of the world's textures
#: (the sea's wave normals; clouds are procedural, without texels) and of the aircraft's
#: liveries (:meth:`datagen.render.world.World.texel_footprint_px`); null where none is seen.
TEXEL_COLUMNS: Final = _group("texels")
#: Manifest columns that name a frame's files (relative to the dataset root; null when absent).
FILE_COLUMNS: Final = _group("files")
#: A frame's pinhole camera: width, height, fx, fy, cx, cy (:class:`datagen.core.camera.Intrinsics`).
INTRINSICS_COLUMNS: Final = _group("intrinsics")
#: Each rigid object's pose column, ``world_from_<object>``, by object.
POSE_COLUMNS: Final = {c.name.removeprefix("world_from_"): c.name for c in MANIFEST_COLUMNS if c.group == "poses"}
#: Each rigid object's pose rate column (a rolling shutter's), ``cam_from_<object>_per_s``, by object.
RATE_COLUMNS: Final = {c.name.removeprefix("cam_from_").removesuffix("_per_s"): c.name
                       for c in MANIFEST_COLUMNS if c.group == "rates"}
#: Manifest columns that describe the run rather than the frame: they differ between
#: two builds of the same config; every other column is identical.
RUN_COLUMNS: Final = _group("run")
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



def manifest_record(values: Mapping[str, object]) -> dict[str, object]:
    """A frame's manifest row from ``values``, in the schema's order: a value for each of
    :data:`MANIFEST_COLUMNS` and for nothing else, a required column's not None (ValueError
    naming the columns otherwise: a column added to the table without its computation, or
    computed under another name, fails the first frame written, never becomes nulls)."""
    missing = [c.name for c in MANIFEST_COLUMNS if c.name not in values]
    unknown = sorted(set(values) - COLUMNS.keys())
    empty = [c.name for c in MANIFEST_COLUMNS if c.required and c.name in values and values[c.name] is None]
    if missing or unknown or empty:
        raise ValueError("a manifest row " + "; ".join(
            f"{what} {', '.join(names)}" for what, names in (("without columns", missing),
                                                             ("with columns no manifest has:", unknown),
                                                             ("with nulls in required columns", empty)) if names))
    return {c.name: values[c.name] for c in MANIFEST_COLUMNS}


def column_values(array: pa.Array | pa.ChunkedArray, column: Column) -> Any:
    """A manifest column's values as a reader holds them, by its Arrow type: floats (and
    fixed-size lists of them: vectors, matrices) as one float64 array ``(B, ...)`` with NaN
    where a value or a row is null; never-null integers as int64 ``(B,)``; every other
    column (text, flags, integers that may be null, lists of records) as a list of Python
    values, None where null."""
    t = column.type
    if pa.types.is_floating(t) or pa.types.is_fixed_size_list(t):
        shape: tuple[int, ...] = ()
        while pa.types.is_fixed_size_list(t):
            shape, t = (*shape, t.list_size), t.value_type
        return flat_floats(_one_chunk(array)).reshape(len(array), *shape)
    if pa.types.is_integer(t) and column.required:
        return np.asarray(_one_chunk(array), dtype=np.int64)
    return array.to_pylist()


def _one_chunk(array: pa.Array | pa.ChunkedArray) -> pa.Array:
    return array.combine_chunks() if isinstance(array, pa.ChunkedArray) else array


def flat_floats(array: pa.Array) -> NDArray[np.float64]:
    """A float column, or (nested) fixed-size lists of floats, flattened to float64, NaN where
    a value or a list is null."""
    if pa.types.is_fixed_size_list(array.type):
        n = array.type.list_size
        values = flat_floats(array.values.slice(array.offset * n, len(array) * n)).reshape(len(array), -1)
        null = np.asarray(array.is_null())
        if null.any():
            values = values.copy()
            values[null] = np.nan  # a null list hides its (arbitrary) values
        return values.reshape(-1)
    return np.asarray(pc.fill_null(array, float("nan")).to_numpy(zero_copy_only=False), dtype=np.float64)


class ManifestColumns(Mapping[str, Any]):
    """The manifest columns of a table of rows, each decoded when first read
    (:func:`column_values`) and kept: a reader's view of its rows, by column name."""

    def __init__(self, table: pa.Table) -> None:
        self.table = table
        self._values: dict[str, Any] = {}

    def __getitem__(self, name: str) -> Any:
        if name not in self._values:
            if name not in COLUMNS or name not in self.table.column_names:
                raise KeyError(name)
            self._values[name] = column_values(self.table.column(name), COLUMNS[name])
        return self._values[name]

    def __iter__(self) -> Iterator[str]:
        return (c.name for c in MANIFEST_COLUMNS if c.name in self.table.column_names)

    def __len__(self) -> int:
        return sum(1 for _ in self)

    def null(self, name: str) -> NDArray[np.bool_]:
        """``(B,)`` whether each row's value of column ``name`` is null."""
        return np.asarray(_one_chunk(self.table.column(name)).is_null().to_numpy(zero_copy_only=False), dtype=bool)


_T = TypeVar("_T")


class ManifestColumn(Generic[_T]):
    """A manifest column as an attribute of the rows that hold it (an object whose ``columns``
    is a :class:`ManifestColumns`): its values (:func:`column_values`), under the column's
    own name, so that a reader names no column in a string; a name that is no manifest
    column fails when the class is made."""

    name: str

    def __set_name__(self, owner: type, name: str) -> None:
        if name not in COLUMNS:
            raise TypeError(f"{owner.__name__}.{name}: no manifest column of that name")
        self.name = name

    @overload
    def __get__(self, obj: None, owner: type | None = None) -> ManifestColumn[_T]: ...

    @overload
    def __get__(self, obj: object, owner: type | None = None) -> _T: ...

    def __get__(self, obj: object, owner: type | None = None) -> Any:
        if obj is None:
            return self
        return obj.columns[self.name]  # type: ignore[attr-defined]  # (the owner's rows)


def manifest_schema() -> pa.Schema:
    """The schema of a manifest shard (version in the metadata): :data:`MANIFEST_COLUMNS`'s fields."""
    return pa.schema([c.field for c in MANIFEST_COLUMNS], metadata={"datagen.manifest_version": MANIFEST_VERSION})


def manifest_table() -> str:
    """``manifests/README.md``'s table of manifest columns, from :data:`MANIFEST_COLUMNS`: a
    row per meaning, naming the columns that share it."""
    rows: list[list[Column]] = []
    for c in MANIFEST_COLUMNS:
        if c.meaning or not rows:
            rows.append([c])
        else:
            rows[-1].append(c)
    lines = ["| column | type | unit | meaning |", "|---|---|---|---|"]
    lines += [f"| {', '.join(f'`{c.name}`' for c in row)} | {row[0].type_text} | {row[0].unit} | {row[0].meaning} |"
              for row in rows]
    return "\n".join(lines) + "\n"


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
        return {str(Exclusion(int(c)).reason): int(n) for c, n in zip(codes, counts, strict=True)}


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
