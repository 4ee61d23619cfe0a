"""The audit's statistics: how far the tight box centre lies from the true centre projection
(by distance, size and obliqueness: paper Fig. 8), exclusions, visibility, PnP coverage and the
appearance draws, exactly as numpy gives them on the whole dataset's values in frame order, from
values spilled to disk shard by shard."""

from __future__ import annotations

import itertools
import math
from collections import Counter
from dataclasses import dataclass
from typing import Any, Final

import numpy as np
from numpy.typing import NDArray

from datagen.analysis.audit.box_geometry import feature_normals, obliqueness_deg, tight_centre_drift_px
from datagen.analysis.audit.check import DriftPlot
from datagen.analysis.audit.summary import (
    AppearanceColumn,
    AuditStatistics,
    DistanceCoverage,
    DriftBin,
    DriftStatistics,
    DriftSummary,
    PnPCoverage,
    Visibility,
)
from datagen.analysis.exact import (
    OrderedSum,
    Spill,
    median,
    median_positions,
    order_statistics,
    percentile,
    percentile_positions,
)
from datagen.core.label_boxes import Exclusion, FrameLabels
from datagen.dataset.columns import APPEARANCE
from datagen.dataset.reader import DatasetMeta, DatasetView

#: PnP needs at least this many labeled features of an object in a frame.
PNP_MIN_FEATURES: Final = 3


# --- statistics ------------------------------------------------------------------------------
@dataclass(frozen=True)
class StatisticsPart:
    """What the statistics keep of some rows (:func:`statistics_part`): per feature in view its
    drift (px), distance (m), obliqueness (degrees), class and its frame's ``rank`` in the
    dataset's frame order; counts of exclusions and of labeled features per class; per frame
    the labeled features of each object and the distance; the labeled features' visible
    fractions, the centres seen and visible (counts); and the appearance draws
    (:func:`_appearance_part`)."""

    drift: NDArray[np.float64]
    distance: NDArray[np.float64]
    obliqueness: NDArray[np.float64]
    cls: NDArray[np.int16]
    rank: NDArray[np.int32]
    exclusions: NDArray[np.int64]
    labeled_per_class: NDArray[np.int64]
    labeled_per_object: NDArray[np.int32]
    visible_fraction: NDArray[np.float64]
    centre_visible: tuple[int, int]
    frame_distance: NDArray[np.float64]
    appearance: dict[str, dict]


def statistics_part(view: DatasetView, labels: FrameLabels, rank: NDArray[np.int64]) -> StatisticsPart:
    """What the statistics need of ``view``'s rows: the drift, distance, obliqueness and class
    of each feature in view (with its frame's position ``rank`` in the dataset's frame
    order, so that the merged values keep the order a whole-dataset view has), and counts."""
    features = view.features
    k = view.intrinsics
    in_image = labels.exclusion != Exclusion.BEHIND_CAMERA
    tight = labels.tight_xyxy
    inside = in_image & (tight[..., 0] >= 0) & (tight[..., 1] >= 0) & (tight[..., 2] <= k.width) \
        & (tight[..., 3] <= k.height)
    drift = tight_centre_drift_px(tight, labels.center_px)
    cam_from_model = view.cam_from_objects()[:, features.object_index]
    oblique = obliqueness_deg(cam_from_model, feature_normals(features.points_model, features.n_points),
                              features.center_model)
    rows, cls = np.nonzero(inside)
    vis = view.visible_fraction[labels.labeled]
    cv = view.center_visible[labels.labeled]
    cv = cv[np.isfinite(cv)]
    return StatisticsPart(
        drift=drift[inside], distance=view.distance_m[rows], obliqueness=oblique[inside],
        cls=cls.astype(np.int16), rank=rank[rows].astype(np.int32),
        exclusions=np.bincount(labels.exclusion.ravel().astype(np.int64), minlength=max(Exclusion) + 1),
        labeled_per_class=labels.labeled.sum(axis=0),
        labeled_per_object=np.stack([labels.labeled[:, features.object_index == j].sum(axis=1)
                                     for j in range(len(features.objects))], axis=1).astype(np.int32),
        visible_fraction=vis[np.isfinite(vis)],
        centre_visible=(int(cv.size), int((cv == 1.0).sum())),
        frame_distance=view.distance_m.copy(),
        appearance=_appearance_part(view.appearance, rank),
    )


