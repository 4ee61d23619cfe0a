"""``datagen preview``'s label sheets (Fig. 11's three panels per object, magnified): on a
2K wingcam55 frame at the approach's longest range no two number tags overlap, every
feature in view is numbered in every panel and named in the key, the true centre's
crosshair lies on the true centre within 0.1 px at the crop's scale, and the colours
stay apart under simulated colour-vision deficiencies."""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
import pytest

from datagen.core.label_boxes import Exclusion
from datagen.dataset.reader import load_dataset
from datagen.report.overlays import COLOURS, PANELS, draw_sheet

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def wingcam(tmp_path_factory):
    """wingcam55 at its own 2048x1080, labels only (a black canvas under the drawing)."""
    from datagen.config import load_config, override_config
    from datagen.pipeline.build import build_dataset

    tmp = tmp_path_factory.mktemp("preview")
    config = override_config(load_config(ROOT / "scenes" / "wingcam55.yaml"), {"dataset.frames": 240})
    build_dataset(config, tmp / "ds", render=False)
    view = load_dataset(tmp / "ds")
    return view, view.recompute()


def _frames(view, labels) -> dict[str, int]:
    """The frame at the longest range that labels a feature, the one at the longest range
    that labels every object, and the one labelling the most features."""
    out = {}
    objects = range(len(view.features.objects))
    every = np.all([labels.labeled[:, view.features.object_index == o].any(axis=1) for o in objects], axis=0)
    for what, wanted in (("longest range", labels.labeled.any(axis=1)), ("longest range, every object", every)):
        out[what] = int(np.flatnonzero(wanted)[np.argmax(view.distance_m[wanted])])
    out["most features"] = int(np.argmax(labels.labeled.sum(axis=1)))
    return out


def _overlap(a, b) -> bool:
    return a[0] <= b[2] and b[0] <= a[2] and a[1] <= b[3] and b[1] <= a[3]


