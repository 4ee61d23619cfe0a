"""Image quality per second: each render setting (spp x denoiser) against a converged
reference of the same frames, with the wall time of the whole frame.

    python bench/bench_quality.py [--frames wingcam55:14 podcam15:22 dashcam75:12]
        [--spp 1 2 4 8 16] [--modes off oidn-fast oidn-fast-guided oidn-high oidn-high-guided]
        [--reference-spp 1024] [--cache bench/.quality-cache] [--references-only] [--out DIR]

Reference: the frame rendered at ``--reference-spp`` (in chunks of 64 spp with their own
sampler seeds, averaged), no denoiser, with the scene's sea model (Cox-Munk, the
firefly fix) and again with the uniform glassy sea of earlier datagen (``fix off``).
References are cached under ``--cache`` (they take minutes each).

Quality: PSNR and SSIM (datagen.analysis.image_quality) of the 8-bit sRGB image
against the reference's, over the whole frame. Fireflies: the share of pixels of a
reference that stand far above their neighbourhood (``fireflies``: luminance above
4x the second brightest of the 8 neighbours and by at least a quarter of white), in parts per
million; the brightest sea pixel (display-linear luminance; 1 is white) shows whether
the sun's glint on the sea is still there.

Time: seconds per frame for the whole frame as the build does it (approach state and
look, labels, render, denoise, feature visibility, PNG encoding), split into
``mi.render``, the denoiser and the rest. Each setting renders its frames once after
a warm-up frame (kernel compilation) that is not counted.
"""

from __future__ import annotations

import argparse
import os
import platform
import tempfile
import time
from pathlib import Path

import numpy as np

from datagen.analysis.image_quality import fireflies, luminance, psnr, ssim
from datagen.config import load_config, override_config
from datagen.core.conventions import object_id
from datagen.files import write_bytes, write_image
from datagen.pipeline.frame import draw_frame, frame_labels
from datagen.render.renderer import Renderer
from datagen.render.tonemap import to_srgb8
from datagen.scene.approach import FrameStates
from datagen.scene.resolved import Scene

MODES = {"off": {"render.denoise": "off"}} | {  # name -> render config overrides
    f"oidn-{quality}{'-guided' if guides else ''}": {"render.denoise": "oidn", "render.denoise_quality": quality,
                                                      "render.denoise_guides": guides}
    for quality in ("fast", "high") for guides in (False, True)
}
CHUNK_SPP = 64
NOFIX = {"randomization.sea.model": "uniform"}


def reference_path(cache: Path, name: str, frame: int, spp: int, fix: bool) -> Path:
    return cache / f"{name}-{frame}-{spp}spp-{'fix' if fix else 'nofix'}.npz"