class Totals:
    """What the statistics keep in memory of every :func:`statistics_part`: counts; the
    per-feature, per-frame and per-draw values go to the spill."""

    def __init__(self, classes: int) -> None:
        self.exclusions = np.zeros(max(Exclusion) + 1, dtype=np.int64)
        self.per_class = np.zeros(classes, dtype=np.int64)
        self.visible = np.zeros(10, dtype=np.int64)  # histogram of labeled features' visible fractions
        self.visible_n = self.visible_full = self.cv_count = self.cv_ones = 0
        self.appearance: dict[str, dict] = {}  # column -> frames, and counts per value (names, flags)

    def add(self, spill: Spill, part: StatisticsPart) -> None:
        spill.add("drift", part.rank, drift=part.drift, distance=part.distance, obliqueness=part.obliqueness,
                  cls=part.cls)
        spill.add("frames", None, distance=part.frame_distance, labeled=part.labeled_per_object)
        self.exclusions += part.exclusions
        self.per_class += part.labeled_per_class
        vis = part.visible_fraction
        self.visible += np.histogram(vis, bins=10, range=(0.0, 1.0))[0]
        self.visible_n += vis.size
        self.visible_full += int((vis >= 1.0).sum())
        self.cv_count += part.centre_visible[0]
        self.cv_ones += part.centre_visible[1]
        for name, column in part.appearance.items():
            mine = self.appearance.setdefault(name, {"frames": 0})
            mine["frames"] += column["frames"]
            if "values" in column:
                mine["values"] = mine.get("values", Counter()) + column["values"]
            elif column["frames"]:
                spill.add(f"appearance.{name}", column["rank"], value=column["numbers"])


#: Drift groups (:func:`_drift_groups`): all features, then per distance bin, size tag and
#: obliqueness bin from these offsets.
_ALL, _BY_DISTANCE, _BY_SIZE, _BY_OBLIQUENESS = 0, 1, 100_000, 200_000


#: Bins of the drift by view obliqueness, degrees.
OBLIQUENESS_EDGES_DEG: Final = np.arange(0.0, 91.0, 15.0)


def bin_of(values: NDArray[np.float64], edges: NDArray[np.float64]) -> NDArray[np.int64]:
    """The bin ``k`` with ``edges[k] <= value < edges[k + 1]`` of each value; -1 outside."""
    k = np.searchsorted(edges, values, side="right") - 1
    return np.where((k >= 0) & (k < len(edges) - 1), k, -1)


def _drift_groups(part: dict, distance_edges: NDArray, size_of_class: NDArray[np.int64]) -> list[NDArray[np.int64]]:
    """Each drift value's group in each grouping (-1: none): all, its distance bin, its
    feature's size tag, its obliqueness bin."""
    def offset(k: NDArray[np.int64], base: int) -> NDArray[np.int64]:
        return np.where(k >= 0, k + base, -1)

    return [np.full(len(part["drift"]), _ALL, dtype=np.int64),
            offset(bin_of(part["distance"], distance_edges), _BY_DISTANCE),
            _size_group(part["cls"], size_of_class),
            offset(bin_of(part["obliqueness"], OBLIQUENESS_EDGES_DEG), _BY_OBLIQUENESS)]


def _size_group(cls: NDArray, size_of_class: NDArray[np.int64]) -> NDArray[np.int64]:
    """Each drift value's size-tag group (:func:`_drift_groups`)."""
    return size_of_class[cls.astype(np.int64)] + _BY_SIZE


#: Drift values the report's scatter plot shows at most (every k-th in frame order).
SCATTER_POINTS: Final = 20000


