"""The ``datagen`` commands on scenes and datasets: validate, scenes, approach, build,
audit, preview, evaluate, export, train, render, gallery."""


from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Annotated, cast, get_args

import typer

from datagen.cli.common import (
    EXIT_INTERRUPTED,
    MAX_FRAME_LIST,
    MAX_OVERLAYS,
    MAX_PRINTED_FRAMES,
    MAX_SPP,
    ConfigOption,
    PartialOption,
    app,
    output_path,
    path_value,
    report_out,
    require_plan,
    unit_value,
    user_errors,
    workers_value,
)
from datagen.config import find_config, load_config
from datagen.core.errors import ConfigError, DatagenError, shown
from datagen.core.training import MATCH_PX
from datagen.pipeline.estimate import CPU_WORKERS

if TYPE_CHECKING:
    from datagen.analysis.evaluate import ErrorStats


@app.command()
@user_errors
def validate(
    configs: Annotated[list[Path], typer.Argument(parser=path_value,
                                                  help="Scene config files (YAML), or shipped scenes by name.",
                                                  show_default=False)],
) -> None:
    """Check configs against the schema, and their meshes and feature files;
    print every problem, one line each."""
    from datagen.scene.resolved import Scene

    failed = []
    for path in configs:
        try:
            config = load_config(path)
            scene = Scene.resolve(config)
            found = find_config(path)
        except ConfigError as exc:
            failed.append(exc)
            continue
        cam, k, table = config.camera, scene.intrinsics, scene.features
        typer.echo(
            f"{path}{'' if found == path else f' ({found})'}: ok "
            f"({config.name}: {cam.mount}, {cam.hfov_deg:g} deg hFOV, "
            f"{cam.width}x{cam.height}, fx=fy={k.fx:.3f} px, {config.dataset.frames} frames, "
            f"{'corrected' if config.labels.corrected else 'tight'} labels, {len(table)} classes "
            f"({config.features.variant} features of {' + '.join(config.features.objects)}))"
        )
    if failed:
        raise ConfigError([problem for exc in failed for problem in exc.problems])


@app.command()
@user_errors
def scenes() -> None:
    """List the shipped scenes: paper model, camera, field of view, range, features, frames."""
    from datagen.config import shipped_scenes

    rows = [("scene", "model", "camera", "hFOV", "range", "features", "frames")]
    for name, path in shipped_scenes().items():
        c = load_config(path)
        lo, hi = c.approach.range_m
        rows.append((name, c.paper_model or "-", c.camera.mount, f"{c.camera.hfov_deg:g} deg", f"{lo:g}-{hi:g} m",
                     f"{c.features.variant} of {' + '.join(c.features.objects)}", f"{c.dataset.frames:,}"))
    widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
    for row in rows:
        typer.echo("  ".join(cell.ljust(w) for cell, w in zip(row, widths, strict=True)).rstrip())
    typer.echo("Use a name as --config (datagen build --config wingcam55); a local file of that name wins.")


@app.command()
@user_errors
def approach(
    config: ConfigOption,
    plot: Annotated[Path | None, typer.Option("--plot", parser=path_value,
                                              help="Write a PNG of the approaches here.")] = None,
    approaches: Annotated[int, typer.Option("--approaches", min=1, max=50, help="Approaches to draw.")] = 5,
    frames: Annotated[int, typer.Option("--frames", min=0, max=MAX_PRINTED_FRAMES,
                                        help="Also print the state of the first N frames.")] = 0,
    seed: Annotated[int | None, typer.Option("--seed", min=0, help="Override the config's seed.")] = None,
) -> None:
    """Simulate Monte Carlo refueling approaches; plot a few, print frame states."""
    from datagen.scene.approach import frame_states
    from datagen.scene.chains import trace_approach

    if plot is not None:
        output_path(plot, "--plot")
    cfg = load_config(config)
    seed = cfg.dataset.seed if seed is None else seed
    for a in range(approaches):
        tr = trace_approach(cfg, seed, a)
        typer.echo(f"approach {a}: start {tr['distance_m'][0]:7.2f} m, contact after {tr['time_s'][-1]:6.1f} s")
    for i, st in enumerate(frame_states(cfg, range(frames), seed)):
        x, y, z = st.ptd_receiver_m
        again = f" (after {st.approach_number} contacts)" if st.approach_number else ""
        typer.echo(f"frame {i:5d}: approach {st.approach_index}{again} t={st.time_s:7.2f} s "
                   f"distance {st.distance_m:8.3f} m  PtD_receiver [{x:8.3f} {y:7.3f} {z:7.3f}] m")
    if plot is not None:
        from datagen.report.plots import plot_approaches

        plot_approaches(cfg, plot, approaches, seed)
        typer.echo(f"wrote {plot}")


