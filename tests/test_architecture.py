"""The house rules a newcomer relies on: no import cycles, one-way packages, no world branches."""

from tests.import_graph import ROOT, file_graph, imported_names, project_modules, report
from tests.world_branches import world_branches


def test_no_import_cycles_between_files_or_packages():
    found = report()
    assert found == {"files": [], "packages": [], "top level": []}


def test_analysis_imports_nothing_from_app():
    upward = {src: sorted(t for t in targets if t.split(".")[0] == "app")
              for src, targets in file_graph().items() if src.split(".")[0] == "analysis"}
    assert {src: t for src, t in upward.items() if t} == {}


OFFLINE = ("worlds", "data", "learning", "interaction", "observers", "study", "bank")
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
