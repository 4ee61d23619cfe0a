"""``datagen evaluate``: probe-to-drogue (PtD) vectors by dual-object PnP, scored the
way the paper scores them (3.3-3.6).

Per frame, the 2D points of each object come from the truth (the projections of
the labeled features' true 3D centres, perturbed by a pixel noise radius) or
from a detector's predictions (Ultralytics ``save_txt`` files). Each object's
pose is solved by ``cv2.solvePnPRansac`` with the paper's settings, with the
previous frame's estimate as the extrinsic guess within an approach. The PtD
vector in the receiver frame is ``R_p^T (t_t - t_p)`` (paper 3.5): it needs no
camera extrinsics at all. The target is the drogue (its origin is the drogue
centre) or the tanker (its origin is the average drogue centre).

Metrics (paper 3.6): error magnitude against the true vector to the target as
a function of distance (mean and +-2 sigma per bin), reliability (successes /
attempts; fewer than 3 matches for an object, a vector longer than 120 m or an
outlier beyond 6 sigma of a rolling average fail), and accuracy at contact
(distance < 0.5 m).
"""

from __future__ import annotations

import math
import time
from collections import deque
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Final

import numpy as np
from numpy.typing import NDArray

from datagen.core.camera import Intrinsics
from datagen.core.conventions import evaluation_rng
from datagen.core.errors import DatagenError
from datagen.core.keypoints import PoseLayout
from datagen.core.transforms import invert_rigid
from datagen.dataset.reader import DatasetView
from datagen.dataset.yolo import parse_line

__all__ = [
    "PnPSettings",
    "Predictions",
    "covered_splits",
    "evaluate",
    "noise_offsets",
    "parse_predictions",
    "ptd_from_points",
    "solve_pose",
    "summarize",
]

#: Failure reasons of a PtD attempt, recorded per frame. With predictions, a frame without
#: enough matches is ``no_detections`` (no prediction file: the detector found nothing, or
#: the frame was not predicted), ``below_conf`` (every detection of the frame is below
#: ``--conf``) or ``too_few_matches`` (fewer than 3 classes of an object detected).
REASONS: Final = ("ok", "too_few_matches", "pnp_failed", "beyond_range", "outlier", "no_detections", "below_conf")


@dataclass(frozen=True)
class PnPSettings:
    """The paper's PnP and scoring settings (3.4, 3.6)."""

    iterations: int = 500
    reprojection_px: float = 4.0
    confidence: float = 0.9999
    min_matches: int = 3
    max_range_m: float = 120.0
    outlier_sigma: float = 6.0
    rolling_window: int = 30  # previous successful vectors of the approach in the rolling average
    rolling_min: int = 10  # no outlier verdict with fewer
    contact_m: float = 0.5


# --- one frame ---------------------------------------------------------------------------
def solve_pose(points_model: NDArray, uv_px: NDArray, k: Intrinsics, settings: PnPSettings,
               guess: tuple[NDArray, NDArray] | None = None,
               distortion: NDArray | None = None) -> tuple[NDArray, NDArray] | None:
    """``(rvec, tvec)`` of the object in the OpenCV camera frame, or None; ``distortion``:
    the frame's lens (OpenCV's five coefficients), None for a pinhole camera.

    Four or more matches: RANSAC with the paper's settings (and ``guess`` as the
    extrinsic guess), checked against SQPnP on its inliers. Exactly three: SQPnP,
    the one OpenCV solver that takes three.
    """
    import cv2

    n = len(points_model)
    if n < settings.min_matches:
        return None
    obj = np.ascontiguousarray(points_model, dtype=np.float64).reshape(-1, 1, 3)
    img = np.ascontiguousarray(uv_px, dtype=np.float64).reshape(-1, 1, 2)
    if n < 4:
        ok, rvec, tvec = cv2.solvePnP(obj, img, k.K, distortion, flags=cv2.SOLVEPNP_SQPNP)
        return (rvec.ravel(), tvec.ravel()) if ok else None
    use_guess = guess is not None
    rvec0 = np.array(guess[0], dtype=np.float64).reshape(3, 1) if use_guess else None
    tvec0 = np.array(guess[1], dtype=np.float64).reshape(3, 1) if use_guess else None
    ok, rvec, tvec, inliers = cv2.solvePnPRansac(
        obj, img, k.K, distortion, rvec=rvec0, tvec=tvec0, useExtrinsicGuess=use_guess,
        iterationsCount=settings.iterations, reprojectionError=settings.reprojection_px,
        confidence=settings.confidence, flags=cv2.SOLVEPNP_ITERATIVE)
    if not ok or inliers is None or len(inliers) < settings.min_matches:
        return None
    # EPnP, RANSAC's minimal solver, can return a mirrored pose for a nearly degenerate
    # set (five receiver points, three of them on the probe, gave a 69 m error with
    # noise-free points); the iterative refinement then stays in that minimum. SQPnP
    # on the inliers finds the global minimum: keep whichever reprojects better.
    obj_in, img_in = obj[inliers.ravel()], img[inliers.ravel()]
    ok_sq, rvec_sq, tvec_sq = cv2.solvePnP(obj_in, img_in, k.K, distortion, flags=cv2.SOLVEPNP_SQPNP)
    if ok_sq and _reprojection_rms(obj_in, img_in, rvec_sq, tvec_sq, k, distortion) < _reprojection_rms(
            obj_in, img_in, rvec, tvec, k, distortion):
        rvec, tvec = rvec_sq, tvec_sq
    return rvec.ravel(), tvec.ravel()


