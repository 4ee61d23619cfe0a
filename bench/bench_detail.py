"""The denoiser's waxy look, compared between two checkouts: the fine detail on the aircraft's
surfaces in frames rendered as a build renders them (the configs' sampling and denoiser, every
world randomizer on, the camera model off as in ``bench_quality.py``, so that only rendering
is measured), and how much of a converged reference's detail each keeps.

    python bench/bench_detail.py render --out DIR [--frames wingcam55:14 podcam15:30 dashcam75:12]
        [--scale 0.5] [--reference-spp 0] [--variant llvm_ad_rgb]
    PYTHONPATH=<other checkout> python bench/bench_detail.py render --out DIR_OTHER ...
    python bench/bench_detail.py compare DIR DIR_OTHER

``render`` keeps each frame's 8-bit image and object ids (``DIR/<scene>_<frame>.npz``) and,
with ``--reference-spp``, the frame converged at that many samples without the denoiser; it
uses only what every checkout since the procedural world has, so that it runs on older ones.
``compare`` prints per frame the aircraft's fine detail in each directory
(:func:`datagen.analysis.image_quality.detail_rms` on the receiver's and tanker's pixels
:data:`SURFACE_INSET_PX` or more inside their silhouettes, so that outlines against the sky do
not count), their ratio, and where a directory has references, the share of its reference's
detail each frame keeps (``detail_ratio``: under 1 is the denoiser's wax).
"""

from __future__ import annotations

import argparse
import os
import platform
from pathlib import Path

import numpy as np

#: How far inside an aircraft's silhouette (pixels) its surface is measured: past the outline's
#: own high-pass (3.5 sigma of the detail measure's blur) and a pixel of antialiasing.
SURFACE_INSET_PX = 7


#: References in chunks of this many samples, each with its own sampler seed.
CHUNK_SPP = 64


def render(out: Path, frames: list[str], scale: float, reference_spp: int, variant: str = "llvm_ad_rgb") -> None:
    """Each frame's 8-bit image and object ids, and its reference when asked, into ``out``."""
    from datagen.config import load_config, override_config
    from datagen.pipeline.frame import draw_frame
    from datagen.render.renderer import Renderer
    from datagen.render.runtime import set_threads, use_variant
    from datagen.render.tonemap import to_srgb8
    from datagen.scene.approach import FrameStates
    from datagen.scene.resolved import Scene

    use_variant(variant)
    set_threads(os.cpu_count() or 1)
    out.mkdir(parents=True, exist_ok=True)
    for item in frames:
        name, i = item.split(":")
        base = load_config(name)
        config = override_config(base, {"camera.width": round(base.camera.width * scale),
                                        "camera.height": round(base.camera.height * scale),
                                        "randomization.sensor.enabled": False})
        scene = Scene.resolve(config)
        draws = draw_frame(scene, FrameStates(config), int(i))
        result = Renderer(scene).render(draws.state, draws.look, draws.render_seed, geometry=True)
        arrays = {"srgb": to_srgb8(result.rgb), "object_id": result.object_id}
        if reference_spp:
            plain = Scene.resolve(override_config(config, {"render.denoise": "off"}))
            renderer, chunks, total = Renderer(plain, spp=CHUNK_SPP), max(1, reference_spp // CHUNK_SPP), 0.0
            for k in range(chunks):
                seed = (draws.render_seed + 7919 * (k + 1)) % 2**32
                total = total + renderer.render(draws.state, draws.look, seed).rgb.astype(np.float64)
            arrays["reference"] = to_srgb8(total / chunks)
        np.savez_compressed(out / f"{name}_{i}.npz", **arrays)
        print(f"{item}: {out / f'{name}_{i}.npz'}", flush=True)


def compare(a: Path, b: Path) -> None:
    """Per frame in both directories, the aircraft's surface detail in each and their ratio."""
    from scipy.ndimage import binary_erosion

    from datagen.analysis.image_quality import detail_ratio, detail_rms
    from datagen.core.conventions import object_id

    def surface(ids: np.ndarray) -> np.ndarray:
        aircraft = np.isin(ids, [object_id("receiver"), object_id("tanker")])
        return binary_erosion(aircraft, iterations=SURFACE_INSET_PX)

    print(f"machine: {platform.machine()}, {os.cpu_count()} CPUs")
    print(f"| frame | surface px | detail {a.name} | detail {b.name} | ratio "
          f"| kept of the reference's {a.name} / {b.name} |")
    print("|---|---|---|---|---|---|")
    ratios = []
    for path in sorted(a.glob("*.npz")):
        if not (b / path.name).exists():
            continue
        x, y = np.load(path), np.load(b / path.name)
        mx, my = surface(x["object_id"]), surface(y["object_id"])
        dx, dy = detail_rms(x["srgb"], mx), detail_rms(y["srgb"], my)
        ratios.append(dx / dy)
        kept = [f"{detail_ratio(d['srgb'], d['reference'], m):.2f}" if "reference" in d else "-"
                for d, m in ((x, mx), (y, my))]
        print(f"| {path.stem} | {int(mx.sum())} / {int(my.sum())} | {dx * 255:.2f} | {dy * 255:.2f} | {dx / dy:.2f} "
              f"| {' / '.join(kept)} |")
    if not ratios:
        raise SystemExit(f"no frame is in both {a} and {b}")
    print(f"geometric mean ratio {float(np.exp(np.mean(np.log(ratios)))):.2f} (detail in 8-bit levels)")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)
    r = sub.add_parser("render", help="keep frames' training images and object ids")
    r.add_argument("--out", type=Path, required=True)
    r.add_argument("--frames", nargs="+", default=["wingcam55:14", "podcam15:30", "dashcam75:12"])
    r.add_argument("--scale", type=float, default=0.5)
    r.add_argument("--reference-spp", type=int, default=0, help="also a converged reference at this many spp")
    r.add_argument("--variant", default="llvm_ad_rgb", help="the Mitsuba variant (cuda_ad_rgb on a GPU)")
    c = sub.add_parser("compare", help="the aircraft's surface detail in two directories")
    c.add_argument("a", type=Path)
    c.add_argument("b", type=Path)
    args = parser.parse_args()
    if args.command == "render":
        render(args.out, args.frames, args.scale, args.reference_spp, args.variant)
    else:
        compare(args.a, args.b)


if __name__ == "__main__":
    main()
