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

import dataclasses
import itertools
import math
import time
from collections import deque
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Final

import numpy as np
from numpy.typing import NDArray

from datagen.analysis.predictions import Predictions
from datagen.console import NullProgress, Progress
from datagen.core.camera import Intrinsics
from datagen.core.conventions import evaluation_rng
from datagen.core.errors import DatagenError, shown
from datagen.core.transforms import invert_rigid
from datagen.dataset.reader import DatasetMeta, DatasetView, FrameOrder
from datagen.parallel import map_in_order

__all__ = [
    "DistanceBin",
    "ErrorStats",
    "EvaluationPlan",
    "PnPSettings",
    "Run",
    "RunResult",
    "RunSummary",
    "covered_splits",
    "evaluate",
    "evaluate_runs",
    "failure_text",
    "noise_offsets",
    "noise_radii",
    "plan_evaluation",
    "prediction_split",
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
#: Up to this many matches, AP3P on every four of them is also tried (at most 35 solves).
_AP3P_MAX_POINTS: Final = 7
#: Levenberg-Marquardt's stop for the chosen pose's refinement (:func:`_solve_pose`): at most
#: this many iterations, or a step below this.
_REFINE_ITERATIONS, _REFINE_EPS = 100, 1e-14
#: How far apart, as a share of the distance, the poses that fit three matches may lie for
#: the pose to be kept (:func:`_three_point_pose`).
THREE_POINT_AGREEMENT: Final = 1e-3


def solve_pose(points_model: NDArray, uv_px: NDArray, k: Intrinsics, settings: PnPSettings,
               guess: tuple[NDArray, NDArray] | None = None,
               distortion: NDArray | None = None) -> tuple[NDArray, NDArray] | None:
    """``(rvec, tvec)`` of the object in the OpenCV camera frame, or None; ``distortion``:
    the frame's lens (OpenCV's five coefficients), None for a pinhole camera.

    Four or more matches: RANSAC with the paper's settings (and ``guess`` as the
    extrinsic guess), checked against SQPnP on its inliers. Exactly three: SQPnP's pose
    where it is the only one they fit (:func:`_three_point_pose`: almost never).
    Points OpenCV's solvers refuse (SQPnP's variance check on points far outside any image)
    are a failed solve, as is no pose.
    """
    import cv2

    try:
        return _solve_pose(points_model, uv_px, k, settings, guess, distortion)
    except cv2.error:
        return None


def _solve_pose(points_model: NDArray, uv_px: NDArray, k: Intrinsics, settings: PnPSettings,
                guess: tuple[NDArray, NDArray] | None, distortion: NDArray | None) -> tuple[NDArray, NDArray] | None:
    import cv2

    n = len(points_model)
    if n < settings.min_matches:
        return None
    camera = k.K
    obj = np.ascontiguousarray(points_model, dtype=np.float64).reshape(-1, 1, 3)
    img = np.ascontiguousarray(uv_px, dtype=np.float64).reshape(-1, 1, 2)
    if n < 4:
        return _three_point_pose(obj, img, camera, distortion)
    use_guess = guess is not None
    rvec0 = None if guess is None else np.array(guess[0], dtype=np.float64).reshape(3, 1)
    tvec0 = None if guess is None else np.array(guess[1], dtype=np.float64).reshape(3, 1)
    ok, rvec, tvec, inliers = cv2.solvePnPRansac(
        obj, img, camera, distortion, rvec=rvec0, tvec=tvec0, useExtrinsicGuess=use_guess,
        iterationsCount=settings.iterations, reprojectionError=settings.reprojection_px,
        confidence=settings.confidence, flags=cv2.SOLVEPNP_ITERATIVE)
    if not ok or inliers is None or len(inliers) < settings.min_matches:
        return None
    # EPnP, RANSAC's minimal solver, can return a mirrored pose for a nearly degenerate
    # set (five receiver points, three of them on the probe, gave a 69 m error with
    # noise-free points); EPnP, SQPnP and RANSAC all missed the pose of another five
    # noise-free receiver points through a distorting lens (150 px RMS, a 13 m error)
    # that AP3P on any four of them found. So the pose is the best of several candidates:
    # RANSAC's, SQPnP on its inliers and on every point, and for a few points AP3P on every
    # four of them (only while no candidate explains every point: that search is 35 solves
    # for seven points); the most inliers win, then the lowest RMS over them.
    candidates = [(rvec, tvec)]
    every = np.array_equal(inliers.ravel(), np.arange(n))  # then both subsets are the same points
    for subset in (inliers.ravel(),) if every else (inliers.ravel(), slice(None)):
        ok_sq, rvec_sq, tvec_sq = cv2.solvePnP(obj[subset], img[subset], camera, distortion,
                                               flags=cv2.SOLVEPNP_SQPNP)
        candidates += [(rvec_sq, tvec_sq)] if ok_sq else []
    scores = [_score(obj, img, r, t, camera, distortion, settings.reprojection_px) for r, t in candidates]
    if n <= _AP3P_MAX_POINTS and max(scores)[0] < n:
        for four in itertools.combinations(range(n), 4):
            ok_p3, rvec_p3, tvec_p3 = cv2.solvePnP(obj[list(four)], img[list(four)], camera, distortion,
                                                   flags=cv2.SOLVEPNP_AP3P)
            if ok_p3:
                candidates.append((rvec_p3, tvec_p3))
                scores.append(_score(obj, img, rvec_p3, tvec_p3, camera, distortion, settings.reprojection_px))
    best = max(range(len(candidates)), key=scores.__getitem__)  # the first of equals: RANSAC's
    if scores[best][0] < settings.min_matches:
        return None
    rvec, tvec = candidates[best]
    # The solvers stop short where a far object's pose is ill-conditioned (noise-free points:
    # 6e-4 px RMS left, a 4 cm error at 67 m); Levenberg-Marquardt on the pose's inliers
    # finishes the descent (1.7e-7 px there).
    inlier = _distances_px(obj, img, rvec, tvec, camera, distortion) <= settings.reprojection_px
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, _REFINE_ITERATIONS, _REFINE_EPS)
    rvec, tvec = cv2.solvePnPRefineLM(obj[inlier], img[inlier], camera, distortion, rvec.copy(), tvec.copy(),
                                      criteria)
    return rvec.ravel(), tvec.ravel()


