"""Bring your own aircraft: ``datagen assets features`` writes a feature file the loader
accepts (and refuses bad flags on one line, writing nothing), a mesh that names no parts
gets one warning line, and ``examples/own-aircraft`` builds and audits as its README says."""

from __future__ import annotations

import re
import shlex
import sys
from pathlib import Path

import numpy as np
import pytest
import trimesh

from datagen.assets.loader import load_features, load_mesh
from datagen.atomic import is_temporary
from datagen.core.features import STORED_VARIANTS

from .support import ROOT, run_cli

EXAMPLE = ROOT / "examples" / "own-aircraft"
CONFIG = EXAMPLE / "own-aircraft.yaml"


def datagen(monkeypatch, capsys, *args: str) -> tuple[int, str, str]:
    """The ``datagen`` command in this process (exit status, stdout, stderr)."""
    from datagen.cli import main

    monkeypatch.setattr(sys, "argv", ["datagen", *args])
    with pytest.raises(SystemExit) as done:
        main()
    out = capsys.readouterr()
    return done.value.code, out.out, out.err


@pytest.fixture(scope="module")
def jet(tmp_path_factory) -> Path:
    """A GLB with named parts: a 4 m box fuselage (paint) and a glass sphere on it."""
    folder = tmp_path_factory.mktemp("jet")
    scene = trimesh.Scene()
    scene.add_geometry(trimesh.creation.box(extents=(4.0, 1.0, 1.0)), geom_name="paint")
    glass = trimesh.creation.icosphere(radius=0.3)
    glass.apply_translation((1.0, 0.0, 0.5))
    scene.add_geometry(glass, geom_name="canopy_glass")
    path = folder / "jet.glb"
    scene.export(path)
    return path


# --- datagen assets features -------------------------------------------------------------
def test_the_command_writes_named_points_and_rings_the_loader_accepts(jet, tmp_path, monkeypatch, capsys) -> None:
    out = tmp_path / "jet.json"
    code, stdout, stderr = datagen(monkeypatch, capsys, "assets", "features", "receiver", "--mesh", str(jet),
                                   "--point", "nose=2.05,0,0", "--point", "belly=0,0,-0.5,large",
                                   "--ring", "intake=-2,0,0,0.4,x,12,small", "--out", str(out),
                                   "--small-radius", "0.05")
    assert code == 0, stderr
    assert stderr == ""
    assert stdout.startswith(f"wrote {out}: 3 features of receiver (2 points, 1 ring), small radius 0.05 m")
    for variant in STORED_VARIANTS:
        features = load_features(out, "receiver", variant)
        assert [(f.class_id, f.name) for f in features] == [(0, "nose"), (1, "belly"), (2, "intake")]
    nose, belly, intake = load_features(out, "receiver", "baseline")
    np.testing.assert_allclose(nose.center_m, [2.0, 0.0, 0.0], atol=1e-6)  # snapped onto the nose face
    np.testing.assert_allclose(belly.center_m, [0.0, 0.0, -0.5], atol=1e-6)
    assert (nose.size, belly.size, intake.size) == ("medium", "large", "small")
    assert len(nose.points_m) == 9 and not nose.internal
    radius = np.linalg.norm(belly.points_m[1:] - belly.center_m, axis=1)
    np.testing.assert_allclose(radius, 0.05 * 4, atol=1e-6)  # large: 4 x the small radius, on the flat belly
    assert intake.internal and len(intake.points_m) == 12
    np.testing.assert_allclose(intake.center_m, [-2.0, 0.0, 0.0])
    np.testing.assert_allclose(intake.points_m[:, 0], -2.0)  # in the plane normal to x
    np.testing.assert_allclose(np.linalg.norm(intake.points_m[:, 1:], axis=1), 0.4, atol=1e-6)
    small = load_features(out, "receiver", "small")
    assert [f.size for f in small] == ["small", "small", "small"]
    np.testing.assert_allclose(small[1].center_m, belly.center_m)  # co-located: the same centres


