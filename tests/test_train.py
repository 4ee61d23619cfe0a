"""datagen's labels through Ultralytics' own code: the label verifier, the training
dataloader at the recipe's imgsz, the label caches it leaves behind, and the documented
train -> predict -> evaluate commands run offline from another folder.

Marked ``train``: they need the ``train`` extra (``pip install -e '.[train]'``, which
pulls torch) and are skipped cleanly without it; CI does not install it.
"""

from __future__ import annotations

import os
import shlex
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

from datagen.analysis.audit import audit
from datagen.config import load_config, override_config
from datagen.dataset.layout import Layout
from datagen.dataset.reader import load_dataset
from datagen.pipeline.build import build_dataset
from datagen.pipeline.image_lists import write_placeholder_images
from datagen.pipeline.plan import dataset_layout, plan_shards

pytestmark = pytest.mark.train
pytest.importorskip("ultralytics", reason="needs the train extra: pip install -e '.[train]'")

from datagen.analysis.ultralytics import dataloader_learnability, pose_items  # noqa: E402  (imports Ultralytics lazily)

ROOT = Path(__file__).resolve().parents[1]
#: Not a seed any shipped config uses: the labels are checked on frames nobody tuned on.
HELD_OUT_SEED = 2024


def labels_with_blank_images(root: Path, frames: int, scene: str = "wingcam55", **overrides) -> Path:
    """A labels-only build whose images are one grey PNG, hard-linked at every frame's image
    path: Ultralytics' dataloader needs images, but not rendered ones."""
    config = override_config(load_config(ROOT / "scenes" / f"{scene}.yaml"),
                             {"dataset.frames": frames, "dataset.seed": HELD_OUT_SEED, **overrides})
    build_dataset(config, root, render=False)
    write_placeholder_images(dataset_layout(root, config), plan_shards(config), config.camera.width,
                             config.camera.height)
    return root


@pytest.fixture(scope="module")
def held_out(tmp_path_factory) -> Path:
    return labels_with_blank_images(tmp_path_factory.mktemp("train") / "ds", 200)


@pytest.fixture(scope="module")
def rendered(tmp_path_factory) -> Path:
    """Eight rendered wingcam55 frames (1 spp; frame 7 is the val split) in ``.../data/w55``."""
    config = override_config(load_config(ROOT / "scenes" / "wingcam55.yaml"),
                             {"dataset.frames": 8, "dataset.seed": HELD_OUT_SEED, "render.spp": 1})
    root = tmp_path_factory.mktemp("train") / "data" / "w55"
    build_dataset(config, root)
    return root


def test_ultralytics_keeps_and_anchors_at_least_95_percent_of_label_lines(held_out) -> None:
    for split in ("train", "val"):
        seen = dataloader_learnability(held_out, split)
        assert seen["imgsz"] == 864 and seen["lines"] > 1000
        assert seen["kept"] / seen["lines"] >= 0.95, seen
        assert seen["anchored"] / seen["lines"] >= 0.95, seen


def test_datagen_learnable_rule_equals_ultralytics_line_by_line(tmp_path: Path) -> None:
    """With no minimum size most lines are lost; datagen's audit must say which, exactly: the
    lines Ultralytics' dataloader keeps with an anchor centre are those datagen says reach
    the loss, and the learnable ones are among them."""
    root = labels_with_blank_images(tmp_path / "ds", 120, **{"labels.min_box_px": 0.0})
    seen = dataloader_learnability(root, "train")
    assert seen["kept"] < 0.6 * seen["lines"] and seen["anchored"] < seen["kept"]
    view = load_dataset(root)
    row = {Path(p).stem: b for b, p in enumerate(view.label_path)}
    for i, image in enumerate(seen["im_files"]):
        b = row[Path(image).stem]
        classes = np.flatnonzero(view.labeled[b])
        boxes = view.label_xyxy[b][view.labeled[b]]
        mine = seen["image"] == i
        assert set(classes[view.train_view.survives(boxes)]) == set(seen["classes"][mine]), image
        anchored = set(seen["classes"][mine & seen["anchored_mask"]])
        assert set(classes[view.train_view.reaches_loss(boxes)]) == anchored, image
        assert set(classes[view.train_view.learnable(boxes)]) <= anchored  # and large enough for a target
    learnable = audit(view).stats.learnable
    assert learnable is not None
    share = learnable.share
    assert share < 0.95
    assert not {c.name: c for c in audit(view).checks}["learnable"].passed


