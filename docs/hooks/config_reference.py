"""MkDocs hook: renders every field of the typed configs from the pydantic models themselves.

A page line `::: config-model app.study.config:StudyConfig` becomes a table per model (the
model, then each nested model it uses): key, type, default and description. The description
is the field's `description=`, else the code comment on or just above the field's line, so
the reference is the code's own words and cannot drift from it; a field with neither fails the
build, naming the model and the field. `::: env-settings app.settings:Settings` renders the
environment variables of a pydantic-settings model."""

import importlib
import inspect
import re
import sys
import types
import typing
from pathlib import Path

from mkdocs.exceptions import PluginError
from pydantic import BaseModel
from pydantic_core import PydanticUndefined

REPO = Path(__file__).resolve().parents[2]
MARKER = re.compile(r"^::: (config-model|env-settings) ([\w.]+):(\w+)[ \t]*$", re.M)
FIELD_LINE = re.compile(r"^(\s+)(\w+)\s*:(?!\s*ClassVar)")


def on_page_markdown(markdown: str, page, config, files) -> str:
    """Replaces each marker line with the tables it names."""
    if str(REPO) not in sys.path:
        sys.path.insert(0, str(REPO))
    shown: set[type[BaseModel]] = set()  # a model nested in two configs is drawn once a page
    return MARKER.sub(lambda m: render(m.group(1), load(m.group(2), m.group(3)), shown),
                      markdown)


def load(module: str, name: str) -> type[BaseModel]:
    """The model `module:name`; a clear error naming the marker if it is not one."""
    model = getattr(importlib.import_module(module), name, None)
    if not (inspect.isclass(model) and issubclass(model, BaseModel)):
        raise ValueError(f"config reference: {module}:{name} is not a pydantic model")
    return model


def render(kind: str, model: type[BaseModel], shown: set[type[BaseModel]]) -> str:
    """The marker's tables: the model and every model nested in it not yet on the page."""
    if kind == "env-settings":
        return settings_table(model)
    fresh = [m for m in nested_models(model) if m not in shown]
    shown.update(fresh)
    return "\n\n".join(model_table(m) for m in fresh)


def nested_models(model: type[BaseModel]) -> list[type[BaseModel]]:
    """The model, then the models its fields use, depth first, each once."""
    found: list[type[BaseModel]] = []

    def visit(current: type[BaseModel]) -> None:
        if current in found:
            return
        found.append(current)
        for field in current.model_fields.values():
            for inner in models_in(field.annotation):
                visit(inner)

    visit(model)
    return found


def models_in(annotation) -> list[type[BaseModel]]:
    """The pydantic models named anywhere in a type annotation."""
    if inspect.isclass(annotation) and issubclass(annotation, BaseModel):
        return [annotation]
    return [m for arg in typing.get_args(annotation) for m in models_in(arg)]


def model_table(model: type[BaseModel]) -> str:
    """One model's heading, docstring and a row per field."""
    keys = {name: f"`{name}`" for name in model.model_fields}
    return "\n".join([f"### {model.__name__} {{ #{anchor(model)} }}", "",
                      field_table(model, "key", keys)])


def settings_table(model: type[BaseModel]) -> str:
    """A settings model's environment variables (prefix and aliases as it reads them)."""
    prefix = model.model_config.get("env_prefix", "")
    variables = {name: f"`{alias if isinstance(alias, str) else (prefix + name).upper()}`"
                 for name, field in model.model_fields.items()
                 for alias in [field.validation_alias]}
    return field_table(model, "variable", variables)


def field_table(model: type[BaseModel], first: str, names: dict[str, str]) -> str:
    """The model's docstring and where it lives, then a row per field: `names[field]`, its
    type, default and description."""
    notes = source_comments(model)
    rows = [f"| {names[name]} | {type_name(field.annotation)} | {default_text(field)} | "
            f"{cell(description(model, name, notes))} |"
            for name, field in model.model_fields.items()]
    return "\n".join([f"{cell(inspect.getdoc(model) or '')} "
                      f"(`{model.__module__}.{model.__qualname__}`)", "",
                      f"| {first} | type | default | description |", "|---|---|---|---|", *rows])


def description(model: type[BaseModel], name: str, notes: dict[str, str]) -> str:
    """A field's `description=`, else its code comment; PluginError naming the field if neither
    (a reader would have to read the code to learn what the key does)."""
    text = model.model_fields[name].description or notes.get(name, "")
    if not text.strip():
        raise PluginError(f"config reference: {model.__module__}.{model.__qualname__}.{name} "
                          "has no description: give it Field(description=...) or a comment on "
                          "or just above its line (the unit, the range, what it changes)")
    return text


def source_comments(model: type[BaseModel]) -> dict[str, str]:
    """Each field's comment in the class body: the comment lines above it and on its line."""
    try:
        lines = inspect.getsource(model).splitlines()
    except (OSError, TypeError):
        return {}
    notes, above, indent = {}, [], None
    for line in lines[1:]:
        stripped = line.strip()
        if stripped.startswith("#"):
            above.append(stripped.lstrip("# "))
            continue
        match = FIELD_LINE.match(line)
        if match and (indent is None or match.group(1) == indent):
            indent = match.group(1)
            trailing = line.split("  # ", 1)[1] if "  # " in line else ""
            notes[match.group(2)] = " ".join([*above, trailing]).strip()
        above = []
    return notes


def type_name(annotation) -> str:
    """A readable type: `int`, `list[str]`, `HourlyPay | None`, a link for a nested model."""
    if inspect.isclass(annotation) and issubclass(annotation, BaseModel):
        return f"[{annotation.__name__}](#{anchor(annotation)})"
    origin = typing.get_origin(annotation)
    args = typing.get_args(annotation)
    if origin is typing.Annotated:
        return type_name(args[0])
    if origin is typing.Literal:
        return " \\| ".join(f"`{a!r}`" for a in args)
    if origin in (typing.Union, types.UnionType):
        return " \\| ".join(type_name(a) for a in args)
    if origin is not None:
        inner = ", ".join(type_name(a) for a in args)
        return f"{getattr(origin, '__name__', str(origin))}[{inner}]"
    if annotation is type(None):
        return "None"
    return getattr(annotation, "__name__", None) or str(annotation).replace("typing.", "")


def default_text(field) -> str:
    """The default as YAML would hold it, or *required*."""
    if field.default_factory is not None:
        value = field.default_factory()
    elif field.default is PydanticUndefined:
        return "*required*"
    else:
        value = field.default
    if isinstance(value, BaseModel):
        return "(its defaults)"
    if isinstance(value, Path):
        value = shown_path(value)
    return f"`{value!r}`" if len(repr(value)) < 60 else f"`{repr(value)[:57]}...`"


def shown_path(path: Path) -> str:
    """A path under the repository as written from its root (no machine's own folders)."""
    try:
        return str(path.resolve().relative_to(REPO))
    except ValueError:
        return str(path)


def anchor(model: type) -> str:
    """A page anchor for a model: its lower-case class name."""
    return model.__name__.lower()


def cell(text: str) -> str:
    """Text that fits one table cell."""
    return " ".join(text.split()).replace("|", "\\|")