BAD_FLAGS = {
    "no equals sign": (["--point", "nose"], "--point 'nose': expected NAME=X,Y,Z[,SIZE]"),
    "two coordinates": (["--point", "nose=1,2"], "--point 'nose=1,2': expected NAME=X,Y,Z[,SIZE], got 2 values"),
    "not a number": (["--point", "nose=1,x,2"], "--point 'nose=1,x,2': 'x' is not a number"),
    "unknown size": (["--point", "nose=1,0,0,huge"], "--point 'nose=1,0,0,huge': unknown size 'huge'"),
    "duplicate name": (["--point", "nose=2,0,0", "--ring", "nose=0,0,0,0.3,x,8"],
                       "--ring 'nose=0,0,0,0.3,x,8': the name 'nose' is taken by --point 'nose=2,0,0'"),
    "bad axis": (["--ring", "intake=0,0,0,0.3,w,8"], "--ring 'intake=0,0,0,0.3,w,8': AXIS must be x, y or z"),
    "too few ring points": (["--ring", "intake=0,0,0,0.3,x,2"], "COUNT must be a whole number of points from 3"),
    "zero radius": (["--ring", "intake=0,0,0,0,x,8"], "RADIUS must be at least 0.001 m"),
    "no feature": ([], "name at least one feature"),
    "bad small radius": (["--point", "nose=2,0,0", "--small-radius", "-1"], "--small-radius: -1: expected"),
}


@pytest.mark.parametrize("case", BAD_FLAGS, ids=str)
def test_bad_flags_are_one_line_naming_the_flag_and_write_nothing(case, jet, tmp_path, monkeypatch,
                                                                  capsys) -> None:
    args, message = BAD_FLAGS[case]
    out = tmp_path / "jet.json"
    out.write_text("mine\n")  # a file already there stays as it was
    code, _, stderr = datagen(monkeypatch, capsys, "assets", "features", "receiver", "--mesh", str(jet),
                              "--out", str(out), *args)
    assert code == 2
    assert len(stderr.splitlines()) == 1 and message in stderr, stderr
    assert out.read_text() == "mine\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["jet.json"]


def test_a_point_without_a_mesh_and_an_unknown_object_are_refused(tmp_path, monkeypatch, capsys) -> None:
    out = tmp_path / "f.json"
    code, _, stderr = datagen(monkeypatch, capsys, "assets", "features", "receiver", "--point", "a=0,0,0",
                              "--out", str(out))
    assert (code, stderr) == (2, "--point needs --mesh: a point's feature is made on the mesh's surface\n")
    code, _, stderr = datagen(monkeypatch, capsys, "assets", "features", "boom", "--ring", "a=0,0,0,1,x,8",
                              "--out", str(out))
    assert code == 2 and stderr.startswith("unknown object 'boom'")
    assert not out.exists()


def test_a_point_far_from_the_surface_is_a_warning(jet, tmp_path, monkeypatch, capsys) -> None:
    code, _, stderr = datagen(monkeypatch, capsys, "assets", "features", "receiver", "--mesh", str(jet),
                              "--point", "off=5,0,0", "--out", str(tmp_path / "f.json"))
    assert code == 0
    assert stderr.startswith("warning: --point 'off=5,0,0': 3 m from the mesh surface")
    assert len(stderr.splitlines()) == 1


# --- meshes that name no parts -------------------------------------------------------------
def materialless_obj(folder: Path) -> Path:
    """What trimesh exports for a scene of parts without materials: objects, no usemtl."""
    scene = trimesh.Scene()
    scene.add_geometry(trimesh.creation.box(extents=(4.0, 1.0, 1.0)), geom_name="paint")
    inlet = trimesh.creation.cylinder(radius=0.3, height=0.5)
    inlet.apply_translation((1.0, 0.8, 0.0))
    scene.add_geometry(inlet, geom_name="engine_inlets")
    path = folder / "plane.obj"
    scene.export(path)
    return path


def test_a_trimesh_obj_without_materials_gets_one_warning_line(tmp_path) -> None:
    path = materialless_obj(tmp_path)
    mesh = load_mesh(path, "drogue")
    assert len(mesh.parts) == 1  # the inlets merged into the paint: what the warning is about
    assert len(mesh.warnings) == 1
    assert mesh.warnings[0].startswith(f"{path}: warning: no materials (no usemtl lines): the whole mesh is painted")


def test_named_parts_and_the_builtin_meshes_get_no_warning(jet) -> None:
    from datagen.assets.loader import builtin_paths

    assert load_mesh(jet, "drogue").warnings == ()
    assert all(load_mesh(builtin_paths(name)[0], name).warnings == () for name in ("receiver", "drogue"))


