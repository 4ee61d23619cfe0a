"""The documentation: a short front page, a site that builds with strict link and anchor
checking, references generated from the schema and the commands (every key and command
in them, every field documented), and the built pages rendered by a real browser."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from datagen.cli.command_reference import cli_reference, command_paths
from datagen.config.key_reference import config_keys, config_reference, undocumented_fields

ROOT = Path(__file__).resolve().parents[1]


def test_every_schema_field_has_a_docstring() -> None:
    assert undocumented_fields() == []


def test_every_config_key_appears_in_the_generated_reference() -> None:
    page = config_reference()
    keys = config_keys()
    assert len(keys) > 100 and "randomization.sea.waves" in keys and "labels.min_box_px" in keys
    assert [k for k in keys if f"| `{k}` |" not in page] == []


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


def test_the_site_builds_with_strict_link_and_anchor_checking(site: Path) -> None:
    config = (site / "reference" / "config" / "index.html").read_text()
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