def _three_point_pose(obj: NDArray, img: NDArray, camera: NDArray, distortion: NDArray | None
                      ) -> tuple[NDArray, NDArray] | None:
    """The pose of three matches, or None when they do not tell it. Three points fit up to
    four poses exactly (P3P), and for almost every three-point set two or more of them lie
    in front of the camera, metres apart: SQPnP alone picked poses 15-55 m off from
    noise-free points. A pose is kept only where every pose in front of the camera that
    fits lies within :data:`THREE_POINT_AGREEMENT` of SQPnP's distance. (The approach's
    previous pose does not choose reliably: frames of an approach lie metres apart, and
    on podcam15 frames it chose poses 33 m off.)"""
    import cv2

    ok, rvec, tvec = cv2.solvePnP(obj, img, camera, distortion, flags=cv2.SOLVEPNP_SQPNP)
    if not ok:
        return None
    rvec, tvec = np.ravel(rvec), np.ravel(tvec)
    solved, _, tvecs = cv2.solveP3P(obj, img, camera, distortion, flags=cv2.SOLVEPNP_AP3P)
    reach = THREE_POINT_AGREEMENT * float(np.linalg.norm(tvec))
    others = [np.ravel(t) for t in tvecs if np.ravel(t)[2] > 0] if solved else []
    return (rvec, tvec) if all(np.linalg.norm(t - tvec) <= reach for t in others) else None


