"""datagen audit and preview: a built dataset passes, each corruption fails naming its
file, the drift statistics match a hand computation, the HTML report renders."""

from __future__ import annotations

import json
import math
import shutil
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml
from hypothesis import given
from hypothesis import strategies as st

from datagen.analysis.audit import audit, feature_normals, obliqueness_deg, tight_centre_drift_px
from datagen.analysis.audit.frames import frames_to_draw
from datagen.core.camera import Intrinsics
from datagen.core.errors import DatagenError
from datagen.core.features import FeatureTable
from datagen.core.label_boxes import compute_labels
from datagen.core.transforms import make_transform
from datagen.dataset.reader import load_dataset
from datagen.pipeline.build import build_dataset
from datagen.report.audit_report import write_report
from datagen.report.overlays import write_previews

from .support import tiny_config

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def dataset(tmp_path_factory) -> Path:
    """A tiny rendered build (the audit's subject; copied before any corruption)."""
    tmp = tmp_path_factory.mktemp("audited")
    build_dataset(tiny_config(tmp), tmp / "ds")
    return tmp / "ds"


@pytest.fixture
def copy(dataset, tmp_path) -> Path:
    target = tmp_path / "ds"
    shutil.copytree(dataset, target)
    return target


def checks(root: Path) -> dict:
    return {c.name: c for c in audit(load_dataset(root)).checks}


def first_line(root: Path) -> tuple[Path, list[str]]:
    for path in sorted((root / "labels").rglob("*.txt")):
        lines = path.read_text().splitlines()
        if lines:
            return path, lines
    raise AssertionError("no label line")


# --- a good dataset ------------------------------------------------------------------------
@pytest.mark.render
def test_a_built_dataset_passes_every_check(dataset) -> None:
    result = audit(load_dataset(dataset))
    assert result.passed, [(c.name, c.offenders[:3]) for c in result.checks if not c.passed]
    by_name = {c.name: c for c in result.checks}
    assert set(by_name) == {"manifest_boxes", "manifest_objects", "label_lines", "centre_drift",
                            "edge_margin_and_front", "ultralytics_rules", "learnable", "files", "images",
                            "image_content", "label_content", "class_names", "training_recipe", "world_texels"}
    assert by_name["label_lines"].checked > 100
    assert by_name["centre_drift"].worst < 1e-3  # seven decimals: under 1.2e-4 px at most
    stats = result.stats
    assert stats.drift.overall.count > 0 and (stats.drift.overall.max or 0.0) > 0
    assert sum(stats.exclusions.values()) == 8 * 80
    assert stats.exclusions["labeled"] == sum(stats.labels_per_class.values())
    assert sum(stats.coverage.frames) == 8
    assert set(stats.pnp) == {"receiver", "tanker"}


@pytest.mark.render
def test_audit_command_writes_the_report(copy) -> None:
    out = subprocess.run([sys.executable, "-m", "datagen", "audit", str(copy)], capture_output=True, text=True,
                         timeout=300, cwd=ROOT)
    assert out.returncode == 0, out.stdout + out.stderr
    assert out.stdout.strip().splitlines()[-1] == f"PASSED: {copy / 'audit' / 'report.html'}"
    doc = json.loads((copy / "audit" / "report.json").read_text())
    assert doc["passed"] is True and doc["frames"] == 8 and len(doc["checks"]) == 14
    assert len(list((copy / "audit" / "plots").glob("*.png"))) == 5
    # The report is not a dataset file: a second audit still finds no orphan.
    assert checks(copy)["files"].passed


# --- corruptions --------------------------------------------------------------------------------
@pytest.mark.render
def test_a_shifted_label_fails_naming_its_line(copy) -> None:
    path, lines = first_line(copy)
    cls, cx, *rest = lines[0].split()
    lines[0] = " ".join([cls, f"{float(cx) + 0.01:.7f}", *rest])
    path.write_text("\n".join(lines) + "\n")
    result = checks(copy)
    where = f"{path.relative_to(copy)}:1"
    for name in ("label_lines", "centre_drift"):
        assert not result[name].passed and result[name].offenders[0].startswith(where)
    assert result["centre_drift"].worst == pytest.approx(0.01 * 128, rel=1e-3)
    out = subprocess.run([sys.executable, "-m", "datagen", "audit", str(copy)], capture_output=True, text=True,
                         timeout=300, cwd=ROOT)
    assert out.returncode == 1 and where in out.stdout and "FAILED" in out.stdout


