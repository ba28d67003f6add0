"""Every way a session ends stores its receipt (outcome, code, time) before the browser is
told where to go: completed, failed checks, declined consent, screened out; MTurk's preview
and hand-in; each trial's undo/reset history (SQLite and PostgreSQL, same tests)."""

import io

from sqlmodel import Session, select

from analysis.exports import read_export
from app.server.flow.plan import Phase
from app.server.storage.tables import Event, Participant, Submission, TrialResponse
from tests.server.flow import (
    ADMIN,
    fail_attention_checks,
    new_id,
    prediction_body,
    start,
    with_recruitment,
)
from tests.server.flow import Participant as Client

MTURK = {"workerId": "A1B2C3", "assignmentId": "3XYZ", "hitId": "H1"}


def stored(client, token: str) -> Participant:
    """The participant row behind a session token."""
    with Session(client.app.state.engine) as db:
        return db.exec(select(Participant).where(Participant.session_token == token)).one()


def rows_of(client, table, participant_id: int) -> list:
    """Every row of `table` that belongs to one participant."""
    with Session(client.app.state.engine) as db:
        return db.exec(select(table).where(table.participant_id == participant_id)).all()


def test_a_completed_session_stores_its_receipt_before_the_redirect(codes, client, small_study,
                                                                   bank):
    p = Client(client, small_study.study_id)
    p.start()
    p.pass_intro()
    done = p.finish(bank)
    assert done["phase"] == Phase.DONE
    assert done["step"] | {"message": ""} == {
        "outcome": "completed", "completion_code": codes["completed"], "message": "",
        "redirect_url": f"https://app.prolific.com/submissions/complete?cc={codes['completed']}",
        "mturk_submit": None}
    row = stored(client, p.token)
    assert (row.outcome, row.completion_code, row.completed) == (
        "completed", codes["completed"], True)
    assert row.ended_at is not None and row.completed_at is not None


def test_failing_two_attention_checks_ends_for_review_with_its_own_code(codes, client,
                                                                         small_study, bank):
    sid = small_study.study_id
    p = Client(client, sid)
    p.start()
    p.pass_intro()
    fail_attention_checks(p, bank)
    done = p.survey()["step"]
    row = stored(client, p.token)
    assert row.attention_failed == 2  # one check per world
    assert (done["outcome"], done["completion_code"]) == ("failed_checks", codes["failed_checks"])
    assert done["redirect_url"].endswith(f"cc={codes['failed_checks']}")
    assert "reviewed" in done["message"]
    assert (row.outcome, row.completion_code, row.completed) == (
        "failed_checks", codes["failed_checks"], True)
    endings = client.app.state.studies[sid].config.recruitment.endings
    with_recruitment(client, sid, endings=endings.model_copy(update={"min_failed": 3}))
    q = Client(client, sid)
    q.start()
    q.pass_intro()
    fail_attention_checks(q, bank)
    done = q.survey()["step"]  # 2 failed < min_failed 3, but the exclusion rule holds
    assert (done["outcome"], done["completion_code"]) == ("excluded", codes["excluded"])


def test_a_session_the_rules_exclude_never_gets_the_approve_code(codes, client, small_study,
                                                                  bank):
    sid = small_study.study_id
    hasty = Client(client, sid)
    hasty.start()
    hasty.pass_intro()
    done = hasty.finish(bank, duration_ms=1000)["step"]  # every trial too fast
    assert (done["outcome"], done["completion_code"]) == ("excluded", codes["excluded"])
    assert codes["excluded"] != codes["completed"] and "reviewed" in done["message"]
    careful = Client(client, sid)
    careful.start()
    careful.pass_intro()
    assert careful.finish(bank)["step"]["outcome"] == "completed"
    endings = client.app.state.studies[sid].config.recruitment.endings
    chosen = endings.excluded.model_copy(update={"completion_code": "C5TOMFAST"})
    with_recruitment(client, sid, endings=endings.model_copy(update={"excluded": chosen}))
    other = Client(client, sid)
    other.start()
    other.pass_intro()
    done = other.finish(bank, duration_ms=1000)["step"]
    assert (done["outcome"], done["completion_code"]) == ("excluded", "C5TOMFAST")
    r = client.get(f"/api/researcher/export/participants.csv?study_id={sid}", headers=ADMIN)
    sheet = read_export(io.StringIO(r.text), "participants").set_index("participant_id")
    assert sheet.loc[stored(client, hasty.token).public_id, "exclusion_reasons"] == "too_fast"
    assert sheet.loc[stored(client, careful.token).public_id, "excluded"] == False  # noqa: E712
    assert sheet["excluded"].dtype == bool


