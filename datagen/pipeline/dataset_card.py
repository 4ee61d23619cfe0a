"""The dataset card, ``README.md``: what the dataset is and how it was made, with the front
matter Hugging Face ``datasets`` reads; never written over a README.md that is the user's."""

from __future__ import annotations

from pathlib import Path
from typing import Final

import yaml

from datagen.atomic import write_text
from datagen.dataset.layout import SPLITS, Layout, ShardJob
from datagen.paths import regular_file
from datagen.scene.resolved import Scene

__all__ = [
    "CARD_MARK",
    "dataset_card",
    "is_dataset_card",
    "write_dataset_card",
]


def _rendered(config) -> str:
    r = config.render
    denoised = ", denoised with Intel Open Image Denoise" if r.denoise == "oidn" else ""
    return f"rendered with Mitsuba 3 at {r.spp} spp{denoised}"


#: The first line of a dataset card datagen wrote; a README.md without it is the user's and is never touched.
CARD_MARK: Final = "<!-- datagen dataset card: rewritten by every finished build -->"


def dataset_card(scene: Scene, jobs: list[ShardJob], *, render: bool, labels: int,
                 excluded: dict[str, int], never_labeled: list[int] | None = None) -> str:
    """``README.md``: the dataset card. Its front matter tells Hugging Face ``datasets``
    which parquet files hold each split (``load_dataset(DIR)`` returns the manifests);
    its text says what the dataset is and how it was made."""
    config = scene.config
    frames = {split: sum(len(j.frames) for j in jobs if j.split == split) for split in SPLITS}
    front = {"configs": [{"config_name": "default", "data_files": [
        {"split": split, "path": f"manifests/{split}-*.parquet"} for split in SPLITS if frames[split]]}],
        "pretty_name": f"datagen {config.name}", "tags": ["synthetic", "object-detection", "keypoint-detection",
                                                          "aerial-refueling", "pnp"]}
    k, cam = scene.intrinsics, config.camera
    model = f" (paper model {config.paper_model})" if config.paper_model else ""
    lo, hi = config.approach.range_m
    rules = scene.labelling.rules
    reasons = ", ".join(f"{n:,} {r}" for r, n in excluded.items() if n) or "none"
    boxes = ("YOLO boxes in `labels/`" if config.labels.format != "pose"
             else "labeled features (no detection label files: the pose keypoints below)")
    return f"""---
{yaml.safe_dump(front, sort_keys=False).strip()}
---
{CARD_MARK}
# {config.name}{model}

Synthetic frames of vision-based aerial refueling made by datagen from the scene config
`{config.name}` (root seed {config.dataset.seed}): Monte Carlo refueling approaches over {lo:g}-{hi:g} m
seen by the {cam.mount} camera ({cam.hfov_deg:g} deg hFOV, {k.width}x{k.height}, pinhole, fx = fy = {k.fx:.3f} px,
cx = {k.cx:g}, cy = {k.cy:g}), {_rendered(config) if render else "labels only (no images)"}.

- **Frames**: {frames['train']:,} train, {frames['val']:,} val; {len(scene.features)} classes (the
  {config.features.variant} features of {' and '.join(config.features.objects)}).
- **Labels**: {labels:,} {boxes}, each centred exactly on the projection of its feature's
  true 3D centre ({'corrected' if rules.corrected else 'tight (uncorrected)'} boxes, at least
  {config.labels.min_box_px:g} px at imgsz {config.labels.train_imgsz}, {rules.edge_margin_px:g} px edge
  margin); excluded feature-frames: {reasons}.
- **World**: {_world_card(config)}; every draw is recorded per frame in the manifests.
{_unseen_card(scene, never_labeled or [])}{_pose_card(scene)}- **Tables**: `manifests/{{split}}-{{shard}}.parquet`, one row per frame (poses as 4x4 matrices, intrinsics,
  seeds, every appearance draw, and per feature its true centre, boxes, exclusion and visibility; missing
  values are nulls), `features.parquet` (each class's 3D points and centre). The columns are documented in
  datagen's `manifests/README.md`; `datasets.load_dataset(this folder)` reads the manifests.
- **Training**: `data.yaml` and `hyp.yaml` for Ultralytics YOLO; their comments give the train, predict and
  evaluate commands. `dataset.json` records the resolved config, the software versions and the asset hashes.
"""  # noqa: E501 (text the user reads, one line per sentence)


