"""What a build will cost before it starts: seconds per frame from the config and the
device, bytes per frame on disk, and how many workers suit the device.

On the CPU (``llvm_ad_rgb``, ``scalar_rgb``): a model of the frame's stages, in
core-seconds measured on the project's standard machine (a 2-core x86_64 VM:
``bench/bench_quality.py``, the performance page), divided by the cores the build may
use. On a CUDA GPU: the host's core-seconds per frame (posing and tracing the kernels,
the geometry pass, the camera model, encoding) over the cores, or the GPU's own time per
frame where that is longer, measured on one H200 with 16 cores. The build prints the
estimate in its first lines; its progress lines then give the measured rate and the ETA
from it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Final

from datagen.config.schema import Config

__all__ = ["FrameCost", "auto_workers", "frame_cost"]

#: Core-seconds of path tracing per megapixel and sample: the world's randomizers off
#: (``path``), and with cloud layers (``volpath``, procedural clouds and sea, liveries:
#: wingcam55 measured 0.57; podcam15 sees more cloud, dashcam75 less).
TRACE_CORE_S: Final = {"path": 0.21, "volpath": 0.6}
#: Core-seconds per frame that do not grow with the image: posing the scene (0.03 s a frame,
#: 0.5 s more at an approach chain's first frame, where its weather and liveries are drawn).
FIXED_CORE_S: Final = {"path": 0.1, "volpath": 0.1}
#: Core-seconds of OIDN per megapixel, by quality (the guides, albedo and normal, cost
#: the filter nothing measurable; the integrator that makes them costs this factor).
DENOISE_CORE_S: Final = {"fast": 0.63, "balanced": 1.15, "high": 1.13}
GUIDES_FACTOR: Final = 1.4
#: Path tracing with aerial perspective (each camera sample's path through the air: up to
#: three rays more and a table lookup; wingcam55's ``mi.render`` measured 1.21x).
AIR_FACTOR: Final = 1.2
#: Core-seconds per megapixel of the geometry pass, the camera model, encoding (sensor on, off).
REST_CORE_S: Final = {True: 0.135, False: 0.086}
#: Bytes a frame adds to a dataset (measured on wingcam55's default world, every randomizer
#: on, at 2048x1080): its image per pixel by format, its EXR per pixel (linear RGB, Z, object
#: id), and its label files and manifest row (80 classes: 1.8 KB of label lines, 8.8 KB of
#: manifest).
IMAGE_BYTES_PER_PX: Final = {"png": 1.1, "jpg": 0.17}
EXR_BYTES_PER_PX: Final = 13.9
LABEL_BYTES_PER_FRAME: Final = 10_700
#: Seconds per frame of a labels-only build (labels, manifests), one core.
LABELS_ONLY_S: Final = 1.0 / 250
#: Local workers ``--workers auto`` runs on the CPU (at most one per core), the cores
#: shared among them: the frame's host work runs on one core beside Dr.Jit's pool.
CPU_WORKERS: Final = 2
#: On a CUDA GPU, seconds of the GPU per megapixel and sample of path tracing, and per
#: megapixel of OIDN (one H200, wingcam55 at 2048x1080 and 4 spp: the kernels execute in
#: 0.04-0.06 s, the denoiser in 0.03 s).
GPU_TRACE_S: Final = 0.006
GPU_DENOISE_S: Final = 0.015
#: On a CUDA GPU, host core-seconds per frame: fixed (posing, tracing the kernels, waiting
#: on them) and per megapixel (geometry pass, camera model, encoding); 2.8 core-seconds a
#: 2048x1080 frame, as 8 workers on the H200's 16 cores built 10,339 frames/h.
GPU_HOST_CORE_S: Final = 1.0
GPU_HOST_CORE_S_PER_MPX: Final = 0.8


@dataclass(frozen=True)
class FrameCost:
    """A frame's predicted wall seconds on ``cores`` cores and bytes on disk, and what it assumed."""

    seconds: float
    cores: int
    setting: str  # "2048x1080, 4 spp, oidn high, air on, clouds on, camera model on" or "labels only"
    disk_bytes: float = LABEL_BYTES_PER_FRAME

    @property
    def frames_per_hour(self) -> float:
        return 3600.0 / self.seconds


