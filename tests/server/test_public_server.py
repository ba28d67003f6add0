"""A public server fails closed: only the study's own traffic, opaque trials, server clocks,
balance kept exactly in the database (SQLite and PostgreSQL, same tests)."""

import io
import json
from datetime import timedelta

import pytest
from sqlalchemy import update
from sqlmodel import Session, select

from analysis.load import load_csv
from app.server.flow import balance
from app.server.flow.plan import TRIAL_PHASES
from app.server.flow.recruitment import preview_key
from app.server.storage.tables import BalanceCount, Participant, TrialResponse, utcnow
from tests.server.flow import (
    ADMIN,
    TOKEN,
    make_client,
    new_id,
    prediction_body,
    prolific,
    start,
    with_recruitment,
)
from tests.server.flow import Participant as Client

HEX = "0123456789abcdef01234567"


PROLIFIC_REFUSALS = {
    "no parameters": ({}, "recruitment.PROLIFIC_PID: missing"),
    "formula as id": ({"PROLIFIC_PID": '=HYPERLINK("http://x","y")', "STUDY_ID": HEX,
                       "SESSION_ID": "s"}, "recruitment.PROLIFIC_PID: must be 24 hex"),
    "no study id": ({"PROLIFIC_PID": HEX, "SESSION_ID": "s"}, "recruitment.STUDY_ID: missing"),
    "no session id": ({"PROLIFIC_PID": HEX, "STUDY_ID": HEX},
                      "recruitment.SESSION_ID: missing"),
    "MTurk ids on Prolific": ({"workerId": "A1", "assignmentId": "B", "hitId": "C"},
                              "recruitment.PROLIFIC_PID: missing"),
}


@pytest.mark.parametrize("case", PROLIFIC_REFUSALS)
def test_a_prolific_study_refuses_sessions_without_prolific_parameters(client, small_study,
                                                                       case):
    params, message = PROLIFIC_REFUSALS[case]
    r = start(client, small_study.study_id, **params)
    assert r.status_code == 403 and r.json()["detail"].startswith(message), r.text
    with Session(client.app.state.engine) as db:
        assert db.exec(select(Participant)).all() == []


def test_a_configured_prolific_study_id_and_the_other_platforms(client, small_study):
    sid = small_study.study_id
    with_recruitment(client, sid, prolific_study_id="5" * 24)
    r = start(client, sid, **prolific("x"))
    assert r.status_code == 403 and r.json()["detail"].startswith("recruitment.STUDY_ID")
    assert start(client, sid, **dict(prolific("x"), STUDY_ID="5" * 24)).status_code == 201
    with_recruitment(client, sid, platform="mturk")
    mturk = {"workerId": "A1B2C3", "assignmentId": "3XYZ", "hitId": "H1"}
    assert start(client, sid, **prolific("y")).json()["detail"].startswith(
        "recruitment.workerId: missing")
    preview = start(client, sid, **dict(mturk, assignmentId="ASSIGNMENT_ID_NOT_AVAILABLE"))
    assert preview.status_code == 403 and "accept the HIT" in preview.json()["detail"]
    assert start(client, sid, **mturk).status_code == 201
    with_recruitment(client, sid, platform="open")
    first, second = start(client, sid).json(), start(client, sid).json()
    assert first["session_token"] != second["session_token"]  # anonymous: a new session


def test_preview_sessions_are_pilots_that_never_count(client, small_study, bank):
    sid = small_study.study_id
    assert start(client, sid, preview="0" * 32).status_code == 403
    key = preview_key(TOKEN, sid)
    summary = client.get(f"/api/researcher/summary?study_id={sid}", headers=ADMIN).json()
    assert summary["preview_link"] == f"/s/{sid}?preview={key}"
    lab = Client(client, sid)
    lab.start(preview=key)
    assert lab.status == 201
    lab.pass_intro()
    lab.finish(bank)
    real = Client(client, sid)
    real.start()
    real.pass_intro()
    real.finish(bank)
    summary = client.get(f"/api/researcher/summary?study_id={sid}", headers=ADMIN).json()
    progress = summary["progress"]
    assert (progress["started"], progress["completed"], progress["pilot_sessions"]) == (1, 1, 1)
    exclusions = summary["alignment_error"]["exclusions"]
    assert exclusions["excluded_pilot"] == 1 and exclusions["participants_kept"] == 1
    ctx = client.app.state.studies[sid]
    with Session(client.app.state.engine) as db:
        pilot = db.exec(select(Participant).where(Participant.pilot)).one()
        assert pilot.recruitment == "pilot" and not pilot.counted
        assert balance.recount(db, ctx) == nonzero(balance.read_counts(db, sid))


