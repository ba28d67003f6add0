"""Phases are spelled once (app/server/flow/plan.py) and the participant page follows the server."""

import json
import re

from sqlmodel import Session, select

from app.server.flow.plan import BEFORE_TRIALS, Phase, dump_plan, parse_plan
from app.server.storage.tables import Participant
from tests.conftest import REPO
from tests.server.flow import at_first_trial, page_json, participant_scripts

APP_JS = REPO / "frontend" / "static" / "js" / "app.js"
# a phase compared with a literal, in either order, or a literal `case` label
PHASE_LITERAL = re.compile(r"""phase\s*[!=]==?\s*["'`]|["'`]\s*[!=]==?\s*[\w.]*phase\b"""
                           r"""|case\s+["'`]""")


def handler_keys(source: str) -> list[str]:
    """The phases app.js's PHASE_HANDLERS table has an entry for (its top-level keys)."""
    table = re.search(r"^const PHASE_HANDLERS = \{\n(.*?)^\};", source, re.M | re.S)
    assert table, "app.js: PHASE_HANDLERS table not found"
    return re.findall(r"^  (\w+): ", table.group(1), re.M)


def test_every_phase_has_exactly_one_handler_in_app_js():
    keys = handler_keys(APP_JS.read_text())
    assert sorted(keys) == sorted(Phase), "app.js PHASE_HANDLERS must match plan.Phase"
    assert len(keys) == len(set(keys))


def test_the_study_page_compares_no_phase_with_a_literal():
    found = [f"{name}: {line.strip()}" for name, source in participant_scripts().items()
             for line in source.splitlines() if PHASE_LITERAL.search(line)]
    assert found == [], "look phases up in app.js's handler table instead"


def test_the_study_page_embeds_the_phases(client, small_study):
    rules = page_json(client.get(f"/s/{small_study.study_id}").text, "page-rules")
    assert rules["phases"] == [phase.value for phase in Phase]
    assert rules["screen_out_phases"] == [phase.value for phase in BEFORE_TRIALS]


def test_a_stored_plan_reads_back_to_the_same_json(client, small_study):
    p = at_first_trial(client, small_study.study_id)
    with Session(client.app.state.engine) as db:
        stored = db.exec(select(Participant.plan)
                         .where(Participant.session_token == p.token)).one()
    steps = parse_plan(stored)
    assert [s.phase for s in steps][:2] == [Phase.CONSENT, Phase.INSTRUCTIONS]
    assert json.dumps(dump_plan(steps)) == json.dumps(stored)
