"""Aircraft liveries: a scheme, panel lines, markings and weathering as linear RGB
(:func:`livery`, bitmaps from a seed that tile: their spectra live on the FFT grid,
:func:`fractal_noise`), mapped onto a mesh by :func:`triplanar_uv`."""

from __future__ import annotations

from typing import Final

import numpy as np
from numpy.typing import NDArray

__all__ = [
    "LIVERY_TEXELS",
    "fractal_noise",
    "livery",
    "triplanar_uv",
]

#: A livery texture's size (it spans the object's bounding box).
LIVERY_TEXELS: Final = 512

FloatArray = NDArray[np.float32]


def fractal_noise(rng: np.random.Generator, size: int, beta: float = 3.0, low_cycles: float = 2.0,
                  stretch: float = 1.0) -> FloatArray:
    """A tileable ``(size, size)`` Gaussian field with power spectrum ~ f^-beta above
    ``low_cycles`` cycles per tile, zero mean and unit standard deviation. ``stretch`` > 1
    elongates features along u (streaks)."""
    fx = np.fft.fftfreq(size) * size / stretch
    fy = np.fft.fftfreq(size) * size
    f = np.hypot(*np.meshgrid(fx, fy))
    amplitude = np.where(f >= low_cycles, np.maximum(f, 1e-9) ** (-beta / 2.0), 0.0)
    spectrum = amplitude * (rng.standard_normal((size, size)) + 1j * rng.standard_normal((size, size)))
    field = np.fft.ifft2(spectrum).real
    field -= field.mean()
    return (field / max(float(field.std()), 1e-12)).astype(np.float32)


def triplanar_uv(vertices: NDArray, faces: NDArray, lo: NDArray, hi: NDArray
                 ) -> tuple[NDArray[np.float32], NDArray[np.uint32], NDArray[np.float32]]:
    """Unwelded vertices, faces and texture coordinates of a mesh: each face is projected
    onto the bounding-box plane most facing it (x-y from above and below, x-z from the
    sides, y-z from the front), coordinates normalized by the box ``lo``..``hi``, so one
    texture covers the object with at most a 2x stretch on sloped faces. Faces keep flat
    normals, so the unwelded mesh renders the same shape."""
    v = np.asarray(vertices, dtype=np.float64)[np.asarray(faces).reshape(-1)].reshape(-1, 3, 3)
    n = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
    axis = np.argmax(np.abs(n), axis=1)  # 0: faces front/back, 1: sides, 2: top/bottom
    span = np.maximum(np.asarray(hi, dtype=np.float64) - np.asarray(lo, dtype=np.float64), 1e-9)
    t = (v - np.asarray(lo, dtype=np.float64)) / span  # (F, 3, 3) in [0, 1]
    planes = np.array([[1, 2], [0, 2], [0, 1]])[axis]  # the two axes of each face's plane
    uv = np.take_along_axis(t, planes[:, None, :].repeat(3, axis=1), axis=2)
    verts = v.reshape(-1, 3).astype(np.float32)
    out_faces = np.arange(len(verts), dtype=np.uint32).reshape(-1, 3)
    return verts, out_faces, uv.reshape(-1, 2).astype(np.float32)


def _mix(a: NDArray, b: NDArray, t: NDArray) -> NDArray:
    return a * (1.0 - t[..., None]) + b * t[..., None]


def _srgb_to_linear(c) -> NDArray[np.float64]:
    c = np.asarray(c, dtype=np.float64)
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def _scheme(rng: np.random.Generator, scheme: str, size: int) -> NDArray[np.float64]:
    """The base paint of a scheme, linear RGB ``(size, size, 3)``."""
    def grey(lo: float, hi: float) -> NDArray:
        value = rng.uniform(lo, hi)
        tint = rng.normal(0.0, 0.015, 3)
        return _srgb_to_linear(np.clip(value + tint + np.array([0.0, 0.005, 0.02]), 0, 1))

    if scheme == "grey_camouflage":
        colours = [grey(0.35, 0.5), grey(0.5, 0.62), grey(0.62, 0.75)]
        field = fractal_noise(rng, size, beta=3.4, low_cycles=2.0)
        img = np.broadcast_to(colours[0], (size, size, 3)).copy()
        img[field > -0.4] = colours[1]
        img[field > 0.5] = colours[2]
        return img
    if scheme == "two_tone":
        dark, light = grey(0.3, 0.45), grey(0.6, 0.8)
        field = fractal_noise(rng, size, beta=4.0, low_cycles=1.0)
        return _mix(np.broadcast_to(dark, (size, size, 3)), np.broadcast_to(light, (size, size, 3)),
                    (field > 0.0).astype(np.float64))
    if scheme == "high_visibility":
        base = _srgb_to_linear(np.clip([0.88, 0.88, 0.86] + rng.normal(0, 0.02, 3), 0, 1))
        band = _srgb_to_linear([rng.uniform(0.85, 1.0), rng.uniform(0.15, 0.4), rng.uniform(0.0, 0.1)])
        img = np.broadcast_to(base, (size, size, 3)).copy()
        u = np.arange(size) / size  # along the body's x (the first texture axis for most faces)
        for centre in rng.uniform(0.05, 0.95, int(rng.integers(2, 5))):
            width = rng.uniform(0.04, 0.12)
            img[:, np.abs(u - centre) < width / 2] = band
        return img
    if scheme == "bare_metal":
        value = rng.uniform(0.55, 0.8)
        tone = fractal_noise(rng, size, beta=2.0, low_cycles=8.0)
        return np.broadcast_to(_srgb_to_linear([value] * 3), (size, size, 3)) * (1.0 + 0.05 * tone[..., None])
    raise ValueError(f"unknown livery scheme {scheme!r}")


