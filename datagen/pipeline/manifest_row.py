"""A frame's manifest row, made from what the build knows of the frame (its state, look,
labels and render); the columns and their types are the dataset's contract
(:mod:`datagen.dataset.columns`)."""

from __future__ import annotations

import dataclasses

import numpy as np

from datagen.core.camera import Intrinsics
from datagen.core.conventions import RIGID_OBJECTS
from datagen.dataset.columns import MEASURED_COLUMNS, FeatureColumns, matrix_field
from datagen.scene.approach import FrameState
from datagen.scene.look import FrameLook, sun_direction_world

__all__ = ["manifest_row"]


def manifest_row(*, frame: int, split: str, shard: int, image_path: str | None, label_path: str | None,
                 pose_label_path: str | None, exr_path: str | None, intrinsics: Intrinsics, state: FrameState,
                 look: FrameLook, seed: int, render_seed: int, spp: int | None, denoise: str | None,
                 features: FeatureColumns, objects: list[dict], n_labeled: int, render_s: float | None,
                 denoise_s: float | None, frame_s: float, worker: str, worker_rss_mib: float,
                 rendered: dict | None = None) -> dict:
    """One frame's manifest row, column by column (:func:`datagen.dataset.columns.manifest_schema`): the frame,
    its files, the camera, the poses, the approach, every appearance draw, the features,
    what the render measured (:data:`~datagen.dataset.columns.MEASURED_COLUMNS`, from ``rendered``) and the run
    columns (:data:`~datagen.dataset.columns.RUN_COLUMNS`)."""
    rendered = rendered or {}
    k = intrinsics
    return {
        "frame_id": frame,
        "split": split,
        "shard": shard,
        "image_path": image_path,
        "label_path": label_path,
        "pose_label_path": pose_label_path,
        "exr_path": exr_path,
        "width": k.width,
        "height": k.height,
        "fx": k.fx,
        "fy": k.fy,
        "cx": k.cx,
        "cy": k.cy,
        "cam_from_world": matrix_field(state.cam_from_world),
        "world_from_tanker": matrix_field(state.world_from_tanker),
        "world_from_receiver": matrix_field(state.world_from_receiver),
        "world_from_drogue": matrix_field(state.world_from_drogue),
        **{f"cam_from_{o}_per_s": matrix_field(state.cam_from_per_s(o)) if look.sensor_readout_s is not None
           else None for o in RIGID_OBJECTS},
        "ptd_receiver_m": state.ptd_receiver_m.tolist(),
        "distance_m": state.distance_m,
        "seed": seed,
        "render_seed": render_seed,
        "spp": spp,
        "denoise": denoise,
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
        **{name: rendered.get(name) for name in MEASURED_COLUMNS},
        "n_labeled": n_labeled,
        "features": features,
        "objects": objects,
        "render_s": render_s,
        "denoise_s": denoise_s,
        "frame_s": frame_s,
        "worker": worker,
        "worker_rss_mib": worker_rss_mib,
    }
