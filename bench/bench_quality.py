"""Image quality per second: each render setting (spp x denoiser) against a converged
reference of the same frames, with the wall time of the whole frame.

    python bench/bench_quality.py [--frames wingcam55:14 podcam15:22 dashcam75:12]
        [--spp 1 2 4 8 16] [--modes off oidn-fast oidn-fast-guided oidn-high oidn-high-guided]
        [--reference-spp 1024] [--scale 1.0] [--cache bench/.quality-cache] [--references-only]
        [--out DIR]

Every world randomizer is on (the shipped scenes), the camera model off (``QUALITY``), so
that only rendering noise is measured; ``--scale 0.5`` renders at half the configs'
resolution (the held-out check: other frames, e.g. ``--frames wingcam55:3 podcam15:40``).

Reference: the frame rendered at ``--reference-spp`` (in chunks of 64 spp with their own
sampler seeds), no denoiser, kept as two halves of independent chunks (even and odd)
whose mean is the reference; ``--fix-off`` adds references with the uniform glassy sea
of earlier datagen. References are cached under ``--cache`` (they take minutes each).

Quality: PSNR and SSIM (datagen.analysis.image_quality) of the 8-bit sRGB image
against the reference's, over the whole frame; on the aircraft alone (the receiver's and
the tanker's pixels), PSNR and the detail ratio (``detail_ratio``: the fine detail the
image keeps of the reference's; under 1 the denoiser's waxy look, over 1 noise). Fireflies of a reference, in parts per
million: ``fireflies`` (luminance above 4x the second brightest of the 8 neighbours and
by at least a quarter of white); ``speckles`` (8-bit, brighter than the 5 x 5 median by
more than 32 levels: noise and converged fine detail alike) and ``noise speckles`` (the
speckles the two halves do not share: noise only). The brightest sea pixel
(display-linear luminance; 1 is white) shows whether the sun's glint is still there.

Time: seconds per frame for the whole frame as the build does it, camera model on
(approach state and look, labels, render, denoise, camera model, feature visibility,
sRGB and JPEG encoding), split into ``mi.render``, the denoiser and the rest; the first
line times the old default (16 spp, no denoiser, world off) on the same frames. Each
setting renders each frame three times and times the third: the first two compile the
frame's kernels (Dr.Jit bakes some of a frame's sky draws into them, and a freshly loaded
scene's first render compiles other kernels than its next).
"""

from __future__ import annotations

import argparse
import os
import platform
import tempfile
import time
from pathlib import Path

import numpy as np

from datagen.analysis.image_quality import detail_ratio, fireflies, luminance, noise_speckles, psnr, speckles, ssim
from datagen.atomic import write_bytes, write_image
from datagen.config import load_config, override_config
from datagen.config.schema import world_off
from datagen.core.conventions import object_id
from datagen.pipeline.frame import draw_frame
from datagen.pipeline.writer import timed_frame
from datagen.render.renderer import Renderer
from datagen.render.timing import DENOISE, PATH_TRACING, rest_of_frame
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
#: Every setting and reference: the camera model off, so that only rendering noise is measured.
QUALITY = {"randomization.sensor.enabled": False}
#: The default of before the denoiser, timed as the baseline: 16 spp, no denoiser, world off.
OLD_DEFAULT = {"render.spp": 16, "render.denoise": "off", **world_off()}


def scaled(config, scale: float):
    """``config`` at ``scale`` times its resolution (the same field of view)."""
    if scale == 1.0:
        return config
    return override_config(config, {"camera.width": round(config.camera.width * scale),
                                    "camera.height": round(config.camera.height * scale)})


def reference_path(cache: Path, config, frame: int, spp: int, fix: bool) -> Path:
    size = f"{config.camera.width}x{config.camera.height}"
    return cache / f"{config.name}-{frame}-{size}-{spp}spp-world-{'fix' if fix else 'nofix'}.npz"