@app.command()
@user_errors
def build(
    config: ConfigOption,
    out: Annotated[Path | None, typer.Option("--out", parser=path_value,
                                             help="Dataset folder (default: datasets/<config name>).")] = None,
    frames: Annotated[int | None, typer.Option("--frames", min=1, help="Override dataset.frames.")] = None,
    seed: Annotated[int | None, typer.Option("--seed", min=0, help="Override dataset.seed.")] = None,
    spp: Annotated[int | None, typer.Option("--spp", min=1, help="Override render.spp.")] = None,
    workers: Annotated[str | None, typer.Option("--workers", parser=workers_value, metavar="auto|N",
                                                help="Shards rendered in parallel (local: processes, default "
                                                "1; ray: tasks, default one per node); auto: what suits the "
                                                f"render's device (a GPU: one per core; the CPU: {CPU_WORKERS}, at "
                                                "most one per core).")] = None,
    shard_size: Annotated[int | None, typer.Option("--shard-size", min=1, help="Override dataset.shard_size.")] = None,
    threads: Annotated[int | None, typer.Option("--threads", min=1, help="Mitsuba threads per worker (default: the "
                                                "cores divided among the workers); 1 gives the same image bytes "
                                                "for a seed on any machine, worker count and resumption.")] = None,
    executor: Annotated[str, typer.Option("--executor", help="local (processes) or ray (RAY_ADDRESS, "
                                          "else a local Ray cluster).")] = "local",
    exr: Annotated[bool, typer.Option("--exr", help="Also write linear EXR (R, G, B, Z, object_id).")] = False,
    overwrite: Annotated[bool, typer.Option("--overwrite", help="Replace a dataset of another config in "
                                            "--out.")] = False,
    no_render: Annotated[bool, typer.Option("--no-render", help="Labels and manifests only, no images "
                                            "(for evaluation).")] = False,
) -> None:
    """Render a sharded, resumable dataset with YOLO labels and parquet manifests.

    Rerunning the same command after an interruption finishes the missing shards."""
    from datagen.config import override_config
    from datagen.console import ConsoleProgress
    from datagen.pipeline.build import build_dataset
    from datagen.pipeline.executors import ExecutorName

    if executor not in get_args(ExecutorName):
        raise DatagenError(f"--executor: unknown executor {executor!r} (choose local or ray)")
    if out is not None:
        output_path(out, "--out")
    config = find_config(config)
    cfg = load_config(config)
    typer.echo(f"config: {config.resolve()}")
    updates = {"dataset.frames": frames, "dataset.seed": seed, "render.spp": spp,
               "dataset.shard_size": shard_size, "render.exr": True if exr else None}
    cfg = override_config(cfg, {k: v for k, v in updates.items() if v is not None})
    out = out if out is not None else output_path(Path("datasets") / cfg.name, "--out")
    report = build_dataset(cfg, out, workers=workers, executor=cast(ExecutorName, executor), overwrite=overwrite,
                           render=not no_render, progress=ConsoleProgress(cfg.name), threads=threads)
    for line in report.lines():
        typer.echo(line)
    if report.interrupted:
        raise typer.Exit(EXIT_INTERRUPTED)