def _panel_lines(rng: np.random.Generator, img: NDArray, span_m: NDArray) -> None:
    """Darken panel seams every ~1-2 m (bricked rows) and rivet rows beside them."""
    import cv2

    size = img.shape[0]
    mask = np.zeros((size, size), np.uint8)
    pitch_u = rng.uniform(1.0, 2.0) / max(span_m[0], 1e-3) * size
    pitch_v = rng.uniform(0.7, 1.4) / max(span_m[1], 1e-3) * size
    rows = np.arange(0.0, size, max(pitch_v, 3.0))
    for r, y in enumerate(rows):
        cv2.line(mask, (0, int(y)), (size - 1, int(y)), 255, 1)
        offset = (r % 2) * pitch_u / 2
        for x in np.arange(offset, size, max(pitch_u, 3.0)):
            cv2.line(mask, (int(x), int(y)), (int(x), int(min(y + pitch_v, size - 1))), 255, 1)
    seams = mask.astype(np.float64) / 255.0
    img *= (1.0 - rng.uniform(0.25, 0.5) * seams)[..., None]


def _markings(rng: np.random.Generator, img: NDArray, low_vis: bool) -> None:
    """Roundels (national markings) and an aircraft number at random spots."""
    import cv2

    size = img.shape[0]
    canvas = np.ascontiguousarray(img[..., ::-1])  # OpenCV draws BGR
    if low_vis:
        rings = [_srgb_to_linear([g] * 3) for g in (rng.uniform(0.2, 0.3), rng.uniform(0.45, 0.55))]
    else:
        rings = [_srgb_to_linear(c) for c in ([0.05, 0.15, 0.45], [0.95, 0.95, 0.95], [0.75, 0.05, 0.08])]
    for _ in range(int(rng.integers(2, 5))):
        centre = (int(rng.uniform(0.1, 0.9) * size), int(rng.uniform(0.1, 0.9) * size))
        radius = int(rng.uniform(0.015, 0.04) * size)
        for j, colour in enumerate(rings):
            cv2.circle(canvas, centre, max(1, radius * (len(rings) - j) // len(rings)),
                       tuple(float(c) for c in colour[::-1]), -1, cv2.LINE_AA)
    ink = _srgb_to_linear([0.04] * 3) if not low_vis else _srgb_to_linear([0.25] * 3)
    text_mask = np.zeros((size, size), np.uint8)  # (OpenCV writes text on 8-bit images only)
    for _ in range(int(rng.integers(1, 3))):
        text = f"{int(rng.integers(10, 1000))}"
        origin = (int(rng.uniform(0.05, 0.75) * size), int(rng.uniform(0.15, 0.95) * size))
        cv2.putText(text_mask, text, origin, cv2.FONT_HERSHEY_SIMPLEX, rng.uniform(1.2, 3.0) * size / 1024,
                    255, max(1, size // 300), cv2.LINE_AA)
    img[...] = _mix(canvas[..., ::-1], np.broadcast_to(ink, img.shape), text_mask.astype(np.float64) / 255.0)


def _weathering(rng: np.random.Generator, img: NDArray, strength: float) -> None:
    """Grime (dark, low-frequency) and streaks along the airflow (u), plus fading."""
    size = img.shape[0]
    grime = np.clip(0.5 + 0.35 * fractal_noise(rng, size, beta=2.6, low_cycles=3.0), 0.0, 1.0)
    streaks = np.clip(0.5 + 0.35 * fractal_noise(rng, size, beta=2.2, low_cycles=4.0, stretch=12.0), 0.0, 1.0)
    dirt = strength * (0.45 * grime + 0.35 * streaks)
    img *= (1.0 - dirt)[..., None]
    img[...] = _mix(img, np.broadcast_to(img.mean(axis=(0, 1)), img.shape), np.full(img.shape[:2], 0.3 * strength))


def livery(rng: np.random.Generator, scheme: str, weathering: float, span_m, *, panel_lines: bool = True,
           markings: bool = True, size: int = LIVERY_TEXELS) -> FloatArray:
    """A livery texture ``(size, size, 3)``, linear RGB in [0, 1], for an object whose
    bounding box spans ``span_m`` (its first two extents set the panel pitch in texels)."""
    img = _scheme(rng, scheme, size)
    span = np.asarray(span_m, dtype=np.float64)
    if panel_lines:
        _panel_lines(rng, img, span)
    if markings:
        _markings(rng, img, low_vis=scheme in ("grey_camouflage", "two_tone"))
    if weathering > 0.0:
        _weathering(rng, img, float(weathering))
    return np.clip(img, 0.0, 1.0).astype(np.float32)
