"""Write the documentation's example frame: one frame of the README's tour build, its image
beside its label file and its manifest row (docs/reference/example-frame.md and
docs/example-frame.jpg).

    .venv/bin/python scripts/example_frame.py          # renders the tour build (about 1.5 min)

The page's text is a pure function of the build's labels and manifests, which a labels-only
build gives too: tests/test_docs.py rebuilds them and fails when the page drifts.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PAGE = ROOT / "docs" / "reference" / "example-frame.md"
IMAGE = ROOT / "docs" / "example-frame.jpg"
#: The README tour's rendered build.
TOUR = {"config": "wingcam55", "frames": 12}
#: Columns of the row the page lists (the draws and geometry; the image statistics and
#: timings are in every rendered row too: see the dataset format).
ROW_COLUMNS = ("frame_id", "split", "shard", "label_path", "width", "height", "fx", "fy", "cx", "cy",
               "distance_m", "ptd_receiver_m", "approach_index", "time_s", "sun_elevation_deg", "sun_azimuth_deg",
               "turbidity", "sea_wind_speed_mps", "cloud_type", "cloud_layer_coverage", "ground_type",
               "receiver_livery", "tanker_livery", "sensor_iso", "n_labeled")


def tour_config():
    from datagen.config import load_config, override_config

    return override_config(load_config(TOUR["config"]), {"dataset.frames": TOUR["frames"]})


def _value(value) -> str:
    if isinstance(value, float):
        return f"{value:.6g}"
    if isinstance(value, list):
        return "[" + ", ".join(_value(v) for v in value) + "]"
    return str(value)


def page(root: Path) -> str:
    """The page for the dataset at ``root`` (a build of :func:`tour_config`, rendered or not):
    its frame with the most labels."""
    import pyarrow.parquet as pq

    rows = [row for path in sorted((root / "manifests").glob("*.parquet")) for row in pq.read_table(path).to_pylist()]
    row = max(sorted(rows, key=lambda r: r["frame_id"]), key=lambda r: r["n_labeled"])
    names = {r["class_id"]: r["name"] for r in pq.read_table(root / "features.parquet").to_pylist()}
    label_text = (root / row["label_path"]).read_text()
    w, h = row["width"], row["height"]
    labeled = [f for f in row["features"] if f["labeled"]]
    excluded = [f for f in row["features"] if not f["labeled"]]
    first = labeled[0]
    suffix = tour_config().render.image_suffix
    cx, cy = first["center_px"]
    x0, y0, x1, y1 = first["label_xyxy"]
    lines = [
        "# One frame, its label file and its manifest row",
        "",
        "<!-- Written by scripts/example_frame.py; tests/test_docs.py fails when it drifts. -->",
        "",
        f"Frame {row['frame_id']} of the README's tour build (`datagen build --config {TOUR['config']} "
        f"--frames {TOUR['frames']}`), the one of its frames with the most labels. The image, "
        f"`{row['label_path'].replace('labels/', 'images/', 1).removesuffix('.txt')}{suffix}` (shown smaller):",
        "",
        "![the frame](../example-frame.jpg)",
        "",
        f"## The label file: `{row['label_path']}`",
        "",
        f"One line per labeled feature ({len(labeled)}): the class, then the label box's centre, "
        "width and height divided by the image's width and height (YOLO's format). The centre is "
        "the projection of the feature's true 3D centre, not the middle of what is visible: see "
        "[corrected labels](../concepts/corrected-labels.md).",
        "",
        "```text",
        label_text.rstrip("\n"),
        "```",
        "",
        f"The first line is class {first['class_id']}, `{names[first['class_id']]}`: its true centre "
        f"projects to ({cx:.3f}, {cy:.3f}) px, and its label box spans x {x0:.3f}-{x1:.3f} and "
        f"y {y0:.3f}-{y1:.3f} px in the {w}x{h} image, so the line's centre is "
        f"{cx:.3f} / {w} = {cx / w:.6f} and {cy:.3f} / {h} = {cy / h:.6f}.",
        "",
        "## The manifest row",
        "",
        f"The frame's row in `manifests/{row['split']}-{row['shard']:05d}.parquet` holds everything "
        "needed to recompute its labels (poses, intrinsics, every draw) and, per feature, why it is "
        "labeled or not. A few of its columns (all of them: [dataset format](dataset-format.md)):",
        "",
        "| column | value |",
        "|---|---|",
        *(f"| `{c}` | {_value(row[c])} |" for c in ROW_COLUMNS),
        "",
        f"Its `features` column has one entry per feature of the config ({len(row['features'])}); "
        "the labeled ones:",
        "",
        "| class | feature | true centre px | label box x0, y0, x1, y1 px |",
        "|---|---|---|---|",
        *(f"| {f['class_id']} | `{names[f['class_id']]}` | {_value(f['center_px'])} | {_value(f['label_xyxy'])} |"
          for f in labeled),
        "",
        "and why the others are not, by [exclusion reason](../concepts/glossary.md#exclusion-reasons):",
        "",
        "| reason | features |",
        "|---|---|",
        *(f"| `{reason}` | {sum(f['exclusion'] == reason for f in excluded)} |"
          for reason in sorted({f["exclusion"] for f in excluded})),
        "",
    ]
    return "\n".join(lines)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.parse_args()
    import cv2

    from datagen.pipeline.build import build_dataset

    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp) / "tour"
        build_dataset(tour_config(), root)
        text = page(root)
        frame = int(text.split("\nFrame ", 1)[1].split(" ", 1)[0])
        image = next((root / "images").rglob(f"{frame:08d}.*"))
        picture = cv2.imread(str(image))
        small = cv2.resize(picture, (1024, round(1024 * picture.shape[0] / picture.shape[1])),
                           interpolation=cv2.INTER_AREA)
        cv2.imwrite(str(IMAGE), small, [cv2.IMWRITE_JPEG_QUALITY, 88])
        PAGE.write_text(text)
    print(f"wrote {PAGE} and {IMAGE} (frame {frame})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
