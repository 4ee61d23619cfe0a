"""The table of manifest columns is the one contract: a row is held to it when it is written,
a reader decodes each column by its type, and a column added to the table is written, read
back and documented with nothing else to change but its computation."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pyarrow as pa
import pytest

import datagen.dataset.columns as columns_module
import datagen.pipeline.manifest_row as manifest_row_module
from datagen.config import load_config, override_config
from datagen.dataset.columns import (
    COLUMNS,
    MANIFEST_COLUMNS,
    MATRIX,
    Column,
    ManifestColumn,
    ManifestColumns,
    column_values,
    manifest_record,
    manifest_schema,
    manifest_table,
)
from datagen.dataset.reader import INDEX_COLUMNS, load_dataset, open_dataset
from datagen.pipeline.build import build_dataset


def _values() -> dict[str, object]:
    """A value for every column (what a writer gives; not a real frame's)."""
    return {c.name: 0 for c in MANIFEST_COLUMNS}


def test_a_manifest_row_holds_every_column_of_the_table_in_its_order() -> None:
    values = _values()
    row = manifest_record(dict(reversed(list(values.items()))))
    assert list(row) == [c.name for c in MANIFEST_COLUMNS]


@pytest.mark.parametrize("change, named", [
    (lambda v: v.pop("sun_scale"), "without columns sun_scale"),
    (lambda v: v.update(sun_scale_x=1.0), "with columns no manifest has: sun_scale_x"),
    (lambda v: v.update(distance_m=None), "with nulls in required columns distance_m"),
])
def test_a_manifest_row_missing_a_column_naming_another_or_null_where_required_is_refused(change, named) -> None:
    values = _values()
    change(values)
    with pytest.raises(ValueError, match=named):
        manifest_record(values)


def test_each_column_is_read_as_its_type_says_nan_or_none_where_null() -> None:
    schema = manifest_schema()
    names = ["frame_id", "split", "distance_m", "spp", "cam_from_world", "sun_backlit", "sea_colour"]
    eye = np.eye(4).tolist()
    table = pa.table({n: pa.array(v, schema.field(n).type) for n, v in zip(names, [
        [3, 4], ["train", "val"], [1.5, 2.5], [4, None], [eye, None], [True, None], [None, [0.1, 0.2, 0.3]],
    ], strict=True)})
    cols = ManifestColumns(table)
    assert cols["frame_id"].dtype == np.int64 and cols["frame_id"].tolist() == [3, 4]
    assert cols["split"] == ["train", "val"] and cols["spp"] == [4, None] and cols["sun_backlit"] == [True, None]
    np.testing.assert_array_equal(cols["distance_m"], [1.5, 2.5])
    assert cols["cam_from_world"].shape == (2, 4, 4) and np.isnan(cols["cam_from_world"][1]).all()
    np.testing.assert_array_equal(cols["cam_from_world"][0], np.eye(4))
    assert cols["sea_colour"].shape == (2, 3) and np.isnan(cols["sea_colour"][0]).all()
    assert cols.null("spp").tolist() == [False, True]
    assert list(cols) == [n for n in (c.name for c in MANIFEST_COLUMNS) if n in names]
    with pytest.raises(KeyError):
        cols["time_s"]  # a column the table does not hold


def test_a_reader_attribute_names_a_manifest_column_or_its_class_is_refused() -> None:
    class Rows:
        distance_m = ManifestColumn[np.ndarray]()

        def __init__(self, columns: ManifestColumns) -> None:
            self.columns = columns

    rows = Rows(ManifestColumns(pa.table({"distance_m": pa.array([7.0])})))
    assert rows.distance_m.tolist() == [7.0]
    with pytest.raises((TypeError, RuntimeError)) as refused:  # Python 3.11 wraps __set_name__'s error
        type("Wrong", (), {"distance_metres": ManifestColumn[np.ndarray]()})
    assert "Wrong.distance_metres: no manifest column" in str(refused.value.__cause__ or refused.value)


def test_the_index_reads_the_columns_its_readers_name() -> None:
    assert set(INDEX_COLUMNS) <= set(COLUMNS)
    assert {"frame_id", "split", "image_path", "approach_index", "world_texel_px"} <= set(INDEX_COLUMNS)


def test_a_column_added_to_the_table_is_written_read_and_documented_with_only_its_computation(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """As a contributor adds one: a line in the table (name, type, meaning, version, unit), and
    the value computed where the row is made (here: twice the distance); the schema, the
    reader and the page of columns follow."""
    extra = Column("distance_twice_m", pa.float64(), "twice the probe-to-drogue distance", since="12", unit="m")
    table = (*MANIFEST_COLUMNS, extra)
    monkeypatch.setattr(columns_module, "MANIFEST_COLUMNS", table)
    monkeypatch.setattr(columns_module, "COLUMNS", {c.name: c for c in table})
    record = manifest_record

    def computed(values):  # the column's computation, beside the others
        return record({**values, extra.name: 2.0 * float(values["distance_m"])})

    monkeypatch.setattr(manifest_row_module, "manifest_record", computed)
    config = override_config(load_config("wingcam55"), {"dataset.frames": 6, "dataset.shard_size": 3})
    build_dataset(config, tmp_path / "ds", render=False)
    shard = open_dataset(tmp_path / "ds").read_shard("manifests/train-00000.parquet")
    for view in (load_dataset(tmp_path / "ds"), shard):
        np.testing.assert_array_equal(view.columns[extra.name], 2.0 * view.distance_m)
    assert "| `distance_twice_m` | float64 or null | m | twice the probe-to-drogue distance |" in manifest_table()
    assert column_values(pa.array([1.0, None]), extra).tolist()[0] == 1.0
    assert manifest_schema().field(extra.name).type == pa.float64() and MATRIX == COLUMNS["cam_from_world"].type
