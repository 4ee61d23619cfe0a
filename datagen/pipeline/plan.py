"""The build's plan of a dataset: which split each frame goes to, the shards, and the
folder layout a config gives a dataset (:class:`datagen.dataset.layout.Layout`)."""

from __future__ import annotations

from pathlib import Path

from datagen.config.schema import Config
from datagen.core.conventions import split_uniform
from datagen.dataset.layout import SPLITS, Layout, ShardJob

__all__ = ["dataset_layout", "frame_split", "plan_shards"]


def dataset_layout(root: Path, config: Config) -> Layout:
    """The layout a config gives a dataset at ``root``."""
    return Layout(Path(root), config.render.image_suffix, config.labels.format)


def frame_split(config: Config, frame_index: int, seed: int | None = None) -> str:
    """``train`` or ``val``, decided by the seed for the frame (or its approach chain)."""
    d = config.dataset
    seed = d.seed if seed is None else seed
    unit = frame_index if d.split_by == "frame" else frame_index // config.frames_per_chain
    return "val" if split_uniform(seed, unit) < d.val_fraction else "train"


def plan_shards(config: Config) -> list[ShardJob]:
    """Every shard of the dataset, train first: a pure function of the config."""
    d, size = config.dataset, config.frames_per_shard
    frames: dict[str, list[int]] = {s: [] for s in SPLITS}
    for i in range(d.frames):
        frames[frame_split(config, i)].append(i)
    return [
        ShardJob(split, n, tuple(indices[start:start + size]))
        for split, indices in frames.items()
        for n, start in enumerate(range(0, len(indices), size))
    ]
