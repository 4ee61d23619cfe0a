"""The configuration: its schema (:mod:`datagen.config.schema`), the bounded reader of
untrusted YAML and JSON (:mod:`datagen.config.inputs`) and the loader
(:mod:`datagen.config.load`). Validated once at the boundary, frozen afterwards."""

from datagen.config.load import find_config, load_config, override_config, parse_config, shipped_scenes
from datagen.config.schema import Config, LabelsConfig

__all__ = ["Config", "LabelsConfig", "find_config", "load_config", "override_config", "parse_config",
           "shipped_scenes"]
