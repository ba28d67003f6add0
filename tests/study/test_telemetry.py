"""Telemetry is bounded: only the kinds the browser sends, each with its own small data."""

import itertools
import re

import pytest
from sqlalchemy import func, select

from app.study.tables import EVENT_DATA, Event
from app.study.tables import Participant as ParticipantRow
from tests.conftest import REPO, fresh_database
from tests.study.flow import Participant, new_id
from tests.study.test_api import at_first_trial, make_client

_db_counter = itertools.count()


@pytest.fixture(params=["sqlite", pytest.param("postgres", marks=pytest.mark.postgres)])
def client(request, small_study, tmp_path):
    """The app on a fresh database of each backend."""
    if request.param == "sqlite":
        url = f"sqlite:///{tmp_path / 'study.db'}"
    else:
        url = fresh_database(request.getfixturevalue("postgres_url"), f"tele{next(_db_counter)}")
    with make_client(small_study, url) as c:
        yield c


def event(kind: str = "resize", data: dict | None = None, **fields) -> dict:
    """One event as the browser posts it (a resize unless told)."""
    data = {"w": 1280, "h": 720} if data is None else data
    return {"submission_id": new_id(), "kind": kind, "t_client_ms": 1.0, "data": data} | fields


def batch(n: int) -> dict:
    """A request body of `n` fresh resize events."""
    return {"events": [event() for _ in range(n)]}


def stored_counts(client, p: Participant) -> int:
    """Event rows of this participant in the database."""
    row = ParticipantRow.__table__
    with client.app.state.engine.connect() as conn:
        pid = conn.execute(select(row.c.id).where(row.c.session_token == p.token)).scalar_one()
        return conn.execute(select(func.count()).select_from(Event.__table__)
                            .where(Event.__table__.c.participant_id == pid)).scalar_one()


def browser_event_kinds() -> set[str]:
    """Every kind the participant app passes to `telemetry.log(...)`."""
    kinds = set()
    for script in (REPO / "frontend" / "static" / "js").glob("*.js"):
        for call in re.findall(r"telemetry\.log\(([^,)]*)", script.read_text()):
            kinds |= set(re.findall(r'"(\w+)"', call))
    return kinds


def test_the_accepted_kinds_are_the_browsers_kinds():
    assert browser_event_kinds() == set(EVENT_DATA)


def test_every_kind_the_browser_sends_is_stored(client, small_study):
    p = at_first_trial(client, small_study.study_id)
    trial_id = p.state()["step"]["trial_id"]
    clip = {"trial_id": trial_id, "replays": 1}
    events = [event("visibility_hidden", {}), event("visibility_shown", {}), event("resize"),
              event("clip_finished", clip), event("replay", clip)]
    r = p.post("events", {"events": events})
    assert (r.status_code, r.json()) == (202, {"stored": 5})
    assert stored_counts(client, p) == 5


def test_an_unknown_kind_is_refused_naming_the_field(client, small_study):
    p = at_first_trial(client, small_study.study_id)
    r = p.post("events", {"events": [event(), event("keystrokes", {"key": "a"})]})
    assert r.status_code == 422
    assert r.json()["message"].startswith("events.1.kind: Input should be 'visibility_hidden'")
    assert stored_counts(client, p) == 0


@pytest.mark.parametrize(("kind", "data", "needle"), [
    ("clip_finished", {"trial_id": "x" * 5000, "replays": 0},
     "events.0.data.trial_id: String should have at most 64 characters"),
    ("resize", {"w": {"deeper": {"still": [1, 2, 3]}}, "h": 1},
     "events.0.data.w: Input should be a valid integer"),
    ("resize", {"w": 1, "h": 1, "note": "x" * 60_000},
     "events.0.data.note: Extra inputs are not permitted"),
    ("visibility_hidden", {"x": 1}, "events.0.data.x: Extra inputs are not permitted"),
    ("resize", {"w": -1, "h": 1}, "events.0.data.w: Input should be greater than or equal to 0"),
    ("replay", {"trial_id": "t"}, "events.0.data.replays: Field required"),
])
def test_data_that_does_not_fit_its_kind_is_refused(client, small_study, kind, data, needle):
    p = at_first_trial(client, small_study.study_id)
    r = p.post("events", {"events": [event(kind, data)]})
    assert r.status_code == 422 and needle in r.json()["message"], r.text
    assert stored_counts(client, p) == 0
