"""Telemetry is bounded: known kinds with small data, a cap per session, nothing after done."""

import io
import re
from concurrent.futures import ThreadPoolExecutor

import pytest
from sqlalchemy import func, select
from sqlmodel import Session

from analysis.exports import read_export
from app.server.flow import telemetry
from app.server.flow.plan import Phase
from app.server.flow.sessions import participant_by_token
from app.server.schemas import EVENT_DATA, EventsCreate
from app.server.storage.tables import Event
from app.server.storage.tables import Participant as ParticipantRow
from app.study.errors import Refused
from tests.conftest import REPO
from tests.server.flow import ADMIN, DEVICE, Participant, at_first_trial, new_id

CAP = telemetry.MAX_EVENTS_PER_SESSION


def event(kind: str = "resize", data: dict | None = None, **fields) -> dict:
    """One event as the browser posts it (a resize unless told)."""
    data = {"w": 1280, "h": 720} if data is None else data
    return {"submission_id": new_id(), "kind": kind, "t_client_ms": 1.0, "data": data} | fields


def batch(n: int) -> dict:
    """A request body of `n` fresh resize events."""
    return {"events": [event() for _ in range(n)]}


def stored_counts(client, p: Participant) -> tuple[int, int]:
    """(event rows in the database, the participant's events_stored counter)."""
    row = ParticipantRow.__table__
    with client.app.state.engine.connect() as conn:
        pid, counter = conn.execute(select(row.c.id, row.c.events_stored).where(
            row.c.session_token == p.token)).one()
        rows = conn.execute(select(func.count()).select_from(Event.__table__)
                            .where(Event.__table__.c.participant_id == pid)).scalar_one()
    return rows, counter


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
    assert stored_counts(client, p) == (5, 5)


def test_an_unknown_kind_is_refused_naming_the_field(client, small_study):
    p = at_first_trial(client, small_study.study_id)
    r = p.post("events", {"events": [event(), event("keystrokes", {"key": "a"})]})
    assert r.status_code == 422
    assert r.json()["message"].startswith("events.1.kind: Input should be 'visibility_hidden'")
    assert stored_counts(client, p) == (0, 0)


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
    assert stored_counts(client, p) == (0, 0)


def test_retries_are_stored_once_and_stored_counts_the_new_rows(client, small_study):
    p = at_first_trial(client, small_study.study_id)
    first = [event() for _ in range(3)]
    assert p.post("events", {"events": first}).json() == {"stored": 3}
    assert p.post("events", {"events": first}).json() == {"stored": 0}
    again_plus_two = [*first, event(), event()]
    assert p.post("events", {"events": again_plus_two}).json() == {"stored": 2}
    twice_in_one = event()
    assert p.post("events", {"events": [twice_in_one, twice_in_one]}).json() == {"stored": 1}
    assert stored_counts(client, p) == (6, 6)


def test_the_cap_refuses_a_batch_that_would_pass_it_whole(client, small_study):
    p = at_first_trial(client, small_study.study_id)
    for _ in range((CAP - 50) // 100):
        assert p.post("events", batch(100)).status_code == 202
    assert p.post("events", batch((CAP - 50) % 100)).status_code == 202
    assert stored_counts(client, p) == (CAP - 50, CAP - 50)
    r = p.post("events", batch(51))
    assert r.status_code == 422
    assert r.json()["detail"] == f"events: at most {CAP} events per session"
    assert stored_counts(client, p) == (CAP - 50, CAP - 50)  # nothing of that batch
    last = batch(50)
    assert p.post("events", last).json() == {"stored": 50}
    assert p.post("events", batch(1)).status_code == 422
    assert p.post("events", last).json() == {"stored": 0}  # a retry still answers
    assert stored_counts(client, p) == (CAP, CAP)


def test_concurrent_batches_cannot_pass_the_cap_together(client, small_study):
    p = at_first_trial(client, small_study.study_id)
    engine = client.app.state.engine

    def post(body: dict) -> int:
        with Session(engine, expire_on_commit=False) as db:
            participant = participant_by_token(db, p.token)
            db.commit()
            try:
                return telemetry.record_events(db, participant, EventsCreate(**body))
            except Refused as refused:
                assert refused.status == 422
                return 0

    batches = [batch(100) for _ in range(CAP // 100 + 6)]
    with ThreadPoolExecutor(8) as pool:
        stored = list(pool.map(post, batches))
    assert sorted(stored) == [0] * 6 + [100] * (CAP // 100)
    assert stored_counts(client, p) == (CAP, CAP)


def test_events_after_the_session_is_done_are_refused(client, small_study):
    p = at_first_trial(client, small_study.study_id)
    assert p.post("events", batch(2)).status_code == 202
    assert p.finish()["phase"] == Phase.DONE
    r = p.post("events", batch(1))
    assert (r.status_code, r.json()["detail"]) == (
        409, "phase: the session is complete; no more events")
    assert stored_counts(client, p) == (2, 2)


def test_nothing_is_stored_before_consent(client, small_study):
    p = Participant(client, small_study.study_id)
    p.start()
    r = p.post("events", {"events": [event(), event("visibility_hidden", {})]})
    assert (r.status_code, r.json()["detail"]) == (409, telemetry.BEFORE_CONSENT)
    opened = p.post("tab", {"tab_id": "tab-aaaaaaaa", "opened": True, "t_client_ms": 1.0})
    assert opened.status_code == 200  # the page may open; the server keeps no event of it
    assert stored_counts(client, p) == (0, 0)
    assert participant_row(client, p).client == {}
    assert p.consent().status_code == 200
    assert p.post("events", batch(1)).status_code == 202
    assert p.post("tab", {"tab_id": "tab-aaaaaaaa", "opened": True,
                          "t_client_ms": 2.0}).status_code == 200  # a reload after consent
    assert stored_counts(client, p) == (2, 2)


def test_the_consented_device_is_in_the_participants_export(client, small_study):
    consented = Participant(client, small_study.study_id)
    consented.start()
    device = DEVICE | {"reduced_motion": True}
    assert consented.post("consent", {"submission_id": new_id(), "agree": True,
                                      "client": device}).status_code == 200
    Participant(client, small_study.study_id).start()  # opened the link, never consented
    r = client.get(f"/api/researcher/export/participants.csv?study_id={small_study.study_id}",
                   headers=ADMIN)
    sheet = read_export(io.StringIO(r.text), "participants").set_index("participant_id")
    rows = sheet[list(DEVICE) + ["reduced_motion"]].to_dict("records")
    assert rows[0] == device
    assert rows[1] == {"screen_w": -1, "screen_h": -1, "touch_only": False,
                       "user_agent": "", "reduced_motion": False}


def participant_row(client, p: Participant) -> ParticipantRow:
    """The session's database row."""
    with Session(client.app.state.engine) as db:
        return participant_by_token(db, p.token)
