"""Config schema, the wingcam55 baseline, and one-line errors for bad input."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml
from pydantic import BaseModel, ValidationError

from datagen.config import Config, load_config
from datagen.core.errors import ConfigError

ROOT = Path(__file__).resolve().parents[1]
SCENES = sorted((ROOT / "scenes").glob("*.yaml"))

MINIMAL = "name: t\ncamera: {mount: wingcam, hfov_deg: 55}\ndataset: {frames: 4}\n"


def write(tmp_path: Path, text: str, name: str = "scene.yaml") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def problems(path: Path) -> list[str]:
    with pytest.raises(ConfigError) as info:
        load_config(path)
    return info.value.lines()


@pytest.mark.parametrize("path", SCENES, ids=lambda p: p.name)
def test_every_shipped_scene_validates(path: Path) -> None:
    assert load_config(path).name == path.stem


def test_wingcam55_is_paper_model_d() -> None:
    c = load_config(ROOT / "scenes" / "wingcam55.yaml")
    assert (c.camera.mount, c.camera.hfov_deg, c.camera.width, c.camera.height) == ("wingcam", 55.0, 2048, 1080)
    assert c.approach.range_m == (0.0, 120.0)
    assert (c.approach.yaw_deg, c.approach.pitch_deg, c.approach.roll_deg) == (10.0, 15.0, 45.0)
    assert c.labels.corrected is True and c.labels.edge_margin_px == 10.0
    assert c.features.objects == ("receiver", "tanker") and c.features.variant == "baseline"
    assert c.dataset.val_fraction == 0.2


def _models(model: type[BaseModel]):
    yield model
    for field in model.model_fields.values():
        if isinstance(field.annotation, type) and issubclass(field.annotation, BaseModel):
            yield from _models(field.annotation)


def test_every_field_is_documented_and_models_are_strict() -> None:
    for model in _models(Config):
        assert model.model_config.get("extra") == "forbid", model
        assert model.model_config.get("frozen") is True, model
        for name, field in model.model_fields.items():
            assert field.description, f"{model.__name__}.{name} has no docstring"


def test_config_is_frozen(tmp_path: Path) -> None:
    c = load_config(write(tmp_path, MINIMAL))
    with pytest.raises(ValidationError, match="frozen"):
        c.camera.hfov_deg = 10.0  # type: ignore[misc]


def test_defaults_fill_in(tmp_path: Path) -> None:
    c = load_config(write(tmp_path, MINIMAL))
    assert (c.camera.width, c.camera.height) == (2048, 1080)
    assert c.labels.edge_margin_px == 10.0 and c.dataset.shard_size == 500


def test_unknown_key_names_file_line_key_and_suggestion(tmp_path: Path) -> None:
    path = write(tmp_path, MINIMAL.replace("hfov_deg: 55", "hfov_deg: 55, widht: 640"))
    (line,) = problems(path)
    assert line.startswith(f"{path}:2: camera.widht: unknown key")
    assert "did you mean 'width'?" in line


def test_every_problem_reported_one_line_each(tmp_path: Path) -> None:
    text = (
        "name: 'bad name'\n"
        "camera:\n  mount: wingcamm\n  hfov_deg: 200\n"
        "approach:\n  range_m: [50, 10]\n"
        "labels:\n  edge_margin_px: -1\n"
        "objects:\n  tanker: {mesh: missing.obj}\n"
        "dataset:\n  frames: 0\n"
    )
    path = write(tmp_path, text)
    lines = problems(path)
    assert len(lines) == 7
    by_key = {line.split(": ")[1]: line for line in lines}
    assert set(by_key) == {"name", "camera.mount", "camera.hfov_deg", "approach.range_m",
                           "labels.edge_margin_px", "objects.tanker.mesh", "dataset.frames"}
    assert by_key["camera.mount"] == (
        f"{path}:3: camera.mount: value 'wingcamm': Input should be 'wingcam', 'dashcam' or 'podcam'")
    assert by_key["camera.hfov_deg"].startswith(f"{path}:4: camera.hfov_deg: value 200: ")
    assert "low <= high" in by_key["approach.range_m"]
    assert "file not found" in by_key["objects.tanker.mesh"]
    assert all("\n" not in line for line in lines)


def test_missing_required_keys(tmp_path: Path) -> None:
    lines = problems(write(tmp_path, "name: t\n"))
    assert sorted(line.split(": ")[1] for line in lines) == ["camera", "dataset"]
    assert all("required key is missing" in line for line in lines)


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("camera:\n  mount: [\n", ":3: invalid YAML"),
        ("name: a\nname: b\n" + MINIMAL.split("\n", 1)[1], ":2: name: duplicate key"),
        ("", ": expected a mapping of config sections, got empty"),
        ("- a\n- b\n", ": expected a mapping of config sections, got a list"),
        ("name: t\ncamera: 5\ndataset: {frames: 1}\n", ":2: camera: value 5:"),
        (MINIMAL.replace("frames: 4", "frames: 4.5"), ":3: dataset.frames: value 4.5:"),
        (MINIMAL + "labels: {edge_margin_px: 600}\n", "edge_margin_px 600.0 leaves no room"),
        (MINIMAL + "features: {objects: [tanker, tanker]}\n", ":4: features.objects:"),
        (MINIMAL + "randomization: {sky: {turbidity: [0.5, 3]}}\n", "turbidity must lie within [1.0, 10.0]"),
        (MINIMAL + "labels: {min_box_px: -2}\n", ":4: labels.min_box_px: value -2: Input should be greater than or "
         "equal to 0"),
        (MINIMAL + "labels: {min_box_px: .inf}\n", ":4: labels.min_box_px: value inf: Input should be a finite number"),
        (MINIMAL + "labels: {min_box_px: .nan}\n", ":4: labels.min_box_px: value nan: Input should be a finite number"),
        (MINIMAL + "labels: {small_boxes: shrink}\n", ":4: labels.small_boxes: value 'shrink': Input should be 'grow' "
         "or 'exclude'"),
        (MINIMAL + "labels: {train_imgsz: 850}\n", ":4: labels.train_imgsz: value 850: must be a multiple of 32"),
        (MINIMAL + "labels: {train_imgsz: 320, min_box_px: 320}\n", "min_box_px 320 must be smaller than train_imgsz"),
        (MINIMAL + "labels: {edge_margin_px: 500, min_box_px: 40}\n", "does not fit inside the edge margin"),
    ],
)
def test_bad_configs(tmp_path: Path, text: str, expected: str) -> None:
    path = write(tmp_path, text)
    lines = problems(path)
    assert any(line.startswith(str(path)) and expected in line for line in lines), lines


def test_missing_file_and_directory(tmp_path: Path) -> None:
    assert problems(tmp_path / "nope.yaml") == [f"{tmp_path / 'nope.yaml'}: no such file"]
    assert "is a directory" in problems(tmp_path)[0]


def test_not_utf8(tmp_path: Path) -> None:
    path = tmp_path / "x.yaml"
    path.write_bytes(b"name: \xff\xfe\n")
    assert "not UTF-8" in problems(path)[0]


def test_asset_paths_resolve_relative_to_the_config(tmp_path: Path, monkeypatch) -> None:
    (tmp_path / "sub").mkdir()
    (tmp_path / "sub" / "mine.obj").write_text("v 0 0 0\n")
    path = write(tmp_path, MINIMAL + "objects: {receiver: {mesh: sub/mine.obj}}\n")
    monkeypatch.chdir("/")
    c = load_config(path)
    assert c.objects.receiver.mesh == (tmp_path / "sub" / "mine.obj").resolve()


def test_round_trip_through_json_dump(tmp_path: Path) -> None:
    c = load_config(ROOT / "scenes" / "wingcam55.yaml")
    dumped = c.model_dump(mode="json")
    again = load_config(write(tmp_path, yaml.safe_dump(dumped)))
    assert again == c