def _score(obj: NDArray, img: NDArray, rvec: NDArray, tvec: NDArray, camera: NDArray,
           distortion: NDArray | None, threshold_px: float) -> tuple[int, float]:
    """``(inliers, -rms over the inliers)`` of a pose: larger is better."""
    d = _distances_px(obj, img, rvec, tvec, camera, distortion)
    inlier = d <= threshold_px
    rms = math.sqrt(float(np.mean(d[inlier] ** 2))) if inlier.any() else math.inf
    return int(inlier.sum()), -rms


def _distances_px(obj: NDArray, img: NDArray, rvec: NDArray, tvec: NDArray, camera: NDArray,
                  distortion: NDArray | None) -> NDArray[np.float64]:
    """How far each point's projection under a pose lies from its image point, px."""
    import cv2

    projected, _ = cv2.projectPoints(obj, rvec, tvec, camera, distortion)
    return np.linalg.norm((projected - img).reshape(-1, 2), axis=-1)


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


def covered_splits(view: FrameOrder, predictions: Mapping) -> list[str]:
    """The splits of the frames that have a prediction file, in dataset order."""
    return [s for s in dict.fromkeys(view.split[i] for i, stem in enumerate(view.stems) if stem in predictions)]


# --- what to evaluate -----------------------------------------------------------------------------
#: Truth runs: at most this many noise radii, each at most this many pixels.
MAX_NOISE_RUNS: Final = 20
MAX_NOISE_PX: Final = 1000.0


def noise_radii(text: str) -> list[float]:
    """The noise radii of the truth runs from a list like ``0,0.5,1,2.5``.

    Raises:
        ValueError: what is wrong with ``text``, in words.
    """
    try:
        radii = [float(r) + 0.0 for r in text.split(",")]  # + 0.0: -0 is 0
    except ValueError:
        raise ValueError(f"{text[:60]!r} is not a list of radii like 0,0.5,1,2.5") from None
    if not all(math.isfinite(r) and r >= 0 for r in radii):
        raise ValueError(f"{text[:60]!r}: radii must be finite and not negative")
    if max(radii) > MAX_NOISE_PX or len(radii) > MAX_NOISE_RUNS:
        raise ValueError(f"{text[:60]!r}: at most {MAX_NOISE_RUNS} radii of at most {MAX_NOISE_PX:g} px each")
    return radii


def prediction_split(view: FrameOrder, predictions: Mapping) -> tuple[str, str]:
    """The split a detector's predictions are scored on when none is asked for, and why: the
    split (or ``all``) of the frames that have a prediction file; ``val`` when there is no
    file at all (``yolo predict`` writes none for an image without detections).

    Raises:
        ValueError: files exist but none is named after an image of the dataset.
    """
    if not predictions:
        split = "val" if "val" in view.split else "train"  # the list data.yaml validates on
        return split, f"no prediction file: the detector found nothing; scoring the {split} split"
    covered = covered_splits(view, predictions)
    if not covered:
        raise ValueError("no prediction file is named after an image of the dataset "
                         "(expected files like 00000003.txt from `yolo predict save_txt=True`)")
    split = covered[0] if len(covered) == 1 else "all"
    return split, f"scoring the {split} split{'s' if split == 'all' else ''}: the frames the predictions cover"


def failure_text(reason: str, settings: PnPSettings, conf: float) -> str:
    """How a failure reason of :data:`REASONS` reads after a count of frames (``3 with ...``)."""
    return {
        "too_few_matches": f"with fewer than {settings.min_matches} matched features of an object",
        "pnp_failed": "where PnP found no pose, or three matches fit poses apart",
        "beyond_range": f"with a vector longer than {settings.max_range_m:g} m",
        "outlier": f"beyond {settings.outlier_sigma:g} sigma of the approach's rolling mean",
        "no_detections": "with no prediction file (nothing detected, or not predicted)",
        "below_conf": f"with all detections below --conf {conf:g}",
    }.get(reason, reason)


