"""``datagen preview``: label sheets a person can read at any range, after the paper's Fig. 11.

A sheet shows one frame: on top the whole image with each object's region outlined and
named; below, per object in view, that region cropped and magnified (every image pixel a
block of pixels) in the three panels of Fig. 11:

- *points*: the projection of every feature's true 3D centre (a crosshair);
- *tight boxes*: the perceived extent of each feature's projected points;
- *labels*: the corrected box (centred on the true centre), the box written to the label
  file where it was grown to the minimum training size, and the true centres.

Each feature is numbered by its class id, the number its label lines begin with, in the
three panels and the key, in every frame; the numbers stand in columns
beside each panel, joined to their features by leader lines, so that no two overlap
however close the features are, and a key beside the panels names them (excluded
features that are still in view, by edge margin or occlusion, in grey with their reason).
Colours are Okabe and Ito's (2008), told apart under every common colour-vision
deficiency; crosshairs are drawn with sub-pixel precision on the continuous-pixel
convention (:func:`datagen.core.conventions.drawing_px`).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Final

import numpy as np
from numpy.typing import NDArray

from datagen.core.conventions import drawing_px
from datagen.core.errors import shown
from datagen.core.label_boxes import Exclusion, FrameLabels
from datagen.dataset.reader import DatasetView

__all__ = ["COLOURS", "INK", "PANELS", "Sheet", "draw_crosshair", "draw_sheet", "draw_text", "write_previews"]

# Okabe-Ito colours (BGR).
TIGHT: Final = (0, 159, 230)  # orange: the tight box
CORRECTED: Final = (178, 114, 0)  # blue: the corrected box (the paper's label)
WRITTEN: Final = (233, 180, 86)  # sky blue: the label box when grown to labels.min_box_px
CENTRE: Final = (255, 255, 255)  # white (on a dark halo): the true centre
REGION: Final = (66, 228, 240)  # yellow: an object's region in the whole frame
EXCLUDED: Final = (128, 128, 128)  # grey: excluded features still in view
INK: Final = (235, 235, 235)
LEADER: Final = (96, 96, 96)
PAPER: Final = (24, 24, 24)

#: The colours a sheet tells apart (BGR), by what they mark.
COLOURS: Final = {"true centre": CENTRE, "tight box": TIGHT, "corrected box": CORRECTED,
                  "label box grown to the minimum size": WRITTEN, "excluded": EXCLUDED}
#: The three panels of Fig. 11, in order, and what each draws.
PANELS: Final = ("points", "tight boxes", "labels")
#: A panel's size (px), the height of a number's tag and of a line of the key, and the
#: widths of a column of tags and of the key.
PANEL_W: Final = 600
PANEL_H: Final = 450
TAG_H: Final = 17
TAG_W: Final = 34
KEY_W: Final = 250
#: The key's font scale (OpenCV's Hershey simplex).
KEY_FONT: Final = 0.42
#: An object's crop is its features' boxes with this margin (share of its size, and px).
MARGIN: Final = (0.15, 6.0)
#: The most a crop magnifies (a single small feature would otherwise fill a panel).
MAX_SCALE: Final = 24.0
#: An object whose features a panel would show shrunk (below this magnification), or more
#: than :data:`MAX_CROP_FEATURES` of them, is shown in several crops, each magnified by its
#: own factor (a tanker 100 m out spans much of a wide frame: one crop shrank it and piled
#: up its boxes).
MIN_SCALE: Final = 1.0
MAX_CROP_FEATURES: Final = 12
#: Tags (or key lines) a column beside a panel holds.
COLUMN_ROWS: Final = PANEL_H // TAG_H
_FONT: Final = 0  # cv2.FONT_HERSHEY_SIMPLEX
_SHIFT: Final = 4  # OpenCV's sub-pixel drawing: coordinates in 1/16 px


def _fixed(x: float, y: float) -> tuple[int, int]:
    """OpenCV's fixed-point drawing coordinates of continuous pixel ``(x, y)``."""
    u, v = drawing_px((x, y))
    return round(u * (1 << _SHIFT)), round(v * (1 << _SHIFT))


