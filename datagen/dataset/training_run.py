"""Where a detector trained on a dataset and its predictions of the validation frames go,
and the commands that make them: what ``datagen train`` runs
(:func:`datagen.analysis.ultralytics.train_and_predict`) and what a dataset's ``hyp.yaml``
and ``data.yaml`` spell out for Ultralytics' own command line. One recipe, stated here."""

from __future__ import annotations

import math
import sys
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Final

__all__ = ["MODELS", "PREDICT_CONF", "RECIPE_SETTINGS", "Setting", "TrainingRun", "executable", "recipe_problems"]

#: The network each task trains, built from scratch (a ``.yaml``: nothing is downloaded).
MODELS: Final = {"detect": "yolo11n.yaml", "pose": "yolo11n-pose.yaml"}

#: Predictions keep detections down to this confidence; ``datagen evaluate --conf`` then
#: chooses the threshold.
PREDICT_CONF: Final = 0.001


@dataclass(frozen=True)
class Setting:
    """What an Ultralytics setting in a dataset's ``hyp.yaml`` may be: a flag, a whole
    number or a number within ``[lo, hi]``, or one of ``choices``."""

    kind: type  # bool, int or float
    lo: float = 0.0
    hi: float = 1.0
    choices: tuple = ()

    def problem(self, value: object) -> str | None:
        """Why ``value`` may not be this setting, or None."""
        if self.choices:
            return None if value in self.choices and type(value) in (bool, str) else \
                f"expected one of {', '.join(map(str, self.choices))}"
        if self.kind is bool:
            return None if isinstance(value, bool) else "expected true or false"
        kinds = int if self.kind is int else (int, float)
        if not isinstance(value, kinds) or isinstance(value, bool) or not math.isfinite(value) \
                or not self.lo <= value <= self.hi:
            what = "a whole number" if self.kind is int else "a number"
            return f"expected {what} from {self.lo:g} to {self.hi:g}"
        return None


_UNIT: Final = Setting(float)
#: Every setting a dataset's ``hyp.yaml`` may hold (what datagen writes, and the tuning a user
#: may add), with its range: Ultralytics reads the file as it is when it trains, so a setting
#: that names a file, folder, model or command, saves checkpoints every epoch, caches images
#: on disk, or trains without end is not one. ``datagen train --epochs`` trains longer.
RECIPE_SETTINGS: Final[Mapping[str, Setting]] = {
    "imgsz": Setting(int, 32, 8192), "batch": Setting(int, 1, 1024), "nbs": Setting(int, 1, 1024),
    "epochs": Setting(int, 1, 1000), "patience": Setting(int, 0, 1000), "close_mosaic": Setting(int, 0, 1000),
    "workers": Setting(int, 0, 64), "seed": Setting(int, 0, 2**31 - 1),
    "optimizer": Setting(str, choices=("SGD", "Adam", "Adamax", "AdamW", "NAdam", "RAdam", "RMSProp", "auto")),
    "cache": Setting(str, choices=(False, "ram")),
    "lr0": _UNIT, "lrf": _UNIT, "momentum": _UNIT, "weight_decay": _UNIT, "warmup_momentum": _UNIT,
    "warmup_bias_lr": _UNIT, "warmup_epochs": Setting(float, 0, 100), "dropout": _UNIT, "fraction": _UNIT,
    "box": Setting(float, 0, 100), "cls": Setting(float, 0, 100), "dfl": Setting(float, 0, 100),
    "pose": Setting(float, 0, 100), "kobj": Setting(float, 0, 100),
    "mosaic": _UNIT, "mixup": _UNIT, "cutmix": _UNIT, "copy_paste": _UNIT, "fliplr": _UNIT, "flipud": _UNIT,
    "translate": _UNIT, "scale": _UNIT, "perspective": Setting(float, 0, 0.001), "erasing": _UNIT, "bgr": _UNIT,
    "hsv_h": _UNIT, "hsv_s": _UNIT, "hsv_v": _UNIT, "degrees": Setting(float, 0, 180), "shear": Setting(float, 0, 180),
    **{flag: Setting(bool) for flag in ("cos_lr", "amp", "rect", "single_cls", "deterministic", "val", "plots",
                                        "verbose", "exist_ok")},
}


def recipe_problems(doc: object) -> list[str]:
    """What in a ``hyp.yaml`` document is not a setting of :data:`RECIPE_SETTINGS` in its
    range, one text per problem (none: a recipe Ultralytics may be run with)."""
    if not isinstance(doc, dict):
        return ["expected a mapping of Ultralytics settings"]
    problems = []
    for key, value in doc.items():
        setting = RECIPE_SETTINGS.get(key) if isinstance(key, str) else None
        if setting is None:
            problems.append(f"{str(key)[:40]!r}: not a setting a datagen recipe may hold (it may name a file, "
                            "model or command, or write without bound)")
        elif (why := setting.problem(value)) is not None:
            problems.append(f"{key}: value {str(value)[:40]!r}: {why}")
    return problems


def executable(name: str) -> str:
    """``name`` as a path into the environment running datagen (its ``bin`` folder), so that
    a command written down runs from any shell; the bare name where it is not there."""
    path = Path(sys.executable).parent / name
    return str(path) if path.is_file() else name


@dataclass(frozen=True)
class TrainingRun:
    """Where a training run on a dataset reads and writes.

    ``root``: the folder of the set's data.yaml (the dataset, or its ``pose/`` set);
    ``dataset``: the dataset's root; ``runs``: Ultralytics' project folder (default: ``runs``
    beside the dataset, outside it); ``name``: the run (default: the dataset's name, plus
    ``-pose`` for a pose set beside a detect set)."""

    root: Path
    dataset: Path
    task: str = "detect"
    runs: Path | None = None
    name: str | None = None
    model: str | None = None

    @property
    def project(self) -> Path:
        return self.runs if self.runs is not None else self.dataset.parent / "runs"

    @property
    def run_name(self) -> str:
        if self.name is not None:
            return self.name
        return self.dataset.name if self.root == self.dataset else f"{self.dataset.name}-{self.task}"

    @property
    def network(self) -> str:
        return self.model or MODELS[self.task]

    @property
    def weights(self) -> Path:
        return self.project / self.run_name / "weights" / "best.pt"

    @property
    def predictions(self) -> Path:
        """The folder of the prediction label files, one per validation image."""
        return self.project / f"{self.run_name}-predict" / "labels"

    def yolo_commands(self, imgsz: int, val_list: str = "val.txt") -> tuple[str, str]:
        """The train and predict commands of Ultralytics' own command line that
        :func:`datagen.analysis.ultralytics.train_and_predict` runs."""
        yolo, project = executable("yolo"), self.project
        train = (f"{yolo} {self.task} train data={self.root / 'data.yaml'} cfg={self.root / 'hyp.yaml'} "
                 f"model={self.network} project={project} name={self.run_name}")
        predict = (f"{yolo} {self.task} predict model={self.weights} source={self.root / val_list} imgsz={imgsz} "
                   f"conf={PREDICT_CONF:g} save_txt=True save_conf=True project={project} "
                   f"name={self.run_name}-predict")
        return train, predict

    def evaluate_command(self, conf: float = 0.25) -> str:
        return f"{executable('datagen')} evaluate {self.dataset} --predictions {self.predictions} --conf {conf:g}"

    def train_command(self) -> str:
        pose = " --pose" if self.task == "pose" and self.root != self.dataset else ""
        return f"{executable('datagen')} train {self.dataset}{pose}"