@dataclass(frozen=True)
class EvaluationPlan:
    """What an evaluation of a dataset runs (:func:`plan_evaluation`): its runs, each one's
    description for the report (``sources``, in the runs' order), the split it scores (None:
    every frame), the detector's predictions it reads (None: truth runs), and what a user is
    told before it runs: ``notes`` (the split it chose) and ``warnings`` (prediction files
    that name no frame)."""

    runs: tuple[Run, ...]
    sources: tuple[dict, ...]
    split: str | None
    predictions: Predictions | None
    notes: tuple[str, ...] = ()
    warnings: tuple[str, ...] = ()


def plan_evaluation(dataset: DatasetMeta, index: FrameOrder, *, noise_px: str = "0,0.5,1,2.5",
                    predictions: Path | None = None, conf: float = 0.25, split: str | None = None
                    ) -> EvaluationPlan:
    """Plan the evaluation of ``dataset`` (its frames in order: ``index``, read once with
    unique stems): truth runs at each radius of ``noise_px``, or with ``predictions`` (a
    folder of Ultralytics ``save_txt`` files by image stem) one run of the detector's
    detections at confidence ``conf`` or more. ``split``: ``all``, ``train`` or ``val``
    (None: all for truth runs; with predictions, the splits their files cover).

    Raises:
        DatagenError: one line naming the option or file and what is wrong (an unknown split,
            a bad radius list, two frames of one stem, prediction files none of which names
            a frame, a split the build drew no frames of).
    """
    from datagen.analysis.predictions import parse_predictions

    if split not in (None, "all", "train", "val"):
        raise DatagenError(f"--split: {split!r}: choose all, train or val")
    notes: list[str] = []
    warnings: list[str] = []
    found = None
    if predictions is not None:
        k = dataset.intrinsics
        pose = dataset.pose_layout if dataset.pose_yaml is not None else None
        stems = index.stems
        if len(set(stems)) != len(stems):
            twice = next(s for s in stems if stems.count(s) > 1)
            raise DatagenError(f"{dataset.root}: two frames have files of the stem {twice!r}: a prediction file "
                               "could not say which frame it is of (datagen audit names the manifests' paths)")
        found = parse_predictions(predictions, k.width, k.height, len(dataset.features), min_conf=conf, pose=pose,
                                  stems=set(stems), max_bytes=dataset.limits.prediction_bytes)
        if found.ghosts and not found:
            raise DatagenError(f"--predictions: {predictions}: no prediction file is named after an image of the "
                               f"dataset ({len(found.ghosts)} files, the first: {found.ghosts[0]}; expected files "
                               "like 00000003.txt from `yolo predict save_txt=True`)")
        if found.ghosts:
            warnings.append(f"{predictions}: {len(found.ghosts)} prediction files name no frame of {dataset.root} "
                            f"(the first: {shown(found.ghosts[0])}); not read")
        if split is None:
            try:
                split, why = prediction_split(index, found)
            except ValueError as exc:
                raise DatagenError(f"--predictions: {predictions}: {exc}") from None
            notes.append(f"{predictions}: {why} (--split to choose)" if not found else f"{why} (--split to choose)")
        sources: tuple[dict[str, object], ...] = (
            {"source": "predictions", "predictions": str(predictions), "conf": conf, "split": split,
             "files_of_no_frame": found.ghosts[:100]},)
        runs: tuple[Run, ...] = (Run(predictions=found),)
    else:
        split = split or "all"
        try:
            radii = noise_radii(noise_px)
        except ValueError as exc:
            raise DatagenError(f"--noise-px: {exc}") from None
        sources = tuple({"source": "truth", "noise_px": radius, "split": split} for radius in radii)
        runs = tuple(Run(noise_px=radius, run=run) for run, radius in enumerate(radii))
    only = None if split == "all" else split
    if only is not None and only not in index.split:
        counts = ", ".join(f"{index.split.count(s)} {s}" for s in ("train", "val"))
        raise DatagenError(f"{dataset.root}: no {only} frames to score (the build drew {counts}); choose --split "
                           "all or the other split")
    return EvaluationPlan(runs, sources, only, found, tuple(notes), tuple(warnings))


