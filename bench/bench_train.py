"""Labels a detector can learn, end to end through Ultralytics.

    python bench/bench_train.py [--frames 24] [--spp 4] [--epochs 3] [--batch 4] [--seed 2024]
    python bench/bench_train.py --sweep [--sweep-frames 1000] [--plot docs/learnable-sizes.png]
    python bench/bench_train.py --memorize [--epochs 100] [--min-box-px 48] [--optimizer SGD]
        [--nbs 4] [--model yolo11n.yaml]

Needs the ``train`` extra (``pip install -e '.[train]'``). Default run:

1. builds a rendered wingcam55 dataset of ``--frames`` frames at ``--spp`` with a
   held-out seed (not the config's) and its train.txt / val.txt;
2. runs every image of both splits through Ultralytics' own training dataloader
   with the dataset's hyp.yaml and counts the label lines it keeps and those that
   hold an anchor centre of the detection head (``datagen.analysis.ultralytics``), beside what
   ``datagen audit`` computes without Ultralytics;
3. trains ``yolo11n.yaml`` (from scratch: nothing is downloaded) for ``--epochs``
   epochs on the CPU with the dataset's recipe, counting the instances the trainer
   sees per epoch and reading its box loss;
4. predicts ``val.txt`` and scores the detections with ``datagen evaluate --predictions``.

``--memorize`` is the first test of training data: every frame in the train split (val
is the same frames), trained from scratch for ``--epochs`` with the dataset's own
data.yaml and hyp.yaml (``--min-box-px``, ``--optimizer`` and ``--nbs`` vary the recipe
against it), then predicted and scored by ``datagen evaluate --predictions``: the share
of label lines found (right class, conf >= 0.25, centre within 3 px at full resolution).
On a 2-core CPU with one thread an epoch of 24 frames takes about 18 s.

``--sweep`` chooses ``labels.min_box_px``: labels-only builds of ``--sweep-frames``
frames for several minimum sizes, and per size the learnable share (datagen's rule,
which equals Ultralytics' dataloader line for line: tests/test_train.py), the share
of learnable boxes whose every anchor centre also lies in another box of the frame
(the assigner then gives those anchors to one box only), edge-margin exclusions,
labels per frame, and what Ultralytics' own detection loss gives the label lines on
an untrained yolo11n and yolo26n (``datagen.analysis.ultralytics.assigner_positives``):
positive anchors, and the targets that weigh them (a label box much smaller than the
untrained head's first guesses gets a target near zero and teaches nothing).
"""

from __future__ import annotations

import argparse
import csv
import platform
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from datagen.config import load_config, override_config
from datagen.core.training import ANCHOR_STRIDES
from datagen.dataset.reader import load_dataset
from datagen.pipeline.build import build_dataset

ROOT = Path(__file__).resolve().parents[1]


def config_for(seed: int, frames: int, **overrides):
    """wingcam55 with ``frames`` frames: chains of frames_per_approach frames whatever the
    count (approach.min_approaches 1), the datasets the recorded figures were measured on."""
    return override_config(load_config(ROOT / "scenes" / "wingcam55.yaml"),
                           {"dataset.frames": frames, "dataset.seed": seed, "approach.min_approaches": 1,
                            **overrides})


