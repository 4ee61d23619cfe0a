"""PNG plots of the approaches, the audit and the evaluation.

Figures are made with ``matplotlib.figure.Figure`` directly, never through
pyplot: no backend is selected and no figure is kept in a global registry (no
process-wide state), and a figure is rendered to PNG bytes that
:mod:`datagen.atomic` writes.
"""

from __future__ import annotations

from pathlib import Path

from matplotlib.figure import Figure
from matplotlib.ticker import MaxNLocator

from datagen.analysis.audit.check import DriftPlot
from datagen.analysis.audit.summary import AuditStatistics
from datagen.analysis.detections import DetectorSummary
from datagen.analysis.evaluate import RunResult, RunSummary
from datagen.atomic import write_figure
from datagen.config.schema import Config
from datagen.scene.chains import trace_approach

__all__ = ["plot_approaches", "plot_audit", "plot_detector", "plot_evaluation"]


def _figure(*shape: int, **options):
    """A figure and its axes (``Figure.subplots``), laid out with constrained layout."""
    fig = Figure(figsize=options.pop("figsize"), constrained_layout=True)
    return fig, fig.subplots(*shape, **options)


def _save_png(fig: Figure, path: Path, dpi: int = 100) -> Path:
    """Render a figure to PNG and write it atomically."""
    return write_figure(path, fig, dpi=dpi)


def plot_approaches(config: Config, path: Path, approaches: int = 5, seed: int | None = None) -> None:
    """Distance over time and trajectories in the drogue-centred frame for a few approaches."""
    seed = config.dataset.seed if seed is None else seed
    fig, axes = _figure(1, 3, figsize=(16, 4.8))
    for a in range(approaches):
        tr = trace_approach(config, seed, a)
        label = f"approach {a} ({tr['time_s'][-1]:.0f} s)"
        axes[0].plot(tr["time_s"], tr["distance_m"], label=label)
        pos = tr["probe_drogue_m"]
        axes[1].plot(pos[:, 0], pos[:, 1])
        axes[2].plot(pos[:, 0], pos[:, 2])
        for ax, j in ((axes[1], 1), (axes[2], 2)):
            ax.plot(pos[0, 0], pos[0, j], "o", color=ax.lines[-1].get_color(), ms=4)
    axes[0].set(xlabel="time since start (s)", ylabel="probe-to-drogue distance (m)",
                title="PtD distance (contact < 1 cm)", yscale="log")
    axes[0].legend(fontsize=8)
    axes[1].set(xlabel="x, tanker forward (m)", ylabel="y, left (m)", title="top view, drogue-centred frame")
    axes[2].set(xlabel="x, tanker forward (m)", ylabel="z, up (m)", title="side view, drogue-centred frame")
    for ax in axes[1:]:
        ax.plot(0, 0, "k+", ms=12)
        ax.grid(True, alpha=0.3)
    axes[0].grid(True, alpha=0.3)
    fig.suptitle(f"{config.name}: {approaches} Monte Carlo approaches (seed {seed}, start markers o, drogue +)")
    _save_png(fig, path, dpi=110)