def frame_cost(config: Config, cores: int, *, render: bool = True, variant: str = "llvm_ad_rgb",
               mps: str | None = None) -> FrameCost:
    """The model's seconds per frame of ``config`` on ``cores`` cores, rendered with
    Mitsuba ``variant`` (``cuda_ad_rgb``: on a GPU, where the setting says whether the workers
    share it through CUDA MPS: ``mps`` the daemon's pipe directory, :func:`~datagen.render.runtime.cuda_mps_pipe`,
    ``""`` none runs, None not known)."""
    cores = max(1, cores)
    if not render:
        return FrameCost(LABELS_ONLY_S / cores, cores, "labels only")
    cam, r, world = config.camera, config.render, config.randomization
    mpx = cam.width * cam.height / 1e6
    per_px = IMAGE_BYTES_PER_PX[r.image_format] + (EXR_BYTES_PER_PX if r.exr else 0.0)
    disk = LABEL_BYTES_PER_FRAME + 1e6 * mpx * per_px
    clouds = world.clouds.enabled
    integrator = "volpath" if clouds else "path"
    denoised = r.denoise != "off"
    # On the path tracing: the aov integrator that makes the guides, the air's around the tracer.
    tracing = (GUIDES_FACTOR if r.denoise_guides else 1.0) * (AIR_FACTOR if world.haze.enabled else 1.0)
    denoiser = f"oidn {r.denoise_quality}{' guided' if r.denoise_guides else ''}" if denoised else "no denoiser"
    world_text = (f"air {'on' if world.haze.enabled else 'off'}, clouds {'on' if clouds else 'off'}, "
                  f"camera model {'on' if world.sensor.enabled else 'off'}")
    # Samples a pixel on average: the target pass's (datagen.render.target) over its window's share.
    spp = r.spp + (r.target_spp * r.target_window ** 2 if not variant.startswith("scalar") else 0.0)
    target = f" (+{r.target_spp} over the objects)" if r.target_spp and not variant.startswith("scalar") else ""
    setting = f"{cam.width}x{cam.height}, {r.spp} spp{target}, {denoiser}, {world_text}, {variant}"
    if variant.startswith("cuda"):
        if mps is not None:
            setting += (f", CUDA MPS ({mps})" if mps else
                        ", no CUDA MPS (the workers take turns on the GPU; `nvidia-cuda-mps-control -d` starts it)")
        gpu_s = mpx * spp * GPU_TRACE_S * tracing + (mpx * GPU_DENOISE_S if denoised else 0.0)
        host_s = (GPU_HOST_CORE_S + mpx * GPU_HOST_CORE_S_PER_MPX) / cores
        return FrameCost(max(gpu_s, host_s), cores, setting, disk)
    core_s = FIXED_CORE_S[integrator] + mpx * spp * TRACE_CORE_S[integrator] * tracing
    if denoised:
        core_s += mpx * DENOISE_CORE_S[r.denoise_quality]
    core_s += mpx * REST_CORE_S[world.sensor.enabled]
    return FrameCost(core_s / cores, cores, setting, disk)


def auto_workers(variant: str, cores: int, *, render: bool = True) -> int:
    """The local workers (processes) ``--workers auto`` runs for ``variant`` on ``cores``
    cores. On a CUDA GPU one per core, one Mitsuba thread each: the frame's host work is
    the limit there, and the GPU serves many processes (on the H200, 16 workers built
    14,596 frames/h and 8 built 10,339). On the CPU, or without rendering, :data:`CPU_WORKERS`
    of the cores' share each."""
    if render and variant.startswith("cuda"):
        return max(1, cores)
    return max(1, min(cores, CPU_WORKERS))
