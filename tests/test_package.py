"""datagen as an installed package: a wheel built from the repository works outside it
(shipped scenes by name, package data found through importlib.resources), and a
config's bring-your-own paths still resolve against the config's folder."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import sysconfig
from pathlib import Path

import pytest

from datagen.config import find_config, load_config, shipped_scenes
from datagen.core.errors import ConfigError

from .support import ROOT

MINIMAL = "name: mine\ncamera: {mount: wingcam, hfov_deg: 55}\ndataset: {frames: 2}\n"


# --- shipped scenes by name ------------------------------------------------------------------
@pytest.mark.parametrize("value", ["wingcam55", "wingcam55.yaml", "scenes/wingcam55.yaml"])
def test_a_shipped_scene_is_found_by_name_from_any_folder(value, tmp_path, monkeypatch) -> None:
    monkeypatch.chdir(tmp_path)
    assert find_config(value) == shipped_scenes()["wingcam55"]
    assert load_config(value).name == "wingcam55"


def test_a_local_file_always_wins(tmp_path, monkeypatch) -> None:
    monkeypatch.chdir(tmp_path)
    (tmp_path / "wingcam55.yaml").write_text(MINIMAL)
    assert find_config("wingcam55.yaml") == Path("wingcam55.yaml")
    assert load_config("wingcam55.yaml").name == "mine"
    assert load_config("wingcam55").name == "wingcam55"  # no such local file: the shipped scene


def test_an_unknown_name_lists_the_close_matches(tmp_path, monkeypatch) -> None:
    monkeypatch.chdir(tmp_path)
    with pytest.raises(ConfigError) as err:
        load_config("wingcam5")
    assert err.value.lines() == ["wingcam5: no such file, and no shipped scene of that name; close: wingcam55, "
                                 "wingcam55-mid, wingcam55-long (`datagen scenes` lists them)"]


def test_every_shipped_scene_names_its_paper_model_once() -> None:
    models = {name: load_config(path).paper_model for name, path in shipped_scenes().items()}
    assert sorted(models.values()) == list("ABCDEFGHIJKL")
    assert models["wingcam55"] == "D" and models["podcam15"] == "A"


def test_the_scenes_command_lists_every_shipped_scene(tmp_path) -> None:
    out = subprocess.run([sys.executable, "-m", "datagen", "scenes"], capture_output=True, text=True, timeout=120,
                         cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    lines = out.stdout.splitlines()
    assert lines[0].split() == ["scene", "model", "camera", "hFOV", "range", "features", "frames"]
    row = next(line.split() for line in lines if line.startswith("wingcam55 "))
    assert row[:6] == ["wingcam55", "D", "wingcam", "55", "deg", "0-120"]
    assert len([line for line in lines[1:] if line and not line.startswith("Use ")]) == len(shipped_scenes())
    help_text = subprocess.run([sys.executable, "-m", "datagen", "--help"], capture_output=True, text=True,
                               timeout=120).stdout
    assert " scenes " in help_text


def test_the_build_says_which_config_file_it_used(tmp_path) -> None:
    out = subprocess.run([sys.executable, "-m", "datagen", "build", "--config", "podcam15", "--frames", "2",
                          "--no-render", "--out", str(tmp_path / "ds")], capture_output=True, text=True, timeout=120,
                         cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    assert out.stdout.splitlines()[0] == f"config: {shipped_scenes()['podcam15'].resolve()}"


# --- the wheel, outside the repository -------------------------------------------------------------
@pytest.fixture(scope="module")
def wheel_venv(tmp_path_factory) -> Path:
    """A fresh virtual environment outside the repository with the wheel built from it.

    Its dependencies (Mitsuba, numpy, ...) come from this test run's own environment,
    added to its path by a ``.pth`` line, so that the test needs no network: datagen
    itself is the wheel's copy (checked), not the editable checkout."""
    tmp = tmp_path_factory.mktemp("wheel")
    built = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-q", "-w",
                            str(tmp / "dist"), str(ROOT)], capture_output=True, text=True, timeout=600)
    if built.returncode != 0:
        pytest.skip(f"cannot build a wheel here: {built.stderr.strip().splitlines()[-1:]}")
    wheel = next((tmp / "dist").glob("datagen-*.whl"))
    venv = tmp / "venv"
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True, timeout=300)
    python = venv / "bin" / "python"
    subprocess.run([str(python), "-m", "pip", "install", "-q", "--no-deps", "--no-index", str(wheel)], check=True,
                   timeout=300)
    site = subprocess.run([str(python), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                          capture_output=True, text=True, check=True).stdout.strip()
    (Path(site) / "datagen-test-dependencies.pth").write_text(sysconfig.get_paths()["purelib"] + "\n")
    return venv


def run_in(venv: Path, *args: str, cwd: Path) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV")}
    return subprocess.run([str(venv / "bin" / args[0]), *args[1:]], capture_output=True, text=True, timeout=300,
                          cwd=cwd, env=env)


def test_the_wheel_works_outside_the_repository(wheel_venv, tmp_path) -> None:
    where = run_in(wheel_venv, "python", "-c", "import datagen; print(datagen.__file__)", cwd=tmp_path)
    assert where.returncode == 0 and where.stdout.strip().startswith(str(wheel_venv)), where.stdout + where.stderr
    scenes = run_in(wheel_venv, "datagen", "scenes", cwd=tmp_path)
    assert scenes.returncode == 0 and "wingcam55 " in scenes.stdout, scenes.stderr
    valid = run_in(wheel_venv, "datagen", "validate", "wingcam55", cwd=tmp_path)
    assert valid.returncode == 0 and "ok (wingcam55" in valid.stdout, valid.stderr
    assert str(wheel_venv) in valid.stdout  # the shipped scene is the installed copy
    build = run_in(wheel_venv, "datagen", "build", "--config", "wingcam55.yaml", "--frames", "2", "--no-render",
                   "--out", "X", cwd=tmp_path)
    assert build.returncode == 0, build.stderr
    doc = json.loads((tmp_path / "X" / "dataset.json").read_text())
    assert all(a["mesh"].startswith(str(wheel_venv)) for a in doc["assets"].values())
    audit = run_in(wheel_venv, "datagen", "audit", "X", cwd=tmp_path)
    assert audit.returncode == 0, audit.stdout + audit.stderr


def test_bring_your_own_paths_resolve_against_the_config_with_the_wheel(wheel_venv, tmp_path) -> None:
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "meshes").mkdir()
    shipped = next(ROOT.glob("datagen/assets/builtin/meshes/drogue.glb"))
    (mine / "meshes" / "basket.glb").write_bytes(shipped.read_bytes())
    (mine / "scene.yaml").write_text(MINIMAL.replace("wingcam", "podcam").replace("55", "15")
                                     + "features: {objects: [receiver, drogue]}\n"
                                     + "objects: {drogue: {mesh: meshes/basket.glb}}\n")
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    valid = run_in(wheel_venv, "datagen", "validate", str(mine / "scene.yaml"), cwd=elsewhere)
    assert valid.returncode == 0, valid.stderr
    broken = run_in(wheel_venv, "datagen", "validate", "../mine/nope.yaml", cwd=elsewhere)
    assert broken.returncode == 2 and broken.stderr.count("\n") == 1


def test_missing_package_data_is_one_line(monkeypatch, tmp_path) -> None:
    from datagen.config import load as config_load

    monkeypatch.setattr(config_load, "SCENES_DIR", tmp_path / "gone")
    with pytest.raises(ConfigError) as err:
        load_config("wingcam55")
    assert err.value.lines() == [f"{tmp_path / 'gone'}: datagen's shipped scenes are missing from its installation; "
                                 "reinstall datagen"]