def reference(config, frame: int, spp: int, cache: Path, fix: bool) -> tuple[np.ndarray, np.ndarray]:
    """The converged linear image of ``frame`` and its object ids (cached)."""
    tag = "fix" if fix else "nofix"
    path = reference_path(cache, config.name, frame, spp, fix)
    if path.is_file():
        data = np.load(path)
        return data["rgb"], data["ids"]
    cfg = override_config(config, {"render.denoise": "off", **({} if fix else NOFIX)})
    scene = Scene.resolve(cfg)
    renderer = Renderer(scene, spp=CHUNK_SPP)
    draws = draw_frame(scene, FrameStates(cfg), frame)
    total, ids = None, None
    start = time.perf_counter()
    for k in range(max(1, spp // CHUNK_SPP)):
        result = renderer.render(draws.state, draws.look, (draws.render_seed + 7919 * k) % 2**32, geometry=k == 0)
        total = result.rgb.astype(np.float64) if total is None else total + result.rgb
        ids = result.object_id if k == 0 else ids
    rgb = (total / max(1, spp // CHUNK_SPP)).astype(np.float32)
    import io

    buffer = io.BytesIO()
    np.savez_compressed(buffer, rgb=rgb, ids=ids)
    write_bytes(path, buffer.getvalue())
    print(f"  reference {config.name}:{frame} {spp} spp ({tag}) in {time.perf_counter() - start:.0f} s", flush=True)
    return rgb, ids


def firefly_line(name: str, rgb: np.ndarray, ids: np.ndarray) -> str:
    ff = fireflies(rgb)
    on_objects = ff & (ids > 0)
    sea = (ids == 0) & np.isfinite(luminance(rgb))
    sea_max = float(luminance(rgb)[sea].max()) if sea.any() else float("nan")
    return (f"{name}: fireflies {ff.mean() * 1e6:7.1f} ppm ({int(ff.sum())} px, {int(on_objects.sum())} on aircraft), "
            f"brightest sea/sky pixel {sea_max:.2f}")


def write_crop(path: Path, config, frame: int, reference_spp: int, cache: Path) -> None:
    """Four crops of the frame about its tanker, 8-bit sRGB: the converged reference with
    the glassy sea of before and with the Cox-Munk sea; the old default (16 spp, no
    denoiser, glassy sea) and the shipped default setting."""
    import cv2

    before, ids = reference(config, frame, reference_spp, cache, fix=False)
    after, _ = reference(config, frame, reference_spp, cache, fix=True)
    panels = [(f"converged ({reference_spp} spp), glassy sea: fireflies", before),
              (f"converged ({reference_spp} spp), Cox-Munk sea", after)]
    for title, updates in (("before: 16 spp, no denoiser, glassy sea",
                            {"render.spp": 16, "render.denoise": "off", **NOFIX}),
                           (f"after: the default ({config.render.spp} spp, denoise {config.render.denoise})", {})):
        cfg = override_config(config, updates)
        scene = Scene.resolve(cfg)
        draws = draw_frame(scene, FrameStates(cfg), frame)
        panels.append((title, Renderer(scene).render(draws.state, draws.look, draws.render_seed).rgb))
    rows, cols = np.nonzero(ids == object_id("tanker"))
    h, w = 300, 520
    v0 = int(np.clip(np.median(rows) - h // 2, 0, ids.shape[0] - h))
    u0 = int(np.clip(np.median(cols) - w // 2, 0, ids.shape[1] - w))
    tiles = []
    for title, rgb in panels:
        tile = np.ascontiguousarray(to_srgb8(rgb[v0:v0 + h, u0:u0 + w])[..., ::-1])
        cv2.rectangle(tile, (0, 0), (w - 1, 30), (0, 0, 0), -1)
        cv2.putText(tile, title, (8, 21), cv2.FONT_HERSHEY_SIMPLEX, 0.55, (255, 255, 255), 1, cv2.LINE_AA)
        tiles.append(tile)
    grid = np.vstack([np.hstack(tiles[:2]), np.hstack(tiles[2:])])
    write_image(path, grid)
    print(f"  crop of {config.name}:{frame} at u {u0}-{u0 + w}, v {v0}-{v0 + h} -> {path}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", nargs="+", default=["wingcam55:14", "podcam15:22", "dashcam75:12"],
                        help="scene:frame pairs")
    parser.add_argument("--spp", type=int, nargs="+", default=[1, 2, 4, 8, 16])
    parser.add_argument("--modes", nargs="+", default=list(MODES), choices=list(MODES))
    parser.add_argument("--reference-spp", type=int, default=1024)
    parser.add_argument("--cache", type=Path, default=Path("bench/.quality-cache"))
    parser.add_argument("--references-only", action="store_true")
    parser.add_argument("--fix-off", choices=["all", "cached", "none"], default="all",
                        help="references with the glassy sea of before: render them all, only those cached, or none")
    parser.add_argument("--out", type=Path, default=None, help="write each setting's first-frame PNG here")
    parser.add_argument("--crop", type=Path, default=None,
                        help="write a before/after crop of the first frame's tanker here (docs/quality-crop.png)")
    args = parser.parse_args()
    frames = [(name, int(i)) for name, i in (f.split(":") for f in args.frames)]
    configs = {name: load_config(name) for name, _ in frames}
    print(f"machine: {platform.machine()}, {os.cpu_count()} CPUs; frames {' '.join(args.frames)}; "
          f"reference {args.reference_spp} spp")

    refs = {}
    for name, i in frames:
        for fix in (True, False):
            cached = reference_path(args.cache, name, i, args.reference_spp, False).is_file()
            if not fix and (args.fix_off == "none" or (args.fix_off == "cached" and not cached)):
                continue
            rgb, ids = reference(configs[name], i, args.reference_spp, args.cache, fix)
            print("  " + firefly_line(f"{name}:{i} reference, fix {'on ' if fix else 'off'}", rgb, ids), flush=True)
            if fix:
                refs[(name, i)] = to_srgb8(rgb)
    if args.crop is not None:
        write_crop(args.crop, configs[frames[0][0]], frames[0][1], args.reference_spp, args.cache)
    if args.references_only:
        return

    print("\n| spp | denoise | PSNR dB (mean, min) | SSIM (mean) | s/frame whole | mi.render | denoise | rest |")
    print("|---|---|---|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        for spp in args.spp:
            for mode in args.modes:
                scores, times = [], []
                for name, i in frames:
                    config = override_config(configs[name], MODES[mode])
                    scene = Scene.resolve(config)
                    renderer = Renderer(scene, spp=spp)
                    states = FrameStates(config)
                    warm = draw_frame(scene, states, i + 1)
                    renderer.render(warm.state, warm.look, warm.render_seed)  # kernel compilation
                    start = time.perf_counter()  # the build's frame pipeline, timed whole
                    draws = draw_frame(scene, states, i)
                    frame_labels(scene, draws)
                    result = renderer.render(draws.state, draws.look, draws.render_seed)
                    renderer.feature_visibility(draws.state, scene.features)
                    image = to_srgb8(result.rgb)
                    write_image(Path(tmp) / f"{name}-{i}.png", image[..., ::-1])
                    whole = time.perf_counter() - start
                    times.append((whole, result.render_s, result.denoise_s or 0.0))
                    scores.append((psnr(image, refs[(name, i)]), ssim(image, refs[(name, i)])))
                    if args.out is not None:
                        write_image(args.out / f"{name}-{i}-{spp}spp-{mode}.png", image[..., ::-1])
                p = np.array([s[0] for s in scores])
                t = np.mean(np.array(times), axis=0)
                print(f"| {spp} | {mode} | {p.mean():.1f}, {p.min():.1f} | {np.mean([s[1] for s in scores]):.3f} "
                      f"| {t[0]:.2f} | {t[1]:.2f} | {t[2]:.2f} | {t[0] - t[1] - t[2]:.2f} |", flush=True)


if __name__ == "__main__":
    main()