def _reprojection_rms(obj: NDArray, img: NDArray, rvec: NDArray, tvec: NDArray, k: Intrinsics,
                      distortion: NDArray | None = None) -> float:
    import cv2

    projected, _ = cv2.projectPoints(obj, rvec, tvec, k.K, distortion)
    return float(np.sqrt(np.mean(np.sum((projected - img) ** 2, axis=-1))))


def ptd_from_poses(receiver: tuple[NDArray, NDArray], target: tuple[NDArray, NDArray]) -> NDArray[np.float64]:
    """The target's origin in the receiver frame from two camera-frame poses (paper 3.5):
    ``R_p^T (t_t - t_p)``."""
    import cv2

    rotation, _ = cv2.Rodrigues(np.asarray(receiver[0], dtype=np.float64))
    return rotation.T @ (np.asarray(target[1]) - np.asarray(receiver[1]))


def ptd_from_points(receiver_3d, receiver_uv, target_3d, target_uv, k: Intrinsics,
                    settings: PnPSettings = PnPSettings()) -> NDArray[np.float64] | None:
    """The PtD vector of one frame from its 2D-3D matches, or None when a pose fails."""
    receiver = solve_pose(receiver_3d, receiver_uv, k, settings)
    target = solve_pose(target_3d, target_uv, k, settings)
    if receiver is None or target is None:
        return None
    return ptd_from_poses(receiver, target)


def noise_offsets(rng: np.random.Generator, n: int, radius_px: float) -> NDArray[np.float64]:
    """``(n, 2)`` pixel offsets uniform over the disc of ``radius_px`` (a random direction,
    a distance within the radius; the paper's truth-projection collects)."""
    if radius_px <= 0:
        return np.zeros((n, 2))
    angle = rng.uniform(0.0, 2.0 * math.pi, n)
    r = radius_px * np.sqrt(rng.uniform(0.0, 1.0, n))
    return np.stack([r * np.cos(angle), r * np.sin(angle)], axis=1)


# --- predictions --------------------------------------------------------------------------------
@dataclass(frozen=True)
class Predictions(Mapping):
    """A detector's predictions by image stem: per class the highest-confidence detection at
    or above the threshold, as ``(u_px, v_px, conf)`` of its box centre (paper 3.3)."""

    best: dict[str, dict[int, tuple[float, float, float]]]
    min_conf: float
    #: Detections per stem, and those below ``min_conf``.
    detections: dict[str, int] = field(default_factory=dict)
    below_conf: dict[str, int] = field(default_factory=dict)

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


