"""Mitsuba's process-wide settings, set in one place: the variant, the thread count, and
which object holds the process's one scene.

Nothing calls ``mi.set_variant`` or ``dr.set_thread_count`` but this module; the
CLI and the build's worker bootstrap call :func:`use_variant` and
:func:`set_threads` (a :class:`~datagen.render.renderer.Renderer` asks for its
variant through :func:`use_variant` too). Importing datagen sets nothing.

One scene at a time (:func:`hold_scene`): Dr.Jit compiles a call through a Mitsuba
class (a shape's BSDF, an emitter) for every live instance of that class in the process,
so a second scene's objects grew the render kernel and changed its hash when they came or
went; on CUDA, a kernel that touched two scenes' OptiX tables had those rays disabled
(read as misses: wrong images with a warning, mitsuba3 issue 1349). Whatever builds
Mitsuba objects (a renderer, the silhouettes, the contact sheets' views) takes the
process's scene first; the holder before it releases its objects and builds them again
when it is next used.
"""

from __future__ import annotations

import contextlib
import functools
import gc
import weakref
from collections.abc import Iterator
from typing import Final, Protocol

from datagen.core.errors import DatagenError

__all__ = ["HEAP_REQUEST_MAX", "LLVM_HINT", "MPS_PIPE_DIRECTORY", "VARIANTS", "KernelCensus", "SceneHolder",
           "cuda_mps_pipe", "has_backend", "hold_scene", "keep_freed_memory", "resolve_variant", "set_threads",
           "thread_count", "use_variant"]

VARIANTS: Final = ("cuda_ad_rgb", "llvm_ad_rgb", "scalar_rgb")


LLVM_HINT: Final = (
    "Mitsuba's llvm_ad_rgb variant needs LLVM 19: install it with `apt-get install -y libllvm19` "
    "(LLVM 15/16 crash and 14 is too old), or set render.variant: scalar_rgb"
)


@functools.cache
def has_backend(name: str) -> bool:
    import drjit as dr

    backend = {"cuda": dr.JitBackend.CUDA, "llvm": dr.JitBackend.LLVM}[name]
    try:
        return bool(dr.has_backend(backend))
    except Exception:  # an unusable driver or library reads as absent
        return False


def resolve_variant(requested: str = "auto") -> str:
    """The Mitsuba variant ``requested`` names on this machine (``auto``: CUDA, then LLVM,
    then scalar), without setting it; one clear line when it cannot run here."""
    if requested == "auto":
        return "cuda_ad_rgb" if has_backend("cuda") else "llvm_ad_rgb" if has_backend("llvm") else "scalar_rgb"
    if requested not in VARIANTS:
        raise DatagenError(f"render.variant: unknown Mitsuba variant {requested!r} (use auto or {', '.join(VARIANTS)})")
    if requested == "llvm_ad_rgb" and not has_backend("llvm"):
        raise DatagenError(f"render.variant: llvm_ad_rgb is unavailable: {LLVM_HINT}")
    if requested == "cuda_ad_rgb" and not has_backend("cuda"):
        raise DatagenError("render.variant: cuda_ad_rgb is unavailable: no CUDA GPU or driver found")
    return requested


def use_variant(requested: str = "auto") -> str:
    """Set and return the Mitsuba variant :func:`resolve_variant` names."""
    import mitsuba as mi

    chosen = resolve_variant(requested)
    if mi.variant() != chosen:
        mi.set_variant(chosen)
    return chosen


def set_threads(threads: int) -> None:
    """Size Dr.Jit's thread pool (one thread gives byte-identical renders) and OpenCV's (the
    camera model's blurs and remaps), so that workers sharing a machine each keep to their
    share of its cores; and keep the memory a frame frees for the next (:func:`keep_freed_memory`):
    what a process that renders frames sets before its first."""
    import cv2
    import drjit as dr

    dr.set_thread_count(max(1, int(threads)))
    cv2.setNumThreads(max(1, int(threads)))
    keep_freed_memory()


#: glibc's ``mallopt`` parameters (``malloc.h``) that :func:`keep_freed_memory` sets.
_M_TRIM_THRESHOLD: Final = -1
_M_MMAP_THRESHOLD: Final = -3
#: The largest request glibc's malloc serves from its heap once :func:`keep_freed_memory` ran:
#: the most glibc allows on 64-bit, above a 2048x1080 float32 RGB image (27 MB).
HEAP_REQUEST_MAX: Final = 32 * 2**20