@app.command()
@user_errors
def audit(
    dataset: Annotated[Path, typer.Argument(parser=path_value, help="Dataset folder.", show_default=False)],
    out: Annotated[Path | None, typer.Option("--out", parser=path_value,
                                             help="Report folder (default: DATASET/audit).")] = None,
    overlays: Annotated[int, typer.Option("--overlays", min=0, max=MAX_OVERLAYS,
                                          help="Overlay images in the HTML report.")] = 3,
    min_learnable: Annotated[float, typer.Option("--min-learnable", min=0.0, max=1.0, help="Share of label lines "
                                                 "that must be learnable at labels.train_imgsz.")] = 0.95,
    workers: Annotated[int, typer.Option("--workers", min=1, max=64, help="Processes that check shards "
                                         "(each holds one shard at a time).")] = 1,
) -> None:
    """Check a dataset's labels against the true centre projections; write
    report.json, plots and report.html. Exit 1 when a check fails."""
    from datagen.analysis.audit import audit as run_audit
    from datagen.analysis.audit.frames import frames_to_draw
    from datagen.console import ConsoleProgress
    from datagen.dataset.reader import open_dataset
    from datagen.report.audit_report import write_report

    folder = report_out("audit", out, dataset)
    source = open_dataset(dataset)
    result = run_audit(source, min_learnable=min_learnable, workers=workers,
                       progress=ConsoleProgress(source.root.name, verb="audit", announce=False))
    written = write_report(result, source, folder, frames=frames_to_draw(source, overlays))
    for check in result.checks:
        status = "n/a " if not check.applicable else ("pass" if check.passed else "FAIL")
        if check.min_pass_share is not None and check.pass_share is None:
            typer.echo(f"{status}  {check.name}: nothing to check (needs {100 * check.min_pass_share:g}% to pass "
                       "where there is)")
        elif check.min_pass_share is not None and check.pass_share is not None:
            typer.echo(f"{status}  {check.name}: {100 * check.pass_share:.1f}% of {check.checked} pass (needs "
                       f"{100 * check.min_pass_share:g}%), {check.failures} failed")
        else:
            worst = "" if check.worst is None else f", worst {check.worst:.3g}"
            typer.echo(f"{status}  {check.name}: {check.checked} checked, {check.failures} failed{worst}")
        for offender in check.offenders[:5]:
            typer.echo(f"        {offender}")
    drift = result.stats.drift.overall
    if drift.count:
        typer.echo(f"tight-box centre drift from the true centre: median {drift.median:.3f} px, "
                   f"p95 {drift.p95:.3f} px, max {drift.max:.3f} px over {drift.count} features")
    typer.echo(f"{'PASSED' if result.passed else 'FAILED'}: {written['html']}")
    if not result.passed:
        raise typer.Exit(1)


@app.command()
@user_errors
def preview(
    dataset: Annotated[Path, typer.Argument(parser=path_value, help="Dataset folder.", show_default=False)],
    frames: Annotated[str | None, typer.Option("--frames", help="Frame ids, e.g. 0,5,9 or 0-7 "
                                               "(default: the first 4).")] = None,
    out: Annotated[Path | None, typer.Option("--out", parser=path_value,
                                             help="Folder for the overlays (default: DATASET/preview).")]
    = None,
    partial: PartialOption = False,
) -> None:
    """Draw overlays of true centres, tight and corrected boxes (paper Fig. 11)."""
    from datagen.dataset.reader import open_dataset
    from datagen.report.overlays import write_previews

    folder = report_out("preview", out, dataset)
    source = open_dataset(dataset)
    index = source.frames(unique=True)
    require_plan(index, partial)
    wanted = _frame_list(frames) if frames else [int(f) for f in index.frame_id[:4]]
    view = source.read_frames(list(dict.fromkeys(wanted)))  # only the manifests that hold them
    for path in write_previews(view, wanted, folder, warn=lambda line: typer.echo(shown(line), err=True)):
        typer.echo(f"wrote {path}")