# --- a whole dataset -------------------------------------------------------------------------------
def _target_object(view: DatasetMeta) -> str:
    objects = view.features.objects
    if "receiver" not in objects or len(objects) != 2:
        raise DatagenError(f"{view.root / 'features.parquet'}: evaluate needs receiver features and one other "
                           f"object's (drogue or tanker), found {', '.join(objects)}")
    return next(o for o in objects if o != "receiver")


@dataclass(frozen=True)
class Run:
    """One source of 2D points: the truth perturbed by ``noise_px`` (noise stream ``run``),
    or a detector's ``predictions``."""

    noise_px: float = 0.0
    run: int = 0
    predictions: Mapping | None = None


@dataclass(frozen=True)
class RunResult:
    """One run's per-frame results, in frame order (:func:`evaluate_runs`): each frame's id and
    probe-to-drogue distance (m), the matched features of the receiver and of the target, why
    the frame failed (``reason``: an index into :data:`REASONS`, 0 where it succeeded), the
    PtD vector (``ptd_m``, ``(N, 3)``, NaN where none), the true vector to the target's origin
    (``truth_m``), the error against it and against the true drogue centre (m), the solve's
    seconds; the frames without a prediction file, and the target object."""

    frame_id: NDArray[np.int64]
    distance_m: NDArray[np.float64]
    matches_receiver: NDArray[np.int32]
    matches_target: NDArray[np.int32]
    reason: NDArray[np.int8]
    ptd_m: NDArray[np.float64]
    truth_m: NDArray[np.float64]
    error_m: NDArray[np.float64]
    error_to_drogue_m: NDArray[np.float64]
    solve_s: NDArray[np.float64]
    missing_predictions: int
    target: str

    def __len__(self) -> int:
        return len(self.frame_id)

    @property
    def success(self) -> NDArray[np.bool_]:
        """``(N,)`` whether each frame gave an accepted PtD vector."""
        return self.reason == 0


@dataclass
class _Chain:
    """What one run carries from frame to frame within an approach."""

    key: tuple[int, int] | None = None
    guesses: dict = field(default_factory=dict)
    history: deque = field(default_factory=deque)


#: Per-frame result columns and their dtypes (``ptd_m`` and ``truth_m`` are (N, 3)).
_COLUMNS: Final = {"frame_id": np.int64, "distance_m": np.float64, "matches_receiver": np.int32,
                   "matches_target": np.int32, "reason": np.int8, "ptd_m": np.float64, "solve_s": np.float64,
                   "truth_m": np.float64, "ptd_receiver_m": np.float64, "has_predictions": bool}