@pytest.mark.render
def test_a_missing_image_and_an_orphan_fail(copy) -> None:
    image = sorted((copy / "images").rglob("*.png"))[0]
    image.rename(copy / "images" / "train" / "stray.png")
    files = checks(copy)["files"]
    offenders = "\n".join(files.offenders)
    assert f"{image.relative_to(copy)}: named in a manifest but missing" in offenders
    assert "images/train/stray.png: orphan" in offenders


@pytest.mark.render
def test_an_extra_label_line_fails(copy) -> None:
    view = load_dataset(copy)
    b, f = next(zip(*np.nonzero(~view.labeled)))  # an excluded feature
    path = copy / view.label_path[b]
    path.write_text(path.read_text() + f"{f} 0.5000000 0.5000000 0.0100000 0.0100000\n")
    lines = checks(copy)["label_lines"]
    assert not lines.passed and lines.offenders[0].startswith(f"{view.label_path[b]}:")
    assert f"class {f} has a line but the feature is excluded" in lines.offenders[0]


@pytest.mark.render
def test_a_label_inside_the_edge_margin_fails(copy) -> None:
    path, lines = first_line(copy)
    cls = lines[0].split()[0]
    lines[0] = f"{cls} 0.0050000 0.5000000 0.0080000 0.0100000"  # its left side 0.13 px from the border
    path.write_text("\n".join(lines) + "\n")
    margin = checks(copy)["edge_margin_and_front"]
    assert not margin.passed and margin.offenders[0].startswith(f"{path.relative_to(copy)}:1: class {cls} box is")


@pytest.mark.render
def test_a_class_id_out_of_range_fails(copy) -> None:
    path, lines = first_line(copy)
    lines.append("80 0.5000000 0.5000000 0.0100000 0.0100000")
    path.write_text("\n".join(lines) + "\n")
    rules = checks(copy)["ultralytics_rules"]
    assert not rules.passed
    assert rules.offenders == [f"{path.relative_to(copy)}:{len(lines)}: class 80 is not an integer in [0, 80)"]


@pytest.mark.render
def test_data_yaml_names_must_match_the_features(copy) -> None:
    data = yaml.safe_load((copy / "data.yaml").read_text())
    data["names"][3] = "receiver.something_else"
    (copy / "data.yaml").write_text(yaml.safe_dump(data))
    names = checks(copy)["class_names"]
    true_name = load_dataset(copy).features.name[3]
    assert names.offenders == [f"data.yaml: names.3: 'receiver.something_else', features.parquet says {true_name!r}"]


def test_not_a_dataset_is_one_line(tmp_path: Path) -> None:
    with pytest.raises(DatagenError, match=r"dataset\.json: no such file; not a datagen dataset folder"):
        load_dataset(tmp_path)
    out = subprocess.run([sys.executable, "-m", "datagen", "audit", str(tmp_path)], capture_output=True, text=True,
                         timeout=120, cwd=ROOT)
    assert out.returncode == 2 and len(out.stderr.strip().splitlines()) == 1


# --- statistics -------------------------------------------------------------------------------------
@given(a=st.floats(0.05, 2.0), depth=st.floats(5.0, 150.0), theta_deg=st.floats(-75.0, 75.0))
def test_tight_drift_and_obliqueness_match_a_hand_computation(a, depth, theta_deg) -> None:
    """A square of half-size a, tilted by theta about the camera's y axis, centred on the
    optical axis at depth D. Its corners project to u = fx x cos(t) / (D - x sin(t)), so
    the tight box's centre lies fx a^2 sin(t) cos(t) / (D^2 - a^2 sin^2(t)) px off the
    true centre, and the view is theta off the square's normal."""
    k = Intrinsics.from_hfov_deg(2048, 1080, 55.0)
    square = np.array([[a, a, 0.0], [a, -a, 0.0], [-a, a, 0.0], [-a, -a, 0.0]])
    table = FeatureTable.from_point_sets([square], objects=["tanker"], centers=[np.zeros(3)])
    t = math.radians(theta_deg)
    rot = np.array([[math.cos(t), 0, math.sin(t)], [0, 1, 0], [-math.sin(t), 0, math.cos(t)]])
    cam_from_model = make_transform(rot, [0.0, 0.0, depth])
    labels = compute_labels(table, cam_from_model[None, None], k, edge_margin_px=0.0)
    drift = tight_centre_drift_px(labels.tight_xyxy, labels.center_px)[0, 0]
    s, c = math.sin(t), math.cos(t)
    expected = k.fx * a * a * abs(s) * c / (depth**2 - (a * s) ** 2)
    assert drift == pytest.approx(expected, rel=1e-9, abs=1e-9)
    normal = feature_normals(table.points_model, table.n_points)
    assert obliqueness_deg(cam_from_model[None], normal, table.center_model)[0] == pytest.approx(
        abs(theta_deg), abs=1e-6)