@functools.cache
def keep_freed_memory() -> bool:
    """Have glibc's malloc serve requests of up to :data:`HEAP_REQUEST_MAX` from its heap and
    keep the heap's free top instead of handing it back, so that the camera model's
    full-size arrays (numpy's and OpenCV's, a few a step) reuse the memory the frame before
    freed. By default glibc maps a request over 128 KiB anew (its threshold adapts upwards
    as such blocks are freed) and unmaps it when freed, and returns the heap's free top past
    a threshold: a frame's images were fresh pages that the kernel faulted in and zeroed,
    every frame (the performance page has what it cost). The process keeps its largest
    frame's working set instead. Whether the options were set: False where the C library
    is not glibc (nothing changes there)."""
    import ctypes
    import platform

    if platform.system() != "Linux" or platform.libc_ver()[0] != "glibc":
        return False
    try:
        mallopt = ctypes.CDLL("libc.so.6").mallopt
    except (OSError, AttributeError):
        return False
    return bool(mallopt(_M_MMAP_THRESHOLD, HEAP_REQUEST_MAX)) and bool(mallopt(_M_TRIM_THRESHOLD, 2**31 - 1))


#: Where a CUDA MPS control daemon keeps its pipes unless ``CUDA_MPS_PIPE_DIRECTORY`` says otherwise.
MPS_PIPE_DIRECTORY: Final = "/tmp/nvidia-mps"


def cuda_mps_pipe() -> str | None:
    """The pipe directory of the running CUDA MPS control daemon this process's CUDA contexts
    would join (``CUDA_MPS_PIPE_DIRECTORY``, else :data:`MPS_PIPE_DIRECTORY`, holding the
    daemon's ``control`` FIFO), or None where none runs. CUDA joins one by itself, nothing
    to set: with it, the kernels of the workers sharing a GPU run side by side; without it
    the GPU runs one worker's context at a time (time-sliced)."""
    import os
    import stat

    pipes = os.environ.get("CUDA_MPS_PIPE_DIRECTORY") or MPS_PIPE_DIRECTORY
    try:
        return pipes if stat.S_ISFIFO(os.stat(os.path.join(pipes, "control")).st_mode) else None
    except OSError:
        return None


def thread_count() -> int:
    """The size of Dr.Jit's thread pool now."""
    import drjit as dr

    return int(dr.thread_count())


class SceneHolder(Protocol):
    """An object that builds Mitsuba objects when it needs them and can let them go."""

    def release(self) -> None:
        """Drop every Mitsuba object held (built again on next use)."""


_holders: weakref.WeakSet = weakref.WeakSet()


def hold_scene(holder: SceneHolder) -> None:
    """Make ``holder`` the only object in the process that holds Mitsuba scene objects:
    every other holder releases its own, and they are collected, before ``holder``
    builds its scene."""
    others = [h for h in list(_holders) if h is not holder]
    for other in others:
        other.release()
        _holders.discard(other)
    if others:
        gc.collect()  # Python-side textures and emitters hold their C++ objects through cycles
    _holders.add(holder)


class KernelCensus:
    """The JIT kernels a process launches, frame by frame (Dr.Jit's kernel history, on
    while :meth:`recording`): how many a frame launched that no earlier frame of the census
    had, which is a compile (or, for the first frame, a load from the kernel cache)."""

    def __init__(self) -> None:
        self._seen: set[str] = set()
        #: What the last :meth:`new_kernels` found launched since the call before: JIT kernels,
        #: memory copies and fills. A copy of one value is either a value read back to the host
        #: (``jit_var_read``: a wait on a GPU) or a gather of one known element, which Dr.Jit
        #: makes an asynchronous copy on the device (no wait); the history does not say which.
        self.launched = {"kernels": 0, "copies": 0, "one-value copies": 0, "fills": 0}

    @contextlib.contextmanager
    def recording(self) -> Iterator[None]:
        """Keep the kernel history while the block runs (the flag as it was after it)."""
        import drjit as dr

        with dr.scoped_set_flag(dr.JitFlag.KernelHistory, True):
            dr.kernel_history()  # what came before is not a frame's
            yield
            dr.kernel_history()  # nor kept after it

    def new_kernels(self) -> int:
        """Kernels launched since the last call (or since :meth:`recording` began) that no
        earlier call saw; the history is cleared."""
        import drjit as dr

        history = dr.kernel_history()
        copies = [k for k in history if k["type"] == dr.KernelType.Memcpy]
        self.launched = {"kernels": sum(k["type"] == dr.KernelType.JIT for k in history), "copies": len(copies),
                         "one-value copies": sum(k.get("size", 0) <= 8 for k in copies),
                         "fills": sum(k["type"] == dr.KernelType.Memset for k in history)}
        hashes = {k["hash"] for k in history if k["type"] == dr.KernelType.JIT}
        new = len(hashes - self._seen)
        self._seen |= hashes
        return new
