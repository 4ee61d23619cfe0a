"""What every ``datagen`` command shares: the app, the exit status and one-line errors
for bad input, output paths checked before anything is written, the bounds on counts."""


from __future__ import annotations

import contextlib
import functools
import os
import re
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Annotated, Final, TextIO, TypeVar

import typer

from datagen import __version__
from datagen.core.errors import DatagenError

app = typer.Typer(
    name="datagen",
    help="Physically based synthetic training data for vision-based aerial refueling.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    # Click's own help: paragraphs wrapped to the terminal, up to 120 columns (a docstring's
    # line breaks are not kept mid-sentence) and no type shown for a flag.
    rich_markup_mode=None,
    context_settings={"max_content_width": 120},
)
assets_app = typer.Typer(help="Build and inspect the built-in meshes and feature sets.", no_args_is_help=True,
                         rich_markup_mode=None)
app.add_typer(assets_app, name="assets")

#: Exit status for bad input (configs, assets, dataset folders, flags) and for files that
#: cannot be read or written.
EXIT_BAD_INPUT = 2
#: Exit status of a command interrupted by Ctrl-C (128 + SIGINT, as a shell reports it).
EXIT_INTERRUPTED = 130
#: Most frames one --frames list of preview or render may name.
MAX_FRAME_LIST = 10_000
#: Largest --noise-px radius, pixels, and most radii in one run.
#: Largest --spp of render, gallery and assets preview (as render.spp).
MAX_SPP = 65536
#: Most approaches --frames prints, and most overlays in an audit report.
MAX_PRINTED_FRAMES = 100_000
MAX_OVERLAYS = 100

F = TypeVar("F", bound=Callable[..., object])


def path_value(text: str) -> Path:
    """A path as the user typed it: an empty one is refused (``Path("")`` would be the
    working folder, whose files a report or a scan would then touch)."""
    if isinstance(text, Path):
        return text
    if not text.strip():
        raise typer.BadParameter("an empty path; name a file or folder")
    return Path(text)


def workers_value(text: str) -> int | str:
    """``auto`` or a whole number of workers, at least 1."""
    if isinstance(text, int) or text == "auto":
        return text
    try:
        value = int(text)
    except (TypeError, ValueError):
        raise typer.BadParameter(f"{text!r}: expected auto or a whole number of workers") from None
    if value < 1:
        raise typer.BadParameter(f"{text!r}: expected auto or at least 1")
    return value


def unit_value(text: str) -> float:
    """A number in [0, 1] (a threshold or share), NaN refused as not a number."""
    try:
        value = float(text)
    except (TypeError, ValueError):
        raise typer.BadParameter(f"{text!r} is not a number") from None
    if not 0.0 <= value <= 1.0:  # NaN fails both
        raise typer.BadParameter(f"{text!r}: expected a number from 0 to 1")
    return value


#: The ``--config`` option of the commands that read a scene config.
ConfigOption = Annotated[Path, typer.Option("--config", parser=path_value,
                                            help="Scene config file (YAML), or a shipped scene by name "
                                                 "(datagen scenes).")]


def user_errors(func: F) -> F:
    """Turn :class:`DatagenError` into one line per problem on stderr and exit 2."""

    @functools.wraps(func)
    def wrapper(*args, **kwargs):
        try:
            return func(*args, **kwargs)
        except DatagenError as exc:
            lines = exc.lines()
        except OSError as exc:  # a file that cannot be read or written: where and why, on one line
            where = exc.filename if exc.filename is not None else "datagen"
            lines = [f"{os.fsdecode(where)}: {exc.strerror or exc}"]
        except MemoryError:
            lines = ["datagen: out of memory"]
        for line in lines:
            typer.echo(line, err=True)
        raise typer.Exit(EXIT_BAD_INPUT) from None

    return wrapper  # type: ignore[return-value]


def output_path(path: Path, flag: str) -> Path:
    """An output path that can be created: UTF-8 and every name within the filesystem's
    limit, checked before anything is written (a bad one would fail half-way)."""
    text = str(path)
    try:
        text.encode("utf-8")
    except UnicodeEncodeError:
        raise DatagenError(f"{flag}: {text!a}: not a UTF-8 path; choose a name in UTF-8") from None
    for part in Path(text).parts:
        if len(os.fsencode(part)) > 255:
            raise DatagenError(f"{flag}: {part[:40]}...: a name of {len(os.fsencode(part))} bytes, longer than "
                               "the 255 a folder or file name may have")
    return path