def parse_predictions(folder: Path, width: int, height: int, nc: int, *, min_conf: float = 0.25,
                      pose: PoseLayout | None = None) -> Predictions:
    """Ultralytics ``save_txt`` files by image stem: per feature class the highest-confidence
    point at or above ``min_conf``, as ``(u_px, v_px, conf)`` (paper 3.3). Lines without a
    confidence count as confidence 1.

    - a detection line ``cls cx cy w h [conf]`` (normalized) is its feature's box centre;
    - with ``pose`` (the dataset's :class:`~datagen.core.keypoints.PoseLayout`), a pose line
      ``cls cx cy w h (x y kconf) * K [conf]`` (``yolo pose predict``) is an object instance:
      each of its keypoints whose own confidence is at or above ``min_conf`` is its slot's
      feature, with the instance's confidence (an instance below ``min_conf`` gives nothing)."""
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
    for path in sorted(folder.rglob("*.txt")):
        if not path.is_file():  # a folder or a FIFO named *.txt is not a prediction file
            continue
        best: dict[int, tuple[float, float, float]] = {}
        try:
            text = path.read_text()
        except (OSError, UnicodeDecodeError) as exc:
            raise DatagenError(f"{path}: unreadable prediction file ({exc})") from None

        n_detections = n_below = 0
        for n, line in enumerate(text.splitlines(), start=1):
            if not line.split():
                continue
            is_pose = len(line.split()) in pose_columns
            values, problem = parse_line(line, len(pose.objects) if is_pose else nc,
                                         columns=pose_columns if is_pose else (5, 6))
            if problem:
                raise DatagenError(f"{path}:{n}: not {wanted}: {problem}")
            n_detections += 1
            if is_pose:
                conf = values[-1] if len(values) == pose.columns + 1 else 1.0
                if conf < min_conf:
                    n_below += 1
                    continue
                points = np.asarray(values[5:5 + 3 * pose.kpt_count]).reshape(-1, 3)
                for feature, (x, y, kconf) in zip(pose.feature_at[int(values[0])], points, strict=True):
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
    return Predictions(out, min_conf, detections, below)


def covered_splits(view: DatasetView, predictions: Mapping) -> list[str]:
    """The splits of the frames that have a prediction file, in dataset order."""
    return [s for s in dict.fromkeys(view.split[i] for i, stem in enumerate(view.stems) if stem in predictions)]


# --- a whole dataset -------------------------------------------------------------------------------
def _target_object(view: DatasetView) -> str:
    objects = view.features.objects
    if "receiver" not in objects or len(objects) != 2:
        raise DatagenError(f"{view.root / 'features.parquet'}: evaluate needs receiver features and one other "
                           f"object's (drogue or tanker), found {', '.join(objects)}")
    return next(o for o in objects if o != "receiver")


def evaluate(view: DatasetView, *, noise_px: float = 0.0, run: int = 0, seed: int | None = None,
             predictions: Mapping | None = None, settings: PnPSettings = PnPSettings(),
             split: str | None = None) -> dict[str, NDArray]:
    """PtD vectors of every frame (frame order) for one source of 2D points.

    ``split`` limits the attempts to one split's frames (``val`` when scoring a
    detector on what it did not train on).

    Returns per-frame arrays: ``frame_id``, ``distance_m``, ``matches_receiver``,
    ``matches_target``, ``reason`` (index into :data:`REASONS`), ``success``, ``ptd_m``
    (NaN where no vector), ``truth_m`` (the true vector to the target's origin),
    ``error_m``, ``error_to_drogue_m`` (against the true drogue centre) and ``solve_s``.
    """
    features = view.features
    target = _target_object(view)
    k = view.intrinsics
    seed = int(view.doc.get("seed", 0)) if seed is None else seed
    obj_of = features.objects.index
    is_receiver = features.object_index == obj_of("receiver")
    is_target = features.object_index == obj_of(target)
    centers = features.center_model
    b = len(view)
    out = {
        "frame_id": view.frame_id.copy(),
        "distance_m": view.distance_m.copy(),
        "matches_receiver": np.zeros(b, np.int32),
        "matches_target": np.zeros(b, np.int32),
        "reason": np.zeros(b, np.int8),
        "ptd_m": np.full((b, 3), np.nan),
        "solve_s": np.zeros(b),
    }
    receiver_from_world = invert_rigid(view.world_from["receiver"])
    out["truth_m"] = np.einsum("bij,bj->bi", receiver_from_world[:, :3, :3], view.world_from[target][:, :3, 3]) \
        + receiver_from_world[:, :3, 3]
    stems = view.stems
    guesses: dict[str, tuple] = {}
    chain = None
    history: deque = deque(maxlen=settings.rolling_window)
    attempted = np.array([split is None or s == split for s in view.split])
    for i in range(b):
        if not attempted[i]:
            continue
        key = (int(view.approach_index[i]), int(view.approach_number[i]))
        if key != chain:
            chain, guesses, history = key, {}, deque(maxlen=settings.rolling_window)
        if predictions is None:
            uv = view.center_px[i]
            labeled = view.labeled[i]
            if noise_px > 0:
                uv = uv + noise_offsets(evaluation_rng(seed, int(view.frame_id[i]), run), len(uv), noise_px)
            have = labeled
        else:
            found = predictions.get(stems[i], {})
            uv = np.full((len(features), 2), np.nan)
            for cls, (u, v, _) in found.items():
                uv[cls] = (u, v)
            have = np.isfinite(uv[:, 0])
        start = time.perf_counter()
        poses = {}
        for name, mask in (("receiver", is_receiver), (target, is_target)):
            sel = mask & have
            out["matches_receiver" if name == "receiver" else "matches_target"][i] = int(sel.sum())
            if sel.sum() < settings.min_matches:
                poses[name] = "few"
                continue
            poses[name] = solve_pose(centers[sel], uv[sel], k, settings, guesses.get(name),
                                     view.distortion[i] if view.distortion[i].any() else None)
        out["solve_s"][i] = time.perf_counter() - start
        if "few" in poses.values():
            reason = "too_few_matches"
            if predictions is not None:
                stem = stems[i]
                if stem not in predictions:
                    reason = "no_detections"
                elif isinstance(predictions, Predictions) and predictions.all_below_conf(stem):
                    reason = "below_conf"
            out["reason"][i] = REASONS.index(reason)
            continue
        if poses["receiver"] is None or poses[target] is None:
            out["reason"][i] = REASONS.index("pnp_failed")
            continue
        ptd = ptd_from_poses(poses["receiver"], poses[target])
        out["ptd_m"][i] = ptd
        if np.linalg.norm(ptd) > settings.max_range_m:
            out["reason"][i] = REASONS.index("beyond_range")
            continue
        if len(history) >= settings.rolling_min:
            past = np.array(history)
            sigma = np.maximum(past.std(axis=0), 1e-3)
            if np.any(np.abs(ptd - past.mean(axis=0)) > settings.outlier_sigma * sigma):
                out["reason"][i] = REASONS.index("outlier")
                continue
        history.append(ptd)
        guesses = dict(poses)  # only an accepted pose seeds the next frame's solve
    for name in list(out):  # frames of other splits were not attempted: drop them
        out[name] = out[name][attempted]
    out["success"] = out["reason"] == 0
    out["error_m"] = np.linalg.norm(out["ptd_m"] - out["truth_m"], axis=1)
    out["error_to_drogue_m"] = np.linalg.norm(out["ptd_m"] - view.ptd_receiver_m[attempted], axis=1)
    out["missing_predictions"] = 0 if predictions is None else int(sum(
        1 for i in np.flatnonzero(attempted) if (stems[i]) not in predictions))
    out["target"] = target
    return out


