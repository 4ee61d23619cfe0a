"""The one rule for every path a dataset names or holds, and for the folders datagen writes
reports and exports into.

A dataset folder is input from a stranger (datasets are downloaded and shared): a path it
names (a manifest's ``image_path``, say) or a file it holds is read only when, resolved,
it stays inside the dataset folder, so that a symbolic link can lead nobody's reader out
of it. A report or export folder is a real folder: a symbolic link at its name, or
between the dataset and a report folder inside it, is refused, and every folder made
under it is made, never followed. Files themselves are replaced by a rename
(:mod:`datagen.atomic`), which replaces a link instead of writing through it.
"""

from __future__ import annotations

import contextlib
import functools
import os
import stat
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path, PurePosixPath

from datagen.core.errors import DatagenError

__all__ = [
    "DatasetFolder",
    "Unreadable",
    "named_inside",
    "opened_file",
    "read_bytes",
    "real_folder",
    "regular_file",
    "report_folder",
]

#: The problem of a path that names no file inside the dataset (absolute, ``..``, empty).
NOT_INSIDE = "is not a path inside the dataset"
#: The problem of a path that a symbolic link leads out of the dataset.
LEADS_OUT = "leads outside the dataset through a symbolic link"


def named_inside(rel: object) -> bool:
    """Whether ``rel``, as written, names a path inside a folder: a relative path without
    ``..`` (no link is resolved: :meth:`DatasetFolder.problem` does that too)."""
    return isinstance(rel, str) and bool(rel) and not rel.startswith(("/", "\\")) and "\0" not in rel \
        and ".." not in PurePosixPath(rel).parts


@dataclass(frozen=True)
class DatasetFolder:
    """A dataset folder (or another folder of untrusted input, ``what``: a folder of
    predictions) as untrusted input: which of the paths it names may be read."""

    root: Path
    what: str = "dataset"

    @functools.cached_property
    def real_root(self) -> str:
        return os.path.realpath(self.root)

    def _inside(self, resolved: str) -> bool:
        return resolved == self.real_root or resolved.startswith(self.real_root.rstrip(os.sep) + os.sep)

    def problem(self, rel: str) -> str | None:
        """Why the dataset path ``rel`` (relative to the root, as a manifest writes it) may
        not be read, or None: it must be relative, without ``..``, and stay inside the
        dataset once every symbolic link on the way is resolved."""
        if not named_inside(rel):
            return NOT_INSIDE.replace("dataset", self.what)
        if not self._inside(os.path.realpath(os.path.join(self.root, rel))):
            return LEADS_OUT.replace("dataset", self.what)
        return None

    def file(self, rel: str) -> Path:
        """``root / rel`` where :meth:`problem` has none; otherwise one line naming it."""
        problem = self.problem(rel)
        if problem:
            name = str(self.root / str(rel)[:200])
            raise DatagenError(f"{name if name.isprintable() else ascii(name)}: {problem}")
        return self.root / rel

    def links_out(self) -> Iterator[str]:
        """Every symbolic link in the dataset (files and folders, none followed) that leads
        outside it, relative to the root, in walking order (a link inside whose target is
        not there yet, as ``pose/images`` of a labels-only build, stays inside)."""
        for dirpath, dirnames, filenames in os.walk(self.root):
            for name in sorted(dirnames) + sorted(filenames):
                path = os.path.join(dirpath, name)
                if os.path.islink(path) and not self._inside(os.path.realpath(path)):
                    yield os.path.relpath(path, self.root)
            dirnames.sort()


def regular_file(path: Path) -> bool:
    """Whether ``path`` is a regular file (a FIFO would block its reader, a device never end)."""
    try:
        return stat.S_ISREG(os.stat(path).st_mode)
    except (OSError, ValueError):
        return False


class Unreadable(DatagenError):
    """A file that may not be read, one line: ``path: problem`` (:func:`read_bytes`)."""

    def __init__(self, path: Path, problem: str) -> None:
        self.path, self.problem = Path(path), problem
        super().__init__(f"{path}: {problem}")


