"""The folders the reading commands write their reports into (``audit``, ``evaluate``,
``preview``): which files each writer makes, the record it keeps of them, and which
folders it may write into.

A report folder is the command's own: new, empty, or holding nothing but the command's
earlier output (its record and the files the record lists, datagen's temporaries
aside). A folder with anything else in it, a user's ``report.html`` say, is refused
before any work starts, as ``datagen export`` refuses a folder that is not empty; so
that ``--out`` never overwrites a file datagen did not write there. ``--overwrite`` of a
build removes a report's files by the same record, and only names of the writer's own
form.
"""

from __future__ import annotations

import os
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Final

from datagen.atomic import is_temporary
from datagen.config.inputs import read_json
from datagen.core.errors import DatagenError, shown
from datagen.paths import report_folder

__all__ = ["RECORD_BYTES", "REPORTS", "ReportKind", "claim_report_folder", "record_of", "recorded_files"]

#: The largest report record read, bytes (a preview of the most frames one run may draw lists
#: about 10,000 names).
RECORD_BYTES: Final = 4 * 2**20


@dataclass(frozen=True)
class ReportKind:
    """One command's report: its default folder in the dataset, its record (written last,
    listing every file the run wrote) and the names its writer makes."""

    command: str
    folder: str  # the default folder, inside the dataset
    record: str  # the record, relative to the folder
    names: re.Pattern  # every other file the writer makes, relative to the folder

    def owns(self, rel: str) -> bool:
        """Whether ``rel`` (relative to the folder) is a name this writer makes."""
        return rel == self.record or self.names.fullmatch(rel) is not None


_EVALUATION: Final = re.compile(r"results\.parquet|detections\.parquet|plots/[a-z0-9_]+\.png")
#: The reading commands' reports, by command (``evaluate --predictions`` has a folder of its
#: own, so that scoring a detector keeps the truth runs' report).
REPORTS: Final = {kind.command: kind for kind in (
    ReportKind("audit", "audit", "report.json",
               re.compile(r"report\.html|plots/[a-z0-9_]+\.png|sheets/[0-9]{8}\.jpg")),
    ReportKind("evaluate", "evaluation", "evaluation.json", _EVALUATION),
    ReportKind("evaluate --predictions", "evaluation-predictions", "evaluation.json", _EVALUATION),
    ReportKind("preview", "preview", "preview.json", re.compile(r"[0-9]{8}\.jpg")),
)}


def record_of(kind: ReportKind, folder: Path) -> list[str] | None:
    """The files ``kind``'s record in ``folder`` lists, names of the writer's own form only;
    None where there is no such record: missing, a link (never read through), not a regular
    file, or not JSON of a record (a mapping with a list of ``files``)."""
    record = Path(folder) / kind.record
    if record.is_symlink():
        return None
    try:
        doc = read_json(record, "report record", RECORD_BYTES)
    except DatagenError:
        return None
    files = doc.get("files") if isinstance(doc, dict) else None
    if not isinstance(files, list):
        return None
    return [f for f in files if isinstance(f, str) and kind.names.fullmatch(f)]


def recorded_files(kind: ReportKind, folder: Path) -> list[str]:
    """The files ``kind``'s record in ``folder`` lists (none without a record,
    :func:`record_of`). A report keeps listing an earlier run's files, so that
    ``--overwrite`` removes them."""
    return record_of(kind, folder) or []


def claim_report_folder(kind: ReportKind, folder: Path, dataset: Path, flag: str = "--out", *,
                        make: bool = True) -> Path:
    """``folder`` as ``kind``'s report folder (:func:`datagen.paths.report_folder`: real
    folders, no link on the way), once it is new, empty or holds only ``kind``'s earlier
    output; otherwise one line naming the first file that is not, and nothing written.
    ``make`` False: only check, before the command's work starts."""
    folder = report_folder(folder, dataset, flag, make=False)
    if folder.is_dir():
        recorded = record_of(kind, folder)
        listed, has_record = set(recorded or ()), recorded is not None
        for rel in _entries(folder):
            if is_temporary(Path(rel).name) or (has_record and (rel == kind.record or rel in listed)):
                continue
            if os.path.islink(folder / rel):
                what = "a symbolic link"
            elif rel == kind.record or not kind.owns(rel):
                what = "not a record datagen can read" if rel == kind.record else "a file datagen did not write"
            else:
                what = f"a file no {kind.record} of datagen {kind.command} lists"
            raise DatagenError(f"{flag}: {folder}: holds {shown(rel)}, {what}; datagen {kind.command} writes "
                               "only into a new or empty folder, or over its own earlier report (move the file or "
                               "choose another folder)")
    return report_folder(folder, dataset, flag, make=make)


def _entries(folder: Path, limit: int = 100_000):
    """The files and links under ``folder`` (relative, links not followed; folders that
    hold something are not entries themselves, empty ones are), at most ``limit`` of them
    before the walk stops with a refusal (a folder of more is not a report)."""
    seen = 0
    for dirpath, dirnames, filenames in os.walk(folder, onerror=_raise):
        names = list(filenames) + [d for d in dirnames if os.path.islink(os.path.join(dirpath, d))]
        dirnames[:] = sorted(d for d in dirnames if not os.path.islink(os.path.join(dirpath, d)))
        for name in sorted(names):
            seen += 1
            if seen > limit:
                raise DatagenError(f"{folder}: more than {limit:,} files; not a report folder (choose another)")
            yield os.path.relpath(os.path.join(dirpath, name), folder)


def _raise(exc: OSError) -> None:
    raise DatagenError(f"{exc.filename}: cannot read the folder ({exc.strerror})")
