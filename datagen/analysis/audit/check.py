"""What every audit check is: its counts and worst offenders (:class:`Check`), the audit's result, and
what the checks share (tolerances, exclusion reasons, reading a label file)."""

from __future__ import annotations

import heapq
import math
from collections.abc import Iterator, Mapping
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Final, Protocol

import numpy as np
from numpy.typing import NDArray

from datagen.analysis.audit.summary import AuditStatistics, Learnability, PoseLearnability
from datagen.analysis.exact import Spill
from datagen.core.errors import shown
from datagen.core.label_boxes import Exclusion, FrameLabels
from datagen.dataset.reader import DatasetMeta, DatasetView
from datagen.dataset.yolo import YOLO_DECIMALS
from datagen.paths import Unreadable, read_bytes

#: The corrected-box centre of a label line may lie this far from the true centre projection.
DRIFT_LIMIT_PX: Final = 1e-3


#: Manifest boxes and centres must match the recomputation this closely.
MANIFEST_TOLERANCE_PX: Final = 1e-6


#: A label line's values may differ from the manifest box by the rounding of
#: :data:`datagen.core.label_boxes.YOLO_DECIMALS` decimals (normalized units).
LINE_TOLERANCE: Final = 0.5 * 10.0 ** -YOLO_DECIMALS + 1e-12


#: A pose keypoint may differ from its true centre projection by this much (normalized units).
POSE_TOLERANCE: Final = 1e-6


#: Offenders listed per check (the worst first).
MAX_OFFENDERS: Final = 20


@dataclass
class Check:
    """One audit check: what it verifies, over how many items, and who failed it."""

    name: str
    description: str
    checked: int = 0
    failures: int = 0
    worst: float | None = None  # the largest error, where the check measures one
    offenders: list[str] = field(default_factory=list)  # "file: what", worst first
    applicable: bool = True
    #: None: any failure fails the check; else the check passes while at least this share passes.
    min_pass_share: float | None = None
    #: (-score, frame order, sequence, text) of every failure; ``row`` (a row of the view
    #: the check ran on) is turned into the frame order by :meth:`ranked`.
    _scored: list[tuple[float, int, int, str]] = field(default_factory=list, repr=False)
    _seq: int = field(default=0, repr=False)

    @property
    def pass_share(self) -> float | None:
        return (self.checked - self.failures) / self.checked if self.checked else None

    @property
    def passed(self) -> bool:
        if self.min_pass_share is None:
            return self.failures == 0
        share = self.pass_share
        return share is None or share >= self.min_pass_share

    def fail(self, where: str, what: str, score: float = math.inf, row: int | None = None,
             seq: int | None = None) -> None:
        """Count a failure; ``row``: the row of the view it is about (offenders of equal
        score are listed in frame order, then in the order they failed, or of ``seq``)."""
        self.failures += 1
        self._scored.append((-score, 0 if row is None else int(row), self._seq if seq is None else seq,
                             shown(f"{where}: {what}")))  # names from the dataset: printed and written escaped
        self._seq += 1

    def ranked(self, rank: NDArray[np.int64]) -> Check:
        """The offenders' rows as positions in the dataset's frame order (``rank[row]``),
        the worst :data:`MAX_OFFENDERS` kept."""
        self._scored = heapq.nsmallest(MAX_OFFENDERS, ((s, int(rank[r]), q, t) for s, r, q, t in self._scored))
        return self

    def merge(self, other: Check) -> Check:
        """Add the counts and offenders of the same check run on other frames."""
        self.checked += other.checked
        self.failures += other.failures
        if other.worst is not None:
            self.worst = other.worst if self.worst is None else max(self.worst, other.worst)
        self._scored = heapq.nsmallest(MAX_OFFENDERS, self._scored + other._scored)
        return self

    def finish(self) -> Check:
        self._scored.sort()
        self.offenders = [text for *_, text in self._scored[:MAX_OFFENDERS]]
        self._scored = []
        return self

    def as_dict(self) -> dict:
        out = {k: v for k, v in asdict(self).items() if not k.startswith("_")}
        out["passed"] = self.passed
        out["pass_share"] = self.pass_share
        return out


# --- the protocol of a group of checks --------------------------------------------------------
@dataclass(frozen=True)
class Recomputed:
    """Some frames' labels recomputed with the labelling context the build used
    (:attr:`datagen.dataset.reader.DatasetMeta.labelling`)."""

    labels: FrameLabels  # the features', the occlusion rule applied
    objects: FrameLabels  # the labeled objects' pose boxes