def _drift_statistics(spill: Spill, distance_edges: NDArray, size_of_class: NDArray[np.int64]) -> dict:
    """Per drift group: count, mean, median, p95 and max, exactly as numpy gives them on the
    group's values in frame order, and what the plots need (quartiles and whiskers per size
    tag, every k-th feature's distance and drift): from the spilled ``drift`` stream."""
    columns = ("drift", "distance", "obliqueness", "cls")
    count: Counter = Counter()
    nans: Counter = Counter()
    top: dict[int, float] = {}
    for part in spill.parts("drift", *columns):
        d = part["drift"]
        for groups in _drift_groups(part, distance_edges, size_of_class):
            for g in np.unique(groups[groups >= 0]).tolist():
                mine = d[groups == g]
                count[g] += mine.size
                nans[g] += int(np.isnan(mine).sum())
                top[g] = float(np.maximum(top[g], mine.max())) if g in top else float(mine.max())
    sums = {g: OrderedSum(n) for g, n in count.items()}
    n_all = count[_ALL]
    pick = np.linspace(0, n_all - 1, min(n_all, SCATTER_POINTS)).astype(int) if n_all else np.zeros(0, dtype=int)
    scatter, seen = [], 0
    for part in spill.ordered("drift", *columns):
        d = part["drift"]
        for groups in _drift_groups(part, distance_edges, size_of_class):
            order = np.argsort(groups, kind="stable")
            present = np.unique(groups)
            bounds = np.searchsorted(groups[order], present)
            for g, piece in zip(present.tolist(), np.split(order, bounds[1:]), strict=True):
                if g >= 0:
                    sums[g].feed(d[piece])
        mine = pick[(pick >= seen) & (pick < seen + d.size)] - seen
        scatter.append(np.stack([part["distance"][mine], d[mine]], axis=1))
        seen += d.size
    quartiles = {g for g in count if _BY_SIZE <= g < _BY_OBLIQUENESS}
    wanted = {g: set(median_positions(n)) | set(percentile_positions(n, 95))
              | (set(percentile_positions(n, 25)) | set(percentile_positions(n, 75)) if g in quartiles else set())
              for g, n in count.items() if not nans[g]}

    def chunks():
        for part in spill.parts("drift", *columns):
            for groups in _drift_groups(part, distance_edges, size_of_class):
                yield groups, part["drift"]

    found = order_statistics(chunks, wanted)
    out: dict[int, dict[str, Any]] = {}
    for g, n in count.items():
        def stat(k: int, g: int = g) -> float:
            return found[(g, k)]

        nan = bool(nans[g])
        out[g] = {"count": n, "mean": sums[g].mean(), "median": math.nan if nan else median(n, stat),
                  "p95": math.nan if nan else percentile(n, 95, stat), "max": top[g]}
        if g in quartiles and not nan:
            out[g]["box"] = {"q1": percentile(n, 25, stat), "med": out[g]["median"], "q3": percentile(n, 75, stat)}
    _whiskers(spill, out, size_of_class)
    return {"groups": out, "scatter": np.concatenate(scatter) if scatter else np.zeros((0, 2))}


def _whiskers(spill: Spill, groups: dict[int, dict], size_of_class: NDArray[np.int64]) -> None:
    """Matplotlib's box whiskers (the extreme values within 1.5 IQR of the quartiles) of the
    size groups' boxes."""
    boxes = {g: v["box"] for g, v in groups.items() if "box" in v}
    for box in boxes.values():
        iqr = box["q3"] - box["q1"]
        box["lo"], box["hi"] = box["q1"] - 1.5 * iqr, box["q3"] + 1.5 * iqr
        box["whislo"], box["whishi"] = math.inf, -math.inf
    for part in spill.parts("drift", "drift", "cls") if boxes else ():
        d = part["drift"]
        size_group = _size_group(part["cls"], size_of_class)
        for g, box in boxes.items():
            mine = d[size_group == g]
            low, high = mine[mine >= box["lo"]], mine[mine <= box["hi"]]
            if low.size:
                box["whislo"] = min(box["whislo"], float(low.min()))
            if high.size:
                box["whishi"] = max(box["whishi"], float(high.max()))
    for box in boxes.values():
        box["whislo"], box["whishi"] = min(box["whislo"], box["q1"]), max(box["whishi"], box["q3"])
        del box["lo"], box["hi"]


@dataclass(frozen=True)
class Statistics:
    """The statistics of a dataset (:func:`statistics`): the group sections and the
    appearance are added to ``summary`` when they are done."""

    summary: AuditStatistics
    plot: DriftPlot
    top_m: float  # the far end of the distance bins (a multiple of 10 m)


