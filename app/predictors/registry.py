"""Plug-in predictors by name, through Python entry points (group `tomstudy.predictors`).

A distribution registers `name = "package.module:factory"` in that group (in its
pyproject.toml's `[project.entry-points."tomstudy.predictors"]`); once it is installed, a study
config's `predictors: [name]` asks for it. The factory takes no arguments and returns a
Predictor (app/predictors/protocol.py) whose `name` is the entry point's: a config holds only
names, never class paths or code. Ours, the VAE, constant velocity, the policy and the coarse
observers are the study's own columns and cannot be taken by a plug-in.
"""

import re
from importlib.metadata import EntryPoint, entry_points

from app.core.contracts import COARSE_OBSERVERS, MODELS
from app.predictors.protocol import Predictor

GROUP = "tomstudy.predictors"
# the export's own column prefixes: the models', the coarse observers', the person agent's and
# the participant's
RESERVED = (*MODELS, *COARSE_OBSERVERS, "human", "participant")
NAME = re.compile(r"^[a-z][a-z0-9]*(_[a-z0-9]+)*$")
MAX_NAME = 32


class UnknownPredictor(LookupError):
    """No installed distribution registers a predictor of that name."""


def registered() -> dict[str, EntryPoint]:
    """Every installed plug-in's entry point, by name. Scanned afresh on every call (a package
    installed while the process runs counts); callers pass the result down, not call again."""
    return {ep.name: ep for ep in entry_points(group=GROUP)}


def listing(plugins: dict[str, EntryPoint]) -> str:
    """The registered names (`plugins`, from registered()) for a message ('none' when nothing
    is installed)."""
    return ", ".join(sorted(plugins)) or "none"


def name_problem(name: str, plugins: dict[str, EntryPoint]) -> str:
    """Why `name` cannot name a plug-in in a study ('' when it can); `plugins` is registered()."""
    if name in RESERVED:
        return f"{name!r} is one of the study's own predictors or column prefixes, not a plug-in"
    if not NAME.match(name) or len(name) > MAX_NAME:
        return (f"{name!r} is not a predictor name (lower-case letters, digits and single "
                f"underscores, starting with a letter, at most {MAX_NAME} characters)")
    if name not in plugins:
        return (f"no installed predictor is named {name!r} (entry point group {GROUP}; "
                f"registered: {listing(plugins)})")
    return ""


def check_names(names: list[str]) -> list[str]:
    """The names, once each is a registered plug-in named once; ValueError saying which not.
    The entry points are scanned once per call (none for no names)."""
    if len(set(names)) != len(names):
        raise ValueError("each predictor may be named once")
    plugins = registered() if names else {}
    problems = [problem for problem in (name_problem(name, plugins) for name in names)
                if problem]
    if problems:
        raise ValueError("; ".join(problems))
    return names


def load_predictor(name: str) -> Predictor:
    """The installed plug-in `name`, made by its entry point's factory (UnknownPredictor if
    none is installed; TypeError if the factory's object is not that predictor)."""
    plugins = registered()
    found = plugins.get(name)
    if found is None:
        raise UnknownPredictor(f"predictor {name}: not installed (no entry point {name!r} in "
                               f"group {GROUP}; registered: {listing(plugins)})")
    predictor = found.load()()
    if not isinstance(predictor, Predictor) or predictor.name != name:
        raise TypeError(f"predictor {name}: the entry point {found.value} does not make a "
                        f"predictor named {name!r} with a content_hash and answer()")
    return predictor


def distribution(name: str) -> dict[str, str]:
    """The installed distribution that registers `name` and its version ('' when none)."""
    found = registered().get(name)
    dist = found.dist if found else None
    return {"distribution": dist.name if dist else "", "version": dist.version if dist else ""}
