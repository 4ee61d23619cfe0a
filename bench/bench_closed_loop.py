"""The closed loop: a detector trained on datagen frames finds the features of approaches it
has never seen, scored the way the paper scores it (3.3-3.6, Figs 14-29).

    python bench/bench_closed_loop.py [--scene podcam15] [--train-frames 240] [--test-frames 80]
        [--epochs 24] [--batch 4] [--model yolo11n.yaml] [--device cpu] [--out DIR] [--no-uncorrected]

    # the paper's scale, where a GPU is (about 8,000-10,000 frames, yolo11s, 300 epochs, imgsz 864):
    python bench/bench_closed_loop.py --device 0 --scene wingcam55 --train-frames 8000 \\
        --test-frames 2000 --epochs 300 --batch 16 --model yolo11s.yaml

Needs the ``train`` extra (``pip install -e '.[train]'``). Nothing is downloaded: the model
is built from its YAML (from scratch). Steps, each skipped when its output is already in
``--out`` (a stopped run resumes; training resumes from its last epoch):

1. a rendered training set (``--train-seed``; every frame in the train split) and a held-out
   test set (``--test-seed``: other approaches, skies, seas and liveries);
2. the training frames again with uncorrected (tight) label boxes, the same images (paper
   model H; ``--no-uncorrected`` skips it);
3. ``yolo detect train`` from scratch with each training set's own ``data.yaml`` and
   ``hyp.yaml`` (on a CPU both at once, each on half the cores; ``--batch`` is also the
   nominal batch, so the optimizer steps every batch);
4. ``yolo detect predict`` on every test frame, and ``datagen evaluate --predictions``: the
   detector per class and distance against the true centres, PtD error and reliability;
5. ``datagen evaluate --noise-px 0,0.5,1,2.5`` on the same test frames (paper Figs 14-17);
6. ``summary.json``, ``summary.md`` and plots in ``--out``: PtD error against distance
   for every source, and the detected centres' bias along the parallax direction
   against the tight-box offset, for the corrected and the uncorrected detector.
"""

from __future__ import annotations

import argparse
import csv
import itertools
import json
import os
import platform
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
from matplotlib.figure import Figure

from datagen.analysis.evaluate import REASONS, RunResult, summarize
from datagen.atomic import link_or_copy, write_figure
from datagen.config import find_config, load_config, override_config
from datagen.pipeline.build import build_dataset
from datagen.pipeline.image_lists import write_image_lists
from datagen.pipeline.plan import dataset_layout, plan_shards
from datagen.report.plots import plot_evaluation

NOISE_PX = (0.0, 0.5, 1.0, 2.5)
#: Tight-box offset bins (px) of the bias plot and table.
OFFSET_EDGES = (0.0, 0.5, 1.0, 2.0, 4.0, 8.0, 16.0, np.inf)
BIN = Path(sys.executable).parent


def log(message: str) -> None:
    print(f"[{time.strftime('%H:%M:%S')}] {message}", flush=True)


def config_of(args, seed: int, frames: int, **overrides):
    """The scene with ``frames`` frames in chains of frames_per_approach whatever the count
    (approach.min_approaches 1): the datasets the recorded figures were measured on."""
    config = load_config(find_config(args.scene))
    return override_config(config, {"dataset.frames": frames, "dataset.seed": seed, "approach.min_approaches": 1,
                                    **overrides, **({"render.spp": args.spp} if args.spp else {})})


def build(config, root: Path, workers: int) -> float:
    """Build (or finish) a rendered dataset; seconds spent."""
    start = time.perf_counter()
    build_dataset(config, root, workers=workers)
    return time.perf_counter() - start


def kept_cost(path: Path, measured: dict[str, float]) -> dict[str, float]:
    """Step times of this bench folder, each the longest measured (a resumed run measures only
    what was left of a step), kept in ``path``."""
    kept = json.loads(path.read_text()) if path.is_file() else {}
    for key, seconds in measured.items():
        kept[key] = max(kept.get(key, 0.0), seconds)
    path.write_text(json.dumps(kept))
    return {key: kept[key] for key in measured}


def relabel(config, rendered: Path, root: Path) -> None:
    """``rendered``'s frames with ``config``'s label rules: a labels-only build of the same
    frames (labels do not depend on pixels), the rendered images hard-linked in."""
    build_dataset(config, root, render=False)
    layout = dataset_layout(root, config)
    jobs = plan_shards(config)
    for job in jobs:
        for i in job.frames:
            rel = layout.image_rel(job.split, job.shard, i)
            if not (root / rel).exists():
                link_or_copy(rendered / rel, root / rel)
    write_image_lists(layout, jobs)