# --- preview and the HTML report ---------------------------------------------------------------------
@pytest.mark.render
def test_preview_sheets_show_each_frame_and_its_crops_pixel_for_pixel(dataset, tmp_path: Path) -> None:
    """A sheet holds the frame and, per object, magnified crops registered to it: a sheet
    pixel of a panel shows the image pixel its centre maps back to (where nothing is
    drawn over it), and the boxes and crosshairs are drawn on top."""
    from datagen.report.overlays import draw_sheet

    view = load_dataset(dataset)
    paths = write_previews(view, [int(view.frame_id[0])], tmp_path)
    assert cv2.imread(str(paths[0])).shape[1] >= 1600
    original = cv2.imread(str(dataset / view.image_path[0]))
    sheet = draw_sheet(view, 0, view.recompute())
    magnified = [p for p in sheet.panels if p.scale >= 3]
    assert magnified  # the tiny frames' objects are small: their crops magnify
    for panel in magnified:
        x, y = np.meshgrid(np.arange(panel.size[0]), np.arange(panel.size[1]))
        u = np.floor(panel.crop[0] + (x + 0.5) / panel.scale).astype(int)
        v = np.floor(panel.crop[1] + (y + 0.5) / panel.scale).astype(int)
        inside = (u >= 0) & (v >= 0) & (u < original.shape[1]) & (v < original.shape[0])
        ox, oy = (int(c) for c in panel.origin)
        shown = sheet.image[oy:oy + panel.size[1], ox:ox + panel.size[0]][inside]
        same = np.all(shown == original[v[inside], u[inside]], axis=1).mean()
        assert same > 0.8, (panel.kind, same)
    with pytest.raises(DatagenError, match="--frames: frame 999 is not in"):
        write_previews(view, [999], tmp_path)


@pytest.mark.render
@pytest.mark.skipif(shutil.which("chromium") is None, reason="needs Chromium (apt-get install -y chromium)")
def test_html_report_renders_in_headless_chromium(dataset, tmp_path: Path) -> None:
    view = load_dataset(dataset)
    written = write_report(audit(view), view, tmp_path / "report", frames=frames_to_draw(view, 3))
    out = subprocess.run(["chromium", "--headless=new", "--no-sandbox", "--disable-gpu", "--enable-logging=stderr",
                          "--v=0", "--dump-dom", written["html"].as_uri()], capture_output=True, text=True,
                         timeout=120)
    assert out.returncode == 0
    assert 'data-images="8/8"' in out.stdout  # 5 plots + 3 overlays, every one decoded
    console = [line for line in out.stderr.splitlines() if "CONSOLE" in line]
    assert not [line for line in console if "Error" in line or "Uncaught" in line], console


@pytest.mark.render
def test_the_report_links_each_sheet_at_full_size_and_shows_it_unscaled(dataset, tmp_path: Path) -> None:
    """Each sheet is a file of the report (listed in report.json) that the page links, and the
    page shows it at its own width in a scrolling box, never shrunk to the page's width."""
    import cv2

    view = load_dataset(dataset)
    written = write_report(audit(view), view, tmp_path / "report", frames=frames_to_draw(view, 3))
    page = written["html"].read_text()
    sheets = sorted((tmp_path / "report" / "sheets").glob("*.jpg"))
    assert len(sheets) == 3
    listed = json.loads(written["json"].read_text())["files"]
    for sheet in sheets:
        height, width = cv2.imread(str(sheet)).shape[:2]
        assert f"sheets/{sheet.name}" in listed and f"<a href='sheets/{sheet.name}'>" in page
        assert f"width='{width}' height='{height}'" in page and width >= 1600
    assert ".sheet .scroll img { max-width: none;" in page
    # An audit drawing other frames keeps the earlier sheets in its record (--overwrite removes them).
    again = write_report(audit(view), view, tmp_path / "report", frames=frames_to_draw(view, 1))
    listed = json.loads(again["json"].read_text())["files"]
    assert {f"sheets/{sheet.name}" for sheet in sheets} <= set(listed)


