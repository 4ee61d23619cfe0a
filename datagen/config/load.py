"""Reading a config: the YAML file, through the bounded reader, into the frozen schema.

:func:`find_config` turns what a user typed after ``--config`` into a file: an
existing path always wins; otherwise a shipped scene by name (``wingcam55``,
``wingcam55.yaml`` or ``scenes/wingcam55.yaml``), the way Ultralytics resolves
``coco8.yaml``. The shipped scenes are package data (:data:`SCENES_DIR`).
:func:`load_config` reads a config file, checks it against
:class:`~datagen.config.schema.Config` (unknown keys are errors, so typos cannot
pass silently) and either returns the frozen model or raises
:class:`~datagen.core.errors.ConfigError` listing every problem, one line each, with
the file, the line, the key path, the value and what is wrong. Asset paths are
resolved against the config's folder, so a config means the same from anywhere.
"""

from __future__ import annotations

import difflib
from importlib import resources
from pathlib import Path
from typing import Any, Final

import yaml
from pydantic import BaseModel, ValidationError

from datagen.config.inputs import parse_yaml, read_text
from datagen.config.schema import Config, ObjectSpec
from datagen.core.conventions import RIGID_OBJECTS
from datagen.core.errors import ConfigError, Problem

__all__ = ["SCENES_DIR", "find_config", "load_config", "override_config", "parse_config", "shipped_scenes",
           "stored_config"]

#: Keys added to the schema after datasets were built without them, and the value that gives
#: what those builds made (1: no small-build rule).
ADDED_KEYS: Final = {("approach", "min_approaches"): 1, ("dataset", "min_shards"): 1}

#: The scene configs shipped with datagen (package data).
SCENES_DIR: Final = Path(str(resources.files("datagen") / "scenes"))


def shipped_scenes() -> dict[str, Path]:
    """Every shipped scene config by name (the file name without ``.yaml``), sorted."""
    if not SCENES_DIR.is_dir():
        raise ConfigError([Problem(SCENES_DIR, "", "datagen's shipped scenes are missing from its installation; "
                                   "reinstall datagen")])
    return {p.stem: p for p in sorted(SCENES_DIR.glob("*.yaml"), key=lambda p: p.stem)}


def find_config(value: str | Path) -> Path:
    """The config file ``value`` names: an existing path as it is, else the shipped scene of
    that name (``wingcam55``, ``wingcam55.yaml`` and ``scenes/wingcam55.yaml`` alike).

    Raises:
        ConfigError: one line naming ``value`` and the closest shipped scenes.
    """
    path = Path(value)
    if path.exists() or path.is_symlink():
        return path
    if str(path.parent) not in (".", "scenes"):  # a path, not a name: it does not exist
        raise ConfigError([Problem(path, "", "no such file")])
    name = path.name.removesuffix(".yaml").removesuffix(".yml")
    scenes = shipped_scenes()
    if name in scenes:
        return scenes[name]
    close = difflib.get_close_matches(name, list(scenes), n=3, cutoff=0.5)
    hint = f"; close: {', '.join(close)}" if close else ""
    raise ConfigError([Problem(path, "", f"no such file, and no shipped scene of that name{hint} "
                               "(`datagen scenes` lists them)")])


# --- loading -------------------------------------------------------------------
def load_config(path: str | Path) -> Config:
    """Read, parse and validate a config file (or a shipped scene by name: :func:`find_config`).

    Raises:
        ConfigError: listing every problem found (missing file, YAML syntax, input
            bombs (:mod:`datagen.config.inputs`), duplicate keys, unknown keys, bad values,
            missing asset files).
    """
    path = find_config(path)
    return parse_config(read_text(path, "YAML config file"), path)



def parse_config(text: str, path: Path) -> Config:
    """Validate config ``text`` read from ``path`` (used in messages and for relative paths)."""
    data = parse_yaml(text, path)
    lines, problems = _key_lines(text, path)
    if not isinstance(data, dict):
        kind = "empty" if data is None else f"a {type(data).__name__}"
        raise ConfigError([Problem(path, "", f"expected a mapping of config sections, got {kind}")])
    try:
        config = Config.model_validate(data)
    except ValidationError as exc:
        problems += _problems_from_validation(exc, data, lines, path)
        config = None
    problems += _missing_asset_files(data, lines, path)
    if problems or config is None:
        raise ConfigError(problems)
    return _resolve_paths(config, path.parent)



def _key_lines(text: str, path: Path) -> tuple[dict[tuple, int], list[Problem]]:
    """The line of every key path, and a problem for every duplicate key (on text that
    :func:`datagen.config.inputs.parse_yaml` has already checked, so composing it is bounded)."""
    root = yaml.compose(text, Loader=yaml.SafeLoader)
    lines: dict[tuple, int] = {}
    problems: list[Problem] = []

    def walk(node: yaml.Node, key_path: tuple) -> None:
        lines[key_path] = node.start_mark.line + 1
        if isinstance(node, yaml.MappingNode):
            seen: set[str] = set()
            for key_node, value_node in node.value:
                key = key_node.value
                if key in seen:
                    problems.append(
                        Problem(path, _dotted(key_path + (key,)), "duplicate key",
                                line=key_node.start_mark.line + 1)
                    )
                seen.add(key)
                walk(value_node, key_path + (key,))
        elif isinstance(node, yaml.SequenceNode):
            for i, item in enumerate(node.value):
                walk(item, key_path + (i,))

    if root is not None:
        walk(root, ())
    return lines, problems