def test_no_two_tags_overlap_and_every_feature_in_view_is_numbered_in_each_panel_and_named(wingcam) -> None:
    view, labels = wingcam
    assert view.intrinsics.width == 2048
    for what, b in _frames(view, labels).items():
        sheet = draw_sheet(view, b, labels)
        frame = labels.frame(b)
        in_view = set(np.flatnonzero(~np.isin(frame.exclusion, (Exclusion.BEHIND_CAMERA, Exclusion.OFF_FRAME))))
        assert set(np.flatnonzero(frame.labeled)) <= in_view and in_view, what
        numbered: dict[tuple[str, str], list[int]] = {}
        for index, panel in enumerate(sheet.panels):
            rects = [r for p, _, r in sheet.tags if p == index]
            assert not [(a, c) for a, c in itertools.combinations(rects, 2) if _overlap(a, c)], (what, panel.kind)
            numbered.setdefault((panel.obj, panel.kind), []).extend(f for p, f, _ in sheet.tags if p == index)
        for (obj, kind), features in numbered.items():  # an object's crops number each feature once
            mine = {f for f in in_view if view.features.objects[view.features.object_index[f]] == obj}
            assert sorted(features) == sorted(mine), (what, obj, kind)
        assert {f for _, f, _ in sheet.keys} == in_view, what
        assert [p.kind for p in sheet.panels] == list(PANELS) * (len(sheet.panels) // 3)
        keys = [r for _, _, r in sheet.keys]
        assert not [(a, c) for a, c in itertools.combinations(keys, 2) if _overlap(a, c)], what
        assert all(r[2] < sheet.image.shape[1] and r[3] < sheet.image.shape[0] for r in keys), what  # the key fits


def test_far_and_crowded_objects_are_magnified_in_several_crops_and_no_key_line_is_cut(wingcam) -> None:
    """Every crop magnifies at least MIN_SCALE times (or shows one feature) and holds at most
    MAX_CROP_FEATURES features, over the frames of the longest ranges, the most features and
    frames with a tanker far out; each key line's whole text fits its place."""
    import cv2

    from datagen.report.overlays import KEY_FONT, MAX_CROP_FEATURES, MIN_SCALE

    view, labels = wingcam
    frames = set(_frames(view, labels).values())
    far = np.flatnonzero(view.distance_m > 90.0)
    frames.update(int(b) for b in far[:: max(1, len(far) // 6)])
    split = 0
    for b in sorted(frames):
        sheet = draw_sheet(view, b, labels)
        for index, panel in enumerate(sheet.panels):
            shown = [f for p, f, _ in sheet.tags if p == index]
            assert len(shown) <= MAX_CROP_FEATURES, (b, panel.obj)
            assert panel.scale >= MIN_SCALE or len(shown) == 1, (b, panel.obj, panel.scale)
        objects = [p.obj for p in sheet.panels if p.kind == "points"]
        split += len(objects) - len(set(objects))
        frame = labels.frame(b)
        for name, f, rect in sheet.keys:
            reason = Exclusion(int(frame.exclusion[f]))
            text = name.split(".", 1)[-1] + (f" ({reason.reason})" if reason != Exclusion.NONE else "")
            width = cv2.getTextSize(f"{0:>3} {text}", 0, KEY_FONT, 1)[0][0]
            assert rect[2] - rect[0] >= width, (b, name)
    assert split > 0  # some object needed several crops


def _crosses(line, rect) -> bool:
    """Whether the segment ``line`` passes within a pixel of ``rect``."""
    t = np.linspace(0.0, 1.0, 2000)[:, None]
    points = np.asarray(line[:2]) * (1 - t) + np.asarray(line[2:]) * t
    return bool(np.any((points[:, 0] > rect[0] - 1) & (points[:, 0] < rect[2] + 1)
                       & (points[:, 1] > rect[1] - 1) & (points[:, 1] < rect[3] + 1)))


def _white_centroid(image: np.ndarray, near: np.ndarray, radius: int = 12) -> np.ndarray:
    """Intensity centroid (continuous pixels) of what is drawn within ``radius`` of ``near``
    over the background there."""
    x0, y0 = (np.floor(near) - radius).astype(int)
    window = image[y0:y0 + 2 * radius, x0:x0 + 2 * radius].astype(float).mean(axis=2)
    weight = np.clip(window - np.median(window), 0.0, None)
    jj, ii = np.mgrid[0:window.shape[0], 0:window.shape[1]]
    return np.array([(weight * (ii + x0 + 0.5)).sum(), (weight * (jj + y0 + 0.5)).sum()]) / weight.sum()


def test_the_crosshair_in_a_magnified_crop_is_on_the_true_centre_within_a_tenth_of_a_pixel(wingcam) -> None:
    """In the points panels of the longest-range frame showing every object, each crosshair with nothing else
    drawn within 8 px (its arms are 7 long; its own tag stands 9 px off) is centred on
    the true centre's place in the crop within 0.1 px."""
    view, labels = wingcam
    b = _frames(view, labels)["longest range, every object"]
    sheet = draw_sheet(view, b, labels)
    measured = 0
    for index, panel in enumerate(sheet.panels):
        if panel.kind != "points":
            continue
        features = [f for p, f, _ in sheet.tags if p == index]
        marks = {f: panel.to_sheet(labels.center_px[b, f]) for f in features}
        tags = [r for p, _, r in sheet.tags if p == index]
        for f, mark in marks.items():
            window = (mark[0] - 8, mark[1] - 8, mark[0] + 8, mark[1] + 8)
            crowded = any(g != f and np.abs(m - mark).max() < 24 for g, m in marks.items())
            crossed = any(_crosses(line, window) for p, g, line in sheet.leaders if p == index and g != f)
            if crowded or crossed or any(_overlap(window, r) for r in tags):
                continue
            np.testing.assert_allclose(_white_centroid(sheet.image, mark, radius=8), mark, atol=0.1)
            measured += 1
    assert measured >= 2


def test_the_colours_stay_apart_under_simulated_colour_vision_deficiencies() -> None:
    """Machado, Oliveira and Fernandes (2009) at full severity, in linear RGB: every pair of
    the sheet's colours stays at least 60 levels apart (8-bit sRGB) for protanopes,
    deuteranopes, tritanopes and normal vision."""
    simulations = {
        "protanopia": [[0.152286, 1.052583, -0.204868], [0.114503, 0.786281, 0.099216],
                       [-0.003882, -0.048116, 1.051998]],
        "deuteranopia": [[0.367322, 0.860646, -0.227968], [0.280085, 0.672501, 0.047413],
                         [-0.011820, 0.042940, 0.968881]],
        "tritanopia": [[1.255528, -0.076749, -0.178779], [-0.078411, 0.930809, 0.147602],
                       [0.004733, 0.691367, 0.303900]],
        "normal": np.eye(3),
    }

    def linear(bgr):
        c = np.asarray(bgr[::-1], dtype=float) / 255
        return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)

    def srgb(c):
        c = np.clip(c, 0, 1)
        return 255 * np.where(c <= 0.0031308, c * 12.92, 1.055 * c ** (1 / 2.4) - 0.055)

    for name, m in simulations.items():
        seen = {k: srgb(np.asarray(m) @ linear(c)) for k, c in COLOURS.items()}
        for a, c in itertools.combinations(seen, 2):
            assert np.linalg.norm(seen[a] - seen[c]) >= 60, (name, a, c)