def draw_crosshair(image: NDArray[np.uint8], uv_px, colour, *, arm: float, thickness: int = 1,
                   halo: bool = False) -> None:
    """A crosshair centred on continuous pixel coordinates ``uv_px`` (anti-aliased,
    sub-pixel); ``halo``: on a dark outline first, to read on any background."""
    import cv2

    u, v = (float(c) for c in uv_px)
    strokes = [((0, 0, 0), thickness + 2)] if halo else []
    for c, t in (*strokes, (colour, thickness)):
        cv2.line(image, _fixed(u - arm, v), _fixed(u + arm, v), c, t, cv2.LINE_AA, _SHIFT)
        cv2.line(image, _fixed(u, v - arm), _fixed(u, v + arm), c, t, cv2.LINE_AA, _SHIFT)


@dataclass(frozen=True)
class Panel:
    """Where a crop of the frame lies on the sheet: frame pixel ``(u, v)`` (continuous) is
    sheet pixel ``origin + (uv - crop) * scale``."""

    obj: str
    kind: str
    origin: tuple[float, float]
    crop: tuple[float, float]
    scale: float
    size: tuple[int, int] = (PANEL_W, PANEL_H)

    def to_sheet(self, uv) -> NDArray[np.float64]:
        uv = np.asarray(uv, dtype=np.float64)
        return np.asarray(self.origin) + (uv - np.asarray(self.crop)) * self.scale


@dataclass
class Sheet:
    """A drawn sheet and where everything on it is: the panels, each number's tag
    ``(panel index, feature index, (x0, y0, x1, y1))``, each key line the same way, and
    the leader lines."""

    image: NDArray[np.uint8]
    panels: list[Panel] = field(default_factory=list)
    tags: list[tuple[int, int, tuple[int, int, int, int]]] = field(default_factory=list)
    keys: list[tuple[str, int, tuple[int, int, int, int]]] = field(default_factory=list)
    #: ``(panel index, feature index, (x0, y0, x1, y1))``: the leader from a feature to its tag in the margin.
    leaders: list[tuple[int, int, tuple[float, float, float, float]]] = field(default_factory=list)
    #: Why the frame is drawn without its image (:func:`frame_image`), or None.
    problem: str | None = None
    #: The number drawn for each feature (its class id), by feature index.
    numbers: dict[int, int] = field(default_factory=dict)
    #: Where each region's title stands on the whole frame: ``(x0, y0, x1, y1)``, in row order.
    titles: list[tuple[float, float, float, float]] = field(default_factory=list)


def frame_image(view: DatasetView, b: int) -> tuple[NDArray[np.uint8], str | None]:
    """The frame's image and None, or a black canvas and why it is not the image: the
    frame has none (a labels-only build: no reason given), or its file is missing, leads
    outside the dataset, is not an image of the camera's size or does not decode."""
    from datagen.analysis.audit.dataset_files import decode_image, quiet_stderr

    k = view.intrinsics
    image, problem = None, None
    rel = view.image_path[b]
    if rel:
        problem = view.folder.problem(rel)
        if not problem:
            with quiet_stderr():
                image, problem = decode_image(view.root / rel, view.limits)  # its header read before it is decoded
            problem = problem if image is not None or problem else "missing"
    if image is None:
        return np.zeros((k.height, k.width, 3), np.uint8), problem
    return image, None


def _in_view(exclusion: NDArray) -> NDArray[np.bool_]:
    return ~np.isin(exclusion, (Exclusion.BEHIND_CAMERA, Exclusion.OFF_FRAME))


def _crop(boxes: NDArray[np.float64]) -> tuple[float, float, float]:
    """The crop ``(x0, y0, scale)`` of a panel that shows ``boxes`` (N, 4) with a margin
    (at most :data:`MAX_SCALE` times magnified)."""
    x0, y0 = boxes[:, 0].min(), boxes[:, 1].min()
    x1, y1 = boxes[:, 2].max(), boxes[:, 3].max()
    w, h = x1 - x0, y1 - y0
    pad = MARGIN[0] * max(w, h) + MARGIN[1]
    w, h = w + 2 * pad, h + 2 * pad
    scale = min(PANEL_W / w, PANEL_H / h, MAX_SCALE)
    cx, cy = (x0 + x1) / 2, (y0 + y1) / 2
    return cx - PANEL_W / scale / 2, cy - PANEL_H / scale / 2, scale


def _feature_boxes(frame: FrameLabels, features: NDArray) -> NDArray[np.float64]:
    """What a crop must show of ``features``: their tight boxes and true centres (not the label
    boxes grown to the training size: those may run past the panel, the features never do)."""
    boxes = np.concatenate([frame.tight_xyxy[features], np.tile(frame.center_px[features], 2)])
    return boxes[np.isfinite(boxes).all(axis=1)]