@app.command()
@user_errors
def evaluate(
    dataset: Annotated[Path, typer.Argument(parser=path_value, help="Dataset folder (a --no-render build is enough).",
                                            show_default=False)],
    noise_px: Annotated[str, typer.Option("--noise-px", help="Truth runs: pixel noise radii, e.g. 0,0.5,1,2.5.")]
    = "0,0.5,1,2.5",
    predictions: Annotated[Path | None, typer.Option("--predictions", parser=path_value,
                                                     help="Folder of Ultralytics save_txt "
                                                     "detections (cls cx cy w h conf) or, for a dataset with pose "
                                                     "labels, pose predictions (keypoints with confidences), by "
                                                     "image stem; replaces the truth runs.")] = None,
    conf: Annotated[float, typer.Option("--conf", parser=unit_value, help="Minimum detection confidence (0 to "
                                        "1).")] = 0.25,
    split: Annotated[str | None, typer.Option("--split", help="Frames to attempt: all, train or val (default: "
                                              "all for truth runs; with --predictions, the splits the "
                                              "prediction files cover).", show_default=False)] = None,
    seed: Annotated[int | None, typer.Option("--seed", min=0, help="Noise seed (default: the dataset's).")] = None,
    out: Annotated[Path | None, typer.Option("--out", parser=path_value,
                                             help="Output folder (default: DATASET/evaluation, with --predictions "
                                             "DATASET/evaluation-predictions).")] = None,
    workers: Annotated[int, typer.Option("--workers", min=1, max=64, help="Processes that solve approaches "
                                         "(results do not depend on it).")] = 1,
    match_px: Annotated[float, typer.Option("--match-px", min=0.0, max=1000.0, help="With --predictions: a "
                                            "detection within this many px of the true centre is a match.")]
    = MATCH_PX,
    partial: PartialOption = False,
) -> None:
    """PtD vectors by dual-object PnP from true centres (with noise) or detections;
    accuracy and reliability against distance (paper 3.3-3.6). With --predictions, also
    the detector itself against the true centres: per class and distance, features
    matched, mislocated and missed, spurious detections and the centre error."""
    from datagen.analysis.detections import score_detections
    from datagen.analysis.evaluate import (
        PnPSettings,
        evaluate_runs,
        failure_text,
        plan_evaluation,
    )
    from datagen.console import ConsoleProgress
    from datagen.dataset.reader import open_dataset
    from datagen.report.evaluation_report import write_evaluation

    folder = report_out("evaluate" if predictions is None else "evaluate --predictions", out, dataset)
    source = open_dataset(dataset)
    index = source.frames(unique=True)
    require_plan(index, partial, split if split in ("train", "val") else None)
    progress = ConsoleProgress(source.root.name, verb="evaluate", announce=False)
    plan = plan_evaluation(source, index, noise_px=noise_px, predictions=predictions, conf=conf, split=split)
    for line in plan.warnings:
        typer.echo(line, err=True)
    for line in plan.notes:
        typer.echo(line)
    settings = PnPSettings()  # the paper's: every run is solved, summarized and reported with these
    results = evaluate_runs(source, list(plan.runs), seed=seed, settings=settings, split=plan.split, workers=workers,
                            progress=progress)
    runs = list(zip(plan.sources, results, strict=True))
    detector = None
    if plan.predictions is not None:
        detector = score_detections(source, plan.predictions, split=plan.split, match_px=match_px)
    written = write_evaluation(index, runs, folder, settings=settings, detector=detector)
    if written.detector is not None:
        d = written.detector.overall
        typer.echo(f"detector: {d.matched} of {d.labeled} labeled features found within {match_px:g} px "
                   f"of the true centre ({100 * (d.recall or 0):.1f}%), {d.mislocated} further away, "
                   f"{d.missed} missed, {d.spurious} spurious detections; "
                   + (f"centre error median {d.error_median_px:.2f} px, 95th percentile {d.error_p95_px:.2f} px"
                      if d.error_median_px is not None else "no centre error (no feature found)"))
    for (described, result), s in zip(runs, written.summaries, strict=True):
        what = f"noise {described['noise_px']:g} px" if described["source"] == "truth" else "predictions"
        typer.echo(f"{what}: reliability {100 * (s.overall.reliability or 0):.1f}% of {len(result)}, "
                   f"{_mean_error(s.overall)}, {_at_contact(s.at['contact'], settings.contact_m)}, "
                   f"target {s.target}")
        failures = [(r, n) for r, n in s.reasons.items() if r != "ok" and n]
        if failures:
            typer.echo("  failed: " + ", ".join(f"{n} {failure_text(r, settings, conf)}" for r, n in failures))
    typer.echo(f"wrote {written.files['json']}")


@app.command()
@user_errors
def export(
    dataset: Annotated[Path, typer.Argument(parser=path_value, help="Dataset folder.", show_default=False)],
    format: Annotated[str, typer.Option("--format", help="coco (keypoints per object) or bop (6D poses, "
                                        "models, masks; needs a build with --exr).", show_default=False)],
    out: Annotated[Path, typer.Option("--out", parser=path_value,
                                      help="New folder for the export.", show_default=False)],
    partial: PartialOption = False,
) -> None:
    """Write a built dataset as COCO keypoints or in the BOP format (poses, models, masks)."""
    from datagen.dataset.reader import load_dataset
    from datagen.report.export import EXPORT_FORMATS, export_dataset

    if format not in EXPORT_FORMATS:
        raise DatagenError(f"--format: {format!r}: choose {' or '.join(EXPORT_FORMATS)}")
    folder = output_path(out, "--out")
    view = load_dataset(dataset)
    require_plan(view, partial)
    written = export_dataset(view, folder, format)
    typer.echo(f"wrote {format.upper()} export of {len(view)} frames: {written}")


