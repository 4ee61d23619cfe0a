"""The audit's report: ``report.json`` (for gating in CI), the plots, and a
self-contained ``report.html`` with plots and overlays embedded.

``report.json`` is written last and lists every file the report wrote (``files``):
it is the record ``--overwrite`` reads to remove them, and nothing else.
"""

from __future__ import annotations

import base64
import html
import json
import re
from collections.abc import Iterable
from pathlib import Path

import numpy as np

from datagen.analysis.audit import AuditResult
from datagen.analysis.audit.summary import AppearanceColumn, DriftBin, DriftSummary, Learnability, PoseLearnability
from datagen.atomic import write_image, write_text
from datagen.core.label_boxes import FrameLabels
from datagen.dataset.reader import DatasetMeta, DatasetView
from datagen.dataset.reports import REPORTS, claim_report_folder, recorded_files
from datagen.paths import real_folder

__all__ = ["report_document", "write_report"]


# --- the report --------------------------------------------------------------------------------
def colour_key_html() -> str:
    """The overlays' colour key: a swatch and a name for each colour the sheets draw, from
    their own palette (:data:`datagen.report.overlays.COLOURS`)."""
    from datagen.report.overlays import COLOURS, REGION

    def swatch(bgr: tuple[int, int, int]) -> str:
        b, g, r = bgr
        return (f'<span class="swatch" style="display:inline-block;width:0.9em;height:0.9em;'
                f'background:rgb({r},{g},{b});border:1px solid #444;vertical-align:middle"></span>')

    items = [*COLOURS.items(), ("object region", REGION)]
    return "<p>Colours of the sheets: " + "; ".join(f"{swatch(c)} {name}" for name, c in items) + ".</p>"


def report_document(result: AuditResult) -> dict:
    """report.json: machine-readable, for gating in CI (``passed`` and each check's)."""
    return {
        "dataset": str(result.root),
        "name": result.name,
        "frames": result.frames,
        "passed": result.passed,
        "checks": [c.as_dict() for c in result.checks],
        "stats": result.stats.to_json(),
    }


def write_report(result: AuditResult, dataset: DatasetMeta, out: Path, *,
                 frames: Iterable[tuple[DatasetView, int, FrameLabels]] = ()) -> dict[str, Path]:
    """Write report.json, plots/*.png and a self-contained report.html into ``out``
    (``dataset``: what was audited; ``frames``: the frames to draw, ``(view, row, labels)``
    as :func:`datagen.analysis.audit.frames.frames_to_draw` gives them)."""
    import cv2

    from datagen.report.overlays import draw_sheet
    from datagen.report.plots import plot_audit

    out = claim_report_folder(REPORTS["audit"], out, dataset.root)
    plots = plot_audit(result.stats, result.plot, real_folder(out / "plots"))

    def data_uri(data: bytes, kind: str) -> str:
        return f"data:image/{kind};base64,{base64.b64encode(data).decode()}"

    esc = html.escape
    rows = []
    for c in result.checks:
        status = "n/a" if not c.applicable else ("pass" if c.passed else "FAIL")
        offenders = "".join(f"<li><code>{esc(o)}</code></li>" for o in c.offenders)
        worst = "" if c.worst is None else f"{c.worst:.3g}"
        rows.append(f"<tr class='{status.lower().replace('/', '')}'><td>{esc(c.name)}</td><td>{status}</td>"
                    f"<td>{c.checked}</td><td>{c.failures}</td><td>{worst}</td><td>{esc(c.description)}"
                    f"{'<ul>' + offenders + '</ul>' if offenders else ''}</td></tr>")
    stats = result.stats
    drift = stats.drift

    def cells(stat: DriftSummary) -> str:
        """Count, mean, median, p95 and max cells of one drift bin (empty where no feature)."""
        return f"<td>{stat.count}</td>" + "".join(
            f"<td>{v:.3f}</td>" if stat.count else "<td></td>" for v in (stat.mean, stat.median, stat.p95, stat.max))

    def table(bins: tuple[DriftBin, ...], label: str) -> str:
        body = "".join(f"<tr><td>{b.lo:g}-{b.hi:g}</td>{cells(b.drift)}</tr>" for b in bins)
        return (f"<table><tr><th>{label}</th><th>features</th><th>mean</th><th>median</th><th>p95</th>"
                f"<th>max</th></tr>{body}</table>")

    sizes = "".join(f"<tr><td>{esc(s)}</td>{cells(v)}</tr>" for s, v in drift.by_size.items())
    figures = "".join(f"<figure><img alt='{esc(name)}' src='{data_uri(path.read_bytes(), 'png')}'>"
                      f"<figcaption>{esc(name)}</figcaption></figure>" for name, path in plots.items())
    overlay_html, sheets = [], []
    for view, b, labels in frames:
        # Each sheet at full size, a file of its own that the page links, and on the page at
        # its own size in a box that scrolls: scaled to the page's width no number could be read.
        image = draw_sheet(view, b, labels).image
        sheets.append(write_image(real_folder(out / "sheets") / f"{int(view.frame_id[b]):08d}.jpg", image,
                                  jpeg_quality=90))
        _, data = cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, 85])
        link = f"sheets/{sheets[-1].name}"
        overlay_html.append(f"<figure class='sheet'><figcaption>frame {view.frame_id[b]} ({esc(view.split[b])}): "
                            f"<a href='{link}'>the sheet at full size</a> ({image.shape[1]}x{image.shape[0]} px)"
                            f"</figcaption><div class='scroll'><img alt='overlay frame {view.frame_id[b]}' "
                            f"width='{image.shape[1]}' height='{image.shape[0]}' "
                            f"src='{data_uri(data.tobytes(), 'jpeg')}'></div></figure>")
    verdict = "PASSED" if result.passed else "FAILED"
    page = f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>datagen audit: {esc(result.name)}</title>