def nonzero(counts: dict) -> dict:
    return {k: v for k, v in counts.items() if v}


def test_a_new_attempt_replaces_a_stale_session_and_keeps_its_rows(client, small_study):
    sid = small_study.study_id
    params = prolific("comes-back")
    old = Client(client, sid)
    old.start(**params)
    old.pass_intro()
    old.answer_trial()
    engine = client.app.state.engine
    with Session(engine) as db:  # the first attempt was abandoned long ago
        db.exec(update(Participant).where(Participant.session_token == old.token)
                .values(updated_at=utcnow() - timedelta(days=1)))
        db.commit()
    new = Client(client, sid)
    body = new.start(**dict(params, SESSION_ID="second-attempt"))
    assert new.status == 201 and not body["resumed"] and new.token != old.token
    assert new.consent().status_code == 200  # the new attempt counts from its consent
    again = Client(client, sid)
    again.start(**params)  # the old attempt's key no longer opens anything
    assert again.status == 409
    ctx = client.app.state.studies[sid]
    with Session(engine) as db:
        rows = db.exec(select(Participant).order_by(Participant.id)).all()
        assert [r.replaced_at is not None for r in rows] == [True, False]
        assert [r.counted for r in rows] == [False, True]
        assert len(db.exec(select(TrialResponse)).all()) == 1  # the old answer is kept
        assert balance.recount(db, ctx) == nonzero(balance.read_counts(db, sid))


def test_the_browser_cannot_tell_which_trial_is_the_attention_check(client, small_study, bank):
    sid = small_study.study_id
    refs = []
    for name in ("a", "b"):
        p = Client(client, sid)
        p.start(**prolific(name))
        p.pass_intro()
        seen = []
        while (state := p.state())["phase"] in TRIAL_PHASES:
            raw = p.get("state").text
            assert "attention" not in raw and "clip_sha256" not in raw
            seen.append(state["step"]["trial_id"])
            p.answer_trial(bank)
        refs.append(seen)
        assert not set(seen) & set(bank)
    assert not set(refs[0]) & set(refs[1])  # per-session ids: nothing to compare across


def test_trial_durations_come_from_both_clocks(small_study, db_url):
    with make_client(small_study, db_url, trust_client_clock=False) as c:
        p = Client(c, small_study.study_id)
        p.start()
        trial = p.pass_intro()["step"]
        body = prediction_body(trial, duration_ms=60_000)  # the client claims a minute
        for name, change, field in (
                ("click before shown", (0, 0, -5.0), "click_times_ms.0.0"),
                ("click after submit", (1, 2, 61_000.0), "click_times_ms.1.2")):
            bad = json.loads(json.dumps(body))
            i, j, value = change
            bad["click_times_ms"][i][j] = value
            bad["submission_id"] = new_id()
            r = p.post("predictions", bad)
            assert r.status_code == 422 and r.json()["detail"].startswith(field), name
        absurd = dict(body, submission_id=new_id(), submitted_at_ms=1000.0 + 7 * 3600e3)
        r = p.post("predictions", absurd)
        assert r.status_code == 422 and r.json()["detail"].startswith("submitted_at_ms")
        assert p.post("predictions", body).status_code == 201
        with Session(c.app.state.engine) as db:
            row = db.exec(select(TrialResponse)).one()
    assert row.client_duration_ms == 60_000
    assert row.server_duration_ms < 60_000 and row.duration_ms == row.server_duration_ms


def test_a_reused_submission_id_must_carry_the_same_request(client, small_study):
    p = Client(client, small_study.study_id)
    p.start()
    consent = {"submission_id": new_id(), "agree": True}
    assert p.post("consent", consent).status_code == 200
    assert p.post("consent", consent).status_code == 200  # a true retry
    r = p.post("instructions", {"submission_id": consent["submission_id"]})
    assert r.status_code == 422 and r.json()["detail"].startswith("submission_id:")
    assert p.post("instructions", {"submission_id": new_id()}).status_code == 200
    trial = p.pass_screens()["step"]
    body = prediction_body(trial)
    assert p.post("predictions", body).status_code == 201
    changed = dict(body, points=prediction_body(trial)["points"][::-1])
    r = p.post("predictions", changed)
    assert r.status_code == 422 and "same body" in r.json()["detail"]