def test_ultralytics_label_verifier_accepts_every_label_file(held_out) -> None:
    from ultralytics.data.utils import verify_image_label

    view = load_dataset(held_out)
    nc = len(view.features)
    for b in range(0, len(view), 7):
        image = held_out / Layout(held_out).image_rel(view.split[b], int(view.label_path[b].split("/")[2]),
                                                       int(view.frame_id[b]))
        result = verify_image_label((str(image), str(held_out / view.label_path[b]), "", False, nc, 0, 0, False))
        _, lb, shape, _, _, missing, _found, _empty, corrupt, msg = result
        assert (missing, corrupt) == (0, 0) and msg == "", msg
        assert len(lb) == int(view.labeled[b].sum()) and shape == (1080, 2048)


def test_audit_passes_after_ultralytics_wrote_its_label_caches(rendered) -> None:
    for split in ("train", "val"):
        dataloader_learnability(rendered, split)
    caches = list((rendered / "labels").rglob("*.cache"))
    assert len(caches) == 2  # Ultralytics writes labels/{split}/{shard}.cache beside the label folders
    result = audit(load_dataset(rendered))
    assert result.passed, [(c.name, c.offenders[:3]) for c in result.checks if not c.passed]


def documented_commands(root: Path) -> list[str]:
    """The commands the dataset's hyp.yaml gives (the README gives the same)."""
    lines = (root / "hyp.yaml").read_text().splitlines()
    return [line.removeprefix("#").strip() for line in lines if line.startswith("#   ")]


def test_documented_train_predict_evaluate_commands_run_offline_from_another_folder(rendered, tmp_path) -> None:
    """The hyp.yaml's Ultralytics and evaluate commands, as written, from another folder and a
    shell whose PATH lacks the environment's bin folder (the commands spell it out)."""
    root = rendered
    commands = documented_commands(root)
    bin_dir = Path(sys.executable).parent
    assert [c.split()[:3] for c in commands] == [[str(bin_dir / "datagen"), "train", str(root)],
                                                 [str(bin_dir / "yolo"), "detect", "train"],
                                                 [str(bin_dir / "yolo"), "detect", "predict"],
                                                 [str(bin_dir / "datagen"), "evaluate", str(root)]]
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    path = os.pathsep.join(p for p in os.environ["PATH"].split(os.pathsep) if Path(p) != bin_dir)
    env = {**os.environ, "PATH": path}
    extra = {"train": ["epochs=1", "batch=2", "workers=0", "plots=False"], "predict": [], "evaluate": []}
    for command in commands[1:]:
        words = shlex.split(command)
        verb = words[2] if words[0].endswith("yolo") else words[1]
        out = subprocess.run(words + extra[verb], cwd=elsewhere, env=env, capture_output=True, text=True,
                             timeout=1200)
        assert out.returncode == 0, (command, out.stdout[-2000:], out.stderr[-2000:])
    assert (root.parent / "runs" / "w55" / "weights" / "best.pt").is_file()
    assert (root.parent / "runs" / "w55-predict" / "labels").is_dir()
    doc = yaml.safe_load((root / "evaluation-predictions" / "evaluation.json").read_text())
    assert doc["runs"][0]["source"] == "predictions" and doc["runs"][0]["split"] == "val"
    assert doc["runs"][0]["overall"]["attempts"] == load_dataset(root).split.count("val")
    assert not list(elsewhere.iterdir())  # nothing written where the commands ran


# --- pose labels ---------------------------------------------------------------------------------
def _fit_axis(src: np.ndarray, dst: np.ndarray) -> tuple[float, float, float]:
    """``dst = a * src + t`` by least squares: ``(a, t, largest residual)``."""
    a, t = np.polyfit(src, dst, 1)
    return float(a), float(t), float(np.abs(a * src + t - dst).max())


def _source_instances(root: Path) -> list[tuple[int, np.ndarray]]:
    """Every pose instance in the label files: (class, keypoints (K, 3) in continuous pixels)."""
    view = load_dataset(root)
    k = view.intrinsics
    out = []
    for rel in view.pose_label_path:
        for line in (root / rel).read_text().splitlines():
            v = np.array(line.split(), dtype=float)
            kp = v[5:].reshape(-1, 3) * [k.width, k.height, 1.0]
            out.append((int(v[0]), kp))
    return out