def reference(config, frame: int, spp: int, cache: Path, fix: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The converged linear image of ``frame`` as two halves of independent samples, and
    its object ids (cached)."""
    tag = "fix" if fix else "nofix"
    path = reference_path(cache, config, frame, spp, fix)
    if path.is_file():
        data = np.load(path)
        return data["half_a"], data["half_b"], data["ids"]
    cfg = override_config(config, {"render.denoise": "off", **QUALITY, **({} if fix else NOFIX)})
    scene = Scene.resolve(cfg)
    renderer = Renderer(scene, spp=CHUNK_SPP)
    draws = draw_frame(scene, FrameStates(cfg), frame)
    halves, ids = [0.0, 0.0], None
    start = time.perf_counter()
    chunks = max(2, spp // CHUNK_SPP)
    for k in range(chunks):
        result = renderer.render(draws.state, draws.look, (draws.render_seed + 7919 * k) % 2**32, geometry=k == 0)
        halves[k % 2] = halves[k % 2] + result.rgb.astype(np.float64)
        ids = result.object_id if k == 0 else ids
    half_a, half_b = ((h / (chunks // 2)).astype(np.float32) for h in halves)
    import io

    buffer = io.BytesIO()
    np.savez_compressed(buffer, half_a=half_a, half_b=half_b, ids=ids)
    write_bytes(path, buffer.getvalue())
    print(f"  reference {config.name}:{frame} {spp} spp ({tag}) in {time.perf_counter() - start:.0f} s", flush=True)
    return half_a, half_b, ids


def firefly_line(name: str, half_a: np.ndarray, half_b: np.ndarray, ids: np.ndarray) -> str:
    rgb = (half_a + half_b) / 2
    ff = fireflies(rgb)
    on_objects = ff & (ids > 0)
    sp = speckles(to_srgb8(rgb))
    noise = noise_speckles(to_srgb8(half_a), to_srgb8(half_b))
    sea = (ids == 0) & np.isfinite(luminance(rgb))
    sea_max = float(luminance(rgb)[sea].max()) if sea.any() else float("nan")
    return (f"{name}: fireflies {ff.mean() * 1e6:7.1f} ppm ({int(ff.sum())} px, {int(on_objects.sum())} on aircraft), "
            f"speckles {sp.mean() * 1e6:7.1f} ppm, noise speckles {noise.mean() * 1e6:6.1f} ppm, "
            f"brightest sea/sky pixel {sea_max:.2f}")


def write_crop(path: Path, config, frame: int, reference_spp: int, cache: Path) -> None:
    """Four crops of the frame about its tanker, 8-bit sRGB: the converged reference with
    the glassy sea of before and with the Cox-Munk sea; the old default (16 spp, no
    denoiser, glassy sea) and the shipped default setting."""
    import cv2

    before_a, before_b, ids = reference(config, frame, reference_spp, cache, fix=False)
    after_a, after_b, _ = reference(config, frame, reference_spp, cache, fix=True)
    panels = [(f"converged ({reference_spp} spp), glassy sea: fireflies", (before_a + before_b) / 2),
              (f"converged ({reference_spp} spp), Cox-Munk sea", (after_a + after_b) / 2)]
    for title, updates in (("before: 16 spp, no denoiser, glassy sea",
                            {"render.spp": 16, "render.denoise": "off", **NOFIX}),
                           (f"after: the default ({config.render.spp} spp, denoise {config.render.denoise})", {})):
        cfg = override_config(config, {**QUALITY, **updates})
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


def time_frame(config, frame: int, tmp: Path) -> tuple[float, dict[str, float]]:
    """Seconds for ``frame`` of ``config`` as the build makes it, whole and per stage
    (:func:`datagen.pipeline.writer.timed_frame`), after two untimed renders of it."""
    scene = Scene.resolve(config)
    renderer = Renderer(scene)
    warm = draw_frame(scene, FrameStates(config), frame)
    for _ in range(2):  # kernel compilation: a fresh scene's first render compiles other kernels than the next
        renderer.render(warm.state, warm.look, warm.render_seed)
    return timed_frame(scene, renderer, FrameStates(config), frame, tmp / "frame.jpg")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", nargs="+", default=["wingcam55:14", "podcam15:22", "dashcam75:12"],
                        help="scene:frame pairs")
    parser.add_argument("--spp", type=int, nargs="+", default=[1, 2, 4, 8, 16])
    parser.add_argument("--modes", nargs="+", default=list(MODES), choices=list(MODES))
    parser.add_argument("--reference-spp", type=int, default=1024)
    parser.add_argument("--scale", type=float, default=1.0, help="render at this fraction of the resolution")
    parser.add_argument("--cache", type=Path, default=Path("bench/.quality-cache"))
    parser.add_argument("--references-only", action="store_true")
    parser.add_argument("--fix-off", choices=["all", "cached", "none"], default="none",
                        help="references with the glassy sea of before: render them all, only those cached, or none")
    parser.add_argument("--out", type=Path, default=None, help="write each setting's first-frame PNG here")
    parser.add_argument("--crop", type=Path, default=None,
                        help="write a before/after crop of the first frame's tanker here (docs/quality-crop.png)")
    args = parser.parse_args()
    frames = [(name, int(i)) for name, i in (f.split(":") for f in args.frames)]
    configs = {name: scaled(load_config(name), args.scale) for name, _ in frames}
    first = next(iter(configs.values()))
    print(f"machine: {platform.machine()}, {os.cpu_count()} CPUs; frames {' '.join(args.frames)} at "
          f"{first.camera.width}x{first.camera.height}; every world randomizer on, camera model off; "
          f"reference {args.reference_spp} spp")

    refs, aircraft = {}, {}
    for name, i in frames:
        for fix in (True, False):
            cached = reference_path(args.cache, configs[name], i, args.reference_spp, False).is_file()
            if not fix and (args.fix_off == "none" or (args.fix_off == "cached" and not cached)):
                continue
            half_a, half_b, ids = reference(configs[name], i, args.reference_spp, args.cache, fix)
            print("  " + firefly_line(f"{name}:{i} reference, fix {'on ' if fix else 'off'}", half_a, half_b, ids),
                  flush=True)
            if fix:
                refs[(name, i)] = to_srgb8((half_a + half_b) / 2)
                aircraft[(name, i)] = np.isin(ids, [object_id("receiver"), object_id("tanker")])
    if args.crop is not None:
        write_crop(args.crop, configs[frames[0][0]], frames[0][1], args.reference_spp, args.cache)
    if args.references_only:
        return

    with tempfile.TemporaryDirectory() as tmp:
        old = [time_frame(override_config(configs[name], OLD_DEFAULT), i, Path(tmp))[0] for name, i in frames]
        base = float(np.mean(old))
        print(f"\nold default (16 spp, no denoiser, world off), whole frame: {base:.2f} s/frame")
        print("\n| spp | denoise | PSNR dB (mean, min) | SSIM (mean) | aircraft PSNR dB | aircraft detail "
              "| s/frame whole, world on | x old default | mi.render | denoise | rest |")
        print("|---|---|---|---|---|---|---|---|---|---|---|")
        for spp in args.spp:
            for mode in args.modes:
                scores, times, stages = [], [], {}
                for name, i in frames:
                    config = override_config(configs[name], {**MODES[mode], "render.spp": spp})
                    whole, clock = time_frame(config, i, Path(tmp))
                    times.append(whole)
                    for k, v in clock.items():
                        stages[k] = stages.get(k, 0.0) + v / len(frames)
                    quiet = override_config(config, QUALITY)  # the same frame, rendering noise only
                    scene = Scene.resolve(quiet)
                    draws = draw_frame(scene, FrameStates(quiet), i)
                    image = to_srgb8(Renderer(scene).render(draws.state, draws.look, draws.render_seed).rgb)
                    ref, mask = refs[(name, i)], aircraft[(name, i)]
                    scores.append((psnr(image, ref), ssim(image, ref), psnr(image[mask], ref[mask]),
                                   detail_ratio(image, ref, mask)))
                    if args.out is not None:
                        write_image(args.out / f"{name}-{i}-{spp}spp-{mode}.png", image[..., ::-1])
                p = np.array([s[0] for s in scores])
                whole = float(np.mean(times))
                render, denoise = stages.get(PATH_TRACING, 0.0), stages.get(DENOISE, 0.0)
                print(f"| {spp} | {mode} | {p.mean():.1f}, {p.min():.1f} | {np.mean([s[1] for s in scores]):.3f} "
                      f"| {np.nanmean([s[2] for s in scores]):.1f} | {np.nanmean([s[3] for s in scores]):.2f} "
                      f"| {whole:.2f} | {whole / base:.2f} | {render:.2f} | {denoise:.2f} "
                      f"| {whole - render - denoise:.2f} |",
                      flush=True)
                print("    stages: " + ", ".join(f"{k} {v:.3f} s" for k, v in rest_of_frame(stages))
                      + f" ({(whole - render - denoise) / whole:.0%} of the frame)", flush=True)


if __name__ == "__main__":
    main()