@app.command()
@user_errors
def train(
    dataset: Annotated[Path, typer.Argument(parser=path_value, help="Dataset folder (rendered).",
                                            show_default=False)],
    pose: Annotated[bool, typer.Option("--pose", help="Train the pose set (pose/ beside the detect set of "
                                       "labels.format both).")] = False,
    model: Annotated[str | None, typer.Option("--model", help="Ultralytics model: a .yaml builds it from "
                                              "scratch, a local .pt starts from its weights (default: "
                                              "yolo11n.yaml, yolo11n-pose.yaml for pose labels).",
                                              show_default=False)] = None,
    epochs: Annotated[int | None, typer.Option("--epochs", min=1, help="Epochs (default: Ultralytics' 100).",
                                               show_default=False)] = None,
    device: Annotated[str | None, typer.Option("--device", help="cpu, or CUDA device ids such as 0 or 0,1 "
                                               "(default: Ultralytics' choice, a GPU where there is one).",
                                               show_default=False)] = None,
    batch: Annotated[int | None, typer.Option("--batch", min=1, max=1024, help="Images per batch, one optimizer "
                                              "step each (sets Ultralytics' batch and nbs; default: hyp.yaml's).",
                                              show_default=False)] = None,
    imgsz: Annotated[int | None, typer.Option("--imgsz", min=32, max=8192, help="Training and prediction size, "
                                              "px (default: hyp.yaml's, labels.train_imgsz; the labels' minimum "
                                              "sizes were grown for that size).", show_default=False)] = None,
    runs: Annotated[Path | None, typer.Option("--runs", parser=path_value, help="Ultralytics' project folder "
                                              "(default: runs/ beside the dataset).", show_default=False)]
    = None,
    name: Annotated[str | None, typer.Option("--name", help="The run's name (default: the dataset's).",
                                             show_default=False)] = None,
) -> None:
    """Train a detector with Ultralytics on the dataset's own recipe (hyp.yaml), predict the
    validation frames, and print the evaluate command (needs the train extra)."""
    from datagen.analysis.audit.dataset_files import check_recipe
    from datagen.analysis.audit.label_lines import check_names
    from datagen.analysis.audit.pose import check_pose_names
    from datagen.analysis.ultralytics import train_and_predict
    from datagen.dataset.reader import open_dataset
    from datagen.dataset.training_run import TrainingRun

    source = open_dataset(dataset)  # the checks every reading command makes, one line each
    # Ultralytics runs a data.yaml's download, loads what hyp.yaml names, reads every image a list names and
    # prints the class names: each is checked as the audit checks it, before anything else.
    _refuse_failed(source, check_recipe(source))
    if source.doc.get("render") is False:
        raise DatagenError(f"{source.root / 'dataset.json'}: render: false: a labels-only build has no images to "
                           "train on (build it without --no-render)")
    labels = source.label_format
    if pose and labels == "detect":
        raise DatagenError(f"{source.root / 'dataset.json'}: config.labels.format: detect; --pose needs a build "
                           "with pose labels (labels.format pose or both)")
    _refuse_failed(source, check_pose_names(source) if pose or labels == "pose" else check_names(source))
    task = "pose" if labels == "pose" or pose else "detect"
    root = source.root / "pose" if labels == "both" and pose else source.root
    # Absolute folders: Ultralytics puts a relative project folder under its own settings folder.
    run = TrainingRun(root.resolve(), source.root.resolve(), task,
                      runs=output_path(runs, "--runs").resolve() if runs else None, name=name, model=model)
    train_and_predict(run, epochs=epochs, device=device, batch=batch, imgsz=imgsz)
    typer.echo(f"weights: {run.weights}")
    typer.echo(f"predictions of the validation frames: {run.predictions}")
    typer.echo(f"score them: {run.evaluate_command()}")


def _at_contact(contact: ErrorStats, contact_m: float) -> str:
    """The error at contact, or why there is no figure: no frame within ``contact_m`` of
    contact, or none of them solved."""
    if not contact.attempts:
        return f"at contact: no figure (no frame within {contact_m:g} m of contact)"
    if not contact.successes or contact.mean_m is None or contact.plus_2sigma_m is None:
        return f"at contact: no figure (none of the {contact.attempts} frames within {contact_m:g} m solved)"
    return f"at contact {_m(contact.mean_m)} (+2 sigma {_m(contact.plus_2sigma_m)}, {contact.successes} frames)"


