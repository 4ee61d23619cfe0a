"""MkDocs hooks: the pages generated from the code (configuration and command-line
references, conventions) and the repository's own documents (the dataset format,
feature files, the changelog) join the site at build time, so that none is a copy that
can drift. ``mkdocs build --strict`` then checks every link and anchor."""

from __future__ import annotations

import re
import textwrap
from pathlib import Path

from mkdocs.structure.files import File

ROOT = Path(__file__).resolve().parents[1]
#: Repository documents on the site: path in the repository -> page.
DOCUMENTS = {"manifests/README.md": "reference/dataset-format.md", "assets/README.md": "reference/feature-files.md",
             "CHANGELOG.md": "changelog.md"}
#: Repository images the pages show (they live beside what makes them).
IMAGES = ("assets/previews/*.png",)


#: Markers a page may hold, replaced by text generated from the code when the site is built.
MARKERS = {"<!-- generated: exclusion reasons -->": "exclusion_table"}


def on_page_markdown(markdown, page, config, files):
    """Replace each marker of :data:`MARKERS` with what its function writes."""
    for marker, name in MARKERS.items():
        if marker in markdown:
            markdown = markdown.replace(marker, globals()[name]())
    return markdown


def exclusion_table() -> str:
    """The exclusion reasons and what each means, from ``datagen.core.label_boxes.Exclusion``."""
    from datagen.core.label_boxes import Exclusion

    rows = [f"| `{e.reason}` | {e.meaning} |" for e in Exclusion if e.reason is not None]
    return "\n".join(["| reason | meaning (`Exclusion.meaning`) |", "|---|---|", *rows])


def on_files(files, config):
    from datagen.cli.command_reference import cli_reference
    from datagen.config.key_reference import config_reference

    generated = {"reference/config.md": config_reference(), "reference/cli.md": cli_reference(),
                 "concepts/conventions.md": conventions_page()}
    for path, page in DOCUMENTS.items():
        generated[page] = relink((ROOT / path).read_text(), path)
    for uri, content in generated.items():
        files.append(File.generated(config, uri, content=content))
    for pattern in IMAGES:
        for path in sorted(ROOT.glob(pattern)):
            files.append(File.generated(config, str(path.relative_to(ROOT)), abs_src_path=str(path)))
    return files


def relink(text: str, path: str) -> str:
    """The links of the repository document at ``path``, as its page on the site has them:
    documents that are pages link to their page, anything else in the repository is named
    rather than linked."""
    up = "../" * DOCUMENTS[path].count("/")
    folder = Path(path).parent

    def repl(m: re.Match) -> str:
        label, target = m.group(1), m.group(2)
        if target.startswith(("http", "#")):
            return m.group(0)
        resolved = re.sub(r"[^/]+/\.\./", "", (folder / target).as_posix())
        if resolved in DOCUMENTS:
            return f"[{label}]({up}{DOCUMENTS[resolved]})"
        return label if label.startswith("`") else f"`{label}`"

    return re.sub(r"\[([^\]]+)\]\(([^)]+)\)", repl, text)


def conventions_page() -> str:
    """``datagen.core.conventions``'s docstring as a page (its reStructuredText, simply)."""
    import datagen.core.conventions as conventions

    lines = conventions.__doc__.strip().splitlines()
    titles = [i for i, line in enumerate(lines[:-1]) if line and not line[0].isspace() and lines[i + 1][:1] == " "]
    out = ["# Conventions", "", _inline("\n".join(lines[:titles[0]]).strip()), "",
           "This page is the docstring of `datagen/core/conventions.py`, the one place that states them.", ""]
    for i, start in enumerate(titles):
        body = "\n".join(lines[start + 1:titles[i + 1] if i + 1 < len(titles) else None])
        out += [f"## {lines[start].strip()}", "", _body(textwrap.dedent(body)), ""]
    return "\n".join(out)


def _body(text: str) -> str:
    lines = text.strip("\n").splitlines()
    rules = [i for i, line in enumerate(lines) if re.fullmatch(r"=+(\s+=+)+", line.strip())]
    if len(rules) >= 3:  # a simple table: rule, header, rule, rows, rule
        first, second, last = rules[0], rules[1], rules[-1]
        spans = [m.span() for m in re.finditer(r"=+", lines[first])]

        def cells(line: str) -> list[str]:
            return [line[a:(spans[i + 1][0] if i + 1 < len(spans) else None)].strip() for i, (a, _) in enumerate(spans)]

        rows: list[list[str]] = []
        for line in lines[second + 1:last]:
            parts = cells(line)
            if parts[0] or not rows:
                rows.append(parts)
            else:  # a continuation line
                rows[-1] = [f"{a} {b}".strip() for a, b in zip(rows[-1], parts, strict=True)]
        table = ["| " + " | ".join(cells(lines[first + 1])) + " |", "|" + "---|" * len(spans)]
        table += ["| " + " | ".join(_inline(c) for c in row) + " |" for row in rows]
        return "\n".join([_inline("\n".join(lines[:first])), *table, _inline("\n".join(lines[last + 1:]))]).strip()
    return _inline(text)


def _inline(text: str) -> str:
    text = re.sub(r":(?:data|func|class|mod|meth|attr):`~?([^`]+)`", r"`\1`", text)
    return re.sub(r"``([^`]+)``", r"`\1`", text)
