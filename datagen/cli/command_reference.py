"""The command-line reference, generated from the commands themselves (their docstrings,
arguments and options as Typer declares them): nothing written twice."""

from __future__ import annotations

__all__ = ["cli_reference", "command_paths"]


def _root():
    import typer

    from datagen.cli import app

    return typer.main.get_command(app)


def _walk(group, path: tuple[str, ...] = ("datagen",)):
    for name in sorted(group.commands):
        command = group.commands[name]
        yield (*path, name), command
        if hasattr(command, "commands"):  # a group (Typer's own click classes, duck-typed)
            yield from _walk(command, (*path, name))


def command_paths() -> list[str]:
    """Every command, e.g. ``datagen assets preview``."""
    return [" ".join(path) for path, _ in _walk(_root())]


def _cell(text: str | None) -> str:
    return " ".join((text or "").split()).replace("|", "\\|")


def _default(param) -> str:
    if param.required:
        return "required"
    value = param.default
    if value is None or value == () or callable(value):
        return ""
    if isinstance(value, bool):
        return "on" if value else "off"
    return f"`{value}`"


def _context(path: tuple[str, ...], command):
    """A context for ``command`` of Typer's own click (what its help needs)."""
    return type(command).context_class(command, info_name=" ".join(path))


def cli_reference() -> str:
    """The reference page (Markdown)."""
    lines = ["# Command-line reference", "",
             "Every `datagen` command with its arguments and options, generated from the commands' "
             "own declarations (`datagen/cli/`). `datagen COMMAND --help` prints the same.", ""]
    for path, command in _walk(_root()):
        title = " ".join(path)
        lines += [f"## `{title}`", "", (command.help or "").strip(), ""]
        if hasattr(command, "commands"):
            lines += ["Subcommands: " + ", ".join(f"`{title} {n}`" for n in sorted(command.commands)), ""]
            continue
        context = _context(path, command)
        lines += ["```", " ".join([title, *command.collect_usage_pieces(context)]), "```", ""]
        params = [p for p in command.params if p.name != "help"]
        if params:
            lines += ["| argument or option | type | default | description |", "|---|---|---|---|"]
            for p in params:
                option = p.param_type_name == "option"
                names = ", ".join(f"`{o}`" for o in (*p.opts, *p.secondary_opts)) if option else f"`{p.name.upper()}`"
                kind = "`flag`" if option and p.is_flag else f"`{p.display_type(context)}`"
                lines.append(f"| {names} | {kind} | {_default(p)} | {_cell(getattr(p, 'help', None))} |")
            lines.append("")
    return "\n".join(lines)
