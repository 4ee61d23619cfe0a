"""The documentation: a short front page, a site that builds with strict link and anchor
checking, references generated from the schema and the commands (every key and command
in them, every field documented), and the built pages rendered by a real browser."""

from __future__ import annotations

import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from datagen.cli.command_reference import cli_reference, command_paths
from datagen.config.key_reference import config_keys, config_reference, key_cell, undocumented_fields

ROOT = Path(__file__).resolve().parents[1]


def test_every_schema_field_has_a_docstring() -> None:
    assert undocumented_fields() == []


def test_every_config_key_appears_in_the_generated_reference() -> None:
    page = config_reference()
    keys = config_keys()
    assert len(keys) > 100 and "randomization.sea.waves" in keys and "labels.min_box_px" in keys
    assert [k for k in keys if f"| {key_cell(k)} |" not in page] == []


def test_the_reference_wraps_keys_only_after_a_dot() -> None:
    """Each key cell breaks only at <wbr> after a dot, and the site's CSS keeps names whole."""
    cells = re.findall(r'<code class="config-key">(.*?)</code>', config_reference())
    assert len(cells) == len(config_keys())
    assert all(part and "<" not in part for cell in cells for part in cell.split(".<wbr>"))
    css = (ROOT / "docs" / "stylesheets" / "extra.css").read_text()
    assert re.search(r"code\.config-key\s*\{[^}]*word-break:\s*keep-all", css)
    assert "stylesheets/extra.css" in (ROOT / "mkdocs.yml").read_text()


def test_every_command_and_option_appears_in_the_generated_cli_reference() -> None:
    import typer

    from datagen.cli import app

    page = cli_reference()
    assert [c for c in command_paths() if f"## `{c}`" not in page] == []
    build = typer.main.get_command(app).commands["build"]
    assert [o for p in build.params for o in p.opts if o != "--help" and f"`{o}`" not in page] == []


def test_the_front_page_is_short_and_gives_the_two_commands() -> None:
    readme = (ROOT / "README.md").read_text()
    assert len(readme.splitlines()) <= 200
    assert "bash scripts/install.sh && .venv/bin/datagen build --config wingcam55.yaml --frames 8" in readme
    assert "bash scripts/install.sh && .venv/bin/python -m pytest" in readme


@pytest.fixture(scope="module")
def site(tmp_path_factory) -> Path:
    pytest.importorskip("mkdocs", reason="needs the test extra's MkDocs (pip install -e '.[test]')")
    out = tmp_path_factory.mktemp("site")
    done = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(out)], cwd=ROOT,
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-4000:]
    return out


def test_the_glossary_lists_every_exclusion_reason_from_the_code(site: Path) -> None:
    from datagen.core.label_boxes import Exclusion

    page = (site / "concepts" / "glossary" / "index.html").read_text()
    assert "generated:" not in page
    assert all(e.meaning in page for e in Exclusion if e.reason is not None)


def test_the_site_builds_with_strict_link_and_anchor_checking(site: Path) -> None:
    config = (site / "reference" / "config" / "index.html").read_text().replace("<wbr>", "")
    assert "randomization.sea.waves" in config and "labels.min_box_px" in config
    assert "datagen build" in (site / "reference" / "cli" / "index.html").read_text()
    assert "continuous" in (site / "concepts" / "conventions" / "index.html").read_text()
    assert (site / "index.html").is_file() and (site / "quickstart" / "index.html").is_file()


@pytest.mark.skipif(shutil.which("chromium") is None, reason="needs Chromium (apt-get install -y chromium)")
@pytest.mark.parametrize("page", ["", "quickstart/", "reference/config/"])
def test_headless_chromium_renders_the_home_quick_start_and_configuration_pages(site: Path, page: str,
                                                                              tmp_path: Path) -> None:
    """A screenshot of the built page is not blank: it has the theme's header colour and
    text, and the page's DOM as Chromium built it holds its content."""
    import cv2
    import numpy as np

    url = (site / page / "index.html").as_uri()
    shot = tmp_path / "page.png"
    common = ["chromium", "--headless=new", "--no-sandbox", "--disable-gpu", "--hide-scrollbars"]
    subprocess.run([*common, f"--screenshot={shot}", "--window-size=1280,900", url], capture_output=True,
                   timeout=120, check=True)
    image = cv2.imread(str(shot))
    assert image is not None and image.shape[:2] == (900, 1280)
    header = image[:40].reshape(-1, 3)
    assert np.median(header, axis=0)[0] > 100 and np.ptp(header.astype(int).sum(axis=1)) > 0  # the coloured bar
    assert image.std() > 20  # text and structure, not a blank page
    dom = subprocess.run([*common, "--dump-dom", url], capture_output=True, text=True, timeout=120).stdout
    expected = {"": "corrected", "quickstart/": "scripts/install.sh", "reference/config/": "randomization.sea.waves"}
    assert expected[page] in dom and "md-header" in dom


