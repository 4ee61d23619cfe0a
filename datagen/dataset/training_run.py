"""Where a detector trained on a dataset and its predictions of the validation frames go,
and the commands that make them: what ``datagen train`` runs
(:func:`datagen.analysis.ultralytics.train_and_predict`) and what a dataset's ``hyp.yaml``
and ``data.yaml`` spell out for Ultralytics' own command line. One recipe, stated here."""

from __future__ import annotations

import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Final

__all__ = ["MODELS", "PREDICT_CONF", "TrainingRun", "executable"]

#: The network each task trains, built from scratch (a ``.yaml``: nothing is downloaded).
MODELS: Final = {"detect": "yolo11n.yaml", "pose": "yolo11n-pose.yaml"}

#: Predictions keep detections down to this confidence; ``datagen evaluate --conf`` then
#: chooses the threshold.
PREDICT_CONF: Final = 0.001


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