# --- the sweep ---------------------------------------------------------------------------------
def contested(view) -> tuple[int, int]:
    """(learnable label boxes, those whose every anchor centre lies in another labeled box too)."""
    train = view.train_view
    imgsz = train.imgsz
    total = shared = 0
    for b in range(len(view)):
        boxes = train.to_train(view.label_xyxy[b][view.labeled[b]])
        if not len(boxes):
            continue
        learnable = train.learnable(view.label_xyxy[b][view.labeled[b]])
        for j in np.flatnonzero(learnable):
            x0, y0, x1, y1 = boxes[j]
            others = np.delete(boxes, j, axis=0)
            own = True
            for s in ANCHOR_STRIDES:
                c = (np.arange(imgsz // s) + 0.5) * s
                xs, ys = c[(c > x0) & (c < x1)], c[(c > y0) & (c < y1)]
                for x in xs:
                    for y in ys:
                        if not np.any((others[:, 0] < x) & (x < others[:, 2]) & (others[:, 1] < y)
                                      & (y < others[:, 3])):
                            own = False
                            break
                    if not own:
                        break
                if not own:
                    break
            total += 1
            shared += own
    return total, shared


def blank_images(root: Path, config) -> None:
    """Grey placeholder images and the image lists: Ultralytics' dataloader needs images to
    exist, not rendered ones (labels do not depend on pixels)."""
    from datagen.pipeline.image_lists import write_placeholder_images
    from datagen.pipeline.plan import dataset_layout, plan_shards

    write_placeholder_images(dataset_layout(root, config), plan_shards(config), config.camera.width,
                             config.camera.height)


def sweep(args) -> None:
    from datagen.analysis.audit import audit
    from datagen.analysis.ultralytics import assigner_positives

    models = ("yolo11n.yaml", "yolo26n.yaml")
    print(f"min_box_px sweep: wingcam55, {args.sweep_frames} labels-only frames, seed {args.seed}, imgsz 864, "
          f"{platform.machine()} {platform.node()}; assigner: untrained {' and '.join(models)} (torch seed 0) on "
          f"the first {args.assigner_images} train images: instances with a positive anchor, the median "
          "instance's best target, instances whose best target is at least 0.01")
    print("| min_box_px | label lines | per frame | edge_margin excluded | learnable | all anchors shared | "
          + " | ".join(f"{m}: positive, median target, target >= 0.01" for m in models) + " |")
    print("|---|---|---|---|---|---|" + "---|" * len(models))
    sizes = (0.0, 8.0, 16.0, 24.0, 32.0, 48.0, 64.0)
    rows: dict[str, list[float]] = {"learnable": []} | {f"{m} targeted": [] for m in models}
    for size in sizes:
        with tempfile.TemporaryDirectory() as tmp:
            config = config_for(args.seed, args.sweep_frames, **{"labels.min_box_px": size})
            report = build_dataset(config, Path(tmp) / "ds", render=False)
            view = load_dataset(Path(tmp) / "ds")
            found = audit(view).stats.learnable
            assert found is not None and found.share is not None
            share = found.share
            learnable, shared = contested(view)
            blank_images(Path(tmp) / "ds", config)
            cells = []
            rows["learnable"].append(100 * share)
            for model in models:
                a = assigner_positives(Path(tmp) / "ds", "train", images=args.assigner_images, model=model)
                n = max(1, a["instances"])
                rows[f"{model} targeted"].append(100 * a["targeted"] / n)
                cells.append(f"{100 * a['positive'] / n:.1f}%, {a['target_median']:.2g}, "
                             f"{100 * a['targeted'] / n:.1f}%")
            print(f"| {size:g} | {report.labels} | {report.labels / report.frames:.1f} | "
                  f"{report.excluded['edge_margin']} | {100 * share:.1f}% | "
                  f"{100 * shared / max(1, learnable):.1f}% | " + " | ".join(cells) + " |", flush=True)
    if args.plot:
        plot_sweep(sizes, rows, args.plot)


def plot_sweep(sizes, rows: dict[str, list[float]], path: str) -> None:
    """The sweep's shares against the minimum box size, beside its table in the docs."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from datagen.atomic import write_figure

    fig, ax = plt.subplots(figsize=(6.4, 3.6), layout="constrained")
    labels = {"learnable": "learnable share (datagen audit = Ultralytics' dataloader)"}
    for (name, values), marker in zip(rows.items(), "os^", strict=False):
        ax.plot(sizes, values, marker=marker, label=labels.get(name, f"{name.split()[0]}: target >= 0.01 (untrained)"))
    ax.set_xlabel("labels.min_box_px (px at imgsz 864)")
    ax.set_ylabel("label lines (%)")
    ax.set_ylim(0, 102)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="lower right")
    write_figure(path, fig, dpi=120)
    print(f"plot: {path}")


# --- the end-to-end run ---------------------------------------------------------------------------
def train_and_count(root: Path, runs: Path, epochs: int, batch: int, *, model_name: str = "yolo11n.yaml",
                    nbs: int | None = None, optimizer: str | None = None) -> dict:
    """Train ``model_name`` with the dataset's recipe (``nbs`` and ``optimizer`` override it);
    instances per epoch and losses per epoch."""
    import yaml
    from ultralytics import YOLO

    seen: dict[int, int] = {}
    box_loss: list[float] = []

    def epoch_end(trainer) -> None:  # the epoch's mean loss items, unrounded (results.csv keeps 5 decimals)
        items = trainer.tloss if isinstance(trainer.tloss, dict) else {}
        box_loss.extend(float(v) for k, v in items.items() if "box" in k)

    def count(trainer) -> None:
        original = trainer.preprocess_batch

        def wrapped(batch_dict):
            seen[trainer.epoch] = seen.get(trainer.epoch, 0) + int(batch_dict["cls"].shape[0])
            return original(batch_dict)

        trainer.preprocess_batch = wrapped

    model = YOLO(model_name)
    model.add_callback("on_train_start", count)
    model.add_callback("on_train_epoch_end", epoch_end)
    hyp = yaml.safe_load((root / "hyp.yaml").read_text())
    start = time.perf_counter()
    recipe = {"nbs": nbs or batch, **({"optimizer": optimizer} if optimizer else {})}
    model.train(data=str(root / "data.yaml"), cfg=str(root / "hyp.yaml"), epochs=epochs, batch=batch, workers=0,
                device="cpu", project=str(runs), name="train", exist_ok=True, plots=False, verbose=False, **recipe)
    wall = time.perf_counter() - start
    with open(runs / "train" / "results.csv") as f:
        rows = list(csv.DictReader(f))
    return {"imgsz": hyp["imgsz"], "seconds": wall, "instances": [seen.get(e, 0) for e in range(epochs)],
            "box_loss": box_loss or [float(r["train/box_loss"]) for r in rows],
            "cls_loss": [float(r["train/cls_loss"]) for r in rows], "weights": runs / "train" / "weights" / "last.pt"}


def end_to_end(args) -> None:
    from datagen.analysis.audit import audit
    from datagen.analysis.ultralytics import assigner_positives, dataloader_learnability

    out = Path(args.out or tempfile.mkdtemp(prefix="bench-train-"))
    root = out / "w55"
    shutil.rmtree(root, ignore_errors=True)  # this benchmark's own folder: time a fresh build
    start = time.perf_counter()
    build_dataset(config_for(args.seed, args.frames, **{"render.spp": args.spp}), root, overwrite=True)
    print(f"build: {args.frames} frames at {args.spp} spp in {time.perf_counter() - start:.1f} s -> {root}")
    view = load_dataset(root)
    learn = audit(view).stats.learnable
    assert learn is not None and learn.share is not None and learn.min_side_train_px is not None
    print(f"datagen audit: {learn.lines} label lines, learnable {100 * learn.share:.1f}% "
          f"(min side at imgsz {learn.train_imgsz}: {learn.min_side_train_px:.2f} px)")
    for split in ("train", "val"):
        seen = dataloader_learnability(root, split)
        n = max(1, seen["lines"])
        print(f"Ultralytics training dataloader, {split}: {seen['images']} images, {seen['lines']} label lines, "
              f"kept {seen['kept']} ({100 * seen['kept'] / n:.1f}%), with an anchor centre inside "
              f"{seen['anchored']} ({100 * seen['anchored'] / n:.1f}%), assigner candidates "
              f"{seen['assigner_candidates']} ({100 * seen['assigner_candidates'] / n:.1f}%)")
    assigned = assigner_positives(root, "train")
    print(f"Ultralytics' detection-loss assigner, untrained yolo11n.yaml: {assigned['positive']} of "
          f"{assigned['label_lines']} train label lines get a positive anchor "
          f"({100 * assigned['positive'] / max(1, assigned['label_lines']):.1f}%), {assigned['targeted']} a target of "
          f"at least 0.01 (median best target {assigned['target_median']:.2g}, sum {assigned['target_sum']:.3g})")
    trained = train_and_count(root, out / "runs", args.epochs, args.batch)
    print(f"train yolo11n.yaml, imgsz {trained['imgsz']}, {args.epochs} epochs in {trained['seconds']:.0f} s (CPU): "
          f"instances per epoch {trained['instances']}, box loss per epoch "
          f"{', '.join(f'{x:.3g}' for x in trained['box_loss'])}, cls loss per epoch "
          f"{', '.join(f'{x:.3g}' for x in trained['cls_loss'])}")
    predict_and_evaluate(root, out, trained, "val")


def memorize(args) -> None:
    out = Path(args.out or tempfile.mkdtemp(prefix="bench-memorize-"))
    root = out / "w55"
    config = config_for(args.seed, args.frames, **{"render.spp": args.spp, "dataset.val_fraction": 0.0,
                                                   "labels.min_box_px": args.min_box_px})
    build_dataset(config, root)  # resumes; the training below resumes too
    view = load_dataset(root)
    print(f"memorize: {len(view)} wingcam55 frames (seed {args.seed}, {args.spp} spp), min_box_px "
          f"{args.min_box_px:g}, {int(view.labeled.sum())} label lines; {args.model}, {args.epochs} epochs, batch "
          f"{args.batch}, nbs {args.nbs or args.batch}, optimizer {args.optimizer or 'from hyp.yaml'}; "
          f"{platform.machine()} {platform.node()}, torch threads from OMP_NUM_THREADS")
    trained = train_and_count(root, out / "runs", args.epochs, args.batch, model_name=args.model, nbs=args.nbs,
                              optimizer=args.optimizer)
    print(f"trained in {trained['seconds']:.0f} s; box loss first/last {trained['box_loss'][0]:.3g} / "
          f"{trained['box_loss'][-1]:.3g}, cls loss first/last {trained['cls_loss'][0]:.3g} / "
          f"{trained['cls_loss'][-1]:.3g}")
    predict_and_evaluate(root, out, trained, "train")


def predict_and_evaluate(root: Path, out: Path, trained: dict, split: str) -> None:
    """``yolo detect predict`` on the split's images, scored by ``datagen evaluate --predictions``."""
    yolo = str(Path(sys.executable).parent / "yolo")
    subprocess.run([yolo, "detect", "predict", f"model={trained['weights']}", f"source={root / f'{split}.txt'}",
                    f"imgsz={trained['imgsz']}", "conf=0.001", "save_txt=True", "save_conf=True", "save=False",
                    f"project={out / 'runs'}", "name=predict", "exist_ok=True"], check=True, capture_output=True)
    (out / "runs" / "predict" / "labels").mkdir(parents=True, exist_ok=True)  # none when nothing was detected
    evaluation = subprocess.run([sys.executable, "-m", "datagen", "evaluate", str(root), "--split", split,
                                 "--predictions", str(out / "runs" / "predict" / "labels"), "--conf", "0.25",
                                 "--out", str(out / "evaluation")], check=False, capture_output=True, text=True)
    print(f"datagen evaluate --predictions ({split} frames):")
    print("  " + (evaluation.stdout + evaluation.stderr).strip().replace("\n", "\n  "))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--frames", type=int, default=24)
    parser.add_argument("--spp", type=int, default=4)
    parser.add_argument("--epochs", type=int, default=3)
    parser.add_argument("--batch", type=int, default=4)
    parser.add_argument("--seed", type=int, default=2024, help="held out: no shipped config uses it")
    parser.add_argument("--out", type=str, default=None)
    parser.add_argument("--sweep", action="store_true", help="choose labels.min_box_px instead")
    parser.add_argument("--memorize", action="store_true", help="train on the frames, find their features")
    parser.add_argument("--min-box-px", type=float, default=48.0, help="--memorize: labels.min_box_px")
    parser.add_argument("--optimizer", default=None, help="--memorize: instead of hyp.yaml's (e.g. auto)")
    parser.add_argument("--nbs", type=int, default=None, help="nominal batch (default: --batch)")
    parser.add_argument("--model", default="yolo11n.yaml", help="--memorize: the network, from scratch")
    parser.add_argument("--sweep-frames", type=int, default=1000)
    parser.add_argument("--assigner-images", type=int, default=128)
    parser.add_argument("--plot", default=None, help="--sweep: also plot the shares against the size here")
    args = parser.parse_args()
    sweep(args) if args.sweep else memorize(args) if args.memorize else end_to_end(args)


if __name__ == "__main__":
    main()
