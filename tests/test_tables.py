"""A dataset opens in every table tool as it is: Hugging Face ``datasets`` through the
dataset card, pandas, polars and duckdb through the manifests; missing values are nulls
(a mean over centres is finite) and matrices come back as 4x4. Each reader runs where it
is installed and is skipped where it is not; manifests/README.md's lines are run too."""

from __future__ import annotations

import math

import numpy as np
import pyarrow.parquet as pq
import pytest

from datagen.config import load_config, override_config
from datagen.dataset.reader import load_dataset
from datagen.pipeline.build import build_dataset

from .support import ROOT


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    root = tmp_path_factory.mktemp("tables") / "ds"
    config = override_config(load_config("wingcam55"), {"dataset.frames": 40, "dataset.seed": 7})
    build_dataset(config, root, render=False)
    return root


def labeled_u_mean(root) -> float:
    """The mean u of the labeled features' centres, from datagen's own reader."""
    view = load_dataset(root)
    return float(view.center_px[view.labeled][:, 0].mean())


def test_missing_values_are_nulls_and_matrices_are_4x4(dataset) -> None:
    table = pq.read_table(next((dataset / "manifests").glob("train-*.parquet")))
    features = table.column("features").combine_chunks().flatten()
    centre = features.field("center_px")
    assert centre.null_count > 0  # features behind the camera
    values = centre.drop_null().flatten().to_numpy()
    assert np.isfinite(values).all()  # no NaN anywhere: nulls instead
    assert features.field("label_xyxy").null_count == (~features.field("labeled").to_numpy(zero_copy_only=False)).sum()
    matrix = np.array(table.column("cam_from_world")[0].as_py())
    assert matrix.shape == (4, 4) and np.allclose(matrix[3], [0, 0, 0, 1])


def require(module: str):
    """``module`` imported, or the test skipped: a folder of that name (such as the
    repository's own ``datasets/``, where README command 1 writes) is not the package."""
    import importlib.util

    spec = importlib.util.find_spec(module)
    if spec is None or spec.origin is None:
        pytest.skip(f"{module} is not installed (the tables extra: pip install -e '.[tables]')")
    return importlib.import_module(module)


def test_duckdb_averages_unnested_centres(dataset) -> None:
    duckdb = require("duckdb")
    every = duckdb.sql(f"SELECT avg(f.center_px[1]) FROM (SELECT unnest(features) AS f "
                       f"FROM '{dataset}/manifests/*.parquet')").fetchall()[0][0]
    labeled = duckdb.sql(f"SELECT avg(f.center_px[1]) FROM (SELECT unnest(features) AS f "
                         f"FROM '{dataset}/manifests/*.parquet') WHERE f.labeled").fetchall()[0][0]
    assert math.isfinite(every) and labeled == pytest.approx(labeled_u_mean(dataset), rel=1e-12)


def test_pandas_reads_rows_features_and_matrices(dataset) -> None:
    pd = require("pandas")
    df = pd.read_parquet(dataset / "manifests")
    assert len(df) == 40 and np.stack(df.loc[0, "cam_from_world"]).shape == (4, 4)
    per_feature = pd.json_normalize(df.explode("features")["features"].dropna().tolist())
    u = per_feature.loc[per_feature.labeled, "center_px"].map(lambda c: c[0]).mean()
    assert u == pytest.approx(labeled_u_mean(dataset), rel=1e-12)


def test_polars_reads_the_vectors_as_lists(dataset) -> None:
    pl = require("polars")
    u = (pl.read_parquet(f"{dataset}/manifests/*.parquet").explode("features").unnest("features")
         .filter(pl.col("labeled")).select(pl.col("center_px").list.get(0).mean()).item())
    assert u == pytest.approx(labeled_u_mean(dataset), rel=1e-12)


def test_hugging_face_datasets_loads_the_folder_through_the_card(dataset) -> None:
    datasets = require("datasets")
    loaded = datasets.load_dataset(str(dataset))
    view = load_dataset(dataset)
    assert {name: len(split) for name, split in loaded.items()} == {s: view.split.count(s) for s in ("train", "val")}
    row = loaded["train"][0]
    assert np.array(row["cam_from_world"]).shape == (4, 4)
    assert sorted(loaded["train"]["frame_id"]) == sorted(int(f) for f, s in zip(view.frame_id, view.split,
                                                                              strict=True) if s == "train")


def test_the_manifest_readme_table_lines_run(dataset) -> None:
    for module in ("datasets", "duckdb", "pandas", "polars"):
        require(module)
    text = (ROOT / "manifests" / "README.md").read_text()
    section = text[text.index("## Reading a dataset with table tools"):]
    code = section[section.index("```python") + len("```python"):]
    code = code[:code.index("```")].replace("DATASET", str(dataset))
    scope: dict = {}
    exec(compile(code, "manifests/README.md", "exec"), scope)
    assert scope["m"].shape == (4, 4)
    assert scope["u_mean"] == pytest.approx(labeled_u_mean(dataset), rel=1e-12)


def test_the_dataset_card_describes_the_build_and_a_users_readme_is_left_alone(tmp_path) -> None:
    config = override_config(load_config("podcam15"), {"dataset.frames": 6})
    build_dataset(config, tmp_path / "ds", render=False)
    card = (tmp_path / "ds" / "README.md").read_text()
    assert card.startswith("---\nconfigs:\n") and "path: manifests/train-*.parquet" in card
    assert "# podcam15 (paper model A)" in card and f"(root seed {config.dataset.seed})" in card
    low, high = config.randomization.haze.visibility_m
    assert f"round earth seen through the air (sea-level visibility {low / 1000:g}-{high / 1000:g} km" in card
    hazeless = override_config(config, {"randomization.haze.enabled": False})
    build_dataset(hazeless, tmp_path / "plain", render=False)
    assert "no aerial perspective" in (tmp_path / "plain" / "README.md").read_text()
    mine = tmp_path / "mine"
    mine.mkdir()
    build_dataset(config, mine / "ds", render=False)
    (mine / "ds" / "README.md").write_text("my notes on this dataset\n")
    build_dataset(config, mine / "ds", render=False)  # resumes: every shard done, the card is due again
    assert (mine / "ds" / "README.md").read_text() == "my notes on this dataset\n"
