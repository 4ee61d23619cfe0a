"""A rolling shutter: each row exposed at its own time (datagen.core.conventions.row_time_s),
the labels' points where they were when their row was exposed, the image skewed the same
way, and a dataset's audit recomputing the same labels from the manifest's rates."""

from __future__ import annotations

import numpy as np
import pyarrow.parquet as pq
from hypothesis import assume, given
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from datagen.core.camera import Intrinsics, RollingShutter, project_rolling, project_xyz
from datagen.core.conventions import row_time_s
from datagen.core.features import FeatureTable
from datagen.core.label_boxes import compute_labels
from datagen.render.sensor import rolling_shutter

from .strategies import cam_from_model_in_front, finite, intrinsics, lens_distortions, point_sets
from .support import tiny_config

#: A rate of cam_from_model: a turn of up to 0.3 rad/s about each axis and up to 30 m/s.
rates = arrays(np.float64, 6, elements=st.floats(-1.0, 1.0, **finite)).map(
    lambda r: np.block([[np.array([[0.0, -r[2], r[1]], [r[2], 0.0, -r[0]], [-r[1], r[0], 0.0]]) * 0.3,
                         (r[3:] * 30.0)[:, None]], [np.zeros((1, 4))]]))
readouts = st.floats(0.0, 0.03, **finite)


def _moving(points, cam_from_model, rate, t):
    p = points @ cam_from_model[:3, :3].T + cam_from_model[:3, 3]
    dp = points @ rate[:3, :3].T + rate[:3, 3]
    return p + dp * t


@given(k=intrinsics(), points=point_sets(), cam_from_model=cam_from_model_in_front(), rate=rates,
       readout=readouts, distortion=st.none() | lens_distortions())
def test_a_label_point_is_where_it_was_when_its_row_was_exposed(k, points, cam_from_model, rate, readout,
                                                                 distortion) -> None:
    table = FeatureTable.from_point_sets([points], objects=["receiver"], centers=[None])
    # Within project_rolling's domain: the centre crosses less than a tenth of the image's height
    # during the readout (beyond it the fixed point need not converge in ROLLING_ITERATIONS steps).
    (_, y, z), = _moving(table.center_model[0][None], cam_from_model, rate, 0.0)
    (_, dy, dz), = _moving(table.center_model[0][None], np.zeros((4, 4)), rate, 1.0)
    assume(abs(k.fy * (dy * z - y * dz) / z**2) * readout < 0.1 * k.height)
    shutter = RollingShutter(np.array([readout]), rate[None, None])
    labels = compute_labels(table, cam_from_model[None, None], k, distortion=distortion, shutter=shutter)
    u, v = labels.center_px[0, 0]
    # The centre, moved to the time of the row it lands on, projects to itself.
    p = _moving(table.center_model[0][None], cam_from_model, rate, row_time_s(v, k.height, readout))
    pu, pv = project_xyz(p[:, 0], p[:, 1], p[:, 2], k, distortion)
    scale = max(1.0, abs(u), abs(v))
    np.testing.assert_allclose([pu[0], pv[0]], [u, v], rtol=0, atol=1e-7 * scale)


@given(k=intrinsics(), points=point_sets(), cam_from_model=cam_from_model_in_front(), rate=rates)
def test_a_readout_of_zero_or_a_still_scene_is_a_global_shutter(k, points, cam_from_model, rate) -> None:
    table = FeatureTable.from_point_sets([points], objects=["receiver"], centers=[None])
    plain = compute_labels(table, cam_from_model[None, None], k)
    for shutter in (RollingShutter(np.array([0.0]), rate[None, None]),
                    RollingShutter(np.array([0.02]), np.zeros((1, 1, 4, 4)))):
        rolled = compute_labels(table, cam_from_model[None, None], k, shutter=shutter)
        np.testing.assert_array_equal(rolled.center_px, plain.center_px)
        np.testing.assert_array_equal(rolled.label_xyxy, plain.label_xyxy)


