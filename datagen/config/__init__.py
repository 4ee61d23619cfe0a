"""The configuration: its schema (:mod:`datagen.config.schema`), the bounded reader of
untrusted YAML and JSON (:mod:`datagen.config.inputs`) and the loader
(:mod:`datagen.config.load`). Validated once at the boundary, frozen afterwards."""

from datagen.config.load import load_config, override_config, parse_config
from datagen.config.schema import Config, LabelsConfig

__all__ = ["Config", "LabelsConfig", "load_config", "override_config", "parse_config"]
