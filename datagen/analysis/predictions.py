"""A detector's predictions as ``datagen evaluate`` reads them: Ultralytics ``save_txt``
files (``cls cx cy w h conf``, or pose lines with keypoint confidences), the most confident
point per class and image (paper 3.3)."""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from datagen.core.errors import DatagenError
from datagen.core.keypoints import PoseLayout
from datagen.dataset.yolo import parse_line
from datagen.paths import DatasetFolder, read_bytes

__all__ = ["Predictions", "parse_predictions"]


@dataclass(frozen=True)
class Predictions(Mapping):
    """A detector's predictions by image stem: per class the highest-confidence detection at
    or above the threshold, as ``(u_px, v_px, conf)`` of its box centre (paper 3.3)."""

    best: dict[str, dict[int, tuple[float, float, float]]]
    min_conf: float
    #: Detections per stem, and those below ``min_conf``.
    detections: dict[str, int] = field(default_factory=dict)
    below_conf: dict[str, int] = field(default_factory=dict)
    #: Prediction files (relative to the folder) whose stem is no frame of the dataset: not read.
    ghosts: list[str] = field(default_factory=list)

    def __getitem__(self, stem: str) -> dict[int, tuple[float, float, float]]:
        return self.best[stem]

    def __iter__(self) -> Iterator[str]:
        return iter(self.best)

    def __len__(self) -> int:
        return len(self.best)

    def all_below_conf(self, stem: str) -> bool:
        """The image has detections, every one of them below the threshold."""
        return self.detections.get(stem, 0) > 0 and self.below_conf.get(stem, 0) == self.detections[stem]


def _keep(best: dict, feature: int, u: float, v: float, conf: float) -> None:
    """Keep ``(u, v, conf)`` as the feature's point unless a more confident one is there."""
    if feature not in best or conf > best[feature][2]:
        best[feature] = (u, v, conf)


def _out_of_range(values: list[float], pose: bool) -> str | None:
    """What lies outside the image or a confidence's range in a parsed prediction line
    (normalized ``cx cy w h``, keypoints ``x y kconf``, ``conf``), or None."""
    cx, cy, w, h = values[1:5]
    if not (0.0 <= cx <= 1.0 and 0.0 <= cy <= 1.0):
        return f"box centre ({cx:.6g}, {cy:.6g}) outside the image (normalized values lie in [0, 1])"
    if not (0.0 <= w <= 1.0 and 0.0 <= h <= 1.0):
        return f"box size {w:.6g} x {h:.6g}: expected a width and height from 0 to 1 (normalized)"
    rest = values[5:]
    points = rest[:len(rest) - len(rest) % 3] if pose else []
    for i in range(0, len(points), 3):
        x, y, kconf = points[i:i + 3]
        if not (0.0 <= x <= 1.0 and 0.0 <= y <= 1.0):
            return f"keypoint {i // 3} at ({x:.6g}, {y:.6g}) outside the image (normalized values lie in [0, 1])"
        if not 0.0 <= kconf <= 1.0:
            return f"keypoint {i // 3} confidence {kconf:.6g}: expected a number from 0 to 1"
    if len(rest) % 3 == 1:  # the instance's (or the box's) confidence
        if not 0.0 <= rest[-1] <= 1.0:
            return f"confidence {rest[-1]:.6g}: expected a number from 0 to 1"
    return None


def parse_predictions(folder: Path, width: int, height: int, nc: int, *, max_bytes: int, min_conf: float = 0.25,
                      pose: PoseLayout | None = None, stems: set[str] | None = None) -> Predictions:
    """Ultralytics ``save_txt`` files by image stem: per feature class the highest-confidence
    point at or above ``min_conf``, as ``(u_px, v_px, conf)`` (paper 3.3). Lines without a
    confidence count as confidence 1.

    - a detection line ``cls cx cy w h [conf]`` (normalized) is its feature's box centre;
    - with ``pose`` (the dataset's :class:`~datagen.core.keypoints.PoseLayout`), a pose line
      ``cls cx cy w h (x y kconf) * K [conf]`` (``yolo pose predict``) is an object instance:
      each of its keypoints whose own confidence is at or above ``min_conf`` is its slot's
      feature, with the instance's confidence (an instance below ``min_conf`` gives nothing).

    A value outside the image, a negative size, a confidence outside [0, 1] and two files
    of one stem (in two subfolders) are refused in one line, as is a file over ``max_bytes``
    (:attr:`~datagen.dataset.limits.ReadLimits.prediction_bytes`); with ``stems`` (the
    dataset's frames), a file of another stem is not read and is listed in ``ghosts``."""
    folder = Path(folder)
    if not folder.is_dir():
        raise DatagenError(f"--predictions: {folder}: no such folder")
    out: dict[str, dict[int, tuple[float, float, float]]] = {}
    detections: dict[str, int] = {}
    below: dict[str, int] = {}
    pose_columns = () if pose is None else (pose.columns, pose.columns + 1)
    wanted = ("a detection line 'class cx cy w h [conf]'" if pose is None else
              f"a detection line 'class cx cy w h [conf]' or a pose line of {pose.columns} or {pose.columns + 1} "
              "columns")
    inside = DatasetFolder(folder, "folder of predictions")
    seen: dict[str, Path] = {}
    ghosts = []
    for path in sorted(folder.rglob("*.txt")):
        problem = inside.problem(str(path.relative_to(folder)))
        if problem:
            raise DatagenError(f"{path}: {problem}")
        if not path.is_file():  # a folder or a FIFO named *.txt is not a prediction file
            continue
        if stems is not None and path.stem not in stems:
            ghosts.append(str(path.relative_to(folder)))
            continue
        if path.stem in seen:
            raise DatagenError(f"{path}: frame {path.stem} has a second prediction file (the first: "
                               f"{seen[path.stem]}); keep one")
        seen[path.stem] = path
        best: dict[int, tuple[float, float, float]] = {}
        try:
            text = read_bytes(path, "a prediction file", max_bytes).decode("utf-8")
        except UnicodeDecodeError as exc:
            raise DatagenError(f"{path}: unreadable prediction file (not UTF-8 text at byte {exc.start})") from None

        n_detections = n_below = 0
        for n, line in enumerate(text.splitlines(), start=1):
            if not line.split():
                continue
            layout = pose if pose is not None and len(line.split()) in pose_columns else None  # a pose line's
            values, problem = parse_line(line, len(layout.objects) if layout else nc,
                                         columns=pose_columns if layout else (5, 6))
            if values is None:
                raise DatagenError(f"{path}:{n}: not {wanted}: {problem}")
            problem = _out_of_range(values, layout is not None)
            if problem:
                raise DatagenError(f"{path}:{n}: {problem}")
            n_detections += 1
            if layout is not None:
                conf = values[-1] if len(values) == layout.columns + 1 else 1.0
                if conf < min_conf:
                    n_below += 1
                    continue
                points = np.asarray(values[5:5 + 3 * layout.kpt_count]).reshape(-1, 3)
                for feature, (x, y, kconf) in zip(layout.feature_at[int(values[0])], points, strict=True):
                    if feature >= 0 and kconf >= min_conf:
                        _keep(best, int(feature), x * width, y * height, conf)
                continue
            cls, cx, cy = int(values[0]), values[1], values[2]
            conf = values[5] if len(values) == 6 else 1.0
            if conf < min_conf:
                n_below += 1
            else:
                _keep(best, cls, cx * width, cy * height, conf)
        out[path.stem] = best
        detections[path.stem], below[path.stem] = n_detections, n_below
    return Predictions(out, min_conf, detections, below, ghosts)
