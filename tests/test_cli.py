"""The command line: exit codes, one-line errors, no tracebacks."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def run(*args: str, cwd: Path = ROOT) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "datagen", *args], cwd=cwd, capture_output=True,
                          text=True, timeout=120)


def test_help_lists_the_commands() -> None:
    out = run("--help")
    assert out.returncode == 0
    for command in ("validate", "build", "audit", "preview", "assets"):
        assert command in out.stdout


def test_validate_ok() -> None:
    out = run("validate", "scenes/wingcam55.yaml")
    assert out.returncode == 0, out.stderr
    assert "scenes/wingcam55.yaml: ok" in out.stdout and "fx=fy=1967.086 px" in out.stdout


def test_validate_reports_each_problem_on_one_line(tmp_path: Path) -> None:
    bad = tmp_path / "bad.yaml"
    bad.write_text("name: t\ncamera: {mount: nosecam, hfov_deg: 0}\ndataset: {frames: 1}\nextra: 1\n")
    out = run("validate", "scenes/wingcam55.yaml", str(bad))
    assert out.returncode == 2
    lines = out.stderr.strip().splitlines()
    assert len(lines) == 3
    assert all(line.startswith(f"{bad}:") for line in lines)
    assert "Traceback" not in out.stderr + out.stdout


@pytest.mark.parametrize("content", [None, "a: [\n", "\x00\x01"])
def test_bad_files_exit_nonzero_without_traceback(tmp_path: Path, content: str | None) -> None:
    path = tmp_path / "c.yaml"
    if content is not None:
        path.write_text(content)
    out = run("validate", str(path))
    assert out.returncode == 2
    assert len(out.stderr.strip().splitlines()) == 1 and out.stderr.startswith(str(path))
    assert "Traceback" not in out.stderr


def test_dataset_commands_on_a_missing_folder_are_one_line() -> None:
    for command in ("audit", "preview", "train"):
        out = run(command, "datasets/none")
        assert out.returncode == 2 and out.stderr == "datasets/none: no such dataset folder\n"


def test_approach_plot_and_frames(tmp_path: Path) -> None:
    png = tmp_path / "sub" / "approach.png"
    out = run("approach", "--config", "scenes/podcam15.yaml", "--plot", str(png), "--approaches", "2",
              "--frames", "3")
    assert out.returncode == 0, out.stderr
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert [p.name for p in png.parent.iterdir()] == ["approach.png"]  # no temporary left behind
    lines = out.stdout.splitlines()
    assert sum(line.startswith("approach ") and "contact after" in line for line in lines) == 2
    assert sum(line.startswith("frame ") for line in lines) == 3


def test_approach_bad_config_is_one_line(tmp_path: Path) -> None:
    bad = tmp_path / "bad.yaml"
    bad.write_text("name: t\ncamera: {mount: wingcam, hfov_deg: 55}\ndataset: {frames: 1}\n"
                   "approach: {sampling: sideways}\n")
    out = run("approach", "--config", str(bad), "--plot", str(tmp_path / "x.png"))
    assert out.returncode == 2 and "Traceback" not in out.stderr
    assert out.stderr.strip().startswith(f"{bad}:4: approach.sampling: value 'sideways'")
    assert not (tmp_path / "x.png").exists()


def test_assets_build_and_show(tmp_path: Path) -> None:
    out = run("assets", "build", "--out", str(tmp_path))
    assert out.returncode == 0, out.stderr
    assert sorted(p.relative_to(tmp_path).as_posix() for p in tmp_path.rglob("*") if p.is_file()) == [
        "features/drogue.json", "features/receiver.json", "features/tanker.json",
        "meshes/drogue.glb", "meshes/receiver.glb", "meshes/tanker.glb"]
    out = run("assets", "show", "receiver")
    assert out.returncode == 0, out.stderr
    rows = [line for line in out.stdout.splitlines() if line[:3].strip().isdigit()]
    assert len(rows) == 40 and rows[0].split()[:2] == ["0", "probe_tip"]
    out = run("assets", "show", "hose")
    assert out.returncode == 2 and out.stderr.strip() == "unknown object 'hose' (choose from tanker, receiver, drogue)"


def test_validate_names_a_bad_feature_file(tmp_path: Path) -> None:
    features = tmp_path / "drogue.json"
    doc = (ROOT / "assets" / "features" / "drogue.json").read_text()
    features.write_text(doc.replace('"class_id": 3,', '"class_id": 2,', 1))
    config = tmp_path / "c.yaml"
    config.write_text("name: t\ncamera: {mount: podcam, hfov_deg: 15}\ndataset: {frames: 1}\n"
                      "features: {objects: [receiver, drogue]}\n"
                      "objects: {drogue: {features: drogue.json}}\n")
    out = run("validate", str(config))
    assert out.returncode == 2 and "Traceback" not in out.stderr
    assert out.stderr.strip() == f"{features}: variants.baseline[3].class_id: value 2: duplicate class id (also at [2])"


@pytest.mark.render
def test_assets_preview_without_out_writes_previews_in_the_working_folder_and_no_tracked_file(tmp_path: Path) -> None:
    from .support import ROOT, run_cli

    tracked = ROOT / "assets" / "previews" / "drogue.png"
    before = tracked.stat().st_mtime_ns
    done = run_cli("assets", "preview", "--object", "drogue", "--spp", "1", cwd=tmp_path)
    assert done.returncode == 0, done.stderr[-2000:]
    assert (tmp_path / "previews" / "drogue.png").stat().st_size > 0
    assert tracked.stat().st_mtime_ns == before


def test_train_refuses_a_labels_only_build_and_pose_without_pose_labels_in_one_line(tmp_path: Path) -> None:
    """Checked before Ultralytics is imported: these run without the train extra."""
    root = tmp_path / "labels"
    built = run("build", "--config", "wingcam55", "--frames", "2", "--no-render", "--out", str(root))
    assert built.returncode == 0, built.stderr
    out = run("train", str(root))
    assert out.returncode == 2 and out.stderr.strip() == (
        f"{root / 'dataset.json'}: render: false: a labels-only build has no images to train on "
        "(build it without --no-render)")
    document = root / "dataset.json"
    document.write_text(document.read_text().replace('"render": false', '"render": true'))
    out = run("train", str(root), "--pose")
    assert out.returncode == 2 and len(out.stderr.strip().splitlines()) == 1
    assert "--pose needs a build with pose labels" in out.stderr


def test_train_refuses_training_files_ultralytics_would_run_or_load(tmp_path: Path) -> None:
    """A dataset is a stranger's: Ultralytics executes a data.yaml's `download` and loads the
    files hyp.yaml names. train refuses such files in one line, before Ultralytics runs."""
    root = tmp_path / "labels"
    assert run("build", "--config", "wingcam55", "--frames", "2", "--no-render", "--out", str(root)).returncode == 0
    touched = tmp_path / "pwned"
    data, hyp = (root / "data.yaml").read_text(), (root / "hyp.yaml").read_text()
    for name, text, said in (
            ("data.yaml", data + f"download: \"open('{touched}', 'w').write('x')\"\n", "'download': not a key"),
            ("hyp.yaml", hyp + f"pretrained: {tmp_path / 'evil.pt'}\n", "'pretrained': not a setting"),
            ("hyp.yaml", hyp + "imgsz: [\n", "invalid YAML")):
        (root / "data.yaml").write_text(data)
        (root / "hyp.yaml").write_text(hyp)
        (root / name).write_text(text)
        out = run("train", str(root))
        assert out.returncode == 2 and len(out.stderr.strip().splitlines()) == 1, out.stderr
        assert out.stderr.startswith(str(root / name)) and said in out.stderr, out.stderr
    assert not touched.exists()