def _groups(frame: FrameLabels, features: NDArray) -> list[NDArray]:
    """``features`` in groups a crop each: halves along the wider spread of their centres until
    each group's crop magnifies at least :data:`MIN_SCALE` times and holds at most
    :data:`MAX_CROP_FEATURES` features (or is a single feature), in reading order."""
    boxes = _feature_boxes(frame, features)
    if len(features) <= 1 or (len(boxes) and _crop(boxes)[2] >= MIN_SCALE and len(features) <= MAX_CROP_FEATURES):
        return [features]
    centres = np.nan_to_num(frame.center_px[features], nan=0.0)
    axis = int(np.ptp(centres[:, 0]) < np.ptp(centres[:, 1]))
    order = np.argsort(centres[:, axis], kind="stable")
    half = len(features) // 2
    return [*_groups(frame, features[np.sort(order[:half])]), *_groups(frame, features[np.sort(order[half:])])]


def _magnified(image: NDArray[np.uint8], panel: Panel) -> NDArray[np.uint8]:
    """The panel's crop of ``image``, exactly registered: sheet pixel centre ``i + 0.5`` shows
    frame point ``crop + (i + 0.5) / scale`` (whole image pixels as blocks when magnified)."""
    import cv2

    s = panel.scale
    # OpenCV samples source index coordinates (pixel centres at integers): continuous - 0.5.
    m = np.array([[1 / s, 0, panel.crop[0] + 0.5 / s - 0.5], [0, 1 / s, panel.crop[1] + 0.5 / s - 0.5]])
    flags = (cv2.INTER_NEAREST if s >= 3 else cv2.INTER_LINEAR) | cv2.WARP_INVERSE_MAP
    return np.asarray(cv2.warpAffine(image, m, panel.size, flags=flags, borderMode=cv2.BORDER_CONSTANT,
                                     borderValue=PAPER), np.uint8)


def _columns(n: int) -> int:
    """Columns of :data:`COLUMN_ROWS` that ``n`` tags or key lines take (at least one)."""
    return max(1, math.ceil(n / COLUMN_ROWS))


def _slots(desired: NDArray[np.float64], top: float, bottom: float) -> tuple[list[int], NDArray[np.float64]]:
    """Tags of height :data:`TAG_H` for points at heights ``desired``: each tag's column and
    top, as near its point as the tags before it allow; columns of at most as many tags
    as fit between ``top`` and ``bottom`` (a panel's height), in order of height, never
    overlapping."""
    n = len(desired)
    columns = _columns(n)
    order = np.argsort(desired, kind="stable")
    column = np.empty(n, dtype=int)
    y = np.empty(n)
    for c in range(columns):
        members = order[c::columns]  # each column spans the whole height
        ys = np.clip(desired[members] - TAG_H / 2, top, bottom - TAG_H)
        for i in range(1, len(ys)):  # push down past the one above
            ys[i] = max(ys[i], ys[i - 1] + TAG_H)
        ys[-1:] = np.minimum(ys[-1:], bottom - TAG_H)
        for i in range(len(ys) - 2, -1, -1):  # and back up from the bottom
            ys[i] = min(ys[i], ys[i + 1] - TAG_H)
        column[members], y[members] = c, ys
    return column.tolist(), y


def draw_text(image, text: str, xy: tuple[int, int], colour, scale: float = 0.45) -> None:
    """``text`` at ``xy`` (its baseline's left end) in ``colour``, outlined in black to read on
    any background."""
    import cv2

    # A dark outline from the same strokes shifted a pixel each way (a thicker stroke
    # advances OpenCV's glyphs further, so it would not sit under the text).
    x, y = xy
    for dx, dy in ((-1, -1), (0, -1), (1, -1), (-1, 0), (1, 0), (-1, 1), (0, 1), (1, 1)):
        cv2.putText(image, text, (x + dx, y + dy), _FONT, scale, (0, 0, 0), 1, cv2.LINE_AA)
    cv2.putText(image, text, xy, _FONT, scale, colour, 1, cv2.LINE_AA)


