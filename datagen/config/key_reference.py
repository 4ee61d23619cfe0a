"""The configuration reference, generated from the schema itself: every key of
:class:`datagen.config.schema.Config`, section by section, with its type, default and the
field's own docstring (the schema is the only place a key is described)."""

from __future__ import annotations

import enum
import re
import types
import typing
from typing import Any

from pydantic import BaseModel
from pydantic_core import PydanticUndefined

from datagen.config.schema import Config

__all__ = ["config_keys", "config_reference", "undocumented_fields"]


def _sections(model: type[BaseModel] = Config, prefix: str = "") -> list[tuple[str, type[BaseModel]]]:
    """``(dotted path, model)`` of the config and every nested section, depth first."""
    out = [(prefix, model)]
    for name, info in model.model_fields.items():
        nested = _model_of(info.annotation)
        if nested is not None:
            out += _sections(nested, f"{prefix}{name}.")
    return out


def _model_of(annotation: Any) -> type[BaseModel] | None:
    """The section model an annotation holds directly (``X`` or ``X | None``), if any."""
    candidates = typing.get_args(annotation) if _is_union(annotation) else (annotation,)
    models = [c for c in candidates if isinstance(c, type) and issubclass(c, BaseModel)]
    return models[0] if len(models) == 1 else None


def _is_union(annotation: Any) -> bool:
    return typing.get_origin(annotation) in (typing.Union, types.UnionType)


def config_keys() -> list[str]:
    """Every key of a config, dotted (sections included)."""
    return [f"{prefix}{name}" for prefix, model in _sections() for name in model.model_fields]


def undocumented_fields() -> list[str]:
    """The keys whose field has no docstring."""
    return [f"{prefix}{name}" for prefix, model in _sections()
            for name, info in model.model_fields.items() if not (info.description or "").strip()]


def _type(annotation: Any) -> str:
    """A reader's name for a field's type."""
    origin, args = typing.get_origin(annotation), typing.get_args(annotation)
    if origin is typing.Annotated:
        return _type(args[0])
    if origin is typing.Literal:
        return " \\| ".join(f"`{a}`" for a in args)
    if _is_union(annotation):
        return " or ".join(_type(a) for a in args)
    if origin in (tuple, list, dict):
        inner = ", ".join(_type(a) for a in args if a is not Ellipsis)
        return f"{origin.__name__}[{inner}]"
    if isinstance(annotation, type):
        if issubclass(annotation, BaseModel):
            return f"[{annotation.__name__}](#{_anchor(annotation)})"
        if issubclass(annotation, enum.Enum):
            return " \\| ".join(f"`{m.value}`" for m in annotation)
        return {"NoneType": "null", "str": "text", "float": "number", "int": "integer", "bool": "boolean"}.get(
            annotation.__name__, annotation.__name__)
    return str(annotation).replace("typing.", "")


def _anchor(model: type[BaseModel]) -> str:
    return model.__name__.lower()


def _default(info) -> str:
    if info.default is PydanticUndefined and info.default_factory is None:
        return "required"
    value = info.default if info.default_factory is None else info.default_factory()
    if isinstance(value, BaseModel):
        return "(section)"
    return f"`{text}`" if len((text := yaml_text(value))) < 60 else f"`{text[:57]}...`"


def yaml_text(value: Any) -> str:
    """A default as it is written in a YAML config, on one line (flow style: ``[receiver,
    tanker]``, ``null``, ``true``, ``"auto"`` where a bare word would read as another type)."""
    import yaml
    from pydantic_core import to_jsonable_python

    if isinstance(value, enum.Enum):
        value = value.value
    return yaml.safe_dump(to_jsonable_python(value), default_flow_style=True, width=10**6).strip().removesuffix(
        "\n...").strip()


def _cell(text: str) -> str:
    """A docstring as one table cell: paragraphs joined, pipes escaped."""
    text = re.sub(r"\s*\n\s*", " ", text.strip())
    return text.replace("|", "\\|")


def key_cell(key: str) -> str:
    """A key as the reference's table shows it: code that a narrow column wraps only after a
    dot (``<wbr>``, which a copy leaves out), never inside a name (the site's CSS class
    ``config-key``)."""
    return f'<code class="config-key">{".<wbr>".join(key.split("."))}</code>'


def config_reference() -> str:
    """The reference page (Markdown)."""
    lines = ["# Configuration reference", "",
             "Every key of a scene config, generated from the schema's own field docstrings "
             "(`datagen/config/schema.py`). Keys are YAML paths: `randomization.sea.waves` is "
             "`waves` under `sea` under `randomization`. Unknown keys are refused, and numbers "
             "are bounded as the schema says: `datagen validate` checks a config. The shipped "
             "scenes (`datagen scenes`) are configs in this format; `datagen build` overrides a "
             "few keys from its flags (`--frames`, `--seed`, `--spp`, `--shard-size`).", ""]
    sections = _sections()
    first: dict[type, str] = {}  # model -> the section its plain anchor goes to (a model may be several sections)
    for prefix, model in sections:
        first.setdefault(model, prefix)
    for prefix, model in sections:
        title = prefix.rstrip(".") or "the config"
        anchor = f'<a id="{_anchor(model)}"></a>' if first[model] == prefix else ""
        lines += [f"## {anchor}`{title}`", "", _cell(model.__doc__ or ""), "",
                  "| key | type | default | description |", "|---|---|---|---|"]
        for name, info in model.model_fields.items():
            lines.append(f"| {key_cell(prefix + name)} | {_type(info.annotation)} | {_default(info)} | "
                         f"{_cell(info.description or '')} |")
        lines.append("")
    return "\n".join(lines)