def _world_card(config) -> str:
    """What the world's randomizers draw, as the config switches them."""
    r = config.randomization
    h = r.haze
    ground = f"the ground drawn per approach ({_shares(r.ground.shares)})" if r.ground.enabled else "the sea"
    air = (f"{ground} on a round earth seen through the air (sea-level visibility {h.visibility_m[0] / 1000:g}-"
           f"{h.visibility_m[1] / 1000:g} km, aerosol scale height {h.aerosol_scale_height_m[0]:g}-"
           f"{h.aerosol_scale_height_m[1]:g} m, per approach)" if h.enabled
           else f"{ground} on a round earth, no aerial perspective")
    c = r.clouds
    clouds = (f"a cloud deck ({_shares(c.forms)}; thickness per form) and a layer {c.layer_thickness_m[0]:g}-"
              f"{c.layer_thickness_m[1]:g} m thick" if c.enabled else "no clouds")
    pieces = [air, clouds,
              "waves, whitecaps and sea colour from the wind" if r.sea.waves or r.sea.whitecaps or r.sea.colour
              else "a uniform sea", "generated liveries" if r.livery.enabled else "plain paint",
              "a camera model (blur, noise, glare, JPEG)" if r.sensor.enabled else "a pinhole camera"]
    return ", ".join(pieces)


def _shares(shares: dict[str, float]) -> str:
    """Named shares as percentages of their sum, those above 0 (``cumulus 40%, ...``)."""
    total = sum(shares.values())
    return ", ".join(f"{name} {share / total:.0%}" for name, share in shares.items() if share > 0)


def _unseen_card(scene: Scene, never: list[int]) -> str:
    """The card's line on the classes no frame labeled (empty when every class was)."""
    if not never:
        return ""
    names = ", ".join(scene.features.name[c] for c in never[:12]) + (", ..." if len(never) > 12 else "")
    return (f"- **Never labeled**: {len(never)} of {len(scene.features)} classes ({names}). By design: a feature "
            "set is its objects' (the same class ids in every scene of those objects), and this camera never sees "
            "these features inside the image and its margins (a wing camera, say, sees little of its own aircraft). "
            "They stay in `nc` without a positive; Ultralytics trains on the others, and `datagen evaluate` scores "
            "only what was labeled.\n")


def _pose_card(scene: Scene) -> str:
    """The card's line on pose labels (empty without them)."""
    labels = scene.config.labels
    if labels.format == "detect":
        return ""
    where = "`pose/` (its own data.yaml and hyp.yaml)" if labels.format == "both" else "`labels/`"
    layout = scene.pose_layout
    flip = "with a `flip_idx`" if layout.flip_idx is not None else f"without `flip_idx` ({layout.flip_problem})"
    return (f"- **Pose labels** in {where}: one instance per object ({', '.join(layout.objects)}), its keypoints the "
            f"true centre projections of its features, `kpt_shape: [{layout.kpt_count}, 3]`, {flip}; truncated "
            f"objects: {labels.truncated_objects}.\n")


def write_dataset_card(layout: Layout, scene: Scene, jobs: list[ShardJob], *, render: bool, labels: int,
                       excluded: dict[str, int], never_labeled: list[int] | None = None) -> Path | None:
    """Write the card of a finished build, unless a README.md that datagen did not write is there."""
    path = layout.root / "README.md"
    if path.exists() and not is_dataset_card(path):
        return None
    return write_text(path, dataset_card(scene, jobs, render=render, labels=labels, excluded=excluded,
                                         never_labeled=never_labeled))


def is_dataset_card(path: Path) -> bool:
    """Whether ``path`` is a card datagen wrote (it carries :data:`CARD_MARK`)."""
    if not regular_file(path):  # a FIFO would block the read
        return False
    try:
        with open(path, encoding="utf-8", errors="replace") as f:
            return CARD_MARK in f.read(4096)
    except OSError:
        return False