def plot_audit(stats: AuditStatistics, plot: DriftPlot, folder: Path) -> dict[str, Path]:
    """The audit's figures as PNGs in ``folder`` (``stats``: the statistics' summary);
    returns {name: path}."""
    import numpy as np

    out: dict[str, Path] = {}

    def save(fig, name: str) -> None:
        out[name] = _save_png(fig, Path(folder) / f"{name}.png")

    scatter = plot.scatter  # every k-th feature in frame order: (distance, drift)
    floor = 1e-4  # a drift of exactly 0 (a symmetric view) still shows on the log axis
    fig, ax = _figure(figsize=(8, 4.5))
    if len(scatter):
        ax.scatter(scatter[:, 0], np.maximum(scatter[:, 1], floor), s=3, alpha=0.25, label="a feature in a frame")
        bins = [b for b in stats.drift.by_distance_m if b.drift.count]
        mid = [(b.lo + b.hi) / 2 for b in bins]
        ax.plot(mid, [max(b.drift.median or 0.0, floor) for b in bins], "o-", color="C3", label="median per 10 m")
        ax.plot(mid, [max(b.drift.p95 or 0.0, floor) for b in bins], "s--", color="C1", label="95th percentile")
        ax.legend()
    ax.set(yscale="log", xlabel="probe-to-drogue distance (m)", ylabel="tight-box centre drift (px)",
           title="Tight-box (perceived) centre vs true centre projection")
    ax.grid(True, alpha=0.3)
    save(fig, "drift_vs_distance")

    fig, axes = _figure(1, 2, figsize=(11, 4.2))
    boxes = plot.boxes  # (size tag, quartiles and whiskers) per tag with features
    if boxes:
        axes[0].bxp([{"label": tag, **{k: max(v, floor) for k, v in box.items()}} for tag, box in boxes],
                    showfliers=False)
    axes[0].set(yscale="log", xlabel="feature size", ylabel="tight-box centre drift (px)", title="by feature size")
    bins = [b for b in stats.drift.by_obliqueness_deg if b.drift.count]
    mid = [(b.lo + b.hi) / 2 for b in bins]
    axes[1].plot(mid, [max(b.drift.median or 0.0, floor) for b in bins], "o-", label="median")
    axes[1].plot(mid, [max(b.drift.p95 or 0.0, floor) for b in bins], "s--", label="95th percentile")
    axes[1].set(yscale="log", xlabel="view obliqueness (deg; 0 = seen head-on)", ylabel="drift (px)",
                title="by view obliqueness")
    axes[1].legend()
    for ax in axes:
        ax.grid(True, alpha=0.3)
    save(fig, "drift_by_size_and_obliqueness")

    per_class = stats.labels_per_class
    fig, ax = _figure(figsize=(max(8, 0.12 * len(per_class)), 4))
    ax.bar(range(len(per_class)), list(per_class.values()))
    ax.set(xlabel="class id", ylabel="labeled (frames)", title="Labels per class")
    ax.grid(True, axis="y", alpha=0.3)
    save(fig, "labels_per_class")

    fig, axes = _figure(1, 2, figsize=(11, 4))
    exclusions = stats.exclusions
    axes[0].bar(list(exclusions), list(exclusions.values()), color=["C2"] + ["C7"] * (len(exclusions) - 1))
    axes[0].set(ylabel="features x frames", title="Labeled and excluded, by reason")
    axes[0].tick_params(axis="x", rotation=20)
    hist = stats.visibility.visible_fraction_histogram
    axes[1].bar(np.arange(10) / 10 + 0.05, hist, width=0.09)
    axes[1].set(xlabel="visible fraction of a labeled feature's points", ylabel="count",
                title="Visibility of labeled features (ray casts)")
    for ax in axes:
        ax.grid(True, axis="y", alpha=0.3)
    save(fig, "exclusions_and_visibility")

    fig, axes = _figure(1, 2, figsize=(11, 4))
    cov = stats.coverage
    edges = np.asarray(cov.edges_m)
    axes[0].bar(edges[:-1] + 2.5, cov.frames, width=4.5)
    axes[0].set(xlabel="probe-to-drogue distance (m)", ylabel="frames", title="Distance coverage")
    axes[0].yaxis.set_major_locator(MaxNLocator(integer=True))  # frames are counted whole
    pnp = stats.pnp
    shares = [100 * v.share_below_3 for v in pnp.values()]
    axes[1].bar(list(pnp), shares, color="C3")
    axes[1].set(ylabel="% of frames", ylim=(0, max(10.0, 1.1 * max(shares, default=0.0))),
                title="Frames where an object has < 3 labeled features (no PnP)")
    for x, share in enumerate(shares):  # a bar of 0 is drawn as its number, not as nothing
        axes[1].annotate(f"{share:.1f}%", (x, share), ha="center", va="bottom", xytext=(0, 3),
                         textcoords="offset points")
    for ax in axes:
        ax.grid(True, axis="y", alpha=0.3)
    save(fig, "coverage_and_pnp")
    return out


#: The smallest PtD error the error plot's log axis shows, metres (the same floor for the
#: points and the lines: a noise-free run's errors of ~1e-10 m are drawn on it, and said so).
ERROR_FLOOR_M = 1e-6


def _label(source: dict) -> str:
    return (f"truth + {source['noise_px']:g} px noise" if source["source"] == "truth"
            else f"predictions ({source.get('predictions', '')})")


