"""The evaluation's outputs: ``evaluation.json`` (settings and each run's metrics),
``results.parquet`` (a row per frame and run) and plots in the style of the
paper's Figs 14-17.

``evaluation.json`` is written last and lists every file the evaluation wrote
(``files``): the record ``--overwrite`` reads to remove them, and nothing else.
"""

from __future__ import annotations

import dataclasses
import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pyarrow as pa

from datagen.analysis.detections import DetectionScores, DetectorSummary, summarize_detections
from datagen.analysis.evaluate import DISTANCE_EDGES, REASONS, PnPSettings, RunResult, RunSummary, summarize
from datagen.atomic import write_parquet, write_text
from datagen.dataset.reader import FrameOrder
from datagen.dataset.reports import REPORTS, claim_report_folder
from datagen.paths import real_folder

__all__ = ["WrittenEvaluation", "write_evaluation"]


@dataclass(frozen=True)
class WrittenEvaluation:
    """What :func:`write_evaluation` wrote (``files``: ``json``, ``parquet`` and each plot) and
    the summaries it wrote there: each run's, and the detector's (None: no predictions)."""

    files: dict[str, Path]
    summaries: list[RunSummary]
    detector: DetectorSummary | None


def write_evaluation(view: FrameOrder, runs: list[tuple[dict, RunResult]], out: Path,
                     settings: PnPSettings = PnPSettings(), detector: DetectionScores | None = None
                     ) -> WrittenEvaluation:
    """``evaluation.json`` (settings and each run's metrics), ``results.parquet`` (one row
    per frame and run) and PNG plots in the style of the paper's Figs 14-17.

    Args:
        runs: ``(source, result)`` pairs; ``source`` describes the 2D points, e.g.
            ``{"source": "truth", "noise_px": 0.5}``.
        detector: the detections scored against the true centres (with predictions):
            ``evaluation.json`` gains a ``detector`` section, ``detections.parquet`` holds
            its rows and two plots show it against distance and per class.
    """
    from datagen.report.plots import plot_detector, plot_evaluation

    kind = REPORTS["evaluate" if detector is None else "evaluate --predictions"]
    out = claim_report_folder(kind, out, view.root)
    real_folder(out / "plots")
    summaries = [summarize(result, settings) for _, result in runs]
    doc = {"dataset": str(view.root), "name": view.doc.get("name"), "frames": len(view),
           "settings": dataclasses.asdict(settings), "reasons": list(REASONS),
           "runs": [{**source, **s.to_json()} for (source, _), s in zip(runs, summaries, strict=True)]}
    tables = []
    for source, r in runs:
        n = len(r)
        tables.append(pa.table({
            "source": pa.array([source["source"]] * n),
            "noise_px": pa.array([float(source.get("noise_px", math.nan))] * n),
            "frame_id": pa.array(r.frame_id),
            "distance_m": pa.array(r.distance_m),
            "matches_receiver": pa.array(r.matches_receiver),
            "matches_target": pa.array(r.matches_target),
            "success": pa.array(r.success),
            "reason": pa.array([REASONS[i] for i in r.reason]),
            "ptd_m": pa.FixedSizeListArray.from_arrays(pa.array(r.ptd_m.ravel()), 3),
            "truth_m": pa.FixedSizeListArray.from_arrays(pa.array(r.truth_m.ravel()), 3),
            "error_m": pa.array(r.error_m),
            "error_to_drogue_m": pa.array(r.error_to_drogue_m),
            "solve_s": pa.array(r.solve_s),
        }))
    write_parquet(out / "results.parquet", pa.concat_tables(tables), compression="zstd")
    plots = plot_evaluation(runs, summaries, out / "plots", name=str(view.doc.get("name", "")))
    files = ["results.parquet"]
    scores = None
    if detector is not None:
        scores = summarize_detections(detector, DISTANCE_EDGES)
        doc["detector"] = scores.to_json()
        write_parquet(out / "detections.parquet", _detections_table(detector), compression="zstd")
        files.append("detections.parquet")
        plots.update(plot_detector(scores, out / "plots", name=str(view.doc.get("name", ""))))
    # evaluation.json last: the record of every file the evaluation wrote (``files``, relative to
    # its folder), which --overwrite removes and nothing else.
    doc["files"] = [*files, *(str(p.relative_to(out)) for p in plots.values())]
    write_text(out / "evaluation.json", json.dumps(doc, indent=2) + "\n")
    return WrittenEvaluation({"json": out / "evaluation.json", "parquet": out / "results.parquet", **plots},
                             summaries, scores)


def _detections_table(s: DetectionScores) -> pa.Table:
    """One row per (frame, class) labeled or detected (``datagen.analysis.detections``)."""
    def pairs(values):  # a missing vector is a null, never NaNs
        missing = ~np.isfinite(values).all(axis=1)
        return pa.FixedSizeListArray.from_arrays(pa.array(np.where(missing[:, None], 0.0, values).ravel()), 2,
                                                 mask=pa.array(missing))

    return pa.table({
        "frame_id": pa.array(s.frame_id),
        "class_id": pa.array(s.class_id),
        "class_name": pa.array([s.names[c] for c in s.class_id.tolist()]),
        "distance_m": pa.array(s.distance_m),
        "labeled": pa.array(s.labeled),
        "detected": pa.array(s.detected),
        "matched": pa.array(s.matched),
        "conf": pa.array(s.conf, from_pandas=True),
        "error_px": pa.array(s.error_px, from_pandas=True),
        "error_uv_px": pairs(s.error_uv),
        "parallax_uv_px": pairs(s.parallax_uv),
        "along_parallax_px": pa.array(s.along_parallax_px, from_pandas=True),
    })
