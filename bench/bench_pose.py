"""Pose labels (issue 19): how many keypoints a pose set carries and how many of its
instances the trainer can learn, per shipped scene and truncation rule.

    python bench/bench_pose.py [--frames 2000] [--seed 2024] [--dataloader-frames 200]

For each scene (wingcam55, podcam15, dashcam75) and each ``labels.truncated_objects``
(exclude, clip), a labels-only build of ``--frames`` frames with ``labels.format: both`` at a
held-out seed, then:

- the labeled features that land in a pose instance (the rest are keypoints no pose line
  carries: their object is excluded);
- the learnable share of pose instances at ``labels.train_imgsz`` without mosaic, measured as
  ``datagen audit`` measures boxes (``datagen.core.training``);
- the build time with pose labels against the same build with detect labels only.

With Ultralytics installed (the ``train`` extra), ``--dataloader-frames`` frames of each
pose set also go through Ultralytics' own pose training dataloader with the pose hyp.yaml
(mosaic, scale, translate on): the images it keeps, the instances that come out and the
share of those whose box holds an anchor centre (strides 8/16/32).
"""

from __future__ import annotations

import argparse
import os
import platform
import shutil
import tempfile
import time
from pathlib import Path

import numpy as np

from datagen.analysis.audit import audit
from datagen.config import load_config, override_config
from datagen.config.schema import Config
from datagen.core.training import TrainView
from datagen.dataset.reader import load_dataset
from datagen.pipeline.build import build_dataset
from datagen.pipeline.image_lists import write_placeholder_images
from datagen.pipeline.plan import dataset_layout, plan_shards

ROOT = Path(__file__).resolve().parents[1]
SCENES = ("wingcam55", "podcam15", "dashcam75")


def build(scene: str, out: Path, frames: int, seed: int, **overrides) -> float:
    config = override_config(load_config(ROOT / "scenes" / f"{scene}.yaml"),
                             {"dataset.frames": frames, "dataset.seed": seed, **overrides})
    start = time.perf_counter()
    build_dataset(config, out, render=False, workers=1)
    return time.perf_counter() - start


def blank_images(root: Path) -> None:
    """Grey placeholder images for a labels-only build (the dataloader reads images)."""
    view = load_dataset(root)
    config = Config.model_validate(view.doc["config"])
    write_placeholder_images(dataset_layout(root, config), plan_shards(config), config.camera.width,
                             config.camera.height)


def dataloader_shares(pose_root: Path) -> dict:
    from datagen.analysis.ultralytics import pose_items

    seen = pose_items(pose_root, "train")
    imgsz = seen["imgsz"]
    boxes = np.concatenate([item["xyxy"] for item in seen["items"]]) if seen["items"] else np.zeros((0, 4))
    anchored = TrainView(imgsz, imgsz, imgsz).has_anchor(boxes)  # boxes already on the square input
    listed = len((pose_root / "train.txt").read_text().splitlines())
    return {"images_kept": f"{len(seen['im_files'])}/{listed}", "lines": seen["lines"], "instances_out": len(boxes),
            "anchored_share": float(anchored.mean()) if len(boxes) else None}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=2000)
    parser.add_argument("--seed", type=int, default=2024)
    parser.add_argument("--dataloader-frames", type=int, default=200)
    args = parser.parse_args()
    try:
        import ultralytics  # noqa: F401
        have_ultralytics = True
    except ImportError:
        have_ultralytics = False
    print(f"# {platform.node()} {platform.processor() or platform.machine()}, {os.cpu_count()} cores; "
          f"{args.frames} labels-only frames per build, seed {args.seed}")
    print("| scene | truncated_objects | pose instances / frame | labeled features in an instance | learnable "
          "instances (no mosaic) | build s (pose+detect / detect) | Ultralytics pose dataloader |")
    print("|---|---|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        for scene in SCENES:
            detect_s = build(scene, tmp / f"{scene}-detect", args.frames, args.seed)
            for truncated in ("exclude", "clip"):
                root = tmp / f"{scene}-{truncated}"
                both_s = build(scene, root, args.frames, args.seed, **{"labels.format": "both",
                                                                       "labels.truncated_objects": truncated})
                view = load_dataset(root)
                in_instance = view.labeled & np.equal(view.object_exclusion[:, view.features.object_index], None)
                stats = audit(view).stats.learnable_pose
                assert stats is not None
                loader = "-"
                if have_ultralytics:
                    small = tmp / f"{scene}-{truncated}-loader"
                    build(scene, small, args.dataloader_frames, args.seed,
                          **{"labels.format": "both", "labels.truncated_objects": truncated})
                    blank_images(small)
                    shares = dataloader_shares(small / "pose")
                    loader = (f"{shares['images_kept']} images kept, {shares['instances_out']} instances out of "
                              f"{shares['lines']} lines, {100 * (shares['anchored_share'] or 0):.1f}% anchored")
                share = "-" if stats.share is None else f"{100 * stats.share:.1f}%"
                print(f"| {scene} | {truncated} | {stats.instances / len(view):.2f} | "
                      f"{in_instance.sum():,} / {view.labeled.sum():,} "
                      f"({100 * in_instance.sum() / view.labeled.sum():.1f}%) | "
                      f"{share} | {both_s:.1f} / {detect_s:.1f} | {loader} |")
                shutil.rmtree(root)


if __name__ == "__main__":
    main()