<style>
body {{ font: 14px/1.4 system-ui, sans-serif; margin: 2em; max-width: 2650px; }}
table {{ border-collapse: collapse; margin: 1em 0; }} td, th {{ border: 1px solid #ccc; padding: 3px 8px; }}
tr.fail td {{ background: #fdd; }} tr.pass td:nth-child(2) {{ color: #080; }} code {{ font-size: 12px; }}
td.hist {{ font-family: monospace; letter-spacing: 1px; }}
figure {{ display: inline-block; margin: 0.5em; }} img {{ max-width: 100%; border: 1px solid #ddd; }}
figure.sheet {{ display: block; }} .sheet .scroll {{ overflow: auto; max-height: 90vh; border: 1px solid #ddd; }}
.sheet .scroll img {{ max-width: none; border: 0; }}
.verdict {{ font-weight: bold; color: {'#080' if result.passed else '#c00'}; }}
</style></head>
<body>
<h1>datagen audit: {esc(result.name)}</h1>
<p><code>{esc(str(result.root))}</code>: {result.frames} frames, {len(dataset.features)} classes,
{'corrected' if dataset.corrected else 'tight (uncorrected)'} boxes, edge margin {dataset.edge_margin_px:g} px.
Verdict: <span class="verdict">{verdict}</span></p>
<h2>Checks</h2>
<table><tr><th>check</th><th>result</th><th>checked</th><th>failures</th><th>worst</th><th>what (worst offenders)</th></tr>
{''.join(rows)}</table>
{_learnable_html(stats.learnable, esc) if stats.learnable is not None else ""}
{_pose_html(stats.learnable_pose) if stats.learnable_pose is not None else ""}
{_appearance_html(stats.appearance, result.frames, esc)}
<h2>Parallax: tight-box centre drift from the true centre projection</h2>
<p>{drift.overall.count} features in view; median {_fmt(drift.overall.median)} px, 95th percentile {_fmt(drift.overall.p95)} px,
max {_fmt(drift.overall.max)} px. Corrected boxes are centred on the true centre; a detector trained on tight
boxes learns this drift.</p>
{table(drift.by_distance_m, 'distance (m)')}
<table><tr><th>size</th><th>features</th><th>mean</th><th>median</th><th>p95</th><th>max</th></tr>{sizes}</table>
{table(drift.by_obliqueness_deg, 'obliqueness (deg)')}
<h2>Plots</h2>
{figures}
<h2>Overlays</h2>
{colour_key_html()}
{''.join(overlay_html)}
<script>
window.addEventListener("load", () => {{
  const images = Array.from(document.images);
  const shown = images.filter(i => i.complete && i.naturalWidth > 0).length;
  document.body.dataset.images = shown + "/" + images.length;
}});
</script>
</body></html>
"""  # noqa: E501 (the page's text, one line per paragraph)
    write_text(out / "report.html", page)
    # report.json last: it is the record of every file the report wrote (``files``, relative to
    # the report folder), which --overwrite removes and nothing else.
    doc = report_document(result)
    doc["files"] = ["report.html", *(str(p.relative_to(out)) for p in plots.values()),
                    *sorted({*_earlier_sheets(out), *(f"sheets/{p.name}" for p in sheets)})]
    write_text(out / "report.json", json.dumps(doc, indent=2, allow_nan=False, default=_json_default) + "\n")
    return {"json": out / "report.json", "html": out / "report.html", **plots,
            **{f"sheet {p.stem}": p for p in sheets}}


#: A sheet's name in the report record.
_SHEET = re.compile(r"sheets/\d{8}\.jpg")


def _earlier_sheets(out: Path) -> list[str]:
    """The sheets an earlier report.json in ``out`` lists (an audit of other frames leaves
    them, and the record keeps naming them so that --overwrite removes them): names of the
    sheet form only."""
    return [f for f in recorded_files(REPORTS["audit"], out) if _SHEET.fullmatch(f)]


def _appearance_html(stats: dict[str, dict[str, AppearanceColumn]], frames: int, esc) -> str:
    """The appearance section: one row per drawn column, its histogram as a bar strip."""
    bars = "\u2581\u2582\u2583\u2584\u2585\u2586\u2587\u2588"
    rows = []
    for dimension, columns in stats.items():
        for name, entry in columns.items():
            if not entry.frames:
                shown = "<td colspan='3'>not drawn (randomizer off)</td>"
            elif entry.values is not None:
                shown = "<td colspan='3'>" + ", ".join(f"{esc(str(v))}: {n}" for v, n in entry.values.items()) \
                    + "</td>"
            elif entry.histogram is not None:
                top = max(entry.histogram) or 1
                strip = "".join(bars[min(len(bars) - 1, round(c / top * (len(bars) - 1)))] if c else "\u2007"
                                for c in entry.histogram)
                shown = (f"<td>{entry.min:.4g} to {entry.max:.4g}</td><td>{entry.mean:.4g}</td>"
                         f"<td class='hist' title='{entry.histogram}'>{strip}</td>")
            else:
                shown = "<td colspan='3'></td>"
            rows.append(f"<tr><td>{esc(dimension)}</td><td><code>{esc(name)}</code></td>"
                        f"<td>{entry.frames} of {frames}</td>{shown}</tr>")
    if not rows:
        return ""
    return ("<h2>Appearance: what the dataset's frames drew</h2><p>Per randomization dimension, the frames "
            "that drew each manifest column and the distribution of the draws (10 bins over the range "
            "drawn); the image statistics come from the render and its geometry pass.</p>"
            "<table><tr><th>dimension</th><th>column</th><th>frames</th><th>range</th><th>mean</th>"
            f"<th>histogram</th></tr>{''.join(rows)}</table>")


def _learnable_html(stats: Learnability, esc) -> str:
    """The report's section on what Ultralytics' trainer can learn of the label lines."""
    def pct(v: float | None) -> str:
        return "-" if v is None else f"{100 * v:.1f}%"

    def rows(items) -> str:
        return "".join(f"<tr><td>{esc(str(k))}</td><td>{v.lines}</td><td>{pct(v.share)}</td></tr>"
                       for k, v in items)

    head = "<tr><th>{}</th><th>lines</th><th>learnable</th></tr>"
    distance = [(f"{b.lo:g}-{b.hi:g}", b.lines) for b in stats.by_distance_m if b.lines.lines]
    everyone = "<tr><td colspan=3>every class fully learnable</td></tr>"
    return f"""<h2>Learnable by the detector</h2>
<p>{stats.lines} label lines; {pct(stats.share)} survive Ultralytics' training transforms at imgsz
{stats.train_imgsz} ({pct(stats.share_survive_2px)} have both sides above 2 px) and hold an anchor centre
({pct(stats.share_with_anchor)}), and are large enough for the untrained head's assigner (both sides at
least {stats.assignable_side_px:g} px: {pct(stats.share_assignable)}) or reached the edge margin while
growing ({pct(stats.share_at_edge_margin)}); the check asks for {pct(stats.threshold)}. Label boxes
are at least {stats.min_box_px:g} px there ({esc(stats.small_boxes)} smaller ones, as far as the edge
margin allows).</p>
<table>{head.format('distance (m)')}{rows(distance)}</table>
<table>{head.format('size')}{rows(stats.by_size.items())}</table>
<table>{head.format('worst classes')}{rows(stats.worst_classes) or everyone}</table>
"""


def _pose_html(stats: PoseLearnability) -> str:
    """The report's line on the pose instances (one per labeled object)."""
    share = "-" if stats.share is None else f"{100 * stats.share:.1f}%"
    return f"""<h2>Pose instances</h2>
<p>{stats.instances} pose instances (one per labeled object, its keypoints the true centre projections of its
features); {share} survive Ultralytics' training transforms at imgsz {stats.imgsz} without mosaic and hold an
anchor centre.</p>
"""


def _fmt(value: float | None) -> str:
    return "-" if value is None else f"{value:.3f}"


def _json_default(value):
    if isinstance(value, np.generic):
        return value.item()
    raise TypeError(f"not JSON: {type(value).__name__}")