def _draw_panel(sheet: Sheet, crop: NDArray[np.uint8], panel: Panel, frame: FrameLabels, features: NDArray,
                numbers: dict[int, int]) -> int:
    """Draw one panel with its tag columns; returns the width used right of the panel."""
    import cv2

    image, (px, py) = sheet.image, (int(panel.origin[0]), int(panel.origin[1]))
    thick = 1
    index = len(sheet.panels)
    sheet.panels.append(panel)
    marks = np.array([panel.to_sheet(frame.center_px[f]) for f in features]).reshape(-1, 2)
    origin = np.array([px, py], dtype=np.float64)

    # Boxes and crosshairs are drawn on the crop (so a box larger than the panel is cut at
    # its border), the tags and their leaders on the sheet (they stand beside the panel).
    def box(xyxy, colour):
        (x0, y0), (x1, y1) = panel.to_sheet(xyxy[:2]) - origin, panel.to_sheet(xyxy[2:]) - origin
        cv2.rectangle(crop, _fixed(x0, y0), _fixed(x1, y1), colour, thick, cv2.LINE_AA, _SHIFT)

    for f, mark in zip(features, marks, strict=True):
        excluded = Exclusion(int(frame.exclusion[f])) != Exclusion.NONE
        if panel.kind == "tight boxes":
            box(frame.tight_xyxy[f], EXCLUDED if excluded else TIGHT)
        elif panel.kind == "labels":
            box(frame.corrected_xyxy[f], EXCLUDED if excluded else CORRECTED)
            if not excluded and not np.array_equal(frame.label_xyxy[f], frame.corrected_xyxy[f]):
                box(frame.label_xyxy[f], WRITTEN)
        if panel.kind != "tight boxes":
            draw_crosshair(crop, mark - origin, EXCLUDED if excluded else CENTRE, arm=7.0, halo=True)
    image[py:py + PANEL_H, px:px + PANEL_W] = crop
    placed = _place_tags(marks, [_tag_width(numbers[f]) for f in features], (px, py, px + PANEL_W, py + PANEL_H))
    for f, mark, (rect, leader) in zip(features, marks, placed, strict=True):
        excluded = Exclusion(int(frame.exclusion[f])) != Exclusion.NONE
        colour = EXCLUDED if excluded else INK
        if leader:  # a tag away from its feature: a faint line from the feature to the tag's nearest point
            end = (float(np.clip(mark[0], rect[0], rect[2] + 1)), float(np.clip(mark[1], rect[1], rect[3] + 1)))
            cv2.line(image, _fixed(*mark), _fixed(*end), LEADER, 1, cv2.LINE_AA, _SHIFT)
            sheet.leaders.append((index, int(f), (float(mark[0]), float(mark[1]), *end)))
        draw_text(image, str(numbers[f]), (rect[0] + 2, rect[3] - 3), colour)
        sheet.tags.append((index, int(f), rect))
    right = max([r[2] for r, _ in placed] + [px + PANEL_W])
    return right - (px + PANEL_W) + 12


def _tag_width(number: int) -> int:
    return 9 * len(str(number)) + 5


def _place_tags(marks: NDArray[np.float64], widths: list[int], bounds: tuple[int, int, int, int]
                ) -> list[tuple[tuple[int, int, int, int], bool]]:
    """A tag ``(x0, y0, x1, y1)`` per mark, and whether it needs a leader: beside its mark
    (right, left, above, below, then the diagonals) where that overlaps no other tag, no
    mark's crosshair and stays in ``bounds``; otherwise in columns right of ``bounds``
    (:func:`_slots`), joined by a leader line. No two tags overlap."""
    x0b, y0b, x1b, y1b = bounds
    arm = 9
    crosses = [(m[0] - arm, m[1] - arm, m[0] + arm, m[1] + arm) for m in marks]
    taken: list[tuple[float, float, float, float]] = []

    def free(r) -> bool:
        inside = r[0] >= x0b and r[1] >= y0b and r[2] < x1b and r[3] < y1b
        return inside and not any(_overlap(r, o) for o in (*taken, *crosses))

    out: list = [None] * len(marks)
    for i in np.argsort(marks[:, 1], kind="stable"):
        (u, v), w, h = marks[i], widths[i], TAG_H
        for dx, dy in ((arm, -h / 2), (-arm - w, -h / 2), (-w / 2, -arm - h), (-w / 2, arm),
                       (arm, -arm - h), (-arm - w, -arm - h), (arm, arm), (-arm - w, arm)):
            x, y = round(u + dx), round(v + dy)
            r = (x, y, x + w - 1, y + h - 1)
            if free(r):
                taken.append(r)
                out[i] = (r, False)
                break
    for i in np.argsort(marks[:, 1], kind="stable"):  # then nearby, with a short leader (never across the panel)
        if out[i] is not None:
            continue
        (u, v), w, h = marks[i], widths[i], TAG_H
        for radius in range(2 * arm, NEAR_TAG_PX + 1, arm):
            for angle in np.linspace(0.0, 2 * np.pi, 16, endpoint=False):
                cx, cy = u + radius * np.cos(angle), v + radius * np.sin(angle)
                x, y = round(cx - (w if np.cos(angle) < 0 else 0)), round(cy - h / 2)
                r = (x, y, x + w - 1, y + h - 1)
                if free(r):
                    taken.append(r)
                    out[i] = (r, True)
                    break
            if out[i] is not None:
                break
    rest = [i for i in range(len(marks)) if out[i] is None]
    if rest:
        columns, tops = _slots(marks[rest, 1], y0b, y1b)
        for i, c, top in zip(rest, columns, tops, strict=True):
            x = x1b + 6 + c * TAG_W
            y = round(top)
            out[i] = ((x, y, x + widths[i] - 1, y + TAG_H - 1), True)
    return out


