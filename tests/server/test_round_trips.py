"""Database round trips per route stay at or below the checked-in baseline (round_trips.json).

One participant goes through the whole flow (start, tab claims and heartbeats, consent,
instructions, part screens, practice and trials with draft saves, events, survey, tab
release, a resumed start), two more end early (a declined consent, a screen-out), on each
backend, and each route's most costly request is compared with the baseline. `pytest -s`
prints the table; TOMSTUDY_WRITE_ROUND_TRIPS=1 rewrites the baseline from this run (after a
change that lowers a count)."""

import json
import os
from pathlib import Path

from app.main import create_app
from app.server.flow.plan import TRIAL_PHASES
from tests.conftest import local_client
from tests.server.flow import Participant, new_id, prolific
from tests.server.round_trips import RouteCounter, format_table

BASELINE = Path(__file__).with_name("round_trips.json")
COMPARED = ("statements", "round_trips")
TAB = "roundtrip-tab-1"


def test_round_trips_per_route_stay_within_the_baseline(served_study, db_url, bank):
    backend = "postgresql" if db_url.startswith("postgresql") else "sqlite"
    now = whole_flow_round_trips(served_study, db_url, bank)
    stored = json.loads(BASELINE.read_text()) if BASELINE.exists() else {}
    baseline = stored.get(backend, {})
    print("\n" + format_table(backend, baseline, now))
    if os.environ.get("TOMSTUDY_WRITE_ROUND_TRIPS"):
        stored[backend] = {route: {k: row[k] for k in COMPARED} for route, row in now.items()}
        BASELINE.write_text(json.dumps(stored, indent=1, sort_keys=True) + "\n")
        return
    assert set(now) == set(baseline), (
        f"{BASELINE.name} ({backend}) names other routes than this run: "
        f"{sorted(set(now) ^ set(baseline))}")
    problems = [f"{route}: {kind} {'grew' if row[kind] > baseline[route][kind] else 'fell'} "
                f"from {baseline[route][kind]} to {row[kind]}"
                for route, row in now.items() for kind in COMPARED
                if row[kind] != baseline[route][kind]]
    if any(" fell " in problem for problem in problems):
        problems.append(f"a count that fell: lower the baseline with "
                        f"TOMSTUDY_WRITE_ROUND_TRIPS=1 pytest {Path(__file__).name}")
    assert not problems, "\n".join(problems)


def whole_flow_round_trips(study, db_url: str, bank: dict) -> dict[str, dict[str, int]]:
    """Each route's costliest request while one participant takes the whole study."""
    settings = study.settings(db_url, trust_client_clock=True)
    counter = RouteCounter(create_app(settings, [study.study_id]))
    with local_client(counter) as client:
        counter.listen(counter.app.state.engine)
        take_the_study(client, counter, study.study_id, bank)
    return counter.table(counter.app.state.engine.dialect.name)


def take_the_study(client, counter: RouteCounter, study_id: str, bank: dict) -> None:
    """Every participant route, as a browser calls them, through to the end."""
    recruitment = prolific(new_id())
    p = Participant(client, study_id)
    p.start(**recruitment)
    assert p.status == 201
    claim(p, opened=True)
    assert p.consent().status_code == 200
    claim(p, opened=True)  # the page reloaded: stored as an event from consent on
    assert p.post("instructions", {"submission_id": new_id()}).status_code == 200
    while p.pass_screens()["phase"] in TRIAL_PHASES:
        for seq in (1, 2):
            assert p.save_draft(clicks=seq, seq=seq).status_code == 200
        claim(p)
        send_events(p)
        p.answer_trial(bank)
    assert p.survey()["phase"] == "done"
    assert p.post("tab/release", {"tab_id": TAB}).status_code == 204
    counter.label = "POST /api/sessions (resume)"
    p.start(**recruitment)
    assert p.status == 200
    counter.label = None
    end_before_taking_part(client, study_id)


def end_before_taking_part(client, study_id: str) -> None:
    """One person declines consent, another's device is screened out at the instructions."""
    declines, screened = Participant(client, study_id), Participant(client, study_id)
    declines.start()
    assert declines.post("decline", {"submission_id": new_id()}).status_code == 200
    screened.start()
    assert screened.consent().status_code == 200
    r = screened.post("screen-out", {"submission_id": new_id(), "reason": "touch_only"})
    assert r.status_code == 200, r.text


def claim(p: Participant, opened: bool = False) -> None:
    """POST .../tab: the page loaded (`opened`) or its heartbeat."""
    r = p.post("tab", {"tab_id": TAB, "opened": opened, "t_client_ms": 10.0})
    assert r.status_code == 200, r.text


def send_events(p: Participant) -> None:
    """POST .../events: a batch of two, as the page sends them."""
    events = [{"submission_id": new_id(), "kind": kind, "t_client_ms": 50.0, "data": {}}
              for kind in ("visibility_hidden", "visibility_shown")]
    assert p.post("events", {"events": events}).status_code == 202
