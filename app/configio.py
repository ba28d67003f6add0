"""Typed YAML configs: a misspelt key or a bad value is an error that names the field."""

from pathlib import Path
from typing import TypeVar

import yaml
from pydantic import BaseModel, ConfigDict, ValidationError, model_serializer

M = TypeVar("M", bound=BaseModel)


class ConfigError(ValueError):
    """A config file is missing, unreadable or invalid; the message names file and field."""


class StrictModel(BaseModel):
    """Base for every config: unknown keys are errors, instances are immutable."""

    model_config = ConfigDict(extra="forbid", frozen=True)


def omitted_when_empty(*keys: str):
    """A model's serializer that leaves out these keys while their value is None or empty, so a
    model given a newer key dumps, byte for byte (and hash for hash), as it did before the key
    existed. Assign it in the class body: `_serialized = omitted_when_empty("key")`."""
    return omitted_when(empty=keys)


def omitted_when_default(*keys: str):
    """A model's serializer that leaves out these keys while they hold their default, so a
    config that leaves a newer key out, or sets it to its default, dumps as before the key
    existed. Read such a key from the model, not from its dump."""
    return omitted_when(default=keys)


def omitted_when(empty: tuple[str, ...] = (), default: tuple[str, ...] = ()):
    """Both rules in one serializer (a model has one): the `empty` keys are left out while
    None or empty, the `default` keys while they hold their default."""

    @model_serializer(mode="wrap")
    def serialize(self, handler):
        data = handler(self)
        for key in empty:
            if key in data and data[key] in (None, [], {}):
                del data[key]
        for key in default:
            if key in data and getattr(self, key) == type(self).model_fields[key].default:
                del data[key]
        return data

    return serialize


def describe_validation_error(err: ValidationError, source: str) -> str:
    """One line per problem: `source: field.path: message`."""
    lines = []
    for problem in err.errors():
        field = ".".join(str(part) for part in problem["loc"]) or "(root)"
        lines.append(f"{source}: {field}: {problem['msg']}")
    return "\n".join(lines)


def load_yaml_model(path: Path, model: type[M], overrides: dict | None = None) -> M:
    """Read a YAML file into `model`; `overrides` are applied on top of the file's keys."""
    path = Path(path)
    if not path.is_file():
        raise ConfigError(f"{path}: config file not found")
    try:
        data = yaml.safe_load(path.read_text()) or {}
    except yaml.YAMLError as err:
        raise ConfigError(f"{path}: not valid YAML: {err}") from err
    if not isinstance(data, dict):
        raise ConfigError(f"{path}: top level must be a mapping of keys")
    data.update(overrides or {})
    try:
        return model.model_validate(data)
    except ValidationError as err:
        raise ConfigError(describe_validation_error(err, str(path))) from err