def test_balance_counts_match_the_sessions_they_summarise(client, small_study, bank):
    sid = small_study.study_id
    ctx = client.app.state.studies[sid]
    people = []
    for _ in range(6):
        p = Client(client, sid)
        p.start()
        p.pass_intro()
        people.append(p)
    people[0].finish(bank)
    people[1].finish(bank, duration_ms=1000)  # too fast: excluded, stops counting
    people[2].finish(None)  # fails the attention checks
    engine = client.app.state.engine
    with Session(engine) as db:  # one running session goes stale
        db.exec(update(Participant).where(Participant.session_token == people[3].token)
                .values(updated_at=utcnow() - timedelta(days=1)))
        db.commit()
    assert balance.release_stale_batch(engine, ctx) == 1  # what each worker's sweep runs
    # a start after the sweep sees the released order (one before it would see the stale
    # session's order as held, and a tie broken at random could leave 3 to 1)
    Client(client, sid).start()
    with Session(engine) as db:
        rows = {p.session_token: p for p in db.exec(select(Participant))}
        careless = rows[people[2].token].attention_failed == 0  # straight clicks may pass
        assert [rows[p.token].counted for p in people] == [True, False, careless, False, True,
                                                            True]
        counts = balance.read_counts(db, sid)
        assert balance.recount(db, ctx) == nonzero(counts)
        assert min(counts.values()) >= 0
        orders = [v for k, v in counts.items() if k.startswith(balance.ORDER)]
        assert max(orders) - min(orders) <= 1
        assert db.exec(select(BalanceCount)).all()  # rows exist for every order and trial


def test_a_replaced_attempt_refuses_every_write_and_the_exports_mark_it(client, small_study,
                                                                        bank):
    sid = small_study.study_id
    params = prolific("two-tabs")
    old = Client(client, sid)
    old.start(**params)
    old.pass_intro()
    old.answer_trial(bank)
    with Session(client.app.state.engine) as db:  # the first tab was left for hours
        db.exec(update(Participant).where(Participant.session_token == old.token)
                .values(updated_at=utcnow() - timedelta(days=1)))
        db.commit()
    new = Client(client, sid)
    new.start(**dict(params, SESSION_ID="second-attempt"))
    new.pass_intro()
    trial = old.get("state")
    writes = {what: old.post(what, body) for what, body in (
        ("predictions", prediction_body(new.state()["step"])),
        ("survey", {"submission_id": new_id(), "answers": {}}),
        ("events", {"events": [{"submission_id": new_id(), "kind": "visibility_hidden",
                                "t_client_ms": 1.0, "data": {}}]}))}
    assert trial.status_code == 410 and {k: r.status_code for k, r in writes.items()} == {
        "predictions": 410, "survey": 410, "events": 410}
    assert "continues in the other tab or attempt" in trial.json()["detail"]
    new.finish(bank)
    export = client.get(f"/api/researcher/export/predictions.csv?study_id={sid}", headers=ADMIN)
    frame = load_csv(io.StringIO(export.text))
    replaced = frame.groupby("participant_id")["replaced"].first()
    assert sorted(replaced.tolist()) == [False, True]  # the old attempt's one trial, marked
    assert frame[frame["replaced"]]["trial_id"].nunique() == 1


def test_platform_ids_are_one_person_in_any_case(client, small_study, bank):
    sid = small_study.study_id
    lower = {"PROLIFIC_PID": "abcdef0123456789abcdef01", "STUDY_ID": HEX, "SESSION_ID": "s1"}
    first = Client(client, sid)
    first.start(**lower)
    first.pass_intro()
    first.finish(bank)
    upper = Client(client, sid)
    upper.start(**dict(lower, PROLIFIC_PID=lower["PROLIFIC_PID"].upper(), SESSION_ID="s2"))
    assert upper.status == 409  # the same person, already completed
    with_recruitment(client, sid, platform="mturk")
    worker = {"workerId": "a1b2c3d4", "assignmentId": "ASG1", "hitId": "H1"}
    Client(client, sid).start(**worker)
    again = Client(client, sid)
    again.start(**dict(worker, workerId="A1B2C3D4"))
    assert again.status == 200  # the same worker and assignment: resumed
    with Session(client.app.state.engine) as db:
        ids = sorted(p.external_id for p in db.exec(select(Participant)))
    assert ids == ["A1B2C3D4", "abcdef0123456789abcdef01"]


def test_the_device_is_stored_only_after_consent(client, small_study):
    p = Client(client, small_study.study_id)
    r = client.post("/api/sessions", json={"study_id": small_study.study_id,
                                           "recruitment": prolific("ua"), "client": {
                                               "user_agent": "Mozilla/5.0"}})
    assert r.status_code == 422 and "client" in r.json()["message"]  # not taken at start
    p.start()
    with Session(client.app.state.engine) as db:
        assert db.exec(select(Participant)).one().client == {}
    p.consent()
    with Session(client.app.state.engine) as db:
        assert db.exec(select(Participant)).one().client["user_agent"] == "pytest"
