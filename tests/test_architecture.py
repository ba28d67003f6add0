"""The house rules a newcomer relies on: no import cycles, one-way packages, no world branches,
one form of the data directory."""

import ast

from tools.import_graph import (
    ROOT,
    file_graph,
    imported_names,
    project_modules,
    report,
)
from tools.world_branches import world_branches


def test_no_import_cycles_between_files_or_packages():
    found = report()
    assert found == {"files": [], "packages": [], "top level": []}


def imports_from(importers: str, imported) -> dict[str, list[str]]:
    """Each module under `importers` (a dotted prefix) and the modules it imports for which
    `imported(name)` holds; modules importing none are left out."""
    found = {src: sorted(t for t in targets if imported(t))
             for src, targets in file_graph().items() if within(src, importers)}
    return {src: targets for src, targets in found.items() if targets}


def within(module: str, prefix: str) -> bool:
    """True if `module` is `prefix` or inside it (app.core.files is within app.core)."""
    return module == prefix or module.startswith(prefix + ".")


def test_the_foundations_import_neither_app_nor_analysis():
    """app.core is the ground floor: only the standard library and third-party packages."""
    assert imports_from("app.core", lambda t: not within(t, "app.core")) == {}


def test_analysis_imports_from_app_only_the_foundations():
    assert imports_from("analysis", lambda t: within(t, "app") and not within(t, "app.core")) == {}


# the server, the pipeline and everything they import run without the analysis package
NEVER_ANALYSIS = ("app.server", "app.learning", "app.worlds", "app.bank", "app.recordings",
                  "app.study", "app.data", "app.predictors", "app.pilot", "app.core")
# the modules whose job is running an analysis or rendering its results
RUNS_ANALYSES = {
    "app.cli",  # `analyze`, and `archive` and `reproduce`, which run it on an archive
    "app.interaction.experiment", "app.interaction.horizons", "app.interaction.report",
    "app.observers.design_goal", "app.observers.instrument_grid",
    "app.observers.simulated_study",
    "app.prereg.inputs", "app.prereg.sections", "app.prereg.write",
    "app.researcher.archive", "app.researcher.dashboard", "app.researcher.exports",
    "app.researcher.progress",
}


def test_the_server_and_the_pipeline_never_import_analysis():
    for package in NEVER_ANALYSIS:
        assert imports_from(package, lambda t: within(t, "analysis")) == {}, package


def test_only_modules_running_an_analysis_import_it():
    assert set(imports_from("app", lambda t: within(t, "analysis"))) == RUNS_ANALYSES


def test_recordings_never_import_the_interaction_experiment():
    """app.recordings reads recorded data; app.interaction is one experiment run on it."""
    assert imports_from("app.recordings", lambda t: within(t, "app.interaction")) == {}


OFFLINE = ("worlds", "data", "learning", "interaction", "recordings", "observers", "study",
           "bank", "predictors", "prereg")
WEB = ("fastapi", "sqlmodel", "sqlalchemy", "starlette", "app.http", "app.server",
       "app.researcher", "app.pilot", "app.main")


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


def test_the_researcher_side_reads_the_server_through_its_query_interface():
    """app.researcher imports from app.server only app.server.queries, so the server's rooms
    can change behind that one module."""
    found = imports_from("app.researcher", lambda t: within(t, "app.server"))
    assert {src: [t for t in targets if t != "app.server.queries"]
            for src, targets in found.items() if set(targets) != {"app.server.queries"}} == {}


def test_the_server_stands_without_the_researcher_side():
    """The researcher side reads the server; the server never imports it."""
    assert imports_from("app.server", lambda t: within(t, "app.researcher")) == {}


# the web layer is the top floor: only the app that mounts it and the CLI's `serve` import it
WEB_LAYER_IMPORTERS = {"app.main", "app.cli"}


def test_nothing_below_the_web_layer_imports_it():
    """app.server, app.researcher and the offline packages run without the HTTP layer."""
    importers = imports_from("app", lambda t: within(t, "app.http"))
    assert {src for src in importers if not within(src, "app.http")} == WEB_LAYER_IMPORTERS


def test_every_route_is_declared_in_the_routes_package():
    """Participant and researcher routes live in one place: app/http/routes/."""
    routers = [name for name, path in project_modules().items()
               for node in ast.walk(ast.parse(path.read_text(), filename=str(path)))
               if isinstance(node, ast.Call) and called_name(node.func) == "APIRouter"]
    assert routers and [name for name in routers if not within(name, "app.http.routes")] == []


# the trees whose modules may import test helpers
TEST_TREES = ("tests", "benchmarks", "tools")


def imports_of_test_modules() -> dict[str, list[str]]:
    """Each module under TEST_TREES that imports a test_*.py module, and those it imports."""
    modules = project_modules(TEST_TREES)
    tests = {name for name, path in modules.items() if path.name.startswith("test_")}
    found = {str(path.relative_to(ROOT)): sorted(imported_names(path, name) & tests - {name})
             for name, path in modules.items()}
    return {src: targets for src, targets in found.items() if targets}


def test_no_module_imports_a_test_module():
    """Shared test helpers live in helper modules and conftest.py files: importing a test_*.py
    module copies its names (fixtures, tests) into the importer and couples two test files."""
    assert imports_of_test_modules() == {}


def direct_researcher_gets() -> list[str]:
    """file:line of each `httpx.get` of a literal /api/researcher/ URL under TEST_TREES."""
    found = []
    for path in project_modules(TEST_TREES).values():
        for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
            if (isinstance(node, ast.Call) and ast.unparse(node.func) == "httpx.get"
                    and node.args and "/api/researcher/" in ast.unparse(node.args[0])):
                found.append(f"{path.relative_to(ROOT)}:{node.lineno}")
    return found


def test_researcher_gets_over_http_go_through_one_helper():
    """tests.conftest.researcher_get sends the token and waits patience(30) by default."""
    assert direct_researcher_gets() == []
