"""A dataset seen through Ultralytics' own code (the optional ``train`` extra).

:mod:`datagen.core.training` restates what Ultralytics' trainer does to a label so that
``datagen audit`` can judge learnability without importing it. This module asks
Ultralytics itself: it builds the trainer's own dataset object from the dataset's
``data.yaml`` and ``hyp.yaml``, draws every image through the training
transforms and counts which label lines come out, and which of those hold an
anchor centre of the detection head. Tests and ``bench/bench_train.py`` compare
the two.
"""

from __future__ import annotations

import warnings
from pathlib import Path
from typing import Any, Final, cast

import numpy as np

from datagen.config.inputs import parse_yaml, read_text
from datagen.core.errors import DatagenError
from datagen.core.training import ANCHOR_STRIDES
from datagen.dataset.limits import DATA_YAML_BYTES, HYP_YAML_BYTES
from datagen.dataset.training_run import PREDICT_CONF, TrainingRun
from datagen.paths import DatasetFolder

__all__ = ["assigner_positives", "dataloader_learnability", "pose_items", "require_ultralytics", "train_and_predict"]


#: torchvision's minor version for each torch 2.x: torch 2.N pairs with torchvision 0.(N + 15).
TORCHVISION_MINOR_OFFSET: Final = 15


def require_ultralytics():
    """The ``ultralytics`` module once the trainer's stack works, or one line saying what to
    install: Ultralytics missing, or torch and torchvision of different releases or builds
    (a CPU torch beside a CUDA torchvision, say), whose operators fail only when training
    reaches them (``operator torchvision::nms does not exist``, after ~60 lines of traceback)."""
    try:
        import ultralytics
    except ImportError:
        raise DatagenError("Ultralytics is not installed; install it with `pip install -e '.[train]'`") from None
    check_torch_stack()
    return ultralytics


def check_torch_stack() -> None:
    """Run one torchvision operator (non-maximum suppression, which Ultralytics' every
    prediction uses) on a tiny input; one line naming the versions and what to install when
    it fails."""
    try:
        import torch
        from torchvision.ops import nms

        nms(torch.zeros((1, 4)), torch.zeros(1), 0.5)
    except Exception as exc:  # an ImportError, a RuntimeError of a missing operator, a symbol error
        versions = []
        for name in ("torch", "torchvision"):
            try:
                from importlib.metadata import version

                versions.append(f"{name} {version(name)}")
            except Exception:
                versions.append(f"no {name}")
        torch_version = versions[0].split(" ")[-1]
        major, _, rest = torch_version.partition(".")
        minor = rest.split(".")[0]
        pair = (f"torchvision 0.{int(minor) + TORCHVISION_MINOR_OFFSET}.x built for torch {torch_version}"
                if major == "2" and minor.isdigit() else "matching torch and torchvision")
        raise DatagenError(f"the trainer's stack does not work: {' and '.join(versions)} "
                           f"({type(exc).__name__}: {' '.join(str(exc).split())[:100]}); install {pair} from the "
                           "same index as torch (CPU builds: pip install torch torchvision --index-url "
                           "https://download.pytorch.org/whl/cpu)") from None


def _training_dataset(root: Path, split: str, task: str = "detect"):
    """Ultralytics' training ``YOLODataset`` of ``root`` (its data.yaml, its hyp.yaml)."""
    require_ultralytics()
    from ultralytics.cfg import get_cfg
    from ultralytics.data.build import build_yolo_dataset
    from ultralytics.data.utils import check_det_dataset

    folder = DatasetFolder(Path(root))
    data = check_det_dataset(str(folder.file("data.yaml")))
    hyp = parse_yaml(read_text(folder.file("hyp.yaml"), "hyp.yaml", max_bytes=HYP_YAML_BYTES), Path(root) / "hyp.yaml")
    cfg = get_cfg(overrides={**hyp, "task": task, "mode": "train", "cache": False, "workers": 0})
    # (get_cfg is annotated as returning a SimpleNamespace; it returns the IterableSimpleNamespace this takes)
    dataset = build_yolo_dataset(cast(Any, cfg), data[split], batch=1, data=data, mode="train",
                                 stride=max(ANCHOR_STRIDES))
    return dataset, cfg