def trained_epochs(run: Path) -> int:
    results = run / "results.csv"
    if not results.is_file():
        return 0
    with open(results) as f:
        return len(list(csv.DictReader(f)))


def train(args, data: Path, name: str, threads: int) -> subprocess.Popen | None:
    """Start ``yolo detect train`` on ``data`` (its data.yaml and hyp.yaml), or resume it."""
    run = args.out / "runs" / name
    if trained_epochs(run) >= args.epochs:
        return None
    env = {**os.environ, "OMP_NUM_THREADS": str(threads), "MKL_NUM_THREADS": str(threads)}
    if (run / "weights" / "last.pt").is_file():
        command = [str(BIN / "yolo"), "detect", "train", f"model={run / 'weights' / 'last.pt'}", "resume=True"]
    else:
        command = [str(BIN / "yolo"), "detect", "train", f"data={data / 'data.yaml'}", f"cfg={data / 'hyp.yaml'}",
                   f"model={args.model}", f"epochs={args.epochs}", f"batch={args.batch}", f"nbs={args.batch}",
                   f"device={args.device}", "workers=0" if args.device == "cpu" else f"workers={args.workers}",
                   f"project={args.out / 'runs'}", f"name={name}", "exist_ok=True", "plots=False", "val=False",
                   f"seed={args.train_seed}"]
    log(f"train {name}: {' '.join(command)}")
    log_file = open(args.out / f"train-{name}.log", "a")
    return subprocess.Popen(command, env=env, stdout=log_file, stderr=subprocess.STDOUT)


def losses(run: Path) -> dict[str, list[float]]:
    with open(run / "results.csv") as f:
        rows = [{k.strip(): v for k, v in row.items()} for row in csv.DictReader(f)]
    return {k: [float(r[k]) for r in rows] for k in rows[0] if k.startswith("train/") or k == "time"}


def predict(args, name: str, images: Path, imgsz: int) -> Path:
    folder = args.out / "predict" / name
    if not (folder / "done").is_file():
        shutil.rmtree(folder, ignore_errors=True)
        weights = args.out / "runs" / name / "weights" / "last.pt"
        subprocess.run([str(BIN / "yolo"), "detect", "predict", f"model={weights}",
                        f"source={images}", f"imgsz={imgsz}", "conf=0.001", "save_txt=True", "save_conf=True",
                        "save=False", f"device={args.device}", f"project={args.out / 'predict'}", f"name={name}",
                        "exist_ok=True", "verbose=False"], check=True, capture_output=True)
        (folder / "labels").mkdir(parents=True, exist_ok=True)  # none written when nothing was detected
        (folder / "done").write_text("")
    return folder / "labels"


def evaluate(test: Path, out: Path, *options: str) -> dict:
    if not (out / "evaluation.json").is_file():
        result = subprocess.run([str(BIN / "datagen"), "evaluate", str(test), "--split", "all", "--out", str(out),
                                 *options], check=False, capture_output=True, text=True)
        if result.returncode:
            raise SystemExit(f"datagen evaluate failed:\n{result.stdout}{result.stderr}")
        log("datagen evaluate " + " ".join(options) + ":\n  " + result.stdout.strip().replace("\n", "\n  "))
    return json.loads((out / "evaluation.json").read_text())


def per_frame(out: Path) -> list[RunResult]:
    """Each run of an evaluation (its results.parquet, in the order of evaluation.json's runs)
    as the results the evaluation summarized."""
    table = pq.read_table(out / "results.parquet")
    targets = [run["target"] for run in json.loads((out / "evaluation.json").read_text())["runs"]]
    keys = list(zip(table.column("source").to_pylist(), map(repr, table.column("noise_px").to_pylist()), strict=True))
    results = []
    for key, target in zip(dict.fromkeys(keys), targets, strict=True):
        rows = pa.array([k == key for k in keys])
        t = table.filter(rows)

        def floats(name: str, shape: tuple[int, ...] = (-1,), t=t) -> np.ndarray:
            column = t.column(name).combine_chunks()
            values = column.flatten() if pa.types.is_fixed_size_list(column.type) else column
            return np.asarray(values.to_numpy(zero_copy_only=False), dtype=np.float64).reshape(shape)

        results.append(RunResult(
            frame_id=np.asarray(t.column("frame_id"), dtype=np.int64), distance_m=floats("distance_m"),
            matches_receiver=np.asarray(t.column("matches_receiver"), dtype=np.int32),
            matches_target=np.asarray(t.column("matches_target"), dtype=np.int32),
            reason=np.array([REASONS.index(r) for r in t.column("reason").to_pylist()], dtype=np.int8),
            ptd_m=floats("ptd_m", (-1, 3)), truth_m=floats("truth_m", (-1, 3)), error_m=floats("error_m"),
            error_to_drogue_m=floats("error_to_drogue_m"), solve_s=floats("solve_s"), missing_predictions=0,
            target=target))
    return results