def test_the_configuration_reference_writes_every_default_as_yaml_a_config_could_hold() -> None:
    import yaml
    from pydantic import BaseModel
    from pydantic_core import PydanticUndefined, to_jsonable_python

    from datagen.config.key_reference import _sections, yaml_text

    checked = 0
    for _prefix, model in _sections():
        for info in model.model_fields.values():
            if info.default is PydanticUndefined and info.default_factory is None:
                continue
            value = info.default if info.default_factory is None else info.default_factory()
            if isinstance(value, BaseModel):  # a section
                continue
            text = yaml_text(value)
            assert "\n" not in text and not text.startswith("(") and text not in ("None", "True", "False")
            assert yaml.safe_load(text) == to_jsonable_python(getattr(value, "value", value)), text
            checked += 1
    assert checked > 100


def _script(name: str):
    import importlib.util

    spec = importlib.util.spec_from_file_location(name, ROOT / "scripts" / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_example_frame_page_is_what_the_tour_build_writes_today(tmp_path: Path) -> None:
    """docs/reference/example-frame.md (label file, manifest row) from a labels-only build of
    the README's tour config: the same labels and draws a rendered build writes."""
    from datagen.pipeline.build import build_dataset

    example = _script("example_frame")
    build_dataset(example.tour_config(), tmp_path / "tour", render=False)
    assert example.PAGE.read_text() == example.page(tmp_path / "tour")
    assert example.IMAGE.is_file()


# --- every command the docs show --------------------------------------------------------------
DOC_FILES = [ROOT / "README.md", ROOT / "manifests" / "README.md", *sorted((ROOT / "docs").rglob("*.md")),
             *sorted((ROOT / "examples").rglob("README.md"))]


def documented_shell_commands() -> list[tuple[str, list[str]]]:
    """``(file, words)`` of every command in the docs' ``bash`` blocks: continuation lines
    joined, comments dropped, ``&&`` chains split."""
    import shlex

    found = []
    for path in DOC_FILES:
        blocks = re.findall(r"^ *```bash\n(.*?)^ *```", path.read_text(), flags=re.S | re.M)
        for block in blocks:
            for line in block.replace("\\\n", " ").splitlines():
                for part in re.split(r"&&|;", line):
                    words = shlex.split(part, comments=True)
                    if words:
                        found.append((str(path.relative_to(ROOT)), words))
    return found


def test_the_docs_show_datagen_commands_in_bash_blocks() -> None:
    commands = documented_shell_commands()
    assert sum(Path(w[0]).name == "datagen" for _, w in commands) >= 20
    assert any(w[1:2] == ["train"] for _, w in commands if Path(w[0]).name == "datagen")


def test_every_datagen_command_the_docs_show_exists_and_parses() -> None:
    """Each `datagen ...` line of a bash block parses as the command line would (sub-command,
    options, their values and the required ones), without running it. Typer carries its own
    click (typer._click): its contexts parse, its UsageError says what is wrong."""
    import typer
    from typer._click.exceptions import UsageError

    from datagen.cli import app

    root = typer.main.get_command(app)
    bad, parsed = [], 0
    for where, words in documented_shell_commands():
        if Path(words[0]).name != "datagen" or "--help" in words:
            continue
        try:
            command, args, ctx = root, words[1:], None
            while True:
                ctx = command.make_context("datagen", list(args), parent=ctx)
                if not hasattr(command, "resolve_command"):  # a command, not a group
                    break
                _, command, args = command.resolve_command(ctx, ctx._protected_args + ctx.args)
            parsed += 1
        except UsageError as exc:
            bad.append(f"{where}: {' '.join(words)}: {exc.format_message()}")
    assert bad == []
    assert parsed >= 20


def test_every_script_and_file_the_docs_run_exists() -> None:
    """`python SCRIPT`, `bash SCRIPT` and `.venv/bin/...` lines name files of the repository
    (or the environment's own programs)."""
    missing = []
    for where, words in documented_shell_commands():
        first = Path(words[0]).name
        if first in ("python", "bash") and len(words) > 1 and not words[1].startswith("-"):
            if not (ROOT / words[1]).is_file():
                missing.append(f"{where}: {' '.join(words)}")
    assert missing == []


def test_every_yolo_command_the_docs_show_uses_ultralytics_keys() -> None:
    pytest.importorskip("ultralytics", reason="needs the train extra")
    from ultralytics.cfg import DEFAULT_CFG_DICT, MODES, TASKS

    bad = []
    for where, words in documented_shell_commands():
        if Path(words[0]).name != "yolo":
            continue
        keys = [w.split("=", 1)[0] for w in words[3:]]
        if words[1] not in TASKS or words[2] not in MODES or any(k not in DEFAULT_CFG_DICT for k in keys):
            bad.append(f"{where}: {' '.join(words)}")
    assert bad == []


def test_the_tutorials_audit_table_names_every_check_the_audit_makes() -> None:
    names = set()
    for path in (ROOT / "datagen" / "analysis" / "audit").glob("*.py"):
        names.update(re.findall(r'Check\("([a-z_]+)"', path.read_text()))
    table = [line for line in (ROOT / "docs" / "tutorials" / "first-dataset.md").read_text().splitlines()
             if line.startswith("| `")]
    documented = {name for line in table for name in re.findall(r"`([a-z_]+)`", line.split(" | ")[0])}
    assert len(names) >= 18 and names - documented == set()


@pytest.fixture(scope="module")
def readme_build(tmp_path_factory) -> tuple[Path, str]:
    """The README's small build without its images (the same labels, manifests and
    summary lines that do not time anything) and the summary it prints."""
    root = tmp_path_factory.mktemp("readme") / "wingcam55"
    done = subprocess.run([sys.executable, "-m", "datagen", "build", "--config", "wingcam55.yaml", "--frames", "8",
                           "--no-render", "--out", str(root)], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    return root, done.stderr + done.stdout


def test_the_tutorials_build_output_is_what_the_readme_build_prints_today(readme_build) -> None:
    """Every line of the first-dataset tutorial's output block that times nothing (the
    dataset, the labels, the exclusion reasons and the classes never labeled)."""
    _, printed = readme_build
    page = (ROOT / "docs" / "tutorials" / "first-dataset.md").read_text()
    block = page.split("```\nconfig: ", 1)[1].split("```", 1)[0]
    stable = [line for line in block.splitlines()
              if line.startswith(("  labels:", "    ", "  never labeled", "wingcam55: "))]
    assert len(stable) >= 4
    for line in stable:
        wanted = line.split(" -> ")[0]
        assert wanted in printed, wanted


def test_the_tutorials_audit_figures_are_the_readme_builds(readme_build) -> None:
    from datagen.analysis.audit import audit
    from datagen.dataset.reader import load_dataset

    root, _ = readme_build
    result = audit(load_dataset(root))
    drift = {c.name: c for c in result.checks}["centre_drift"].worst
    tight = result.stats.drift.overall
    page = " ".join((ROOT / "docs" / "tutorials" / "first-dataset.md").read_text().split())
    assert result.passed
    assert (f"every check passes (worst label-centre drift {drift:.2e} px); tight-box drift median "
            f"{tight.median:.2f} px, 95th percentile {tight.p95:.2f} px, max {tight.max:.2f} px") in page


def test_the_readme_and_the_site_cite_the_paper_alike() -> None:
    readme, index = ((ROOT / name).read_text() for name in ("README.md", "docs/index.md"))
    entries = [re.findall(r"```bibtex\n(.*?)```", text, re.S) for text in (readme, index)]
    assert entries[0] == entries[1] and len(entries[0]) == 1
    title = "Relative vectoring using dual object detection for autonomous aerial refueling"
    assert title in entries[0][0] and title in " ".join(readme.split())


def test_no_page_names_an_issue_or_a_commit() -> None:
    """The pages describe the program; its history (issues, commits) is in CHANGELOG.md only."""
    from datagen.cli.command_reference import cli_reference
    from datagen.config.key_reference import config_reference

    pages = {str(p.relative_to(ROOT)): p.read_text() for p in DOC_FILES + [ROOT / "assets" / "README.md"]}
    pages.update({"reference/config.md": config_reference(), "reference/cli.md": cli_reference()})
    history = re.compile(r"\bissues? #?\d+|\bcommit\b|\b(?=[0-9a-f]*[a-f])(?=[0-9a-f]*\d)[0-9a-f]{7,40}\b", re.I)
    found = [f"{name}: {m.group(0)}" for name, text in pages.items() for m in history.finditer(text)]
    assert found == []