def _dotted(loc: tuple) -> str:
    out = ""
    for part in loc:
        out += f"[{part}]" if isinstance(part, int) else (f".{part}" if out else str(part))
    return out



def _line_of(lines: dict[tuple, int], loc: tuple) -> int | None:
    while loc:
        if loc in lines:
            return lines[loc]
        loc = loc[:-1]
    return lines.get(())



def _lookup(data: Any, loc: tuple) -> tuple[bool, Any]:
    for part in loc:
        try:
            data = data[part]
        except (KeyError, IndexError, TypeError):
            return False, None
    return True, data



def _model_at(loc: tuple) -> type[BaseModel] | None:
    """The pydantic model that owns the mapping at ``loc`` (for listing allowed keys)."""
    model: type[BaseModel] | None = Config
    for part in loc:
        if model is None or not isinstance(part, str) or part not in model.model_fields:
            return None
        annotation = model.model_fields[part].annotation
        model = annotation if isinstance(annotation, type) and issubclass(annotation, BaseModel) else None
    return model



def _problems_from_validation(
    exc: ValidationError, data: dict, lines: dict[tuple, int], path: Path
) -> list[Problem]:
    problems = []
    for err in exc.errors(include_url=False):
        loc = tuple(p for p in err["loc"] if not (isinstance(p, str) and p.startswith("function-")))
        found, value = _lookup(data, loc)
        kind = err["type"]
        message = err["msg"]
        if kind == "extra_forbidden":
            owner = _model_at(loc[:-1])
            allowed = sorted(owner.model_fields) if owner else []
            close = difflib.get_close_matches(str(loc[-1]), allowed, n=1)
            hint = f"; did you mean {close[0]!r}?" if close else ""
            message = f"unknown key (allowed: {', '.join(allowed)}){hint}"
            found = False
        elif kind == "missing":
            message = "required key is missing"
        elif kind == "value_error":
            message = message.removeprefix("Value error, ")
        if isinstance(value, dict):  # a section's own check: its message names the keys
            found = False
        problems.append(
            Problem(path, _dotted(loc), message, line=_line_of(lines, loc), value=value, has_value=found)
        )
    return problems



def _missing_asset_files(data: dict, lines: dict[tuple, int], path: Path) -> list[Problem]:
    """Asset paths that name no file, checked on the raw mapping so that they are
    reported together with schema problems."""
    problems = []
    objects = data.get("objects")
    for name in RIGID_OBJECTS:
        spec = objects.get(name) if isinstance(objects, dict) else None
        for field in ("mesh", "features"):
            value = spec.get(field) if isinstance(spec, dict) else None
            if not isinstance(value, str):
                continue
            resolved = path.parent / value
            if not resolved.is_file():
                loc = ("objects", name, field)
                what = "not a regular file" if resolved.exists() else "file not found"
                problems.append(
                    Problem(path, _dotted(loc), f"{what} ({resolved})",
                            line=_line_of(lines, loc), value=value, has_value=True)
                )
    return problems



def _resolve_paths(config: Config, base: Path) -> Config:
    """Make asset paths absolute, so that the config means the same from any directory."""
    objects = {}
    for name in RIGID_OBJECTS:
        spec: ObjectSpec = getattr(config.objects, name)
        update = {
            field: (base / value).resolve()
            for field in ("mesh", "features")
            if (value := getattr(spec, field)) is not None
        }
        objects[name] = spec.model_copy(update=update)
    return config.model_copy(update={"objects": config.objects.model_copy(update=objects)})



def override_config(config: Config, updates: dict[str, object], source: str = "command line") -> Config:
    """``config`` with dotted keys replaced (``{"dataset.frames": 8}``), validated again.

    Raises:
        ConfigError: one problem per bad value, naming ``source`` and the key.
    """
    data = config.model_dump()
    for dotted, value in updates.items():
        *parents, leaf = dotted.split(".")
        section = data
        for part in parents:
            section = section[part]
        if leaf not in section:
            raise KeyError(f"override of unknown config key {dotted!r}")
        section[leaf] = value
    try:
        return Config.model_validate(data)
    except ValidationError as exc:
        raise ConfigError([
            Problem(Path(source), _dotted(tuple(err["loc"])), err["msg"].removeprefix("Value error, "),
                    value=err.get("input"), has_value="input" in err)
            for err in exc.errors(include_url=False)
        ]) from None


def stored_config(data: object) -> Config:
    """The config a dataset.json recorded (``config``), as the build that wrote it planned:
    a key of :data:`ADDED_KEYS` it lacks takes the value that reproduces that build's shards
    and approaches, not today's default. Raises ValueError or TypeError for what is not a
    config."""
    if not isinstance(data, dict):
        raise TypeError("a config is a mapping")
    data = {k: (dict(v) if isinstance(v, dict) else v) for k, v in data.items()}
    for (section, key), value in ADDED_KEYS.items():
        if isinstance(data.get(section, {}), dict):
            data.setdefault(section, {}).setdefault(key, value)
    return Config.model_validate(data)
