"""The project's import graph: cycles between files and between packages, and upward imports.

    python -m tools.import_graph

Every `import` statement counts, also those inside functions: a lazy import hides a cycle
from the interpreter, not from a reader. Prints each cycle found (exit 1 if any).
"""

import ast
import sys
from collections import defaultdict
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("app", "analysis")


def module_name(path: Path) -> str:
    """app/server/storage/crud.py -> app.server.storage.crud; app/study/__init__.py -> app.study."""
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def project_modules(packages: tuple[str, ...] = PACKAGES) -> dict[str, Path]:
    """Every module of these top-level folders (the project's packages unless told), by dotted
    name; an npm folder's JavaScript tooling (node_modules) holds no project module."""
    return {module_name(p): p for pkg in packages for p in sorted((ROOT / pkg).rglob("*.py"))
            if "node_modules" not in p.parts}


def imported_names(path: Path, this: str) -> set[str]:
    """Dotted names a file imports (absolute, relative ones resolved), with `from x import y`
    also giving x.y so a submodule import is seen."""
    tree = ast.parse(path.read_text(), filename=str(path))
    package = this if path.name == "__init__.py" else this.rpartition(".")[0]
    names: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join([*anchor, base] if base else anchor)
            names.add(base)
            names.update(f"{base}.{alias.name}" for alias in node.names)
    return names


def file_graph() -> dict[str, set[str]]:
    """module -> the project modules it imports (a package import counts as its __init__)."""
    modules = project_modules()
    graph: dict[str, set[str]] = {}
    for name, path in modules.items():
        targets = {n for n in imported_names(path, name) if n in modules and n != name}
        # `import app` is a real dependency on app/__init__.py; a parent package of the
        # importer is not (Python runs it anyway), so skip edges to own ancestors
        graph[name] = {t for t in targets if not name.startswith(t + ".")}
    return graph


def package_of(module: str) -> str:
    """The package a module belongs to at the layout's level: app.study, app.cli, analysis."""
    parts = module.split(".")
    return ".".join(parts[:2]) if parts[0] == "app" and len(parts) > 1 else parts[0]


def top_level(module: str) -> str:
    """The unit a module belongs to at the top: app, analysis, or app.core (the foundations
    both import, so app -> analysis -> app.core is no cycle)."""
    return "app.core" if module == "app.core" or module.startswith("app.core.") else \
        module.split(".")[0]


def collapse(graph: dict[str, set[str]], key) -> dict[str, set[str]]:
    """The graph with nodes merged by key(node); self-loops dropped."""
    out: dict[str, set[str]] = defaultdict(set)
    for src, targets in graph.items():
        out[key(src)].update(key(t) for t in targets if key(t) != key(src))
    return dict(out)


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one node (Tarjan), each sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []

    def visit(node: str) -> None:
        index[node] = low[node] = len(index)
        stack.append(node)
        on_stack.add(node)
        for nxt in sorted(graph.get(node, ())):
            if nxt not in index:
                visit(nxt)
                low[node] = min(low[node], low[nxt])
            elif nxt in on_stack:
                low[node] = min(low[node], index[nxt])
        if low[node] == index[node]:
            component = []
            while True:
                top = stack.pop()
                on_stack.discard(top)
                component.append(top)
                if top == node:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for node in sorted(graph):
        if node not in index:
            visit(node)
    return found


def report() -> dict[str, list[list[str]]]:
    """Cycles at each level: files, packages (app.<sub>), top level (app, analysis, app.core)."""
    files = file_graph()
    return {"files": cycles(files),
            "packages": cycles(collapse(files, package_of)),
            "top level": cycles(collapse(files, top_level))}


def main() -> None:
    """Print every cycle; exit 1 if there is one."""
    found = report()
    for level, items in found.items():
        print(f"{level}: {len(items)} cycle(s)")
        for component in items:
            print("  " + " <-> ".join(component))
    sys.exit(1 if any(found.values()) else 0)


if __name__ == "__main__":
    main()