@pytest.mark.render
def test_duplicate_coarse_and_non_finite_lines_fail_without_a_traceback(copy, tmp_path: Path) -> None:
    path, lines = first_line(copy)
    cls, cx, cy, w, h = lines[0].split()
    lines.append(f"{cls} {float(cx):.2f} {float(cy):.2f} {float(w):.2f} {float(h):.2f}")  # same class, coarse
    lines.append("nan 0.5 0.5 0.1 0.1")
    lines.append(f"{cls} inf 0.5 0.1 0.1")
    path.write_text("\n".join(lines) + "\n")
    view = load_dataset(copy)
    result = audit(view)
    by_name = {c.name: c for c in result.checks}
    rel = path.relative_to(copy)
    line_offenders = "\n".join(by_name["label_lines"].offenders)
    assert f"{rel}:{len(lines) - 2}: class {cls} has more than one line" in line_offenders
    assert f"{rel}:{len(lines) - 2}: class {cls} differs from the manifest box" in line_offenders
    rules = "\n".join(by_name["ultralytics_rules"].offenders)
    assert f"{rel}:{len(lines) - 1}: value 1 of 5 is not finite" in rules
    assert f"{rel}:{len(lines)}: value 2 of 5 is not finite" in rules
    written = write_report(result, view, tmp_path / "report")  # strict JSON: no NaN or inf
    assert json.loads(written["json"].read_text())["passed"] is False


# --- learnability (labels.min_box_px) ---------------------------------------------------------
def wingcam_labels(tmp: Path, **overrides) -> Path:
    """A labels-only wingcam55 build of 40 frames (seed 123, not the config's)."""
    from datagen.config import load_config, override_config

    config = override_config(load_config(ROOT / "scenes" / "wingcam55.yaml"),
                             {"dataset.frames": 40, "dataset.seed": 123, **overrides})
    build_dataset(config, tmp / "ds", render=False)
    return tmp / "ds"


def test_label_boxes_contain_the_corrected_boxes_and_share_their_true_centre(tmp_path: Path) -> None:
    view = load_dataset(wingcam_labels(tmp_path))
    lab = view.labeled
    label, corrected, centre = view.label_xyxy[lab], view.corrected_xyxy[lab], view.center_px[lab]
    assert np.all(label[:, :2] <= corrected[:, :2]) and np.all(label[:, 2:] >= corrected[:, 2:])
    np.testing.assert_allclose(0.5 * (label[:, :2] + label[:, 2:]), centre, rtol=0, atol=1e-9)
    assert np.isnan(view.label_xyxy[~lab]).all()  # null where not labeled
    grown = np.any(label != corrected, axis=1)
    assert grown.mean() > 0.5  # most wingcam55 boxes are smaller than the minimum at imgsz 864
    # Every side reaches the minimum at imgsz, or the edge margin where the centre is nearer to it.
    full = (label[:, 2:] - label[:, :2]) * np.array(view.train_view.scale) >= view.label_rules.min_box_px * (1 - 1e-9)
    assert np.all(full | margin_bound(view, label)) and full.all(axis=1).mean() > 0.95


def margin_bound(view, xyxy: np.ndarray) -> np.ndarray:
    """``(N, 2)``: the box has a side on the edge margin along x, along y."""
    m, k = view.label_rules.edge_margin_px, view.intrinsics
    on = np.isclose(xyxy, [m, m, k.width - m, k.height - m], rtol=0, atol=1e-9)
    return on[:, :2] | on[:, 2:]


def test_labels_grown_to_exactly_the_assigners_size_pass_the_learnable_check(tmp_path: Path) -> None:
    """labels.min_box_px at the assigner's side (32 px at imgsz): the boxes written are that
    size up to their label lines' rounding, and the audit counts them learnable (it counted
    none: the rounding left them a hundred-thousandth of a pixel short)."""
    from datagen.core.training import ASSIGNABLE_SIDE_PX

    result = audit(load_dataset(wingcam_labels(tmp_path, **{"labels.min_box_px": ASSIGNABLE_SIDE_PX})))
    learnable = {c.name: c for c in result.checks}["learnable"]
    assert learnable.passed and learnable.pass_share > 0.95