#: The font scale of the regions' titles on the whole frame.
TITLE_FONT: Final = 1.0


def _baseline(title: str, rect: tuple[float, float, float, float]) -> tuple[int, int]:
    """The left end of a title's baseline in its rectangle (:func:`_place_titles`)."""
    import cv2

    base = cv2.getTextSize(title, _FONT, TITLE_FONT, 1)[1]
    return round(rect[0]), round(rect[3] - base)


def _place_titles(regions: list[tuple[float, float, float, float]], titles: list[str],
                  bounds: tuple[int, int, int, int]) -> list[tuple[float, float, float, float]]:
    """Where each region's title stands, ``(x0, y0, x1, y1)``: above the region's
    outline, inside its top, below it, inside its bottom, a line further out (left-aligned,
    right-aligned, or along the edge; then beside the region), the first place that stays in
    ``bounds``, overlaps no title placed before it and crosses no region's outline; where
    none is free, the place with the fewest such conflicts (another title counting most)."""
    import cv2

    x0b, y0b, x1b, y1b = bounds
    edges = [e for a0, b0, a1, b1 in regions
             for e in ((a0 - 2, b0 - 2, a1 + 2, b0 + 2), (a0 - 2, b1 - 2, a1 + 2, b1 + 2),
                       (a0 - 2, b0 - 2, a0 + 2, b1 + 2), (a1 - 2, b0 - 2, a1 + 2, b1 + 2))]
    taken: list[tuple[float, float, float, float]] = []
    out = []
    for (a0, b0, a1, b1), title in zip(regions, titles, strict=True):
        (w, h), base = cv2.getTextSize(title, _FONT, TITLE_FONT, 1)
        h += base
        tops = (b0 - 6 - h, b0 + 6, b1 + 6, b1 - 6 - h, b0 - 10 - 2 * h, b1 + 10 + h)
        lefts = [a0 + 4, a1 - 4 - w, *np.arange(a0 + 4, a1 - w, max(w / 2, 8.0)), a0 - w - 8, a1 + 8]
        candidates = [(x, y) for y in tops for x in lefts]
        inside = [(x, y) for x, y in candidates
                  if x >= x0b + 2 and y >= y0b + 2 and x + w <= x1b - 2 and y + h <= y1b - 2]
        inside = inside or [(min(max(x0b + 4, a0), x1b - w - 4), max(y0b + 4, min(b0 + 6, y1b - h - 4)))]
        # The first free place, or the least crowded one (another title weighs more than an outline).
        def crowding(xy: tuple[float, float], w: float = w, h: float = h) -> float:
            box = (*xy, xy[0] + w, xy[1] + h)
            return 10 * sum(_overlap(box, t) for t in taken) + sum(_overlap(box, e) for e in edges)

        x, y = min(inside, key=crowding)
        taken.append((x - 2, y - 2, x + w + 2, y + h + 2))
        out.append((x, y, x + w, y + h))
    return out


#: How far from its mark a tag that cannot stand beside it may stand inside the panel (sheet
#: pixels) before it goes to the columns beside the panel.
NEAR_TAG_PX: Final = 72