def dataloader_learnability(root: str | Path, split: str = "train") -> dict:
    """Run every image of ``split`` through Ultralytics' training transforms (the dataset's
    own ``hyp.yaml``) and count label lines, the instances that come out, and those
    that hold an anchor centre (``make_anchors``: strictly inside the box) or get
    candidate anchors from Ultralytics' own assigner (``select_candidates_in_gts``,
    which widens boxes under 16 px).

    Returns totals (``lines``, ``kept``, ``anchored``, ``assigner_candidates``,
    ``images``, ``imgsz``), the image files in dataset order (``im_files``) and
    per-instance arrays: ``image`` (index into ``im_files``), ``classes``,
    ``xyxy_train`` (pixels on the square training input) and ``anchored_mask``.
    """
    import torch
    from ultralytics.utils.tal import TaskAlignedAssigner, make_anchors

    root = Path(root)
    dataset, cfg = _training_dataset(root, split)
    imgsz = int(cfg.imgsz)
    sizes = torch.tensor([[imgsz // s, imgsz // s] for s in ANCHOR_STRIDES])
    points, strides = make_anchors(sizes, torch.tensor(ANCHOR_STRIDES, dtype=torch.float32), 0.5)
    centres = points * strides  # (A, 2) pixels
    assigner = TaskAlignedAssigner(stride=list(ANCHOR_STRIDES))
    lines = kept = 0
    classes, boxes, images = [], [], []
    for i in range(len(dataset)):
        lines += len(dataset.labels[i]["cls"])
        item = dataset[i]
        if not len(item["cls"]):
            continue
        h, w = item["img"].shape[1:]
        xywh = item["bboxes"].double() * torch.tensor([w, h, w, h], dtype=torch.float64)
        xyxy = torch.cat([xywh[:, :2] - xywh[:, 2:] / 2, xywh[:, :2] + xywh[:, 2:] / 2], dim=1)
        kept += len(xyxy)
        classes.append(item["cls"].view(-1).numpy().astype(np.int64))
        boxes.append(xyxy.numpy())
        images.append(np.full(len(xyxy), i, dtype=np.int64))
    every = np.concatenate(boxes) if boxes else np.zeros((0, 4))
    gt = torch.from_numpy(every).float()
    inside = ((centres[None, :, 0] > gt[:, None, 0]) & (centres[None, :, 1] > gt[:, None, 1])
              & (centres[None, :, 0] < gt[:, None, 2]) & (centres[None, :, 1] < gt[:, None, 3]))
    candidates = assigner.select_candidates_in_gts(centres, gt[None], torch.ones(1, len(gt), 1))[0]
    return {
        "im_files": list(dataset.im_files),
        "images": len(dataset),
        "imgsz": imgsz,
        "lines": lines,
        "kept": kept,
        "anchored": int(inside.any(dim=1).sum()),
        "assigner_candidates": int(candidates.any(dim=1).sum()),
        "image": np.concatenate(images) if images else np.zeros(0, np.int64),
        "classes": np.concatenate(classes) if classes else np.zeros(0, np.int64),
        "xyxy_train": xyxy,
        "anchored_mask": inside.any(dim=1).numpy(),
    }


def pose_items(root: str | Path, split: str = "train") -> dict:
    """Every image of a pose set's ``split`` through Ultralytics' own pose training dataset
    and transforms (its ``hyp.yaml``: mosaic, scale, translate and, with a ``flip_idx``,
    fliplr; Ultralytics draws them from the global RNGs, which datagen leaves alone).

    Returns ``im_files`` (the images Ultralytics kept: one it found corrupt is missing),
    ``imgsz``, ``lines`` (pose instances in the label files), and per image what came out:
    ``items``, each with ``classes`` ``(n,)``, ``xyxy`` ``(n, 4)`` and ``keypoints``
    ``(n, K, 3)``, in pixels of the square training input."""
    import torch

    dataset, cfg = _training_dataset(Path(root), split, task="pose")
    items = []
    for i in range(len(dataset)):
        item = dataset[i]
        h, w = item["img"].shape[1:]
        scale = torch.tensor([w, h, w, h], dtype=torch.float64)
        xywh = item["bboxes"].double() * scale
        xyxy = torch.cat([xywh[:, :2] - xywh[:, 2:] / 2, xywh[:, :2] + xywh[:, 2:] / 2], dim=1)
        kp = item["keypoints"].double().clone()
        kp[..., 0] *= w
        kp[..., 1] *= h
        items.append({"classes": item["cls"].view(-1).numpy().astype(np.int64), "xyxy": xyxy.numpy(),
                      "keypoints": kp.numpy()})
    return {"im_files": list(dataset.im_files), "imgsz": int(cfg.imgsz), "items": items,
            "lines": sum(len(label["cls"]) for label in dataset.labels)}


def assigner_positives(root: str | Path, split: str = "train", *, images: int | None = None, batch: int = 8,
                       model: str = "yolo11n.yaml", seed: int = 0) -> dict:
    """What Ultralytics' own detection loss makes of the label lines at the start of training:
    the task-aligned assigner of the untrained ``model`` (built from its YAML, seeded) run on
    the trainer's own batches of ``split``.

    The assigner picks positive anchors inside each box and gives each a classification
    target of ``score^0.5 * CIoU^6`` against the head's current prediction, normalized by the
    box's best such metric plus 1e-9 and scaled by its best CIoU; the box loss of a positive
    is weighted by that target. An untrained head predicts boxes of a fixed size in strides
    (about 15 for a DFL head, 4 for YOLO26's), so a label box much smaller than that gets a
    target near 0 however many positives it has: it teaches only "background".

    Returns ``label_lines`` (in the label files), ``instances`` (what the dataloader produced
    of them), ``positive`` (instances given at least one positive anchor), ``target_sum``
    (the sum of every positive's target, the box loss's normalizer), ``target_median`` (the
    median over instances of their best positive's target) and ``targeted`` (instances whose
    best positive's target is at least 0.01)."""
    import torch
    from ultralytics.nn.tasks import DetectionModel

    root = Path(root)
    dataset, cfg = _training_dataset(root, split)
    torch.manual_seed(seed)
    network = DetectionModel(model, nc=len(dataset.data["names"]), verbose=False)
    network.args = cfg
    criterion = network.init_criterion()
    one2many = getattr(criterion, "one2many", criterion)  # an end-to-end head: its one-to-many branch
    seen: dict = {}
    forward = one2many.assigner.forward

    def capture(*args, **kwargs):
        out = forward(*args, **kwargs)
        seen["scores"], seen["fg"], seen["gt_idx"], seen["mask_gt"] = out[2], out[3], out[4], args[5]
        return out

    one2many.assigner.forward = capture
    count = len(dataset) if images is None else min(images, len(dataset))
    label_lines = sum(len(dataset.labels[i]["cls"]) for i in range(count))
    lines = positive = 0
    target_sum = 0.0
    best: list[torch.Tensor] = []
    with torch.no_grad():
        for start in range(0, count, batch):
            items = dataset.collate_fn([dataset[i] for i in range(start, min(start + batch, count))])
            items["img"] = items["img"].float() / 255
            criterion(network(items["img"]), items)
            mask, fg, gt_idx = seen["mask_gt"], seen["fg"], seen["gt_idx"]
            target = seen["scores"].float().sum(-1)  # (b, anchors): a positive's target, 0 elsewhere
            lines += int(mask.sum())
            target_sum += float(target.sum())
            for b in range(fg.shape[0]):
                n = int(mask[b].sum())
                per_box = torch.zeros(mask.shape[1])
                per_box.scatter_reduce_(0, gt_idx[b][fg[b]], target[b][fg[b]], reduce="amax")
                positive += len(gt_idx[b][fg[b]].unique())
                best.append(per_box[:n])
    best_target = torch.cat(best) if best else torch.zeros(0)
    return {"images": count, "label_lines": label_lines, "instances": lines, "positive": positive,
            "target_sum": target_sum, "target_median": float(best_target.median()) if len(best_target) else 0.0,
            "targeted": int((best_target >= 0.01).sum())}


def train_and_predict(run: TrainingRun, *, epochs: int | None = None, device: str | None = None,
                      workers: int | None = None, batch: int | None = None, imgsz: int | None = None) -> None:
    """Train ``run.network`` on the set with its own ``hyp.yaml``, then predict its validation
    frames with the best weights. Ultralytics appends to the label files of a prediction
    folder, so those of an earlier run (``*.txt`` in ``run.predictions``, no other file) are
    removed first. ``run``'s folders should be absolute: Ultralytics puts a relative project
    folder under its own settings folder. The caller checks the recipe files first
    (:func:`datagen.analysis.audit.dataset_files.check_recipe`)."""
    require_ultralytics()
    from ultralytics import YOLO

    folder = DatasetFolder(run.root)
    data = folder.file("data.yaml")
    hyp = folder.file("hyp.yaml")
    doc = parse_yaml(read_text(data, "data.yaml", max_bytes=DATA_YAML_BYTES), data)
    recipe = parse_yaml(read_text(hyp, "hyp.yaml", max_bytes=HYP_YAML_BYTES), hyp)
    if not isinstance(doc, dict) or not isinstance(doc.get("val"), str):
        raise DatagenError(f"{data}: val: no image list named")
    if not isinstance(recipe, dict) or not isinstance(recipe.get("imgsz"), int):
        raise DatagenError(f"{hyp}: imgsz: not an integer")
    val = folder.file(doc["val"])
    predictions = run.predictions
    for path in (predictions.parent, predictions):
        if path.is_symlink() or (path.exists() and not path.is_dir()):
            raise DatagenError(f"{path}: not a folder (a file or a symbolic link is in the way of the predictions)")
    extra = {k: v for k, v in (("epochs", epochs), ("device", device), ("workers", workers), ("imgsz", imgsz),
                                ("batch", batch), ("nbs", batch)) if v is not None}  # one step per batch: nbs = batch
    with warnings.catch_warnings():  # Ultralytics' Ray Tune callback asks Ray for a session that a run has not
        warnings.filterwarnings("ignore", category=UserWarning, module=r"ray(\.|$)")
        YOLO(run.network, task=run.task).train(data=str(data), cfg=str(hyp), project=str(run.project),
                                               name=run.run_name, exist_ok=True, **extra)
    if not run.weights.is_file():
        raise DatagenError(f"{run.weights}: Ultralytics wrote no weights")
    if predictions.is_dir():
        for old in predictions.glob("*.txt"):
            if old.is_file() and not old.is_symlink():
                old.unlink()
    predictor = YOLO(str(run.weights), task=run.task)
    for _ in predictor.predict(source=str(val), imgsz=imgsz or recipe["imgsz"], conf=PREDICT_CONF, save_txt=True,
                               save_conf=True, project=str(run.project), name=f"{run.run_name}-predict",
                               exist_ok=True, stream=True, verbose=False,
                               **({"device": device} if device is not None else {})):
        pass
    if not predictions.parent.is_dir():
        raise DatagenError(f"{predictions.parent}: Ultralytics wrote no predictions")
    predictions.mkdir(exist_ok=True)  # Ultralytics makes it only for a first detection
