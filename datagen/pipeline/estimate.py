"""What a build will cost before it starts: seconds per frame from the config alone.

A model of the frame's stages, in core-seconds measured on the project's standard
machine (a 2-core x86_64 VM: ``bench/bench_quality.py``, the README's performance table),
divided by the cores the build may use. The build prints it in its first lines; its
progress lines then give the measured rate.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Final

from datagen.config.schema import Config

__all__ = ["FrameCost", "frame_cost"]

#: Core-seconds of path tracing per megapixel and sample: the world's randomizers off
#: (``path``), and with cloud layers (``volpath``, procedural clouds and sea, liveries:
#: the shipped scenes' mean; podcam15, which sees the most cloud, is a third above it).
TRACE_CORE_S: Final = {"path": 0.21, "volpath": 0.89}
#: Core-seconds per frame that do not grow with the samples: posing the scene, tracing
#: the integrator, the kernels a frame's draws compile (measured: a new frame's first
#: render of the world took 1-2.5 s longer than its repeat).
FIXED_CORE_S: Final = {"path": 0.5, "volpath": 2.0}
#: Core-seconds of OIDN per megapixel, by quality (with two workers denoising at once: one
#: alone is faster); guides (albedo, normal) cost this factor.
DENOISE_CORE_S: Final = {"fast": 1.3, "balanced": 2.3, "high": 2.2}
GUIDES_FACTOR: Final = 1.4
#: Core-seconds per megapixel of the geometry pass, the camera model, encoding (sensor on, off).
REST_CORE_S: Final = {True: 0.45, False: 0.25}
#: Seconds per frame of a labels-only build (labels, manifests), one core.
LABELS_ONLY_S: Final = 1.0 / 250


@dataclass(frozen=True)
class FrameCost:
    """A frame's predicted wall seconds on ``cores`` cores, and what it assumed."""

    seconds: float
    cores: int
    setting: str  # "2048x1080, 4 spp, oidn high, clouds on, camera model on" or "labels only"

    @property
    def frames_per_hour(self) -> float:
        return 3600.0 / self.seconds


def frame_cost(config: Config, cores: int, *, render: bool = True) -> FrameCost:
    """The model's seconds per frame of ``config`` on ``cores`` cores."""
    cores = max(1, cores)
    if not render:
        return FrameCost(LABELS_ONLY_S / cores, cores, "labels only")
    cam, r, world = config.camera, config.render, config.randomization
    mpx = cam.width * cam.height / 1e6
    clouds = world.clouds.enabled
    integrator = "volpath" if clouds else "path"
    core_s = FIXED_CORE_S[integrator] + mpx * r.spp * TRACE_CORE_S[integrator]
    denoised = r.denoise != "off"
    if denoised:
        core_s += mpx * DENOISE_CORE_S[r.denoise_quality] * (GUIDES_FACTOR if r.denoise_guides else 1.0)
    core_s += mpx * REST_CORE_S[world.sensor.enabled]
    denoiser = f"oidn {r.denoise_quality}{' guided' if r.denoise_guides else ''}" if denoised else "no denoiser"
    world_text = f"clouds {'on' if clouds else 'off'}, camera model {'on' if world.sensor.enabled else 'off'}"
    return FrameCost(core_s / cores, cores, f"{cam.width}x{cam.height}, {r.spp} spp, {denoiser}, {world_text}")