def _evaluate_rows(view: DatasetView, rows: NDArray[np.int64], runs: list[Run], chains: list[_Chain], *,
                   seed: int, settings: PnPSettings, out: list[dict[str, list]]) -> None:
    """Solve ``rows`` of ``view`` (in frame order) for every run, appending to ``out``."""
    features = view.features
    target = _target_object(view)
    k = view.intrinsics
    obj_of = features.objects.index
    masks = (("receiver", features.object_index == obj_of("receiver")),
             (target, features.object_index == obj_of(target)))
    centers = features.center_model
    receiver_from_world = invert_rigid(view.world_from["receiver"][rows])
    truth = np.einsum("bij,bj->bi", receiver_from_world[:, :3, :3], view.world_from[target][rows][:, :3, 3]) \
        + receiver_from_world[:, :3, 3]
    stems = view.stems if any(r.predictions is not None for r in runs) else []
    for j, i in enumerate(rows.tolist()):
        key = (int(view.approach_index[i]), int(view.approach_number[i]))
        distortion = view.distortion[i] if view.distortion[i].any() else None
        for run, chain, res in zip(runs, chains, out, strict=True):
            if key != chain.key:
                chain.key, chain.guesses, chain.history = key, {}, deque(maxlen=settings.rolling_window)
            predictions = run.predictions
            if predictions is None:
                uv = view.center_px[i]
                if run.noise_px > 0:
                    uv = uv + noise_offsets(evaluation_rng(seed, int(view.frame_id[i]), run.run), len(uv),
                                            run.noise_px)
                have = view.labeled[i]
            else:
                found = predictions.get(stems[i], {})
                uv = np.full((len(features), 2), np.nan)
                for cls, (u, v, _) in found.items():
                    uv[cls] = (u, v)
                have = np.isfinite(uv[:, 0])
            res["frame_id"].append(int(view.frame_id[i]))
            res["distance_m"].append(float(view.distance_m[i]))
            res["truth_m"].append(truth[j])
            res["ptd_receiver_m"].append(view.ptd_receiver_m[i])
            res["has_predictions"].append(predictions is None or stems[i] in predictions)
            start = time.perf_counter()
            poses: dict[str, tuple[NDArray, NDArray] | None] = {}
            few = False
            matches = {}
            for name, mask in masks:
                sel = mask & have
                matches[name] = int(sel.sum())
                if matches[name] < settings.min_matches:
                    few = True
                    continue
                poses[name] = solve_pose(centers[sel], uv[sel], k, settings, chain.guesses.get(name), distortion)
            res["solve_s"].append(time.perf_counter() - start)
            res["matches_receiver"].append(matches["receiver"])
            res["matches_target"].append(matches[target])
            ptd = np.full(3, np.nan)
            reason = "ok"
            receiver_pose, target_pose = poses.get("receiver"), poses.get(target)
            if few:
                reason = "too_few_matches"
                if predictions is not None:
                    stem = stems[i]
                    if stem not in predictions:
                        reason = "no_detections"
                    elif isinstance(predictions, Predictions) and predictions.all_below_conf(stem):
                        reason = "below_conf"
            elif receiver_pose is None or target_pose is None:
                reason = "pnp_failed"
            else:
                ptd = ptd_from_poses(receiver_pose, target_pose)
                if np.linalg.norm(ptd) > settings.max_range_m:
                    reason = "beyond_range"
                elif len(chain.history) >= settings.rolling_min and _outlier(ptd, chain.history, settings):
                    reason = "outlier"
                else:
                    chain.history.append(ptd)
                    chain.guesses = dict(poses)  # only an accepted pose seeds the next frame's solve
            res["ptd_m"].append(ptd)
            res["reason"].append(REASONS.index(reason))


def _outlier(ptd: NDArray[np.float64], history: deque, settings: PnPSettings) -> bool:
    """Beyond ``outlier_sigma`` of the rolling average of the approach's accepted vectors."""
    past = np.array(history)
    sigma = np.maximum(past.std(axis=0), 1e-3)
    return bool(np.any(np.abs(ptd - past.mean(axis=0)) > settings.outlier_sigma * sigma))


def _evaluate_block(dataset: DatasetMeta, positions: NDArray[np.int64], runs: list[Run], seed: int,
                    settings: PnPSettings) -> list[dict[str, NDArray]]:
    """The per-frame results of every run over the frames at ``positions`` (whole approaches,
    in frame order), as arrays."""
    chains = [_Chain() for _ in runs]
    out: list[dict[str, list]] = [{c: [] for c in _COLUMNS} for _ in runs]
    for view, rows in dataset.walk(positions):
        _evaluate_rows(view, rows, runs, chains, seed=seed, settings=settings, out=out)
    return [{c: (np.array(v, dtype=t).reshape(-1, 3) if c in ("ptd_m", "truth_m", "ptd_receiver_m")
                 else np.array(v, dtype=t)) for (c, t), v in zip(_COLUMNS.items(), res.values(), strict=True)}
            for res in out]


