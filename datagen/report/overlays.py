"""``datagen preview``: overlays in the style of the paper's Fig. 11.

On each frame's image: the projection of every feature's true 3D centre (a
crosshair), its tight box (the perceived extent), its corrected box (centred
on the true centre) and, where it was grown to the minimum training size, the
box written to the label file, with the class name; features that are excluded but in
view (edge margin, occluded) are drawn in another colour with their reason.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from datagen.core.conventions import drawing_px
from datagen.core.labels import Exclusion, FrameLabels
from datagen.dataset.reader import DatasetView

__all__ = ["draw_crosshair", "draw_overlay", "write_previews"]

# BGR colours.
TIGHT = (0, 200, 255)  # amber: the tight box
CORRECTED = (80, 220, 60)  # green: the corrected box (the paper's label)
WRITTEN = (255, 200, 0)  # cyan: the label box when grown to labels.min_box_px
CENTRE = (255, 80, 255)  # magenta: true centre crosshair
EXCLUDED = (160, 160, 160)  # grey: excluded features still in view


#: OpenCV's sub-pixel drawing: coordinates in 1/16 px.
_SHIFT = 4


def _fixed(x: float, y: float) -> tuple[int, int]:
    """OpenCV's fixed-point drawing coordinates of continuous pixel ``(x, y)``."""
    u, v = drawing_px((x, y))
    return round(u * (1 << _SHIFT)), round(v * (1 << _SHIFT))


def draw_crosshair(image: NDArray[np.uint8], uv_px, colour, *, arm: float, thickness: int = 1) -> None:
    """A crosshair centred on continuous pixel coordinates ``uv_px`` (anti-aliased, sub-pixel)."""
    import cv2

    u, v = (float(c) for c in uv_px)
    cv2.line(image, _fixed(u - arm, v), _fixed(u + arm, v), colour, thickness, cv2.LINE_AA, _SHIFT)
    cv2.line(image, _fixed(u, v - arm), _fixed(u, v + arm), colour, thickness, cv2.LINE_AA, _SHIFT)


def draw_overlay(view: DatasetView, b: int, labels: FrameLabels, *, names: bool = True) -> NDArray[np.uint8]:
    """The overlay of row ``b`` of ``view`` (a black canvas when the frame has no image)."""
    import cv2

    k = view.intrinsics
    image = None
    if view.image_path[b] and (view.root / view.image_path[b]).is_file():  # a FIFO would block the read
        image = cv2.imread(str(view.root / view.image_path[b]), cv2.IMREAD_COLOR)
        if image is not None and image.shape[:2] != (k.height, k.width):
            image = None
    if image is None:
        image = np.zeros((k.height, k.width, 3), np.uint8)
    scale = max(1.0, k.width / 1024)
    thick = max(1, round(scale))
    font = 0.35 * scale
    pt, shift = _fixed, _SHIFT

    frame = labels.frame(b)
    for f in range(len(view.features)):
        reason = Exclusion(int(frame.exclusion[f]))
        if reason in (Exclusion.BEHIND_CAMERA, Exclusion.OFF_FRAME):
            continue
        excluded = reason != Exclusion.NONE
        x0, y0, x1, y1 = frame.tight_xyxy[f]
        cv2.rectangle(image, pt(x0, y0), pt(x1, y1), EXCLUDED if excluded else TIGHT, thick, cv2.LINE_AA, shift)
        x0, y0, x1, y1 = frame.corrected_xyxy[f]
        cv2.rectangle(image, pt(x0, y0), pt(x1, y1), EXCLUDED if excluded else CORRECTED, thick, cv2.LINE_AA, shift)
        if not excluded and not np.array_equal(frame.label_xyxy[f], frame.corrected_xyxy[f]):
            lx0, ly0, lx1, ly1 = frame.label_xyxy[f]
            cv2.rectangle(image, pt(lx0, ly0), pt(lx1, ly1), WRITTEN, thick, cv2.LINE_AA, shift)
        u, v = frame.center_px[f]
        colour = EXCLUDED if excluded else CENTRE
        draw_crosshair(image, (u, v), colour, arm=6 * scale, thickness=thick)
        if names:
            text = view.features.name[f].split(".", 1)[-1] + (f" ({reason.reason})" if excluded else "")
            cv2.putText(image, text, (int(x1) + 2, int(y0) + int(8 * scale)), cv2.FONT_HERSHEY_SIMPLEX, font,
                        colour, 1, cv2.LINE_AA)
    caption = (f"frame {view.frame_id[b]}  {view.split[b]}  PtD {view.distance_m[b]:.1f} m   "
               "magenta +: true centre   amber: tight box   green: corrected box   cyan: label box grown to the "
               "minimum training size   grey: excluded")
    cv2.putText(image, caption, (8, int(20 * scale)), cv2.FONT_HERSHEY_SIMPLEX, 0.5 * scale, (255, 255, 255),
                thick, cv2.LINE_AA)
    return image


def write_previews(view: DatasetView, frames: list[int] | None, out: Path, labels: FrameLabels | None = None,
                   *, limit: int = 4) -> list[Path]:
    """Write ``out/{frame:08d}.jpg`` for the given frame ids (default: the first ``limit``)."""
    import json

    from datagen.core.errors import DatagenError
    from datagen.files import write_image, write_text

    labels = labels if labels is not None else view.recompute()
    index = {int(fid): b for b, fid in enumerate(view.frame_id)}
    wanted = frames if frames is not None else [int(f) for f in view.frame_id[:limit]]
    missing = [f for f in wanted if f not in index]
    if missing:
        raise DatagenError(f"--frames: frame {missing[0]} is not in {view.root} "
                           f"(frames {int(view.frame_id.min())}-{int(view.frame_id.max())})")
    out = Path(out)
    written = [write_image(out / f"{f:08d}.jpg", draw_overlay(view, index[f], labels), jpeg_quality=90)
               for f in wanted]
    # preview.json: the record of every overlay written here (``files``, relative to the folder),
    # which --overwrite removes and nothing else.
    record = out / "preview.json"
    try:
        earlier = json.loads(record.read_text()).get("files", [])
    except (OSError, ValueError, AttributeError):
        earlier = []
    files = sorted({*(f for f in earlier if isinstance(f, str)), *(p.name for p in written)})
    write_text(record, json.dumps({"dataset": str(view.root), "files": files}, indent=2) + "\n")
    return written
