"""A session takes a place in the study (live cap, "full", balance, progress) from consent
on: made-up Prolific ids that never consent hold nothing, and free their id after
consent_timeout_min (app/server/flow/places.py)."""

import dataclasses
import secrets
from collections import Counter
from datetime import timedelta

from sqlalchemy import update
from sqlmodel import Session, select

from app.server.flow import balance
from app.server.flow.recruitment import preview_key
from app.server.storage.tables import Participant, utcnow
from tests.server.flow import TOKEN, new_id, with_recruitment
from tests.server.flow import Participant as Client

FORGED_STUDY_ID = "f" * 24


def forged(client, study_id: str) -> int:
    """One start with a made-up 24-hex PROLIFIC_PID that never consents; the status."""
    pid = secrets.token_hex(12)
    return client.post("/api/sessions", json={"study_id": study_id, "recruitment": {
        "PROLIFIC_PID": pid, "STUDY_ID": FORGED_STUDY_ID, "SESSION_ID": pid[:8]}}).status_code


def with_config(client, study_id: str, **changes) -> None:
    """Serve `study_id` with these top-level config keys changed."""
    ctx = client.app.state.studies[study_id]
    config = ctx.config.model_copy(update=changes)
    client.app.state.studies[study_id] = dataclasses.replace(ctx, config=config)


def rows(client) -> list[Participant]:
    with Session(client.app.state.engine) as db:
        return list(db.exec(select(Participant).order_by(Participant.id)))


def summary(client, study_id: str) -> dict:
    r = client.get(f"/api/researcher/summary?study_id={study_id}",
                   headers={"Authorization": f"Bearer {TOKEN}"})
    assert r.status_code == 200, r.text
    return r.json()["progress"]


def test_a_session_counts_from_consent_on(client, small_study):
    sid = small_study.study_id
    ctx = client.app.state.studies[sid]
    p = Client(client, sid)
    p.start()
    assert [r.counted for r in rows(client)] == [False]
    with Session(client.app.state.engine) as db:
        assert not any(balance.read_counts(db, sid).values())
    progress = summary(client, sid)
    assert (progress["awaiting_consent"], progress["in_progress"]) == (1, 0)
    assert p.consent().status_code == 200
    assert [r.counted for r in rows(client)] == [True]
    with Session(client.app.state.engine) as db:
        counts = {k: v for k, v in balance.read_counts(db, sid).items() if v}
        assert counts == balance.recount(db, ctx)
    progress = summary(client, sid)
    assert (progress["awaiting_consent"], progress["in_progress"]) == (0, 1)


def test_forged_starts_leave_the_cap_to_real_participants(client, small_study):
    """The issue's attack: 220 made-up ids filled the live cap of 220 (10 x 22)."""
    sid = small_study.study_id
    with_config(client, sid, target_sample_size=22, max_live_sessions_per_target=10)
    assert [forged(client, sid) for _ in range(220)] == [201] * 220
    assert sum(r.counted for r in rows(client)) == 0
    real = Client(client, sid)
    real.start()
    assert real.status == 201 and real.consent().status_code == 200


def test_forged_starts_do_not_make_the_study_full(client, small_study):
    sid = small_study.study_id
    with_recruitment(client, sid, max_counted_sessions=22)
    assert [forged(client, sid) for _ in range(22)] == [201] * 22
    real = Client(client, sid)
    real.start()
    assert real.status == 201 and real.consent().status_code == 200


def test_a_study_fills_up_with_consents_and_says_so_at_consent(client, small_study):
    sid = small_study.study_id
    with_recruitment(client, sid, max_counted_sessions=2)
    people = [Client(client, sid) for _ in range(3)]
    for p in people:
        p.start()
    assert [p.status for p in people] == [201] * 3  # none holds a place yet
    assert [people[0].consent().status_code, people[1].consent().status_code] == [200, 200]
    late = people[2].consent()  # started before the study filled up
    assert late.status_code == 409 and late.json()["notice"]["title"] == "This study is full"
    assert people[2].state()["phase"] == "consent"  # refused, nothing stored
    newcomer = Client(client, sid)
    newcomer.start()
    assert newcomer.status == 409
    lab = Client(client, sid)
    lab.start(preview=preview_key(TOKEN, sid))
    assert lab.consent().status_code == 200  # a pilot never counts, so is never refused
    assert sum(r.counted for r in rows(client)) == 2


def test_an_unconsented_session_frees_its_id_after_the_consent_timeout(client, small_study):
    sid = small_study.study_id
    params = {"PROLIFIC_PID": "a" * 24, "STUDY_ID": FORGED_STUDY_ID, "SESSION_ID": "first"}
    first = Client(client, sid)
    first.start(**params)
    again = Client(client, sid)
    again.start(**params | {"SESSION_ID": "second"})
    assert again.status == 409  # another attempt in progress: within the consent timeout
    started_before(client, first.token, minutes=11)  # past the default 10
    again.start(**params | {"SESSION_ID": "second"})
    assert again.status == 201
    assert [r.replaced_at is not None for r in rows(client)] == [True, False]
    assert again.consent().status_code == 200


def test_a_consented_session_keeps_its_id_past_the_consent_timeout(client, small_study):
    sid = small_study.study_id
    params = {"PROLIFIC_PID": "b" * 24, "STUDY_ID": FORGED_STUDY_ID, "SESSION_ID": "first"}
    first = Client(client, sid)
    first.start(**params)
    assert first.consent().status_code == 200
    started_before(client, first.token, minutes=30)
    again = Client(client, sid)
    again.start(**params | {"SESSION_ID": "second"})
    assert again.status == 409  # consented: held until in_progress_timeout_min


def test_a_slow_reader_may_still_consent_after_the_timeout(client, small_study):
    sid = small_study.study_id
    p = Client(client, sid)
    p.start()
    started_before(client, p.token, minutes=11)
    assert summary(client, sid)["stale"] == 1
    assert p.consent().status_code == 200  # nobody took the id over: the session goes on
    assert [r.counted for r in rows(client)] == [True]


def test_sessions_started_together_are_balanced_at_consent(client, small_study):
    """Plans are given at consent from the counts then: four people who all started before
    anyone consented still get each world order twice."""
    sid = small_study.study_id
    people = [Client(client, sid) for _ in range(4)]
    for p in people:
        p.start()
    for p in people:
        assert p.consent().status_code == 200
    orders = Counter(r.world_order for r in rows(client))
    assert sorted(orders.values()) == [2, 2]
    assert people[0].post("instructions", {"submission_id": new_id()}).status_code == 200


def started_before(client, token: str, minutes: float) -> None:
    """Make a session look started (and last written) `minutes` ago."""
    moment = utcnow() - timedelta(minutes=minutes)
    with Session(client.app.state.engine) as db:
        db.exec(update(Participant).where(Participant.session_token == token)
                .values(created_at=moment, updated_at=moment))
        db.commit()