def statistics(meta: DatasetMeta, spill: Spill, totals: Totals) -> Statistics:
    """The statistics of every shard's :func:`statistics_part` (``totals`` and ``spill``),
    the same numbers numpy gives on the whole dataset's values in frame order."""
    features = meta.features
    frames = spill.rows["frames"]
    far = np.max([p["distance"].max() for p in spill.parts("frames", "distance")]) if frames else 0.0
    top = max(10.0, float(np.ceil(far / 10.0) * 10.0)) if frames else 10.0
    tags = sorted(set(features.size))
    size_of_class = np.array([tags.index(t) for t in features.size], dtype=np.int64)
    distance_edges = np.arange(0.0, top + 10.0, 10.0)
    drift = _drift_statistics(spill, distance_edges, size_of_class)
    groups = drift["groups"]

    def summary(g: int) -> DriftSummary:
        v = groups.get(g)
        return DriftSummary(0) if v is None else DriftSummary(v["count"], v["mean"], v["median"], v["p95"], v["max"])

    def binned(base: int, edges: NDArray) -> tuple[DriftBin, ...]:
        return tuple(DriftBin(float(lo), float(hi), summary(base + k))
                     for k, (lo, hi) in enumerate(itertools.pairwise(edges)))

    coverage_edges = np.arange(0.0, top + 5.0, 5.0)
    coverage = np.zeros(len(coverage_edges) - 1, dtype=np.int64)
    # per object: how many frames have each count of labeled features (at most every feature)
    labeled = np.zeros((len(features.objects), len(features) + 1), dtype=np.int64)
    for part in spill.parts("frames", "distance", "labeled"):
        coverage += np.histogram(part["distance"], bins=coverage_edges)[0]
        for j, counts in enumerate(labeled):
            counts += np.bincount(part["labeled"][:, j], minlength=counts.size)
    pnp: dict[str, PnPCoverage] = {}
    for obj, counts in zip(features.objects, labeled, strict=True):
        cum = np.cumsum(counts)
        below = int(counts[:PNP_MIN_FEATURES].sum())
        def labeled_at(k: int, cum: NDArray[np.int64] = cum) -> float:
            return float(np.searchsorted(cum, k, side="right"))

        pnp[obj] = PnPCoverage(below, below / frames if frames else 0.0,
                               median(frames, labeled_at) if frames else 0.0)
    per_class, exclusions = totals.per_class, totals.exclusions
    stats = AuditStatistics(
        drift=DriftStatistics(
            overall=summary(_ALL),
            by_distance_m=binned(_BY_DISTANCE, distance_edges),
            by_size={(tag or "untagged"): summary(_BY_SIZE + i) for i, tag in enumerate(tags)},
            by_obliqueness_deg=binned(_BY_OBLIQUENESS, OBLIQUENESS_EDGES_DEG),
        ),
        labels_per_class={features.name[i]: int(per_class[i]) for i in range(len(features))},
        exclusions={r.reason or "labeled": int(exclusions[r]) for r in Exclusion},
        visibility=Visibility(
            labeled_features_rendered=totals.visible_n,
            visible_fraction_histogram=totals.visible.tolist(),
            share_fully_visible=totals.visible_full / totals.visible_n if totals.visible_n else None,
            # centre_visible is 1 or 0 where rendered: the mean is the share of ones
            share_centre_visible=totals.cv_ones / totals.cv_count if totals.cv_count else None,
        ),
        pnp=pnp,
        coverage=DistanceCoverage(coverage_edges.tolist(), coverage.tolist()),
        appearance={},
    )
    boxes = [((tag or "untagged"), groups[_BY_SIZE + i]["box"]) for i, tag in enumerate(tags)
             if "box" in groups.get(_BY_SIZE + i, {})]
    return Statistics(stats, DriftPlot(drift["scatter"], boxes), top)


#: Bins of the appearance section's histograms.
APPEARANCE_BINS: Final = 10


