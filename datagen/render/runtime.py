"""Mitsuba's process-wide settings, set in one place: the variant and the thread count.

Nothing calls ``mi.set_variant`` or ``dr.set_thread_count`` but this module; the
CLI and the build's worker bootstrap call :func:`use_variant` and
:func:`set_threads` (a :class:`~datagen.render.renderer.Renderer` asks for its
variant through :func:`use_variant` too). Importing datagen sets nothing.
"""

from __future__ import annotations

import functools
from typing import Final

from datagen.core.errors import DatagenError

__all__ = ["LLVM_HINT", "VARIANTS", "has_backend", "set_threads", "thread_count", "use_variant"]

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


def use_variant(requested: str = "auto") -> str:
    """Set and return the Mitsuba variant: ``auto`` prefers CUDA, then LLVM, then scalar."""
    import mitsuba as mi

    if requested == "auto":
        chosen = "cuda_ad_rgb" if has_backend("cuda") else "llvm_ad_rgb" if has_backend("llvm") else "scalar_rgb"
    elif requested in VARIANTS:
        chosen = requested
        if requested == "llvm_ad_rgb" and not has_backend("llvm"):
            raise DatagenError(f"render.variant: llvm_ad_rgb is unavailable: {LLVM_HINT}")
        if requested == "cuda_ad_rgb" and not has_backend("cuda"):
            raise DatagenError("render.variant: cuda_ad_rgb is unavailable: no CUDA GPU or driver found")
    else:
        raise DatagenError(f"render.variant: unknown Mitsuba variant {requested!r} (use auto or {', '.join(VARIANTS)})")
    if mi.variant() != chosen:
        mi.set_variant(chosen)
    return chosen


def set_threads(threads: int) -> None:
    """Size Dr.Jit's thread pool (one thread gives byte-identical renders)."""
    import drjit as dr

    dr.set_thread_count(max(1, int(threads)))


def thread_count() -> int:
    """The size of Dr.Jit's thread pool now."""
    import drjit as dr

    return int(dr.thread_count())