def _open_regular(path: Path, what: str, max_bytes: int) -> int:
    """A descriptor of the regular file ``path`` of at most ``max_bytes`` (opened without
    blocking and judged by the descriptor itself), or one :class:`Unreadable` line."""
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | os.O_CLOEXEC)
    except FileNotFoundError:
        raise Unreadable(path, "no such file") from None
    except IsADirectoryError:
        raise Unreadable(path, f"is a directory, expected {what}") from None
    except (OSError, ValueError) as exc:
        raise Unreadable(path, f"cannot read: {getattr(exc, 'strerror', None) or exc}") from None
    try:
        info = os.fstat(fd)
        if stat.S_ISDIR(info.st_mode):
            raise Unreadable(path, f"is a directory, expected {what}")
        if not stat.S_ISREG(info.st_mode):
            raise Unreadable(path, f"not a regular file, expected {what}")
        if info.st_size > max_bytes:
            raise Unreadable(path, f"{info.st_size:,} bytes: larger than the {max_bytes:,} bytes {what} may have")
    except BaseException:
        os.close(fd)
        raise
    return fd


def read_bytes(path: str | Path, what: str, max_bytes: int, *, head: int | None = None) -> bytes:
    """The bytes of the regular file ``path``, at most ``max_bytes`` of them (only the first
    ``head`` where given), or one :class:`Unreadable` line saying why not: missing, a
    folder, a FIFO or device (it is opened without blocking and judged by the descriptor
    itself, so that a file swapped for a FIFO between a check and the read blocks nothing),
    larger than ``max_bytes`` (judged before anything is read, so that a sparse or huge
    file costs no memory), or unreadable. ``what`` names the kind of file in the message
    (``a label file``)."""
    path = Path(path)
    fd = _open_regular(path, what, max_bytes)
    want = max_bytes + 1 if head is None else min(head, max_bytes + 1)
    chunks = []
    try:
        while want > 0:
            chunk = os.read(fd, min(want, 1 << 24))
            if not chunk:
                break
            chunks.append(chunk)
            want -= len(chunk)
    except OSError as exc:
        raise Unreadable(path, f"cannot read: {exc.strerror or exc}") from None
    finally:
        os.close(fd)
    data = b"".join(chunks)
    if len(data) > max_bytes:  # grown while it was read
        raise Unreadable(path, f"larger than the {max_bytes:,} bytes {what} may have")
    return data


@contextlib.contextmanager
def opened_file(path: str | Path, what: str, max_bytes: int) -> Iterator[str]:
    """A name of the regular file ``path`` (of at most ``max_bytes``) that a library opening
    files by name (OpenEXR) reads: the descriptor datagen opened and judged, as
    ``/proc/self/fd/N``, so that the file read is the file checked (:func:`read_bytes`)."""
    fd = _open_regular(Path(path), what, max_bytes)
    try:
        yield f"/proc/self/fd/{fd}"
    finally:
        os.close(fd)


def real_folder(folder: Path, flag: str = "--out", *, make: bool = True) -> Path:
    """Make ``folder`` (and its missing parents) and return it; a symbolic link at its name
    is refused, not followed (one line naming ``flag``). ``make`` False: only check, before
    any work starts, that it could be made."""
    folder = Path(folder)
    if folder.is_symlink():
        raise DatagenError(f"{flag}: {folder}: a symbolic link; datagen writes reports and exports only into a "
                           "real folder (remove the link or choose another folder)")
    if folder.exists() and not folder.is_dir():
        raise DatagenError(f"{flag}: {folder}: a file is in the way; choose a folder")
    if not make:
        return folder
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except (FileExistsError, NotADirectoryError):
        raise DatagenError(f"{flag}: {folder}: a file is in the way of the folder; choose another") from None
    if folder.is_symlink() or not folder.is_dir():
        raise DatagenError(f"{flag}: {folder}: not a folder")
    return folder


def report_folder(folder: Path, dataset: Path, flag: str = "--out", *, make: bool = True) -> Path:
    """:func:`real_folder` for a report of the dataset ``dataset``: where the folder lies in
    the dataset (its default), no folder between the two may be a symbolic link either."""
    folder, dataset = Path(folder), Path(dataset)
    try:
        rel = Path(os.path.abspath(folder)).relative_to(os.path.abspath(dataset))
    except ValueError:
        rel = None
    if rel is not None:
        step = dataset
        for part in rel.parts:
            step = step / part
            if step.is_symlink():
                raise DatagenError(f"{flag}: {step}: a symbolic link inside the dataset; datagen writes its "
                                   "reports only into real folders (remove the link or choose another --out)")
    return real_folder(folder, flag, make=make)