@dataclass
class GroupPart:
    """What a group of checks found in some frames: its per-frame checks (offenders by the
    view's rows) and the values its dataset-wide part needs (None: none), which the driver
    keeps on disk in the group's stream."""

    checks: list[Check]
    values: dict[str, NDArray] | None = None


#: A group's section of the statistics (a field of :class:`~datagen.analysis.audit.summary.AuditStatistics`).
Section = Learnability | PoseLearnability


@dataclass(frozen=True)
class Finish:
    """What a group's dataset-wide part is given once every frame is checked."""

    merged: Mapping[str, Check]  # every per-frame check, merged over the parts
    spill: Spill  # the parts' values, each group's in its own stream
    top_m: float  # the far end of the statistics' distance bins
    min_learnable: float  # the share of labels that must be learnable


class CheckGroup(Protocol):
    """A group of the audit's checks (one module each): per-frame checks run on each shard's
    rows (or a whole view's) by :meth:`frames`, then :meth:`finish` gives the group's checks
    in report order, with a statistics section where it has one."""

    #: The spill stream of the group's values.
    stream: str

    def applies(self, meta: DatasetMeta) -> bool:
        """Whether the dataset has what the group checks."""
        ...

    def frames(self, view: DatasetView, found: Recomputed) -> GroupPart:
        """The per-frame checks of ``view``'s rows."""
        ...

    def finish(self, meta: DatasetMeta, done: Finish) -> tuple[list[Check], Section | None]:
        """The group's checks, and its section of the statistics (None: none)."""
        ...


@dataclass(frozen=True)
class DriftPlot:
    """What the report's drift figures draw (the numbers are in the statistics)."""

    scatter: NDArray[np.float64]  # (N, 2): distance (m) and drift (px) of every k-th feature in frame order
    boxes: list[tuple[str, dict]]  # per size tag with features: quartiles (q1, med, q3) and whiskers


@dataclass
class AuditResult:
    root: Path
    name: str
    frames: int
    checks: list[Check]
    stats: AuditStatistics  # report.json records their to_json()
    plot: DriftPlot

    @property
    def passed(self) -> bool:
        return all(c.passed for c in self.checks)


# --- label files --------------------------------------------------------------------------
def read_label_file(path: Path, max_bytes: int) -> tuple[list[str], str | None]:
    """The non-blank lines of a label file, or why there are none (a file over ``max_bytes``,
    :attr:`~datagen.dataset.limits.ReadLimits.label_bytes`, is not read)."""
    try:
        text = read_bytes(path, "a label file", max_bytes).decode("utf-8")
    except Unreadable as exc:
        return [], "missing" if exc.problem == "no such file" else exc.problem
    except UnicodeDecodeError as exc:
        return [], f"unreadable (not UTF-8 text at byte {exc.start})"
    return [line for line in text.splitlines() if line.strip()], None


def label_files(view: DatasetView, paths: list[str | None], check: Check,
                 kind: str = "label file") -> Iterator[tuple[int, str, list[str]]]:
    """``(row, path, non-empty lines)`` of each frame's label file in ``paths``; a frame whose
    manifest names none, or whose file cannot be read, fails ``check`` instead."""
    for b, rel in enumerate(paths):
        if rel is None:
            check.fail(f"{view.manifest_file[b]} frame {view.frame_id[b]}", f"no {kind} named", row=b)
            continue
        problem = view.folder.problem(rel)
        rows, problem = ([], problem) if problem else read_label_file(view.root / rel, view.limits.label_bytes)
        if problem:
            check.fail(rel, problem, row=b)
            continue
        yield b, rel, rows


#: Exclusion code -> the reason a manifest records (None: labeled).
REASONS: Final = np.array([None if e is Exclusion.NONE else Exclusion(e).reason for e in range(max(Exclusion) + 1)],
                           dtype=object)


def nan_error(stored: NDArray[np.float64], fresh: NDArray[np.float64]) -> NDArray[np.float64]:
    """``(...)`` the largest absolute difference over the last axis; 0 where both are NaN (a
    missing value on both sides), inf where only one is."""
    both_nan = np.isnan(stored) & np.isnan(fresh)
    err = np.where(both_nan, 0.0, np.abs(stored - fresh))
    return np.where(np.isnan(err), np.inf, err).max(axis=-1)