def test_declining_consent_ends_the_session_and_keeps_only_the_receipt(codes, client,
                                                                       small_study):
    sid = small_study.study_id
    p = Client(client, sid)
    params = {"PROLIFIC_PID": "ab" * 12, "STUDY_ID": "cd" * 12, "SESSION_ID": "first"}
    p.start(**params)
    event = {"submission_id": new_id(), "kind": "resize", "t_client_ms": 5, "data": {"w": 1,
                                                                                     "h": 2}}
    assert p.post("events", {"events": [event]}).status_code == 409  # nothing before consent
    r = p.post("decline", {"submission_id": new_id()})
    assert r.status_code == 200, r.text
    done = r.json()
    assert done["phase"] == Phase.DONE and done["step"]["outcome"] == "declined_consent"
    assert done["step"]["completion_code"] == codes["declined_consent"]
    assert "return" in done["step"]["message"]
    row = stored(client, p.token)
    assert (row.outcome, row.completed, row.counted, row.client) == (
        "declined_consent", False, False, {})
    assert [s.kind for s in rows_of(client, Submission, row.id)] == ["decline"]
    assert rows_of(client, Event, row.id) == []
    assert p.post("consent", {"submission_id": new_id(), "agree": True}).status_code == 409
    assert p.post("events", {"events": [dict(event, submission_id=new_id())]}).status_code == 409
    assert start(client, sid, **params).json()["session_token"] == p.token  # same link: resumes
    again = start(client, sid, **dict(params, SESSION_ID="second"))
    assert again.status_code == 409 and "already ended" in again.json()["detail"]
    progress = client.get(f"/api/researcher/summary?study_id={sid}", headers=ADMIN).json()
    target = client.app.state.studies[sid].config.target_sample_size  # the study's own
    assert progress["progress"] | {"world_orders": None} == {
        "target_sample_size": target, "started": 1, "completed": 0, "in_progress": 0,
        "awaiting_consent": 0, "ended_early": 1, "stale": 0, "outcomes": {"declined_consent": 1},
        "failed_attention_check": 0, "pilot_sessions": 0, "replaced_sessions": 0,
        "world_orders": None}


def test_screen_out_only_before_any_trial(codes, client, small_study, bank):
    sid = small_study.study_id
    p = Client(client, sid)
    p.start()
    assert p.post("consent", {"submission_id": new_id(), "agree": True}).status_code == 200
    bad = p.post("screen-out", {"submission_id": new_id(), "reason": "bored"})
    assert bad.status_code == 422 and "reason" in bad.text
    r = p.post("screen-out", {"submission_id": new_id(), "reason": "window_too_small"})
    assert r.status_code == 200, r.text
    assert (r.json()["step"]["outcome"], r.json()["step"]["completion_code"]) == (
        "screened_out", codes["screened_out"])
    row = stored(client, p.token)
    assert (row.outcome, row.counted) == ("screened_out", False)
    reason = [s.payload for s in rows_of(client, Submission, row.id) if s.kind == "screen_out"]
    assert reason == [{"reason": "window_too_small"}]
    late = Client(client, sid)
    late.start()
    late.pass_intro()
    late.answer_trial(bank)
    refused = late.post("screen-out", {"submission_id": new_id(), "reason": "touch_only"})
    assert refused.status_code == 409 and refused.json()["detail"].startswith("phase")


def test_undo_and_reset_history_is_stored_with_the_trial(client, small_study):
    p = Client(client, small_study.study_id)
    p.start()
    p.pass_intro()
    trial = p.state()["step"]
    body = prediction_body(trial)
    history = [{"action": "undo", "start_index": 0, "t_ms": 100.0},
               {"action": "reset", "start_index": 2, "t_ms": 2500.0}]
    for wrong, field in (([dict(history[0], start_index=9)], "history.0.start_index"),
                         ([history[1], history[0]], "history.1.t_ms"),
                         ([dict(history[0], action="redo")], "history")):
        r = p.post("predictions", dict(body, submission_id=new_id(), history=wrong))
        assert r.status_code == 422 and field in r.text, r.text
    assert p.post("predictions", dict(body, history=history)).status_code == 201
    row = stored(client, p.token)
    assert [t.history for t in rows_of(client, TrialResponse, row.id)] == [history]


def test_mturk_preview_starts_nothing_and_completion_posts_to_turk_submit_to(codes, client,
                                                                              small_study,
                                                                              bank):
    sid = small_study.study_id
    with_recruitment(client, sid, platform="mturk",
                     mturk_submit_hosts=["https://workersandbox.mturk.com"])
    page = client.get(f"/s/{sid}?assignmentId=ASSIGNMENT_ID_NOT_AVAILABLE&hitId=H1")
    assert page.status_code == 200 and "Accept the HIT" in page.text
    assert "<script" not in page.text
    assert start(client, sid, **dict(MTURK, turkSubmitTo="https://evil.example")).json()[
        "detail"].startswith("recruitment.turkSubmitTo")
    with Session(client.app.state.engine) as db:
        assert db.exec(select(Participant)).all() == []
    p = Client(client, sid)
    p.start(**dict(MTURK, turkSubmitTo="https://workersandbox.mturk.com/"))
    p.pass_intro()
    done = p.finish(bank)["step"]
    assert done["mturk_submit"] == {
        "action": "https://workersandbox.mturk.com/mturk/externalSubmit",
        "fields": {"assignmentId": "3XYZ", "outcome": "completed",
                   "completion_code": codes["completed"]}}


def test_endings_and_history_reach_the_exports(codes, client, small_study):
    import io

    import pandas as pd

    sid = small_study.study_id
    declined = Client(client, sid)
    public_id = declined.start()["participant_id"]
    declined.post("decline", {"submission_id": new_id()})
    p = Client(client, sid)
    p.start()
    p.pass_intro()
    body = prediction_body(p.state()["step"])
    body["history"] = [{"action": "reset", "start_index": 3, "t_ms": 900.0}]
    assert p.post("predictions", body).status_code == 201

    def export(what: str) -> pd.DataFrame:
        r = client.get(f"/api/researcher/export/{what}.csv?study_id={sid}", headers=ADMIN)
        assert r.status_code == 200, r.text
        return pd.read_csv(io.StringIO(r.text), keep_default_na=False)

    sheet = export("participants").set_index("participant_id")
    assert sheet.loc[public_id, ["outcome", "completion_code", "status"]].tolist() == [
        "declined_consent", codes["declined_consent"], "ended"]
    events = export("events")
    pressed = events[events["source"] == "trial_history"]
    assert pressed[["kind", "start_index", "t_trial_ms"]].values.tolist() == [["reset", 3, 900.0]]
