"""The house rules a newcomer relies on: no import cycles, one-way packages, no world branches,
one form of the data directory."""

import ast

from tests.import_graph import ROOT, file_graph, imported_names, project_modules, report
from tests.world_branches import world_branches


def test_no_import_cycles_between_files_or_packages():
    found = report()
    assert found == {"files": [], "packages": [], "top level": []}


def test_analysis_imports_nothing_from_app():
    upward = {src: sorted(t for t in targets if t.split(".")[0] == "app")
              for src, targets in file_graph().items() if src.split(".")[0] == "analysis"}
    assert {src: t for src, t in upward.items() if t} == {}


OFFLINE = ("worlds", "data", "learning", "interaction", "recordings", "observers", "study",
           "bank", "predictors", "prereg")
WEB = ("fastapi", "sqlmodel", "sqlalchemy", "starlette", "app.server", "app.researcher",
       "app.pilot", "app.main")


def test_offline_packages_stay_out_of_the_web_room():
    """Simulation, learning, observers, the study definition and the bank run without a server."""
    offenders = {}
    for name, path in project_modules().items():
        parts = name.split(".")
        if parts[0] == "app" and len(parts) > 1 and parts[1] in OFFLINE:
            bad = sorted(n for n in imported_names(path, name) if n.startswith(WEB))
            if bad:
                offenders[str(path.relative_to(ROOT))] = bad
    assert offenders == {}


def test_no_module_outside_worlds_branches_on_a_world():
    assert world_branches() == []


# Settings.layout is where a process turns its data dir into a Layout; library code is handed
# one (tests and benchmarks build theirs from temporary folders)
LAYOUT_BUILDERS = {"app.settings"}


def test_a_layout_is_built_only_at_the_edge():
    """Library functions take a `Layout`, never a bare data dir they wrap again."""
    built_at = []
    for name, path in project_modules().items():
        for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
            if isinstance(node, ast.Call) and called_name(node.func) == "Layout":
                built_at.append((name, f"{path.relative_to(ROOT)}:{node.lineno}"))
    assert [where for name, where in built_at if name not in LAYOUT_BUILDERS] == []


def called_name(func: ast.expr) -> str:
    """`Layout` for both `Layout(...)` and `layout.Layout(...)`."""
    if isinstance(func, ast.Attribute):
        return func.attr
    return func.id if isinstance(func, ast.Name) else ""