def test_pose_keypoints_stay_on_the_true_centres_through_mosaic_scale_translate_and_flip(tmp_path) -> None:
    """Ultralytics' own pose dataloader with the pose hyp.yaml (mosaic, scale, translate and, as
    the drogue's features mirror, fliplr on): every keypoint that comes out is the exact image
    of a true centre under one per-axis scale-and-shift (with flip_idx applied when flipped)."""
    root = labels_with_blank_images(tmp_path / "ds", 48, scene="podcam15",
                                    **{"labels.format": "pose", "features.objects": ["drogue"]})
    hyp = yaml.safe_load((root / "hyp.yaml").read_text())
    assert hyp["mosaic"] == 1.0 and hyp["fliplr"] == 0.5 and hyp["scale"] > 0 and hyp["translate"] > 0
    flip = np.array(yaml.safe_load((root / "data.yaml").read_text())["flip_idx"])
    sources = _source_instances(root)
    seen = pose_items(root, "train")
    listed = (root / "train.txt").read_text().splitlines()
    assert len(seen["im_files"]) == len(listed)  # no image dropped as corrupt
    matched = flipped = 0
    for item in seen["items"]:
        for c, kp in zip(item["classes"], item["keypoints"], strict=True):
            on = kp[:, 2] > 0
            if on.sum() < 3:
                continue
            best = None  # (largest residual, flipped) of the source instance it came from
            for cls, src in sources:
                if cls != c:
                    continue
                for mirrored in (False, True):
                    s = src[flip] if mirrored else src
                    if not (s[on, 2] > 0).all():
                        continue
                    ax, _, rx = _fit_axis(s[on, 0], kp[on, 0])
                    ay, _, ry = _fit_axis(s[on, 1], kp[on, 1])
                    if (ax < 0) != mirrored or ay <= 0:
                        continue
                    if best is None or max(rx, ry) < best[0]:
                        best = (max(rx, ry), mirrored)
            assert best is not None and best[0] < 5e-3, best
            matched += 1
            flipped += best[1]
    assert matched > 40 and 0 < flipped < matched, (matched, flipped)
    assert max(len(item["classes"]) for item in seen["items"]) > 1  # mosaic put several images together


def test_ultralytics_pose_verifier_accepts_every_pose_label_file(tmp_path) -> None:
    from ultralytics.data.utils import verify_image_label

    root = labels_with_blank_images(tmp_path / "ds", 40, **{"labels.format": "both",
                                                            "labels.truncated_objects": "clip"})
    doc = yaml.safe_load((root / "pose" / "data.yaml").read_text())
    nkpt, ndim = doc["kpt_shape"]
    view = load_dataset(root)
    instances = 0
    for b in range(len(view)):
        # The label's path with /labels/ turned back into /images/: the file Ultralytics pairs with it.
        image = (root / view.pose_label_path[b].replace("/labels/", "/images/")).with_suffix(".png")
        result = verify_image_label((str(image), str(root / view.pose_label_path[b]), "", True, doc["nc"], nkpt,
                                     ndim, False))
        _, lb, _, _, keypoints, missing, _, _, corrupt, msg = result
        assert (missing, corrupt) == (0, 0) and msg == "", msg
        assert keypoints.shape == (len(lb), nkpt, ndim)
        instances += len(lb)
    assert instances > 40