#: Distance bins of the metrics, metres (contact first).
DISTANCE_EDGES: Final = np.array([0.0, 0.5, 2.5, 5.0, 10.0, 15.0, 20.0, 25.0, 30.0, 40.0, 50.0, 60.0, 70.0, 80.0,
                                  90.0, 100.0, 110.0, 120.0])
#: Distances of the README's noise table; a frame counts within +-2.5 m (contact: < 0.5 m).
TABLE_DISTANCES_M: Final = (20.0, 50.0, 120.0)


def _stats(errors: NDArray, success: NDArray) -> dict:
    e = errors[success]
    return {
        "attempts": int(success.size),
        "successes": int(success.sum()),
        "reliability": float(success.mean()) if success.size else None,
        "mean_m": float(e.mean()) if e.size else None,
        "std_m": float(e.std()) if e.size else None,
        "plus_2sigma_m": float(e.mean() + 2 * e.std()) if e.size else None,
        "median_m": float(np.median(e)) if e.size else None,
        "max_m": float(e.max()) if e.size else None,
    }


def summarize(result: dict, settings: PnPSettings = PnPSettings()) -> dict:
    """Metrics of one run: overall, per distance bin, at contact, at the table distances,
    and the failure reasons."""
    d, e, ok = result["distance_m"], result["error_m"], result["success"]
    bins = []
    for lo, hi in zip(DISTANCE_EDGES[:-1], DISTANCE_EDGES[1:], strict=True):
        sel = (d >= lo) & (d < hi)
        bins.append({"lo_m": float(lo), "hi_m": float(hi), **_stats(e[sel], ok[sel])})
    at = {"contact": _stats(e[d < settings.contact_m], ok[d < settings.contact_m])}
    for x in TABLE_DISTANCES_M:
        sel = np.abs(d - x) < 2.5
        at[f"{x:g}m"] = _stats(e[sel], ok[sel])
    reasons = {r: int((result["reason"] == i).sum()) for i, r in enumerate(REASONS)}
    solve = result["solve_s"]
    return {"target": result["target"], "overall": _stats(e, ok), "by_distance": bins, "at": at,
            "reasons": reasons, "solve_ms_mean": float(solve.mean() * 1e3) if solve.size else None}