def test_ply_and_unnamed_glb_meshes_get_the_warning(tmp_path) -> None:
    box = trimesh.creation.box()
    box.export(tmp_path / "box.ply")
    box.export(tmp_path / "box.glb")
    assert "a PLY file has no materials or part names" in load_mesh(tmp_path / "box.ply", "drogue").warnings[0]
    assert "its meshes have no names" in load_mesh(tmp_path / "box.glb", "drogue").warnings[0]


def test_validate_prints_the_warning_once_and_passes(tmp_path, monkeypatch, capsys) -> None:
    path = materialless_obj(tmp_path)
    config = tmp_path / "c.yaml"
    config.write_text("name: t\ncamera: {mount: podcam, hfov_deg: 15}\ndataset: {frames: 1}\n"
                      "features: {objects: [receiver]}\n"
                      f"objects: {{drogue: {{mesh: {path.name}}}}}\n")
    code, stdout, stderr = datagen(monkeypatch, capsys, "validate", str(config))
    assert code == 0 and f"{config}: ok" in stdout
    assert stderr.splitlines() == [load_mesh(path, "drogue").warnings[0]]


# --- the worked example --------------------------------------------------------------------
def bash_commands(markdown: str) -> list[str]:
    """The commands of a page's bash blocks, continuation lines joined."""
    blocks = re.findall(r"^```bash\n(.*?)^```", markdown, re.DOTALL | re.MULTILINE)
    return [line.strip() for block in blocks for line in block.replace("\\\n", " ").splitlines() if line.strip()]


def test_the_pages_features_command_writes_the_committed_file(tmp_path, monkeypatch, capsys) -> None:
    pages = [EXAMPLE / "README.md", ROOT / "docs" / "tutorials" / "own-aircraft.md"]
    commands = {c for page in pages for c in bash_commands(page.read_text()) if " assets features " in c
                and "examples/own-aircraft/receiver-features.json" in c}
    assert len(commands) == 1  # the same command on both pages
    args = shlex.split(commands.pop())
    assert args[:3] == [".venv/bin/datagen", "assets", "features"]
    out = tmp_path / "receiver-features.json"
    args[args.index("--out") + 1] = str(out)
    monkeypatch.chdir(ROOT)
    code, _, stderr = datagen(monkeypatch, capsys, *args[1:])
    assert code == 0 and stderr == "", stderr
    assert out.read_bytes() == (EXAMPLE / "receiver-features.json").read_bytes()


def test_the_example_mesh_is_what_its_script_makes_and_small() -> None:
    import importlib.util

    spec = importlib.util.spec_from_file_location("make_mesh", EXAMPLE / "make_mesh.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    made = {name: trimesh.util.concatenate(meshes) for name, meshes in module.parts().items()}
    mesh = load_mesh(EXAMPLE / "receiver.glb", "receiver")
    assert mesh.warnings == () and sorted(mesh.parts) == sorted(made)
    for name, part in mesh.parts.items():
        np.testing.assert_allclose(part.vertices, made[name].vertices, atol=1e-5)
    assert sum(p.stat().st_size for p in EXAMPLE.iterdir()) < 1_000_000


@pytest.mark.render
def test_the_example_builds_and_audits_as_its_readme_says(tmp_path) -> None:
    commands = bash_commands((EXAMPLE / "README.md").read_text())
    build = next(c for c in commands if c.startswith(".venv/bin/datagen build "))
    audit = next(c for c in commands if c.startswith(".venv/bin/datagen audit "))
    args = shlex.split(build)
    assert args[args.index("--config") + 1] == "examples/own-aircraft/own-aircraft.yaml"
    assert audit == f".venv/bin/datagen audit {args[args.index('--out') + 1]}"
    root = tmp_path / "own-aircraft"
    args[args.index("--out") + 1] = str(root)
    args[args.index("--frames") + 1] = "3"
    built = run_cli(*args[1:])
    assert built.returncode == 0, built.stderr[-3000:]
    assert "receiver.glb: warning" not in built.stderr  # its mesh names its parts
    checked = run_cli("audit", str(root), "--overlays", "0")
    assert checked.returncode == 0, checked.stdout[-3000:] + checked.stderr[-3000:]
    assert checked.stdout.strip().splitlines()[-1].startswith("PASSED")
    assert not [p for p in root.rglob(".*") if is_temporary(p.name)]