# --- the closed loop ----------------------------------------------------------------------------
def test_a_detector_trained_with_the_datasets_own_files_gets_a_learning_signal(tmp_path: Path) -> None:
    """yolo11n.yaml from scratch, the dataset's data.yaml and hyp.yaml as written (batch and
    nominal batch included), 12 rendered frames, 12 epochs on the CPU: the box loss starts far
    from zero (with labels under the assigner's size it stayed near 1e-6) and falls clearly."""
    import csv

    config = override_config(load_config(ROOT / "scenes" / "wingcam55.yaml"),
                             {"dataset.frames": 12, "dataset.seed": HELD_OUT_SEED, "render.spp": 1,
                              "dataset.val_fraction": 0.0})
    root = tmp_path / "w55"
    build_dataset(config, root)
    yolo = str(Path(sys.executable).parent / "yolo")
    out = subprocess.run([yolo, "detect", "train", f"data={root / 'data.yaml'}", f"cfg={root / 'hyp.yaml'}",
                          "model=yolo11n.yaml", "epochs=12", "device=cpu", "workers=0", "plots=False", "val=False",
                          f"project={tmp_path / 'runs'}", "name=t", "exist_ok=True"],
                         check=False, capture_output=True, text=True, timeout=1800)
    assert out.returncode == 0, out.stdout[-2000:] + out.stderr[-2000:]
    with open(tmp_path / "runs" / "t" / "results.csv") as f:
        box = [float(row["train/box_loss"]) for row in csv.DictReader(f)]
    assert len(box) == 12
    assert box[0] > 1.0, box
    assert box[-1] < 0.8 * box[0], box


def test_datagen_train_trains_predicts_and_prints_an_evaluate_command_that_runs(tmp_path: Path) -> None:
    """`datagen train w55` from the dataset's parent folder (a relative path, as the README
    runs it), 1 epoch on the CPU: the weights and Ultralytics' prediction folder beside the
    dataset in runs/, at most one prediction file per validation image, and the evaluate
    command it prints (the one hyp.yaml names) exits 0."""
    config = override_config(load_config(ROOT / "scenes" / "wingcam55.yaml"),
                             {"dataset.frames": 6, "dataset.seed": HELD_OUT_SEED, "render.spp": 1,
                              "dataset.val_fraction": 0.5})
    root = tmp_path / "w55"
    build_dataset(config, root)
    out = subprocess.run([sys.executable, "-m", "datagen", "train", "w55", "--epochs", "1", "--device", "cpu"],
                         check=False, capture_output=True, text=True, timeout=1800, cwd=tmp_path)
    assert out.returncode == 0, out.stdout[-2000:] + out.stderr[-2000:]
    assert (tmp_path / "runs" / "w55" / "weights" / "best.pt").is_file()
    assert (tmp_path / "runs" / "w55-predict").is_dir()  # Ultralytics' own folder: datagen makes only labels/
    predictions = tmp_path / "runs" / "w55-predict" / "labels"
    assert len(list(predictions.glob("*.txt"))) <= len((root / "val.txt").read_text().split())
    command = out.stdout.strip().splitlines()[-1].removeprefix("score them: ")
    assert command in (root / "hyp.yaml").read_text()
    scored = subprocess.run(shlex.split(command), check=False, capture_output=True, text=True, timeout=600)
    assert scored.returncode == 0, scored.stderr


def test_the_closed_loop_bench_runs_end_to_end_in_miniature(tmp_path: Path) -> None:
    """bench/bench_closed_loop.py on 4 training and 3 test frames, 2 epochs: both detectors
    (corrected and uncorrected labels) trained, predicted and scored, the truth runs beside
    them, and the summary and plots written."""
    out = subprocess.run([sys.executable, str(ROOT / "bench" / "bench_closed_loop.py"), "--train-frames", "4",
                          "--test-frames", "3", "--epochs", "2", "--batch", "2", "--spp", "1", "--out",
                          str(tmp_path / "loop")], check=False, capture_output=True, text=True, timeout=1800)
    assert out.returncode == 0, out.stdout[-3000:] + out.stderr[-3000:]
    summary = yaml.safe_load((tmp_path / "loop" / "summary.json").read_text())
    assert set(summary["models"]) == {"corrected", "uncorrected"}
    for model in summary["models"].values():
        assert len(model["losses"]["train/box_loss"]) == 2 and model["losses"]["train/box_loss"][0] > 0.1
        detector = model["detector"]
        assert detector["frames"] == 3 and detector["overall"]["labeled"] > 0
        assert set(detector["by_class"]) == set(load_dataset(tmp_path / "loop" / "test").features.name)
    assert [t["noise_px"] for t in summary["truth"]] == [0.0, 0.5, 1.0, 2.5]
    for plot in ("error_vs_distance", "reliability_vs_distance", "bias"):
        assert Path(summary["plots"][plot]).is_file()
    assert "## Closed loop: podcam15" in (tmp_path / "loop" / "summary.md").read_text()
