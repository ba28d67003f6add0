"""The files a preregistration reads, and the ledger that ties each number to one of them.

A `Source` is a file read once (its parsed content and SHA-256). `Ledger.take` reads a value by
its key path and records where it came from, so the document's Sources table lists every
number it shows: a number that was not taken through the ledger is not in the document.
"""

import gzip
import json
from dataclasses import dataclass, field
from pathlib import Path
from types import ModuleType
from typing import Any

import yaml

from app.core.files import sha256_file

REPO_ROOT = Path(__file__).resolve().parents[2]
MAX_SHOWN = 80  # a longer text value is cut in the Sources table (the document has it whole)


@dataclass(frozen=True)
class Source:
    """A file the preregistration reads: its path, its SHA-256 and what it holds."""

    path: Path
    sha256: str
    data: Any

    @property
    def shown_path(self) -> str:
        """The path relative to the repository when it is inside it."""
        return shown_path(self.path)


def shown_path(path: Path) -> str:
    """`path` relative to the repository when it is inside it, else as it is."""
    try:
        return Path(path).resolve().relative_to(REPO_ROOT).as_posix()
    except ValueError:
        return str(path)


def read_source(path: Path, data: Any = None) -> Source:
    """A JSON or YAML file (gzipped or not) as a Source; `data` replaces the parsed content
    (a typed config read from the same file)."""
    path = Path(path)
    if data is None:
        data = parse(path)
    return Source(path, sha256_file(path), data)


def parse(path: Path) -> Any:
    """A .json, .yaml or .yml file's content (.gz unpacked first); a .py file's text."""
    raw = gzip.decompress(path.read_bytes()) if path.suffix == ".gz" else path.read_bytes()
    text = raw.decode()
    suffix = Path(path.stem).suffix if path.suffix == ".gz" else path.suffix
    if suffix == ".json":
        return json.loads(text)
    if suffix in (".yaml", ".yml"):
        return yaml.safe_load(text) or {}
    return text


def dig(data: Any, key: str) -> Any:
    """The value at a dotted key path through mappings, lists and attributes (`a.b.0`); a
    mapping's key may hold dots itself (`files.bank.json.gz.sha256`)."""
    value, parts = data, key.split(".")
    while parts:
        value, parts = _step(value, parts)
    return value


def _step(value: Any, parts: list[str]) -> tuple[Any, list[str]]:
    """One step down: the shortest leading parts that name a key, an index or an attribute."""
    if isinstance(value, dict):
        for end in range(1, len(parts) + 1):
            name = ".".join(parts[:end])
            if name in value:
                return value[name], parts[end:]
        raise KeyError(".".join(parts))
    if isinstance(value, list):
        return value[int(parts[0])], parts[1:]
    return getattr(value, parts[0]), parts[1:]


def shown(value: Any) -> str:
    """A value as the document prints it: floats in their shortest form, lists joined."""
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, float):
        return f"{value:g}"
    if isinstance(value, (list, tuple)):
        return ", ".join(shown(v) for v in value)
    return str(value)


@dataclass(frozen=True)
class Citation:
    """One number (or group) of the document and where it was read."""

    what: str
    value: str
    file: str
    key: str
    sha256: str


@dataclass
class Ledger:
    """Every value the document shows, in the order it was taken, with its file and key."""

    citations: list[Citation] = field(default_factory=list)

    def take(self, source: Source, key: str, what: str, note: str = "") -> Any:
        """The value at `key` of `source`, recorded under `what` (`note` follows the key)."""
        value = dig(source.data, key)
        self.cite(source, key + note, what, shown(value))
        return value

    def cite(self, source: Source, key: str, what: str, value: str) -> None:
        """Record a value read (or derived) from `source` at `key`."""
        short = value if len(value) <= MAX_SHOWN else value[:MAX_SHOWN - 3] + "..."
        self.citations.append(Citation(what, short, source.shown_path, key, source.sha256))


def module_source(module: ModuleType) -> Source:
    """A module of the project's code as a Source: its constants are taken by name."""
    path = Path(module.__file__)
    return Source(path, sha256_file(path), module)