def _blocks(index: FrameOrder, attempted: NDArray[np.int64], n: int) -> list[NDArray[np.int64]]:
    """``attempted`` (positions in frame order) cut into about ``n`` blocks of whole approaches."""
    if n <= 1 or len(attempted) < 2:
        return [attempted]
    key = index.approach_index[attempted] * (1 << 32) + index.approach_number[attempted]
    starts = np.flatnonzero(np.r_[True, key[1:] != key[:-1]])  # where an approach begins
    cuts = starts[np.searchsorted(starts, np.linspace(0, len(attempted), n + 1)[1:-1])] if len(starts) > 1 else \
        np.zeros(0, np.int64)
    return [b for b in np.split(attempted, np.unique(cuts)) if len(b)]


def evaluate_runs(dataset: DatasetMeta, runs: list[Run], *, seed: int | None = None,
                  settings: PnPSettings = PnPSettings(), split: str | None = None, workers: int = 1,
                  progress: Progress | None = None) -> list[RunResult]:
    """PtD vectors of every frame (frame order) for each run's 2D points, in one pass over
    the dataset: a loaded view, or an opened source read shard by shard as the frames in
    frame order reach them (one shard per split held at a time). With ``workers`` > 1 the
    approaches are shared among processes in blocks of whole approaches (each approach's
    frames are solved in order, as the rolling average and the extrinsic guess need): the
    results do not depend on ``workers``.

    ``split`` limits the attempts to one split's frames (``val`` when scoring a detector
    on what it did not train on). Returns per run the arrays of :func:`evaluate`."""
    target = _target_object(dataset)
    seed = int(dataset.doc.get("seed", 0)) if seed is None else seed
    rows = dataset.frames(unique=True)
    attempted = np.flatnonzero(np.array([split is None or s == split for s in rows.split], dtype=bool))
    blocks = _blocks(rows, attempted, 4 * workers if workers > 1 else 1)
    progress = progress or NullProgress()
    progress.start(len(attempted), 0)
    parts: list[list[dict[str, NDArray]]] = []
    tasks = [(dataset, block, runs, seed, settings) for block in blocks]
    for block, part in zip(blocks, map_in_order(_evaluate_block, tasks, workers), strict=True):
        parts.append(part)
        progress.advance(len(block))
    progress.close()
    results = []
    for r, run in enumerate(runs):
        out: dict[str, Any] = {c: np.concatenate([p[r][c] for p in parts]) for c in _COLUMNS}
        ptd_m = out["ptd_m"]
        results.append(RunResult(
            frame_id=out["frame_id"], distance_m=out["distance_m"], matches_receiver=out["matches_receiver"],
            matches_target=out["matches_target"], reason=out["reason"], ptd_m=ptd_m, truth_m=out["truth_m"],
            error_m=np.linalg.norm(ptd_m - out["truth_m"], axis=1),
            error_to_drogue_m=np.linalg.norm(ptd_m - out["ptd_receiver_m"], axis=1), solve_s=out["solve_s"],
            missing_predictions=0 if run.predictions is None else int((~out["has_predictions"]).sum()),
            target=target))
    return results


def evaluate(view: DatasetMeta, *, noise_px: float = 0.0, run: int = 0, seed: int | None = None,
             predictions: Mapping | None = None, settings: PnPSettings = PnPSettings(),
             split: str | None = None) -> RunResult:
    """PtD vectors of every frame (frame order) for one source of 2D points
    (:class:`RunResult`).

    ``split`` limits the attempts to one split's frames (``val`` when scoring a
    detector on what it did not train on).
    """
    return evaluate_runs(view, [Run(noise_px, run, predictions)], seed=seed, settings=settings, split=split)[0]


#: Distance bins of the metrics, metres (contact first).
DISTANCE_EDGES: Final = np.array([0.0, 0.5, 2.5, 5.0, 10.0, 15.0, 20.0, 25.0, 30.0, 40.0, 50.0, 60.0, 70.0, 80.0,
                                  90.0, 100.0, 110.0, 120.0])
