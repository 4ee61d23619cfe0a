"""A frame's manifest row, made from what the build knows of the frame (its files, camera,
draws, labels, render and run); the columns, their order and types are the dataset's
contract (:data:`datagen.dataset.columns.MANIFEST_COLUMNS`), and
:func:`~datagen.dataset.columns.manifest_record` holds the row to it: a column of the table
that nothing here computes fails the first frame written."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from datagen.core.camera import Intrinsics
from datagen.dataset.columns import (
    INTRINSICS_COLUMNS,
    MEASURED_COLUMNS,
    POSE_COLUMNS,
    RATE_COLUMNS,
    FeatureColumns,
    manifest_record,
    matrix_field,
)
from datagen.pipeline.frame import FrameDraws
from datagen.scene.look import sun_direction_world

__all__ = ["FrameFiles", "FrameRender", "FrameRun", "manifest_row"]


@dataclass(frozen=True)
class FrameFiles:
    """A frame's place in the dataset and its files (relative to the root; None: not written),
    under their columns' names."""

    frame_id: int
    split: str
    shard: int
    image_path: str | None
    label_path: str | None
    pose_label_path: str | None
    exr_path: str | None


@dataclass(frozen=True)
class FrameRender:
    """What rendering a frame gives its row: the samples, the denoiser, what the render
    measured (:data:`~datagen.dataset.columns.MEASURED_COLUMNS`) and the seconds inside
    ``mi.render`` and the denoiser (None: not denoised)."""

    spp: int
    denoise: str
    measured: dict[str, object]
    render_s: float
    denoise_s: float | None


@dataclass(frozen=True)
class FrameRun:
    """The run's columns of a frame (:data:`~datagen.dataset.columns.RUN_COLUMNS` but the
    render's seconds): they differ between two builds of one config."""

    frame_s: float
    worker: str
    worker_rss_mib: float


def manifest_row(files: FrameFiles, intrinsics: Intrinsics, draws: FrameDraws, features: FeatureColumns,
                 objects: list[dict], render: FrameRender | None, run: FrameRun) -> dict[str, object]:
    """One frame's manifest row (:func:`~datagen.dataset.columns.manifest_record`): its files,
    the camera, the poses, the approach, every appearance draw, the features, what the render
    measured (null without one) and the run's columns."""
    state, look = draws.state, draws.look
    k = intrinsics
    rates = look.sensor_readout_s is not None
    measured = render.measured if render is not None else {}
    return manifest_record({
        **dataclasses.asdict(files),
        **dict(zip(INTRINSICS_COLUMNS, (k.width, k.height, k.fx, k.fy, k.cx, k.cy), strict=True)),
        "cam_from_world": matrix_field(state.cam_from_world),
        **{column: matrix_field(state.world_from(o)) for o, column in POSE_COLUMNS.items()},
        **{column: matrix_field(state.cam_from_per_s(o)) if rates else None for o, column in RATE_COLUMNS.items()},
        "ptd_receiver_m": state.ptd_receiver_m.tolist(),
        "distance_m": state.distance_m,
        "seed": draws.seed,
        "render_seed": draws.render_seed,
        "spp": render.spp if render is not None else None,
        "denoise": render.denoise if render is not None else None,
        "mount": state.mount,
        "approach_index": state.approach_index,
        "approach_number": state.approach_number,
        "time_s": state.time_s,
        "turbulence_intensity": state.turbulence_intensity,
        "bank_deg": state.bank_deg,
        "sun_direction_world": np.asarray(sun_direction_world(state, look), dtype=np.float64).tolist(),
        **{f.name: getattr(look, f.name) for f in dataclasses.fields(look) if f.name != "materials"},
        "materials": [
            {"object": obj, "part_class": cls, "base_color": list(m.base_color), "roughness": m.roughness,
             "metallic": m.metallic, "specular": m.specular}
            for obj, classes in look.materials.items() for cls, m in classes.items()
        ],
        **{name: measured.get(name) for name in MEASURED_COLUMNS},
        "n_labeled": int(features.labeled.sum()),
        "features": features,
        "objects": objects,
        "render_s": render.render_s if render is not None else None,
        "denoise_s": render.denoise_s if render is not None else None,
        **dataclasses.asdict(run),
    })