def _overlap(a, b) -> bool:
    return a[0] <= b[2] and b[0] <= a[2] and a[1] <= b[3] and b[1] <= a[3]


def _key_lines(view: DatasetView, frame: FrameLabels, features: NDArray, numbers: dict[int, int]) -> list[str]:
    """A key line per feature: its number, its name and, when excluded, the reason, whole."""
    lines = []
    for f in features:
        reason = Exclusion(int(frame.exclusion[f]))
        name = view.features.name[f].split(".", 1)[-1] + (f" ({reason.reason})" if reason != Exclusion.NONE else "")
        lines.append(f"{numbers[f]:>3} {name}")
    return lines


def _key_width(lines: list[str]) -> int:
    """The width of a column of the key: its longest line, never cut, and at least :data:`KEY_W`."""
    import cv2

    return max([KEY_W] + [cv2.getTextSize(line, _FONT, KEY_FONT, 1)[0][0] + 12 for line in lines])


def _draw_key(sheet: Sheet, x: int, y: int, view: DatasetView, frame: FrameLabels, features: NDArray,
              numbers: dict[int, int]) -> int:
    """The numbers' names in columns of at most a panel's height; returns its width."""
    lines = _key_lines(view, frame, features, numbers)
    column = _key_width(lines)
    for i, (f, line) in enumerate(zip(features, lines, strict=True)):
        excluded = Exclusion(int(frame.exclusion[f])) != Exclusion.NONE
        kx, ky = x + (i // COLUMN_ROWS) * column, y + (i % COLUMN_ROWS) * TAG_H
        draw_text(sheet.image, line, (kx, ky + TAG_H - 4), EXCLUDED if excluded else INK, KEY_FONT)
        sheet.keys.append((view.features.name[f], int(f), (kx, ky, kx + column - 6, ky + TAG_H - 1)))
    return column * _columns(len(features))


def _legend(width: int, caption: str) -> NDArray[np.uint8]:
    """The caption and the colours' legend, wrapped to ``width``."""
    import cv2

    items = [(c, name) for name, c in COLOURS.items()] + [(REGION, "object region")]
    rows: list[list[tuple[tuple, str, int]]] = [[]]
    x = 12
    for colour, text in items:
        w = 30 + cv2.getTextSize(text, _FONT, 0.5, 1)[0][0] + 24
        if x + w > width and rows[-1]:
            rows.append([])
            x = 12
        rows[-1].append((colour, text, x))
        x += w
    out = np.full((34 + 26 * len(rows), width, 3), PAPER, np.uint8)
    draw_text(out, caption, (12, 22), INK, 0.55)
    for r, row in enumerate(rows):
        y = 34 + 26 * r
        for colour, text, x in row:
            cv2.rectangle(out, (x, y + 4), (x + 22, y + 18), colour, 2)
            draw_text(out, text, (x + 30, y + 17), INK, 0.5)
    return out


def draw_sheet(view: DatasetView, b: int, labels: FrameLabels, image: NDArray[np.uint8] | None = None) -> Sheet:
    """The label sheet of row ``b`` of ``view`` (``image``: the frame's, default its file)."""
    import cv2

    problem = None
    if image is None:
        image, problem = frame_image(view, b)
    frame = labels.frame(b)
    in_view = _in_view(frame.exclusion)
    objects = [(o, np.flatnonzero(in_view & (view.features.object_index == i)))
               for i, o in enumerate(view.features.objects)]
    objects = [(o, f) for o, f in objects if len(f)]
    numbers = {int(f): int(view.features.class_id[f]) for _, fs in objects for f in fs}  # as the label lines say
    # Rows of panels first (their widths set the sheet's), then the whole frame above them:
    # an object in one row, or in several crops (a row each) where one would not magnify it.
    rows = []
    for o, fs in objects:
        groups = _groups(frame, fs)
        for part, group in enumerate(groups):
            title = o if len(groups) == 1 else f"{o} ({part + 1} of {len(groups)})"
            rows.append((o, title, group, _crop(_feature_boxes(frame, group)), numbers))
    tag_room = [TAG_W * _columns(len(fs)) + 12 for _, _, fs, _, _ in rows]
    key_room = [_key_width(_key_lines(view, frame, fs, numbers)) * _columns(len(fs))
                for _, _, fs, _, numbers in rows]
    width = max([3 * (PANEL_W + t) + k + 24 for t, k in zip(tag_room, key_room, strict=True)] + [1600])
    k = view.intrinsics
    scale = width / k.width
    overview = cv2.resize(image, (width, round(k.height * scale)), interpolation=cv2.INTER_AREA)
    missing = f"  NO IMAGE: {shown(view.image_path[b])[:80]}: {problem}" if problem else ""
    caption = (f"frame {view.frame_id[b]}  ({view.split[b]})  PtD {view.distance_m[b]:.1f} m  "
               f"{k.width}x{k.height}{missing}")
    legend = _legend(width, caption)
    row_h = PANEL_H + 40
    sheet = Sheet(np.concatenate([legend, overview, np.full((row_h * len(rows), width, 3), PAPER, np.uint8)]),
                  problem=problem, numbers=numbers)
    top = legend.shape[0]
    regions = []
    for x0, y0, s in (c for _, _, _, c, _ in rows):  # each region in the whole frame
        a = (np.array([x0, y0]) * scale) + (0, top)
        z = (np.array([x0 + PANEL_W / s, y0 + PANEL_H / s]) * scale) + (0, top)
        cv2.rectangle(sheet.image, _fixed(*a), _fixed(*z), REGION, 2, cv2.LINE_AA, _SHIFT)
        regions.append((float(a[0]), float(a[1]), float(z[0]), float(z[1])))
    titles = [title for _, title, _, _, _ in rows]
    for title, rect in zip(titles, _place_titles(regions, titles, (0, top, width, top + overview.shape[0])),
                           strict=True):
        draw_text(sheet.image, title, _baseline(title, rect), REGION, TITLE_FONT)
        sheet.titles.append(rect)
    y = top + overview.shape[0]
    for o, title, fs, (x0, y0, s), numbers in rows:
        draw_text(sheet.image, f"{title}: {len(fs)} features in view, x{s:.1f}", (12, y + 28), REGION, 0.8)
        x = 12
        for kind in PANELS:
            panel = Panel(o, kind, (x, y + 36), (x0, y0), s)
            crop = _magnified(image, panel)
            draw_text(crop, kind, (8, 20), INK, 0.55)
            x += PANEL_W + _draw_panel(sheet, crop, panel, frame, fs, numbers)
        _draw_key(sheet, x, y + 36, view, frame, fs, numbers)
        y += row_h
    return sheet


def write_previews(view: DatasetView, frames: list[int] | None, out: Path, labels: FrameLabels | None = None,
                   *, limit: int = 4, warn: Callable[[str], None] | None = None) -> list[Path]:
    """Write ``out/{frame:08d}.jpg`` sheets for the given frame ids (default: the first
    ``limit``); ``warn``: told one line for each frame drawn without its image (missing,
    damaged or not the camera's size: the sheet says so too)."""
    import json

    from datagen.atomic import write_image, write_text
    from datagen.core.errors import DatagenError
    from datagen.dataset.reports import REPORTS, claim_report_folder, recorded_files

    labels = labels if labels is not None else view.recompute()
    index = {int(fid): b for b, fid in enumerate(view.frame_id)}
    wanted = list(dict.fromkeys(frames)) if frames is not None else [int(f) for f in view.frame_id[:limit]]
    missing = [f for f in wanted if f not in index]
    if missing:
        raise DatagenError(f"--frames: frame {missing[0]} is not in {view.root} "
                           f"(frames {int(view.frame_id.min())}-{int(view.frame_id.max())})")
    for f in wanted:  # a sheet shows nothing from outside the dataset
        rel = view.image_path[index[f]]
        if rel:
            view.folder.file(rel)
    out = claim_report_folder(REPORTS["preview"], out, view.root)
    written = []
    for f in wanted:
        sheet = draw_sheet(view, index[f], labels)
        if sheet.problem and warn is not None:
            warn(f"{view.root / (view.image_path[index[f]] or '')}: {sheet.problem}; frame {f} drawn without its image")
        written.append(write_image(out / f"{f:08d}.jpg", sheet.image, jpeg_quality=92))
    # preview.json: the record of every sheet written here (``files``, relative to the folder),
    # which --overwrite removes and nothing else.
    record = out / "preview.json"
    files = sorted({*recorded_files(REPORTS["preview"], out), *(p.name for p in written)})
    write_text(record, json.dumps({"dataset": str(view.root), "files": files}, indent=2) + "\n")
    return written
