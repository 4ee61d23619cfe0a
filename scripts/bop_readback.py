"""Read a `datagen export --format bop` folder back with the BOP toolkit's own loaders.

The BOP toolkit (github.com/thodan/bop_toolkit) is not on the package registry, so this
check is not part of the test suite; run it by hand against a clone:

    # 1. in datagen's venv: the dataset's true centres, from its manifests
    .venv/bin/python scripts/bop_readback.py dump DATASET /tmp/expected.npz
    # 2. in a venv with numpy, scipy, imageio, pypng and a bop_toolkit clone
    python scripts/bop_readback.py check EXPORT /tmp/expected.npz --toolkit /path/to/bop_toolkit

``check`` loads every scene with ``bop_toolkit_lib.dataset.bop_scenewise`` (scene_camera,
scene_gt, scene_gt_info, masks), the models with ``inout.load_ply`` and ``models_info.json``,
and projects each feature's true centre (model frame, mm) with ``misc.project_pts`` and
the exported ``cam_K``, ``cam_R_m2c``, ``cam_t_m2c``: it must land on the dataset's label
centre (pixel-index convention) within 1e-6 px. It prints one line per finding and a
summary; exit 1 on any mismatch.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np


def dump(dataset: Path, out: Path) -> None:
    from datagen.core.conventions import index_px, object_id
    from datagen.dataset.reader import load_dataset

    view = load_dataset(dataset)
    f = view.features
    np.savez(out, frame_id=view.frame_id, centre_index_px=index_px(view.center_px),
             center_mm=f.center_model * 1000.0,
             obj_id=np.array([object_id(f.objects[o]) for o in f.object_index]),
             objects=np.array([object_id(o) for o in f.objects]))
    print(f"wrote {out}: {len(view)} frames, {len(f)} features")


def check(export: Path, expected: Path, toolkit: Path) -> int:
    sys.path.insert(0, str(toolkit))
    from bop_toolkit_lib import inout, misc
    from bop_toolkit_lib.dataset import bop_scenewise

    e = np.load(expected)
    rows = {int(fid): i for i, fid in enumerate(e["frame_id"])}
    problems, projected, worst, images = 0, 0, 0.0, 0
    info = inout.load_json(export / "models" / "models_info.json", keys_to_int=True)
    for obj in e["objects"]:
        model = inout.load_ply(export / "models" / f"obj_{int(obj):06d}.ply")
        lo = model["pts"].min(axis=0)
        if not np.allclose(lo, [info[obj]["min_x"], info[obj]["min_y"], info[obj]["min_z"]], atol=1e-3):
            print(f"obj {obj}: models_info min {info[obj]} disagrees with the PLY's {lo}")
            problems += 1
    for split in sorted(p for p in export.iterdir() if p.is_dir() and p.name != "models"):
        for scene in sorted(p for p in split.iterdir() if p.is_dir()):
            infos = bop_scenewise.read_scene_infos(scene, read_image_ids=True, read_n_objects=True)
            data = bop_scenewise.load_scene_data(scene)
            for im in infos["image_ids"]:
                images += 1
                image = bop_scenewise.load_image_data(scene, im, load_depth=False, load_mask=True, load_gt=True,
                                                      load_gt_info=True)
                k = data["scene_camera"][im]["cam_K"]
                b = rows[im]
                for gt_index, gt in enumerate(data["scene_gt"][im]):
                    mine = e["obj_id"] == gt["obj_id"]
                    want = e["centre_index_px"][b][mine]
                    got = misc.project_pts(e["center_mm"][mine], k, gt["cam_R_m2c"], gt["cam_t_m2c"])
                    ok = np.isfinite(want).all(axis=1)
                    err = np.abs(got[ok] - want[ok]).max(initial=0.0)
                    worst, projected = max(worst, float(err)), projected + int(ok.sum())
                    if err > 1e-6:
                        print(f"{scene} image {im} gt {gt_index}: centres off by {err:.3g} px")
                        problems += 1
                    visib = image["mask_visib"][gt_index] > 0
                    full = image["mask"][gt_index] > 0
                    gt_info = data["scene_gt_info"][im][gt_index]
                    if int(visib.sum()) != gt_info["px_count_visib"] or int(full.sum()) != gt_info["px_count_all"]:
                        print(f"{scene} image {im} gt {gt_index}: pixel counts differ from the masks")
                        problems += 1
    print(json.dumps({"images": images, "centres_projected": projected, "worst_px": worst, "problems": problems}))
    return 1 if problems or not projected else 0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)
    d = sub.add_parser("dump")
    d.add_argument("dataset", type=Path)
    d.add_argument("out", type=Path)
    c = sub.add_parser("check")
    c.add_argument("export", type=Path)
    c.add_argument("expected", type=Path)
    c.add_argument("--toolkit", type=Path, required=True)
    args = parser.parse_args()
    if args.command == "dump":
        dump(args.dataset, args.out)
    else:
        sys.exit(check(args.export, args.expected, args.toolkit))


if __name__ == "__main__":
    main()
