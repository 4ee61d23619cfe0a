"""Denoising of the linear image with Intel Open Image Denoise (``mitsuba-oidn``).

OIDN's ``RT`` filter takes the noisy linear radiance (``hdr``) and, optionally, the
first hit's albedo and shading normal as guides. Those are noisy at the same spp (the
pixel's samples land on different texels), so each is filtered first and the beauty then
filtered with them as clean guides (OIDN's prefiltering, which keeps more of a surface's
fine detail than noisy guides do: the performance page has the figures). It runs on
the device of the arrays it is given (the CPU for numpy arrays) on Dr.Jit's thread pool,
so :func:`datagen.render.runtime.set_threads` sizes it too: with one thread its output
is the same bytes every time.
"""

from __future__ import annotations

import functools
from typing import Final

from datagen.core.errors import DatagenError

__all__ = ["OIDN_HINT", "denoise", "denoise_render", "guided_integrator", "oidn_version"]

OIDN_HINT: Final = ("render.denoise: oidn needs the mitsuba-oidn package: install it with "
                    "`pip install mitsuba-oidn` (scripts/install.sh does), or set render.denoise: off")


@functools.cache
def _oidn():
    try:
        import mitsuba_oidn
    except ImportError as exc:
        raise DatagenError(f"{OIDN_HINT} ({exc})") from None
    return mitsuba_oidn


def oidn_version() -> str:
    """The version of the installed ``mitsuba-oidn`` (raises the install hint without it)."""
    from importlib.metadata import version

    _oidn()
    return version("mitsuba-oidn")


def denoise(rgb, albedo=None, normal=None, *, quality: str = "high"):
    """The denoised ``(H, W, 3)`` linear radiance ``rgb``, guided by ``albedo`` (in [0, 1])
    and ``normal`` (``(H, W, 3)`` each) when both are given. numpy arrays and Dr.Jit LLVM
    tensors are filtered on the CPU, Dr.Jit CUDA tensors on their GPU; the result is of
    the input's kind."""
    oidn = _oidn()
    q = {"fast": oidn.Quality.Fast, "balanced": oidn.Quality.Balanced, "high": oidn.Quality.High}[quality]
    if albedo is None or normal is None:
        return oidn.denoise(rgb, hdr=True, quality=q)
    # The guides' own noise filtered out first (LDR: albedo in [0, 1], normals in [-1, 1]).
    albedo, normal = (oidn.denoise(guide, hdr=False, quality=q) for guide in (albedo, normal))
    return oidn.denoise(rgb, albedo=albedo, normal=normal, hdr=True, quality=q, clean_aux=True)


def guided_integrator(integrator: dict) -> dict:
    """Mitsuba's ``aov`` integrator around ``integrator``: a render's channels are then
    the beauty RGB (the inner integrator's own samples), the first hit's albedo and its
    shading normal, as :func:`denoise_render` reads them."""
    return {"type": "aov", "aovs": "albedo:albedo,normal:sh_normal", "integrator": integrator}


def denoise_render(image, *, guides: bool, quality: str = "high", beauty=None):
    """:func:`denoise` of a render's ``(H, W, C)`` tensor: its first three channels (or
    ``beauty`` in their place), guided by the albedo and normal of
    :func:`guided_integrator` when ``guides``. Slices of a Dr.Jit tensor stay on its device."""
    extra = [image[..., 3:6], image[..., 6:9]] if guides else []
    return denoise(image[..., 0:3] if beauty is None else beauty, *extra, quality=quality)