def test_a_sideways_motion_skews_the_labels_by_speed_times_row_time() -> None:
    """A point moving right at 10 m/s, 50 m ahead: 200 px/s at a 1000 px focal length; a
    20 ms readout puts it 2 px further right at the bottom edge than at the top."""
    k = Intrinsics(1000, 1000, 1000.0, 1000.0, 500.0, 500.0)
    rate = np.zeros((4, 4))
    rate[0, 3] = 10.0
    shifts = []
    for y in (-24.0, 24.0):  # rows 20 and 980
        x, y_, z = np.array([0.0]), np.array([y]), np.array([50.0])
        u, v, _ = project_rolling(x, y_, z, (np.array([10.0]), np.zeros(1), np.zeros(1)), k, None, 0.02)
        u0, _ = project_xyz(x, y_, z, k)
        shifts.append((u - u0)[0])
        assert abs(v[0] - (500.0 + 1000.0 * y / 50.0)) < 1e-12  # no vertical motion, no vertical shift
    np.testing.assert_allclose(shifts, [200.0 * (20 / 1000 - 0.5) * 0.02, 200.0 * (980 / 1000 - 0.5) * 0.02],
                               rtol=1e-9)


def test_the_image_skews_a_moving_edge_by_its_velocity_times_its_rows_time() -> None:
    """A vertical edge moving right at 400 px/s, a 25 ms readout: row v shows it
    400 * (v / H - 1/2) * 0.025 px right of where it is at the frame's time."""
    h, w, margin = 100, 200, 4
    k = Intrinsics(w, h, 300.0, 300.0, w / 2, h / 2)
    img = np.zeros((h + 2 * margin, w + 2 * margin, 3), np.float32)
    img[:, : margin + 100] = 1.0  # bright left of the output's column 100
    velocity = np.zeros(((h + 2 * margin) // 2, (w + 2 * margin) // 2, 2), np.float32)
    velocity[..., 0] = 400.0
    out = rolling_shutter({"rgb": img}, velocity, 2, 0.025, k, margin)["rgb"][margin:-margin, margin:-margin, 0]
    for row in (5, 50, 95):
        edge = float(np.interp(0.5, out[row, 80:120][::-1], np.arange(80, 120)[::-1])) + 0.5  # continuous
        expected = 100.0 + 400.0 * float(row_time_s(row + 0.5, h, 0.025))
        assert abs(edge - expected) < 0.05, (row, edge, expected)


def test_a_rolling_shutter_build_records_its_rates_and_its_audit_recomputes_its_labels(tmp_path) -> None:
    from datagen.dataset.reader import load_dataset
    from datagen.pipeline.build import build_dataset

    sensor = {"rolling_shutter": True, "readout_s": [0.02, 0.03]}
    config = tiny_config(tmp_path, dataset={"frames": 6}, randomization={"sensor": sensor})
    build_dataset(config, tmp_path / "ds", render=False)
    view = load_dataset(tmp_path / "ds")
    assert ((view.readout_s >= 0.02) & (view.readout_s <= 0.03)).all()
    rates = np.stack([view.cam_from_per_s[o] for o in view.features.objects], axis=1)
    assert np.abs(rates).max() > 0.0
    labels = view.recompute()
    labeled = view.labeled
    assert labeled.any()
    np.testing.assert_allclose(labels.center_px[labeled], view.center_px[labeled], rtol=0, atol=1e-9)
    # And the shutter moved them: a global shutter's labels of the same poses differ.
    still = view.labelling.label_features(view.cam_from_objects())
    moved = np.abs(still.center_px[labeled] - view.center_px[labeled]).max()
    assert moved > 1e-4, moved
    row = pq.read_table(next((tmp_path / "ds" / "manifests").glob("*.parquet"))).slice(0, 1).to_pylist()[0]
    assert row["sensor_readout_s"] is not None and row["cam_from_drogue_per_s"] is not None


def test_a_manifests_impossible_readout_or_rate_is_one_line_naming_the_column(tmp_path) -> None:
    import pyarrow as pa

    from datagen.pipeline.build import build_dataset
    from tests.test_hostile import datagen, refused

    config = tiny_config(tmp_path, dataset={"frames": 3}, randomization={"sensor": {"rolling_shutter": True}})
    build_dataset(config, tmp_path / "ds", render=False)
    manifest = next((tmp_path / "ds" / "manifests").glob("*.parquet"))
    original = pq.read_table(manifest)
    for column, value, expected in (("sensor_readout_s", 5.0, "a readout from 0 to 0.1 s"),
                                    ("cam_from_drogue_per_s", [[float("nan")] * 4] * 4, "the rate of a transform")):
        i = original.schema.get_field_index(column)
        values = original.column(column).to_pylist()
        values[0] = value
        field = original.schema.field(i)
        pq.write_table(original.set_column(i, field, pa.array(values, field.type)), manifest)
        refused(datagen("audit", str(tmp_path / "ds")), column, expected)