def bias_table(detections: Path) -> list[dict]:
    """Detected labeled features binned by their tight-box offset: the mean error along the
    parallax direction (and its standard error) beside the mean offset."""
    t = pq.read_table(detections, columns=["labeled", "detected", "along_parallax_px", "parallax_uv_px"]).to_pydict()
    along = np.array([np.nan if a is None else a for a in t["along_parallax_px"]], dtype=float)
    offset = np.array([np.nan if p is None else np.hypot(*p) for p in t["parallax_uv_px"]], dtype=float)
    keep = np.array(t["labeled"]) & np.array(t["detected"]) & np.isfinite(along)
    rows = []
    for lo, hi in itertools.pairwise(OFFSET_EDGES):
        sel = keep & (offset >= lo) & (offset < hi)
        n = int(sel.sum())
        rows.append({"lo_px": lo, "hi_px": hi if np.isfinite(hi) else None, "features": n,
                     "offset_mean_px": float(offset[sel].mean()) if n else None,
                     "along_parallax_mean_px": float(along[sel].mean()) if n else None,
                     "along_parallax_sem_px": float(along[sel].std() / np.sqrt(n)) if n > 1 else None})
    return rows


def plot_bias(tables: dict[str, list[dict]], path: Path) -> Path:
    fig = Figure(figsize=(7, 4.5), constrained_layout=True)
    ax = fig.subplots()
    top = 1.0
    for (name, rows), colour in zip(tables.items(), ("C0", "C3"), strict=False):
        rows = [r for r in rows if r["features"] >= 5]
        x = [r["offset_mean_px"] for r in rows]
        y = [r["along_parallax_mean_px"] for r in rows]
        e = [2 * (r["along_parallax_sem_px"] or 0) for r in rows]
        ax.errorbar(x, y, yerr=e, fmt="o-", color=colour, capsize=3, label=f"{name} labels")
        top = max([top, *x])
    ax.plot([0, top], [0, top], "k:", lw=0.8, label="detections at the tight-box (perceived) centre")
    ax.axhline(0, color="k", lw=0.8)
    ax.set(xlabel="tight-box centre - true centre, mean of the bin (px)",
           ylabel="detected - true centre along it, mean +- 2 s.e. (px)",
           title="Where the detector puts a feature: the true or the perceived centre")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8)
    return write_figure(path, fig, dpi=110)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--scene", default="podcam15")
    parser.add_argument("--train-frames", type=int, default=240)
    parser.add_argument("--test-frames", type=int, default=80)
    parser.add_argument("--train-seed", type=int, default=2024, help="not a seed any shipped config uses")
    parser.add_argument("--test-seed", type=int, default=4048)
    parser.add_argument("--spp", type=int, default=None, help="render.spp (default: the scene's)")
    parser.add_argument("--epochs", type=int, default=24)
    parser.add_argument("--batch", type=int, default=4)
    parser.add_argument("--model", default="yolo11n.yaml")
    parser.add_argument("--device", default="cpu")
    parser.add_argument("--workers", type=int, default=8, help="dataloader workers on a GPU")
    parser.add_argument("--build-workers", type=int, default=None, help="datagen build --workers")
    parser.add_argument("--no-uncorrected", action="store_true", help="skip the uncorrected model (H)")
    parser.add_argument("--out", type=Path, default=Path("runs/closed-loop"))
    args = parser.parse_args()
    args.out = args.out.resolve()
    args.out.mkdir(parents=True, exist_ok=True)
    cores = os.cpu_count() or 1
    started = time.perf_counter()
    cost: dict = {"machine": f"{platform.machine()}, {cores} CPUs, {platform.python_version()}", "device": args.device}

    train_config = config_of(args, args.train_seed, args.train_frames, **{"dataset.val_fraction": 0.0})
    test_config = config_of(args, args.test_seed, args.test_frames)
    sets = {"corrected": args.out / "train"}
    log(f"build {args.train_frames} training frames of {train_config.name} (seed {args.train_seed})")
    now = {"build_train_s": build(train_config, sets["corrected"], args.build_workers)}
    log(f"build {args.test_frames} test frames (seed {args.test_seed})")
    now["build_test_s"] = build(test_config, args.out / "test", args.build_workers)
    if not args.no_uncorrected:
        sets["uncorrected"] = args.out / "train-uncorrected"
        relabel(override_config(train_config, {"labels.corrected": False}), sets["corrected"], sets["uncorrected"])
    imgsz = train_config.labels.train_imgsz

    start = time.perf_counter()
    threads = max(1, cores // len(sets)) if args.device == "cpu" else cores
    jobs = [(name, train(args, root, name, threads)) for name, root in sets.items()]
    for name, job in jobs:
        if job is not None and job.wait():
            raise SystemExit(f"training {name} failed: see {args.out / f'train-{name}.log'}")
    now["train_wall_s"] = time.perf_counter() - start
    cost.update(kept_cost(args.out / "cost.json", now))  # this run's times, or a longer earlier one's
    cost.update({"epochs": args.epochs, "train_images": args.train_frames, "batch": args.batch, "model": args.model,
                 "imgsz": imgsz, "trained_in_parallel": len(sets) if args.device == "cpu" else 1})

    images = args.out / "test-images.txt"
    images.write_text("".join(str(args.out / "test" / line.strip()) + "\n"
                              for split in ("train", "val") if (args.out / "test" / f"{split}.txt").is_file()
                              for line in (args.out / "test" / f"{split}.txt").read_text().splitlines()))
    summary: dict = {"scene": train_config.name, "train_seed": args.train_seed, "test_seed": args.test_seed,
                     "test_frames": args.test_frames, "cost": cost, "models": {}}
    truth = evaluate(args.out / "test", args.out / "eval" / "truth", "--noise-px", ",".join(f"{r:g}" for r in NOISE_PX))
    truth_results = per_frame(args.out / "eval" / "truth")
    plots_runs = list(zip(truth["runs"], truth_results, strict=True))
    plots_summaries = [summarize(r) for r in truth_results]
    bias = {}
    for name in sets:
        start = time.perf_counter()
        labels = predict(args, name, images, imgsz)
        predict_s = time.perf_counter() - start
        doc = evaluate(args.out / "test", args.out / "eval" / name, "--predictions", str(labels))
        bias[name] = bias_table(args.out / "eval" / name / "detections.parquet")
        (run,) = doc["runs"]
        summary["models"][name] = {"losses": losses(args.out / "runs" / name), "predict_s": predict_s,
                                   "detector": doc["detector"],
                                   "ptd": {k: run[k] for k in ("overall", "at", "by_distance", "reasons")},
                                   "bias_by_offset": bias[name]}
        (result,) = per_frame(args.out / "eval" / name)
        plots_runs.append(({"source": "predictions", "predictions": f"{name} labels"}, result))
        plots_summaries.append(summarize(result))
    plots = plot_evaluation(plots_runs, plots_summaries, args.out / "plots", name=f"{train_config.name} held-out")
    plots["bias"] = plot_bias(bias, args.out / "plots" / "bias_along_parallax.png")
    summary["truth"] = [{k: run[k] for k in ("noise_px", "overall", "at", "by_distance")} for run in truth["runs"]]
    summary["plots"] = {k: str(v) for k, v in plots.items()}
    # The steps' kept times, and the rest (predictions and evaluations) as this run measured it.
    rest = time.perf_counter() - started - sum(now[k] for k in ("build_train_s", "build_test_s", "train_wall_s"))
    cost["total_s"] = cost["build_train_s"] + cost["build_test_s"] + cost["train_wall_s"] + rest
    (args.out / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
    (args.out / "summary.md").write_text(markdown(summary))
    print(markdown(summary))


def _f(value, digits: int = 2, unit: str = "") -> str:
    return "-" if value is None else f"{value:.{digits}f}{unit}"


def markdown(s: dict) -> str:
    c = s["cost"]
    lines = [(f"## Closed loop: {s['scene']}, trained on {c['train_images']} frames (seed {s['train_seed']}), "
              f"tested on {s['test_frames']} held-out frames (seed {s['test_seed']})"), "",
             (f"Training: `{c['model']}` from scratch, imgsz {c['imgsz']}, {c['epochs']} epochs, batch {c['batch']} "
              f"(= nominal batch), {c['trained_in_parallel']} model(s) at once, {c['train_wall_s'] / 60:.1f} min; "
              f"builds {c['build_train_s'] / 60:.1f} + {c['build_test_s'] / 60:.1f} min; whole bench "
              f"{c['total_s'] / 60:.1f} min; {c['machine']}, device {c['device']}."), ""]
    for name, m in s["models"].items():
        loss = m["losses"]
        box = loss.get("train/box_loss", [])
        lines += [f"### {name} labels", "",
                  (f"Box loss per epoch: {', '.join(f'{x:.3g}' for x in box[:3])} ... "
                   f"{', '.join(f'{x:.3g}' for x in box[-3:])}; "
                   f"cls loss {loss['train/cls_loss'][0]:.3g} -> {loss['train/cls_loss'][-1]:.3g}."), ""]
        d = m["detector"]
        lines += [f"Detector on the held-out frames (match: within {d['match_px']:g} px of the true centre):", "",
                  ("| distance (m) | labeled | found | recall | mislocated | missed | spurious | error median px "
                   "| error p95 px | along parallax mean px | tight-box offset mean px |"),
                  "|---|---|---|---|---|---|---|---|---|---|---|"]
        for b in [*d["by_distance"], {"lo_m": None, **d["overall"]}]:
            if not (b["labeled"] or b["spurious"]):
                continue
            where = "all" if b["lo_m"] is None else f"{b['lo_m']:g}-{b['hi_m']:g}"
            recall = _f(b['recall'] and 100 * b['recall'], 1, '%')
            lines.append(f"| {where} | {b['labeled']} | {b['matched']} | {recall} | "
                         f"{b['mislocated']} | {b['missed']} | {b['spurious']} | {_f(b['error_median_px'])} | "
                         f"{_f(b['error_p95_px'])} | {_f(b['along_parallax_mean_px'])} | "
                         f"{_f(b['parallax_offset_mean_px'])} |")
        lines += ["", "Per object:", "", "| object | labeled | recall | error median px | error p95 px |",
                  "|---|---|---|---|---|"]
        objects: dict[str, list] = {}
        for cls, v in d["by_class"].items():
            objects.setdefault(cls.split(".")[0], []).append(v)
        for obj, rows in objects.items():
            labeled = sum(r["labeled"] for r in rows)
            matched = sum(r["matched"] for r in rows)
            med = [r["error_median_px"] for r in rows if r["error_median_px"] is not None]
            p95 = [r["error_p95_px"] for r in rows if r["error_p95_px"] is not None]
            lines.append(f"| {obj} | {labeled} | {_f(labeled and 100 * matched / labeled, 1, '%')} | "
                         f"{_f(float(np.median(med)) if med else None)} (median of classes) | "
                         f"{_f(float(np.median(p95)) if p95 else None)} |")
        lines += ["", "Bias along the parallax direction, by tight-box offset:", "",
                  "| offset bin px | features | offset mean px | along-parallax error mean px (+- s.e.) |",
                  "|---|---|---|---|"]
        for r in m["bias_by_offset"]:
            if r["features"]:
                hi = "inf" if r["hi_px"] is None else f"{r['hi_px']:g}"
                lines.append(f"| {r['lo_px']:g}-{hi} | {r['features']} | {_f(r['offset_mean_px'])} | "
                             f"{_f(r['along_parallax_mean_px'])} (+- {_f(r['along_parallax_sem_px'])}) |")
        lines.append("")
    lines += ["### PtD vector error (m) against distance, and reliability", "",
              "| source | reliability | mean | +2 sigma | at contact (< 0.5 m) mean | frames |",
              "|---|---|---|---|---|---|"]
    rows = [(f"truth + {t['noise_px']:g} px", t) for t in s["truth"]]
    rows += [(f"detector ({name} labels)", m["ptd"]) for name, m in s["models"].items()]
    for label, r in rows:
        o, contact = r["overall"], r["at"]["contact"]
        lines.append(f"| {label} | {_f(o['reliability'] and 100 * o['reliability'], 1, '%')} | {_f(o['mean_m'], 3)} | "
                     f"{_f(o['plus_2sigma_m'], 3)} | {_f(contact['mean_m'], 3)} | {o['attempts']} |")
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    main()