def plot_evaluation(runs: list[tuple[dict, RunResult]], summaries: list[RunSummary], folder: Path, *,
                    name: str = "") -> dict[str, Path]:
    """PtD error magnitude against distance, one panel per run with the mean and +-2 sigma
    per distance bin (paper Figs 14-17), and reliability against distance; ``summaries``:
    each run's :class:`~datagen.analysis.evaluate.RunSummary`."""
    import numpy as np

    out: dict[str, Path] = {}
    n = len(runs)
    cols = min(n, 2)
    rows = (n + cols - 1) // cols
    fig, axes = _figure(rows, cols, figsize=(7 * cols, 4.2 * rows), squeeze=False)
    for ax, (source, result), summary in zip(axes.ravel(), runs, summaries):
        ok = result.success
        d, e = result.distance_m, result.error_m
        floor = ERROR_FLOOR_M  # a log axis shows no 0: errors below it (noise-free points) are drawn on it
        below = int((e[ok] < floor).sum())
        ax.scatter(d[ok], np.maximum(e[ok], floor), s=2, alpha=0.3, color="C0",
                   label="prediction error" + (f" ({below} below {floor:g} m drawn at it)" if below else ""))
        bins = [b for b in summary.by_distance if b.stats.mean_m is not None]
        mid = [(b.lo_m + b.hi_m) / 2 for b in bins]
        ax.plot(mid, [max(b.stats.mean_m or 0.0, floor) for b in bins], "-", color="C3", label="mean")
        ax.plot(mid, [max(b.stats.plus_2sigma_m or 0.0, floor) for b in bins], "--", color="C1", label="mean + 2 sigma")
        ax.axhline(0.07, color="k", lw=0.8, ls=":", label="7 cm (acceptable at contact)")
        ax.set(xscale="symlog", xlim=(0, 125), yscale="log", xlabel="probe-to-drogue distance (m)",
               ylabel="PtD error magnitude (m)", title=f"{_label(source)}: target {summary.target}")
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=7)
    for ax in axes.ravel()[n:]:
        ax.axis("off")
    fig.suptitle(f"{name}: PtD vector error vs distance")
    out["error_vs_distance"] = _save_png(fig, Path(folder) / "error_vs_distance.png")

    fig, ax = _figure(figsize=(8, 4))
    for (source, _), summary in zip(runs, summaries):
        bins = [b for b in summary.by_distance if b.stats.attempts]
        ax.plot([(b.lo_m + b.hi_m) / 2 for b in bins], [100 * (b.stats.reliability or 0.0) for b in bins], "o-",
                ms=3, label=_label(source))
    ax.set(xlabel="probe-to-drogue distance (m)", ylabel="reliability (%)", ylim=(0, 102),
           title=f"{name}: successful PtD predictions / attempts")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8)
    out["reliability_vs_distance"] = _save_png(fig, Path(folder) / "reliability_vs_distance.png")
    return out


def plot_detector(summary: DetectorSummary, folder: Path, *, name: str = "") -> dict[str, Path]:
    """The detector against distance (recall within the match radius, misses and spurious
    detections; the centre error's median and 95th percentile) and recall per class."""
    import numpy as np

    bins = [b.counts for b in summary.by_distance if b.counts.labeled or b.counts.spurious]
    mid = np.array([(b.lo_m + b.hi_m) / 2 for b in summary.by_distance if b.counts.labeled or b.counts.spurious])
    fig, axes = _figure(1, 2, figsize=(13, 4.2))
    labeled = np.array([max(b.labeled, 1) for b in bins])
    for key, counts, style in (("matched", [b.matched for b in bins], "o-"),
                               ("mislocated", [b.mislocated for b in bins], "s--"),
                               ("missed", [b.missed for b in bins], "^--")):
        axes[0].plot(mid, [100 * c / n for c, n in zip(counts, labeled)], style, ms=4, label=f"{key} (% of labeled)")
    axes[0].plot(mid, [100 * b.spurious / n for b, n in zip(bins, labeled)], "x:", label="spurious (% of labeled)")
    axes[0].set(xlabel="probe-to-drogue distance (m)", ylabel="% of labeled features", ylim=(0, None),
                title=f"found within {summary.match_px:g} px of the true centre")
    err = [(m, b.error_median_px, b.error_p95_px) for m, b in zip(mid, bins) if b.error_median_px is not None]
    if err:
        e = np.array(err, dtype=float)
        axes[1].plot(e[:, 0], e[:, 1], "o-", label="median")
        axes[1].plot(e[:, 0], e[:, 2], "s--", label="95th percentile")
    axes[1].axhline(summary.match_px, color="k", lw=0.8, ls=":", label="match radius")
    axes[1].set(yscale="log", xlabel="probe-to-drogue distance (m)", ylabel="detected centre - true centre (px)",
                title="centre error of detected labeled features")
    for ax in axes:
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=7)
    fig.suptitle(f"{name}: the detector against the true feature centres")
    out = {"detector_vs_distance": _save_png(fig, Path(folder) / "detector_vs_distance.png")}

    classes = list(summary.by_class.values())
    fig, ax = _figure(figsize=(max(8, 0.13 * len(classes)), 4))
    recall = [100 * (c.recall or 0) for c in classes]
    ax.bar(range(len(classes)), recall, color=["C0" if c.labeled else "C7" for c in classes])
    ax.set(xlabel="class id", ylabel="recall (%)", ylim=(0, 102),
           title=f"{name}: labeled features found within {summary.match_px:g} px, per class (grey: never labeled)")
    ax.grid(True, axis="y", alpha=0.3)
    out["detector_by_class"] = _save_png(fig, Path(folder) / "detector_by_class.png")
    return out