def _mean_error(overall: ErrorStats) -> str:
    """The mean PtD error, or why there is none (no frame solved)."""
    if overall.mean_m is None:
        return "mean error: no figure (no frame solved)"
    return f"mean error {_m(overall.mean_m)}"


def _m(value: float) -> str:
    return f"{value * 100:.2f} cm"


@app.command()
@user_errors
def render(
    config: ConfigOption,
    frames: Annotated[str, typer.Option("--frames", help="Frame indices, e.g. 0,5,9 or 0-7.")] = "0",
    out: Annotated[Path, typer.Option("--out", parser=path_value, help="Folder for the images.")] = Path("renders"),
    spp: Annotated[int | None, typer.Option("--spp", min=1, max=MAX_SPP,
                                            help="Samples per pixel (default: the config's).")] = None,
    scale: Annotated[float, typer.Option("--scale", min=0.05, max=1.0, help="Image size relative to the "
                                         "config's (same hFOV).")] = 1.0,
    exr: Annotated[bool, typer.Option("--exr", help="Also write linear EXR (R, G, B, Z, object_id).")] = False,
    seed: Annotated[int | None, typer.Option("--seed", min=0, help="Override the config's seed.")] = None,
) -> None:
    """Render single frames of a config (no labels): for looking, not for datasets."""
    from datagen.report.gallery import render_frames

    output_path(out, "--out")
    cfg = load_config(config)
    for path in render_frames(cfg, _frame_list(frames), out, spp=spp, scale=scale, exr=exr, seed=seed):
        typer.echo(f"wrote {path}")


@app.command()
@user_errors
def gallery(
    out: Annotated[Path, typer.Option("--out", parser=path_value,
                                      help="Gallery image (JPEG or PNG).")] = Path("docs/gallery.jpg"),
    spp: Annotated[int | None, typer.Option("--spp", min=1, max=MAX_SPP,
                                            help="Samples per pixel (default: each config's render.spp).")] = None,
    closeups: Annotated[Path | None, typer.Option("--closeups", parser=path_value,
                                                  help="Also write full-resolution close-ups of "
                                                  "clouds and sea, one row per camera type, to this image.")] = None,
    before: Annotated[Path | None, typer.Option("--before", parser=path_value,
                                                help="Folder of `datagen render` images of the "
                                                "close-up frames made by another datagen: shown beside each "
                                                "close-up.")] = None,
) -> None:
    """Render four frames each of wingcam55, podcam15 and dashcam75 into one sheet."""
    from datagen.report.gallery import GALLERY_SCENES, write_closeups, write_gallery

    output_path(out, "--out")
    if closeups is not None:
        output_path(closeups, "--closeups")
    if before is not None and not before.is_dir():
        raise DatagenError(f"--before: {before}: no such folder")
    configs = [load_config(name) for name in GALLERY_SCENES]
    typer.echo(f"wrote {write_gallery(configs, out, spp=spp)}")
    if closeups is not None:
        typer.echo(f"wrote {write_closeups(closeups, before=before, spp=spp)}")


def _refuse_failed(source, check) -> None:
    """One line naming the first offender of an audit check that fails (training refuses the
    files the audit would fail)."""
    check = check.finish()
    if not check.passed:
        raise DatagenError(f"{source.root}/{check.offenders[0]} (datagen audit checks the training files; rebuild "
                           "the dataset to rewrite them)")


def _frame_list(text: str) -> list[int]:
    """Frame indices from ``0,5,9`` or ``0-7`` (at most :data:`MAX_FRAME_LIST`), in the order given."""
    ranges: list[tuple[int, int]] = []
    try:
        for part in text.split(","):
            start, dash, end = part.strip().partition("-")
            ranges.append((int(start), int(end) if dash else int(start)))
    except ValueError:
        raise DatagenError(f"--frames: {text[:60]!r} is not a list of frame indices like 0,5,9 or 0-7") from None
    for lo, hi in ranges:
        if lo < 0:
            raise DatagenError(f"--frames: {text[:60]!r}: frame indices must be non-negative")
        if hi < lo:
            raise DatagenError(f"--frames: {lo}-{hi}: a range goes from the lower index to the higher")
    count = sum(hi - lo + 1 for lo, hi in ranges)
    if count > MAX_FRAME_LIST:
        raise DatagenError(f"--frames: {text[:60]!r} names {count:,} frames; at most {MAX_FRAME_LIST:,} at a time")
    return [i for lo, hi in ranges for i in range(lo, hi + 1)]