#: Distances of the README's noise table; a frame counts within +-2.5 m (contact: < 0.5 m).
TABLE_DISTANCES_M: Final = (20.0, 50.0, 120.0)


@dataclass(frozen=True)
class ErrorStats:
    """PtD prediction errors of a set of frames: attempts and successes, reliability (None:
    no attempt) and the successes' error magnitude, metres (None: no success)."""

    attempts: int
    successes: int
    reliability: float | None
    mean_m: float | None
    std_m: float | None
    plus_2sigma_m: float | None
    median_m: float | None
    max_m: float | None

    @classmethod
    def of(cls, errors: NDArray, success: NDArray) -> ErrorStats:
        """The statistics of frames with PtD errors ``errors`` that succeeded where ``success``."""
        e = errors[success]
        return cls(int(success.size), int(success.sum()), float(success.mean()) if success.size else None,
                   float(e.mean()) if e.size else None, float(e.std()) if e.size else None,
                   float(e.mean() + 2 * e.std()) if e.size else None, float(np.median(e)) if e.size else None,
                   float(e.max()) if e.size else None)

    def to_json(self) -> dict:
        """Its JSON form (``evaluation.json``)."""
        return dataclasses.asdict(self)


@dataclass(frozen=True)
class DistanceBin:
    """:class:`ErrorStats` of the frames whose probe-to-drogue distance is in ``[lo_m, hi_m)``."""

    lo_m: float
    hi_m: float
    stats: ErrorStats

    def to_json(self) -> dict:
        """Its JSON form: the bin's edges and its statistics, in one mapping."""
        return {"lo_m": self.lo_m, "hi_m": self.hi_m, **self.stats.to_json()}


@dataclass(frozen=True)
class RunSummary:
    """The metrics of one evaluation run (:func:`summarize`): the target object, overall, per
    distance bin (:data:`DISTANCE_EDGES`), at contact and at the paper's table distances
    (``at``: ``contact``, ``2m``, ...), frames per failure reason (:data:`REASONS`) and the
    mean solve time (ms; None: no frame)."""

    target: str
    overall: ErrorStats
    by_distance: tuple[DistanceBin, ...]
    at: Mapping[str, ErrorStats]
    reasons: Mapping[str, int]
    solve_ms_mean: float | None

    def to_json(self) -> dict:
        """Its JSON form (a run of ``evaluation.json``)."""
        return {"target": self.target, "overall": self.overall.to_json(),
                "by_distance": [b.to_json() for b in self.by_distance],
                "at": {k: v.to_json() for k, v in self.at.items()}, "reasons": dict(self.reasons),
                "solve_ms_mean": self.solve_ms_mean}


def summarize(result: RunResult, settings: PnPSettings = PnPSettings()) -> RunSummary:
    """Metrics of one run: overall, per distance bin, at contact, at the table distances,
    and the failure reasons."""
    d, e, ok = result.distance_m, result.error_m, result.success
    bins = tuple(DistanceBin(float(lo), float(hi), ErrorStats.of(e[(d >= lo) & (d < hi)], ok[(d >= lo) & (d < hi)]))
                 for lo, hi in itertools.pairwise(DISTANCE_EDGES))
    contact = d < settings.contact_m
    at = {"contact": ErrorStats.of(e[contact], ok[contact])}
    for x in TABLE_DISTANCES_M:
        sel = np.abs(d - x) < 2.5
        at[f"{x:g}m"] = ErrorStats.of(e[sel], ok[sel])
    reasons = {r: int((result.reason == i).sum()) for i, r in enumerate(REASONS)}
    solve = result.solve_s
    return RunSummary(result.target, ErrorStats.of(e, ok), bins, at, reasons,
                      float(solve.mean() * 1e3) if solve.size else None)