def report_out(command: str, out: Path | None, dataset: Path) -> Path:
    """The report folder of ``command`` (audit, evaluate or preview): its ``--out``, or its
    folder in the dataset, checked before any work starts
    (:func:`datagen.dataset.reports.claim_report_folder`: a folder holding anything but
    the command's own earlier report is refused)."""
    from datagen.dataset.reports import REPORTS, claim_report_folder

    kind = REPORTS[command]
    folder = output_path(out if out is not None else Path(dataset) / kind.folder, "--out")
    return claim_report_folder(kind, folder, dataset, make=False)


#: The ``--partial`` option of the commands that read a dataset's frames.
PartialOption = Annotated[bool, typer.Option("--partial", help="Go on when the manifests hold fewer (or other) "
                                             "frames than dataset.json planned (an unfinished build): say so and "
                                             "use the frames there are.")]


def require_plan(rows, partial: bool, only: str | None = None) -> None:
    """Refuse a dataset whose manifests differ from what its dataset.json planned (one
    line), or with ``partial`` say so on stderr and go on (:func:`datagen.dataset.reader.plan_gaps`);
    ``only``: the split the command reads, when it reads one."""
    from datagen.dataset.reader import plan_gaps

    gaps = plan_gaps(rows, only)
    if gaps and not partial:
        raise DatagenError(f"{rows.root / 'dataset.json'}: {gaps[0]}; or pass --partial to go on with the "
                           f"{len(rows.frame_id)} frames there are")
    for gap in gaps:
        typer.echo(f"partial: {rows.root / 'dataset.json'}: {gap}", err=True)


def _version(value: bool) -> None:
    if value:
        typer.echo(f"datagen {__version__}")
        raise typer.Exit()


@app.callback()
def _root(
    version: Annotated[
        bool, typer.Option("--version", callback=_version, is_eager=True, help="Print the version.")
    ] = False,
) -> None:
    pass



#: What a terminal acts on instead of showing: C0 controls but tab and newline, DEL and C1 controls.
_CONTROLS: Final = re.compile(r"[\x00-\x08\x0b-\x1f\x7f-\x9f]")


class _Shown:
    """A text stream that writes every control character a terminal would act on (an escape
    sequence that clears the screen or sets the window title, a carriage return that draws
    over a line) as a Python escape: the last guard, behind the escaping of every name a
    dataset gives (:func:`datagen.core.errors.shown`), between a hostile dataset and the
    user's terminal."""

    def __init__(self, stream: TextIO) -> None:
        self._stream = stream

    def write(self, text: str) -> int:
        self._stream.write(_CONTROLS.sub(lambda m: ascii(m.group())[1:-1], text))
        return len(text)

    def __getattr__(self, name: str):
        return getattr(self._stream, name)


def main() -> None:
    """The ``datagen`` command: a bad flag is one line too, and so is an unprintable path;
    nothing it prints controls the terminal (:class:`_Shown`; ``train`` prints Ultralytics'
    own coloured progress, of names the recipe check allows)."""
    for stream in (sys.stdout, sys.stderr):  # paths with undecodable bytes print escaped, never crash
        with contextlib.suppress(AttributeError, ValueError):
            stream.reconfigure(errors="backslashreplace")  # type: ignore[union-attr]  # (a TextIOWrapper's)
    if sys.argv[1:2] != ["train"]:
        sys.stdout, sys.stderr = _Shown(sys.stdout), _Shown(sys.stderr)
    try:
        code = app(prog_name="datagen", standalone_mode=False)
    except typer.exceptions.TyperException as exc:
        ctx = getattr(exc, "ctx", None)
        if type(exc).__name__ == "NoArgsIsHelpError" and ctx is not None:  # a bare group: its help
            print(ctx.get_help())
            sys.exit(EXIT_BAD_INPUT)
        if not hasattr(exc, "format_message"):
            raise
        where = ctx.command_path if ctx is not None else "datagen"
        print(f"{where}: {' '.join(exc.format_message().split())}", file=sys.stderr)
        sys.exit(EXIT_BAD_INPUT)
    except typer.Abort:
        print("datagen: aborted", file=sys.stderr)
        sys.exit(EXIT_INTERRUPTED)
    command = next((a for a in sys.argv[1:] if not a.startswith("-")), "")
    if code == EXIT_INTERRUPTED and command != "build":  # Typer's answer to Ctrl-C; a build's summary says it
        print(f"datagen {command}: interrupted; no file is left half-written (each is written whole, then renamed "
              "into place)", file=sys.stderr)
    sys.exit(code if isinstance(code, int) else 0)