def _appearance_part(columns: dict[str, Any], rank: NDArray[np.int64]) -> dict[str, dict]:
    """Per appearance column of some rows (:func:`datagen.dataset.columns.column_values`: floats
    NaN where not drawn, other values None): how many drew it, and the draws (counts per value
    for names and flags; for numbers the values with their frames' ``rank``)."""
    out: dict[str, dict] = {}
    for name, column in columns.items():
        if isinstance(column, np.ndarray):
            drawn_rows = ~np.isnan(column.reshape(len(column), -1)).all(axis=1)
            out[name] = {"frames": int(drawn_rows.sum()), "numbers": column[drawn_rows].reshape(-1),
                         "rank": rank[drawn_rows]}
            continue
        rows = [i for i, v in enumerate(column) if v is not None]
        drawn = [column[i] for i in rows]
        if drawn and isinstance(drawn[0], (bool, str)):
            out[name] = {"frames": len(drawn), "values": Counter(str(v).lower() if isinstance(v, bool) else v
                                                                 for v in drawn)}
        else:
            out[name] = {"frames": len(drawn), "numbers": np.asarray(drawn, dtype=np.float64).reshape(-1),
                         "rank": rank[np.asarray(rows, dtype=np.int64)]}
    return out


def appearance_finish(spill: Spill, columns: dict[str, dict]) -> dict[str, dict[str, AppearanceColumn]]:
    """The appearance section: per dimension (:data:`datagen.dataset.columns.APPEARANCE`) and
    column, how many frames drew it and the distribution of the draws (a histogram of
    :data:`APPEARANCE_BINS` bins for numbers, counts per value for names and flags). A
    column no frame drew (its randomizer off) has ``frames`` 0. ``columns``: the counts
    (:class:`Totals`); the numbers are in ``spill``'s streams ``appearance.<column>``."""
    out: dict[str, dict[str, AppearanceColumn]] = {}
    for dimension, names in APPEARANCE.items():
        section = {}
        for name in names:
            if name not in columns:
                continue
            frames = columns[name]["frames"]
            if "values" in columns[name]:
                section[name] = AppearanceColumn(frames, values=dict(sorted(columns[name]["values"].items())))
            elif frames:
                section[name] = AppearanceColumn(frames, **_number_summary(spill, f"appearance.{name}"))
            else:
                section[name] = AppearanceColumn(frames)
        out[dimension] = section
    return out


#: The largest magnitude a histogram holds: a manifest's value beyond it (only a tampered one
#: has such) is counted at this bound, so that no range or bin width overflows.
HISTOGRAM_BOUND: Final = float(np.finfo(np.float64).max / 4)


def _histogrammable(values: NDArray) -> NDArray[np.float64]:
    """The finite values, clipped to +-:data:`HISTOGRAM_BOUND`."""
    values = np.asarray(values, dtype=np.float64)
    return np.clip(values[np.isfinite(values)], -HISTOGRAM_BOUND, HISTOGRAM_BOUND)


def histogram_range(lo: float, hi: float, bins: int = APPEARANCE_BINS) -> tuple[float, float]:
    """``(lo, hi)``, or ``(lo, lo + max(1, |lo|))`` where ``bins`` bins of it would not have
    increasing edges (equal values, or values a few ulps apart: numpy refuses such a range;
    the sea's wave slope variance of a 4-frame build was one value and its neighbour)."""
    edges = np.linspace(lo, hi, bins + 1)
    return (lo, hi) if hi > lo and bool(np.all(np.diff(edges) > 0)) else (lo, lo + max(1.0, abs(lo)))


def _number_summary(spill: Spill, stream: str) -> dict:
    """Min, max, mean (in frame order) and a histogram of a spilled stream's finite values."""
    n, lo, hi = 0, math.inf, -math.inf
    for part in spill.parts(stream, "value"):
        v = _histogrammable(part["value"])
        if v.size:
            n, lo, hi = n + v.size, min(lo, float(v.min())), max(hi, float(v.max()))
    if not n:
        return {}
    total = OrderedSum(n)
    for part in spill.ordered(stream, "value"):
        total.feed(_histogrammable(part["value"]))
    counts = np.zeros(APPEARANCE_BINS, dtype=np.int64)
    for part in spill.parts(stream, "value"):
        counts_, edges = np.histogram(_histogrammable(part["value"]), bins=APPEARANCE_BINS,
                                      range=histogram_range(lo, hi))
        counts += counts_
    return {"min": lo, "max": hi, "mean": total.mean(), "edges": edges.tolist(), "histogram": counts.tolist()}
