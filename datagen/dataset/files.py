"""Every file datagen writes goes through here: hidden temporary name, then rename.

A reader (or a crash) never sees a half-written file. A temporary is named
``.NAME.PID.datagen-tmp``: a name only datagen uses, so that sweeping the
temporaries an interrupted writer left can never touch a user's own files.
"""

from __future__ import annotations

import contextlib
import os
import re
from collections.abc import Iterator
from pathlib import Path
from typing import Final

__all__ = ["TEMPORARY_SUFFIX", "atomic_path", "is_temporary", "write_image"]

#: The suffix of datagen's temporaries (``.NAME.PID.datagen-tmp``).
TEMPORARY_SUFFIX: Final = ".datagen-tmp"
_TEMPORARY: Final = re.compile(r"\..+\.[0-9]+" + re.escape(TEMPORARY_SUFFIX))


def is_temporary(name: str) -> bool:
    """Whether a file name is one of datagen's temporaries."""
    return _TEMPORARY.fullmatch(name) is not None


@contextlib.contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """Yield a hidden temporary path beside ``path``; rename it into place on success,
    remove it on failure."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{os.getpid()}{TEMPORARY_SUFFIX}")
    try:
        yield tmp
        os.replace(tmp, path)
    except OSError as exc:  # a full disk mid-write names no file: name the one being written
        if exc.filename is None or Path(os.fsdecode(exc.filename)) == tmp:
            exc.filename = str(path)
        raise
    finally:
        with contextlib.suppress(FileNotFoundError):
            tmp.unlink()


def write_image(path: str | Path, bgr8, *, jpeg_quality: int = 95) -> Path:
    """Encode an 8-bit BGR image as PNG, or JPEG when the suffix says so, and write
    it atomically."""
    import cv2

    path = Path(path)
    ext = path.suffix.lower()
    if ext in (".jpg", ".jpeg"):
        params = [cv2.IMWRITE_JPEG_QUALITY, jpeg_quality]
    else:
        # zlib level 1 without row filters: on rendered (noisy) images this is both the
        # fastest PNG encoding (60 ms for 2048x1080, 104 ms with filters) and the smallest.
        params = [cv2.IMWRITE_PNG_COMPRESSION, 1]
        if hasattr(cv2, "IMWRITE_PNG_FILTER"):
            params += [cv2.IMWRITE_PNG_FILTER, cv2.IMWRITE_PNG_FILTER_NONE]
    ok, data = cv2.imencode(ext, bgr8, params)
    if not ok:
        raise RuntimeError(f"image encoding failed for {path}")
    with atomic_path(path) as tmp:
        tmp.write_bytes(data.tobytes())
    return path