def test_audit_fails_unlearnable_labels_and_names_the_worst_classes(tmp_path: Path) -> None:
    result = audit(load_dataset(wingcam_labels(tmp_path, **{"labels.min_box_px": 0.0})))
    learnable = {c.name: c for c in result.checks}["learnable"]
    assert not learnable.passed and not result.passed
    assert learnable.pass_share < 0.5  # most tight wingcam55 boxes are a few px at 864
    names = set(load_dataset(tmp_path / "ds").features.name)
    worst = learnable.offenders[0]
    assert worst.startswith("class ") and worst.split(":")[0].split(" ", 2)[2] in names
    assert "lines learnable" in worst
    stats = result.stats.learnable
    assert stats is not None and stats.share == pytest.approx(learnable.pass_share)
    assert stats.worst_classes[0][1].share == min(v.share for v in stats.by_class.values())
    assert {b.lo for b in stats.by_distance_m} >= {0.0, 110.0} and set(stats.by_size) == {"small", "medium"}
    # The same frames with the default minimum are learnable throughout: the boxes short of the
    # assigner's size are those that could not grow past the edge margin, and the audit knows them.
    view = load_dataset(wingcam_labels(tmp_path / "default"))
    default = audit(view)
    check = {c.name: c for c in default.checks}["learnable"]
    assert check.passed and check.failures == 0 and default.stats.learnable and default.stats.learnable.share == 1.0
    boxes = view.label_xyxy[view.labeled]
    short = ~view.train_view.learnable(boxes)
    assert short.any() and margin_bound(view, boxes)[short].any(axis=1).all()
    assert default.stats.learnable.share_at_edge_margin == pytest.approx(short.mean())


def test_audit_command_reports_learnability_and_its_threshold(tmp_path: Path) -> None:
    root = wingcam_labels(tmp_path, **{"labels.min_box_px": 0.0})
    out = subprocess.run([sys.executable, "-m", "datagen", "audit", str(root)], capture_output=True, text=True,
                         timeout=300, cwd=ROOT)
    assert out.returncode == 1
    line = next(x for x in out.stdout.splitlines() if "learnable:" in x)
    assert line.startswith("FAIL  learnable:") and "(needs 95%)" in line
    assert "Learnable by the detector" in (root / "audit" / "report.html").read_text()
    doc = json.loads((root / "audit" / "report.json").read_text())
    share = next(c for c in doc["checks"] if c["name"] == "learnable")["pass_share"]
    assert share < 0.5
    loose = subprocess.run([sys.executable, "-m", "datagen", "audit", str(root), "--min-learnable", "0"],
                           capture_output=True, text=True, timeout=300, cwd=ROOT)
    assert loose.returncode == 0, loose.stdout
    doc = json.loads((root / "audit" / "report.json").read_text())
    check = next(c for c in doc["checks"] if c["name"] == "learnable")
    assert check["passed"] and check["min_pass_share"] == 0.0 and check["pass_share"] == share


@pytest.mark.render
def test_files_ultralytics_writes_are_not_orphans(copy) -> None:
    """Training writes label caches beside the label folders and (cache=disk) .npy images."""
    shard = sorted((copy / "labels" / "train").iterdir())[0]
    shard.with_suffix(".cache").write_bytes(b"ultralytics label cache")
    image = sorted((copy / "images" / "train").rglob("*.png"))[0]
    image.with_suffix(".npy").write_bytes(b"ultralytics image cache")
    assert checks(copy)["files"].passed
    (shard / "stray.txt").write_text("")
    assert not checks(copy)["files"].passed


def test_the_reports_colour_key_names_the_colours_the_sheets_draw() -> None:
    from datagen.report.audit_report import colour_key_html
    from datagen.report.overlays import COLOURS, REGION

    key = colour_key_html()
    for name, (b, g, r) in [*COLOURS.items(), ("object region", REGION)]:
        assert f"background:rgb({r},{g},{b})" in key and name in key
    assert "magenta" not in key.lower() and "amber" not in key.lower()
