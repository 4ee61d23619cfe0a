"""The YOLO line format, written and parsed in one place.

A label line is ``class cx cy w h``: the class id, the label box's centre and its
width and height in continuous pixels divided by the image's W and H
(:mod:`datagen.core.conventions`), with :data:`YOLO_DECIMALS` decimals. A
detector's prediction line (Ultralytics ``save_txt`` with ``save_conf``) adds the
confidence as a sixth column. :func:`yolo_lines` writes label lines;
:func:`parse_line` reads both kinds with the same rules (the audit and
``datagen evaluate`` use it).
"""

from __future__ import annotations

import math
from typing import Final

import numpy as np
from numpy.typing import ArrayLike

from datagen.core.label_boxes import FrameLabels

__all__ = ["YOLO_DECIMALS", "parse_line", "pose_lines", "yolo_lines"]

#: Decimals of the normalized values in a label line. Seven keep the rounding under
#: 1.2e-4 px at 2048x1080 (six would allow 1.02e-3 px, above the audit's drift bound).
YOLO_DECIMALS: Final = 7
_YOLO_LINE: Final = "%d" + f" %.{YOLO_DECIMALS}f" * 4 + "\n"


def yolo_lines(labels: FrameLabels, class_ids: ArrayLike, width: int, height: int) -> list[str]:
    """YOLO lines ``class cx cy w h`` (:data:`YOLO_DECIMALS` decimals, normalized by W and H) of one frame.

    Only labeled features appear, in class-id order of ``class_ids``.
    """
    if labels.exclusion.ndim != 1:
        raise ValueError(f"yolo_lines takes one frame, got batch shape {labels.exclusion.shape[:-1]}")
    keep = labels.labeled
    ids = np.asarray(class_ids)[keep]
    order = np.argsort(ids, kind="stable")
    centre = labels.label_center_px[keep][order]
    box = labels.label_xyxy[keep][order]
    rows = np.column_stack([
        ids[order],
        centre[:, 0] / width,
        centre[:, 1] / height,
        (box[:, 2] - box[:, 0]) / width,
        (box[:, 3] - box[:, 1]) / height,
    ])
    # One %-format over the whole frame: several times faster than per-line f-strings.
    return (_YOLO_LINE * len(rows) % tuple(rows.ravel().tolist())).splitlines()


def parse_line(line: str, nc: int, *, columns: tuple[int, ...] = (5,)) -> tuple[list[float] | None, str | None]:
    """One YOLO line: ``(values, None)``, or ``(None, what is wrong)`` when its tokens are
    not numbers, not finite, not ``columns`` many, or its class is not an integer in
    ``[0, nc)``. Whether the values lie in ``[0, 1]`` is the caller's rule."""
    tokens = line.split()
    values = []
    for i, token in enumerate(tokens):  # the file's text is not quoted: it may be anyone's
        try:
            values.append(float(token))
        except ValueError:
            return None, f"value {i + 1} of {len(tokens)} is not a number"
        if not math.isfinite(values[-1]):
            return None, f"value {i + 1} of {len(tokens)} is not finite"
    if len(values) not in columns:
        want = " or ".join(str(c) for c in columns)
        return None, f"{len(values)} columns, expected {want}"
    cls = values[0]
    if cls != int(cls) or not 0 <= cls < nc:
        return None, f"class {cls:.10g} is not an integer in [0, {nc})"
    return values, None


def pose_lines(rows: ArrayLike) -> list[str]:
    """YOLO pose lines ``class cx cy w h (x y v) * K`` from rows of
    :func:`datagen.core.keypoints.pose_rows`: values with :data:`YOLO_DECIMALS` decimals,
    flags as integers, and a keypoint of flag 0 as ``0 0 0``."""
    rows = np.asarray(rows, dtype=np.float64)
    out = []
    value = f"%.{YOLO_DECIMALS}f"
    for row in rows:
        parts = [f"{int(row[0])}", *(value % v for v in row[1:5])]
        for x, y, v in row[5:].reshape(-1, 3):
            parts.append("0 0 0" if v == 0 else f"{value % x} {value % y} {int(v)}")
        out.append(" ".join(parts))
    return out
