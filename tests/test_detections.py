"""The detector scored against the true centres (datagen.analysis.detections): matches,
misses, spurious detections, centre errors and the bias along the parallax direction,
through the API and through ``datagen evaluate --predictions``."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from datagen.analysis.detections import score_detections, summarize_detections
from datagen.analysis.evaluate import DISTANCE_EDGES
from datagen.analysis.predictions import Predictions
from datagen.config import load_config, override_config
from datagen.core.training import MATCH_PX
from datagen.dataset.reader import load_dataset, open_dataset
from datagen.pipeline.build import build_dataset
from tests.support import run_cli

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def wingcam(tmp_path_factory):
    config = override_config(load_config(ROOT / "scenes" / "wingcam55.yaml"),
                             {"dataset.frames": 120, "dataset.shard_size": 40, "dataset.seed": 31})
    root = tmp_path_factory.mktemp("det") / "w55"
    build_dataset(config, root, render=False)
    return load_dataset(root)


def predictions_at(view, points, classes_of_frame, conf: float = 0.9) -> Predictions:
    """Predictions that put each chosen class of each frame at ``points[frame, class]``."""
    best = {}
    for b, stem in enumerate(view.stems):
        best[stem] = {int(c): (float(points[b, c, 0]), float(points[b, c, 1]), conf) for c in classes_of_frame(b)}
    return Predictions(best, 0.25, {s: len(v) for s, v in best.items()}, {s: 0 for s in best})


def test_detections_on_the_true_centres_are_all_matched_with_zero_error(wingcam) -> None:
    found = predictions_at(wingcam, wingcam.center_px, lambda b: np.flatnonzero(wingcam.labeled[b]))
    s = score_detections(wingcam, found)
    total = int(wingcam.labeled.sum())
    assert s.labeled.sum() == total and s.matched.sum() == total
    assert s.missed.sum() == s.mislocated.sum() == s.spurious.sum() == 0
    assert np.nanmax(s.error_px) == 0.0
    overall = summarize_detections(s, DISTANCE_EDGES).overall
    assert overall.recall == 1.0 and overall.precision == 1.0 and overall.error_p95_px == 0.0


def test_detections_at_the_tight_box_centres_are_biased_by_the_whole_parallax_offset(wingcam) -> None:
    tight_centre = 0.5 * (wingcam.tight_xyxy[..., :2] + wingcam.tight_xyxy[..., 2:])
    found = predictions_at(wingcam, tight_centre, lambda b: np.flatnonzero(wingcam.labeled[b]))
    s = score_detections(wingcam, found)
    along = s.along_parallax_px
    has = np.isfinite(along)
    assert has.sum() > 0.9 * s.labeled.sum()
    np.testing.assert_allclose(along[has], s.parallax_px[has], rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(s.error_px[has], s.parallax_px[has], rtol=1e-9, atol=1e-9)
    overall = summarize_detections(s, DISTANCE_EDGES).overall
    assert overall.along_parallax_mean_px == pytest.approx(overall.parallax_offset_mean_px, rel=1e-9)
    # A match is decided by the radius: only features whose offset is within it match.
    assert s.matched.sum() == int((s.parallax_px[s.labeled] <= MATCH_PX).sum())


def test_missed_mislocated_and_spurious_are_counted_per_feature(wingcam) -> None:
    rng = np.random.default_rng(5)
    n_frames, n_features = wingcam.labeled.shape
    points = wingcam.center_px.copy()
    far = rng.random((n_frames, n_features)) < 0.2
    points[far] += np.array([MATCH_PX * 2, 0.0])
    reported = rng.random((n_frames, n_features)) < 0.7  # the classes the "detector" reports
    points = np.where(np.isfinite(points), points, 500.0)  # a spurious detection needs a place
    found = predictions_at(wingcam, points, lambda b: np.flatnonzero(reported[b]))
    s = score_detections(wingcam, found)
    labeled = wingcam.labeled
    assert s.missed.sum() == (labeled & ~reported).sum()
    assert s.mislocated.sum() == (labeled & reported & far).sum()
    assert s.matched.sum() == (labeled & reported & ~far).sum()
    assert s.spurious.sum() == (~labeled & reported).sum()
    summary = summarize_detections(s, DISTANCE_EDGES)
    by_class = summary.by_class
    for c, name in enumerate(wingcam.features.name):
        assert by_class[name].missed == (labeled[:, c] & ~reported[:, c]).sum()
    assert sum(b.counts.labeled for b in summary.by_distance) == labeled.sum()


def test_a_frame_without_a_prediction_file_misses_every_labeled_feature(wingcam) -> None:
    found = predictions_at(wingcam, wingcam.center_px, lambda b: np.flatnonzero(wingcam.labeled[b]))
    dropped = Predictions({k: v for i, (k, v) in enumerate(found.best.items()) if i % 2}, 0.25)
    s = score_detections(wingcam, dropped)
    assert s.frames == len(wingcam) and s.frames_without_file == (len(wingcam) + 1) // 2
    assert s.missed.sum() == sum(int(wingcam.labeled[b].sum()) for b in range(0, len(wingcam), 2))


def test_scoring_a_source_shard_by_shard_equals_scoring_the_loaded_view(wingcam) -> None:
    rng = np.random.default_rng(9)
    points = wingcam.center_px + rng.normal(0, 2.0, wingcam.center_px.shape)
    found = predictions_at(wingcam, points, lambda b: np.flatnonzero(wingcam.labeled[b] | (rng.random(80) < 0.05)))
    for split in (None, "train", "val"):
        whole = score_detections(wingcam, found, split=split)
        streamed = score_detections(open_dataset(wingcam.root), found, split=split)
        for name in ("frame_id", "class_id", "labeled", "detected"):
            assert np.array_equal(getattr(whole, name), getattr(streamed, name)), (split, name)
        np.testing.assert_array_equal(whole.error_uv, streamed.error_uv)
        assert whole.frames == streamed.frames


@settings(max_examples=200, deadline=None)
@given(st.tuples(st.floats(-50, 50), st.floats(-50, 50)), st.tuples(st.floats(-50, 50), st.floats(-50, 50)))
def test_the_error_along_the_parallax_is_its_projection_on_the_parallax_direction(error, parallax) -> None:
    from datagen.analysis.detections import DetectionScores

    s = DetectionScores(np.zeros(1, np.int64), np.zeros(1, np.int64), np.zeros(1), np.ones(1, bool),
                        np.ones(1, bool), np.ones(1), np.array([error], float), np.array([parallax], float),
                        MATCH_PX, 1, 0, ("a",))
    length = float(np.hypot(*parallax))
    if length <= 1e-6:
        assert np.isnan(s.along_parallax_px[0])
    else:
        expected = (error[0] * parallax[0] + error[1] * parallax[1]) / length
        assert s.along_parallax_px[0] == pytest.approx(expected, abs=1e-9)
        assert abs(s.along_parallax_px[0]) <= s.error_px[0] + 1e-9


def test_evaluate_with_predictions_writes_the_detector_section_table_and_plots(wingcam, tmp_path) -> None:
    folder = tmp_path / "pred"
    for b, stem in enumerate(wingcam.stems):
        if wingcam.split[b] != "val":
            continue
        lines = [f"{c} {u / 2048:.7f} {v / 1080:.7f} 0.01 0.01 0.9"
                 for c in np.flatnonzero(wingcam.labeled[b]) for u, v in [wingcam.center_px[b, c] + [1.0, 0.0]]]
        (folder / f"{stem}.txt").parent.mkdir(parents=True, exist_ok=True)
        (folder / f"{stem}.txt").write_text("\n".join(lines) + "\n")
    out = tmp_path / "eval"
    result = run_cli("evaluate", str(wingcam.root), "--predictions", str(folder), "--out", str(out))
    assert result.returncode == 0, result.stderr
    assert "detector:" in result.stdout and "(100.0%)" in result.stdout
    doc = json.loads((out / "evaluation.json").read_text())
    overall = doc["detector"]["overall"]
    labeled_val = int(sum(wingcam.labeled[b].sum() for b in range(len(wingcam)) if wingcam.split[b] == "val"))
    assert overall["labeled"] == overall["matched"] == labeled_val
    assert overall["error_median_px"] == pytest.approx(1.0, abs=1e-3)
    assert set(doc["files"]) >= {"detections.parquet", "plots/detector_vs_distance.png", "plots/detector_by_class.png"}
    table = pq.read_table(out / "detections.parquet")
    assert table.num_rows == labeled_val and table.column("error_uv_px").null_count == 0
