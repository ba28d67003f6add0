"""Withdrawal deletes every row of one participant, in every table, and nothing else."""

import json
from datetime import timedelta

import pytest
from sqlalchemy import func, select, update
from sqlmodel import Session
from typer.testing import CliRunner

from app.cli import cli
from app.main import create_app
from app.researcher.withdrawal import id_hash
from app.server.flow import balance
from app.server.flow.plan import Phase
from app.server.flow.recruitment import preview_key
from app.server.storage.tables import (
    Event,
    Participant,
    PredictionRow,
    Submission,
    TrialDraft,
    TrialResponse,
    WithdrawalAudit,
    utcnow,
)
from app.settings import Settings, get_settings
from tests.server.flow import (
    ADMIN,
    TOKEN,
    at_first_trial,
    make_client,
    new_id,
    prolific,
    with_recruitment,
)
from tests.server.flow import Participant as Driver

TABLES = (Participant, Submission, TrialResponse, PredictionRow, Event, TrialDraft)
LEAVER = prolific("leaver")
STAYER = prolific("stayer")


def counts(client, external_id: str | None = None) -> dict[str, int]:
    """Rows per table: of one external id's sessions, or of all."""
    with client.app.state.engine.connect() as conn:
        out = {}
        for table in TABLES:
            query = select(func.count()).select_from(table)
            if external_id is not None:
                ids = select(Participant.id).where(Participant.external_id == external_id)
                key = Participant.id if table is Participant else table.participant_id
                query = query.where(key.in_(ids))
            out[table.__tablename__] = conn.execute(query).scalar_one()
        return out


def post_events(p: Driver, n: int) -> None:
    events = [{"submission_id": new_id(), "kind": "resize", "t_client_ms": float(i),
               "data": {"w": 800, "h": 600}} for i in range(n)]
    assert p.post("events", {"events": events}).status_code == 202


@pytest.fixture
def leaver_and_stayer(client, small_study, bank):
    """The leaver: a stale first attempt (replaced) and a completed second one; the
    stayer: a session in progress. Returns the study context."""
    sid = small_study.study_id
    first = at_first_trial(client, sid, **LEAVER)
    first.answer_trial(bank)
    assert first.save_draft().status_code == 200  # clicks in progress on its next trial
    post_events(first, 2)
    with client.app.state.engine.begin() as conn:  # the first attempt goes stale
        conn.execute(update(Participant.__table__)
                     .where(Participant.external_id == LEAVER["PROLIFIC_PID"])
                     .values(updated_at=utcnow() - timedelta(days=1)))
    second = at_first_trial(client, sid, **(LEAVER | {"SESSION_ID": "second-attempt"}))
    post_events(second, 3)
    second.finish(bank)
    stayer = at_first_trial(client, sid, **STAYER)
    stayer.answer_trial(bank)
    post_events(stayer, 1)
    return client.app.state.studies[sid]


def balance_is_exact(client, ctx) -> dict[str, int]:
    """The stored balance counts, after checking them against the counted sessions."""
    with Session(client.app.state.engine) as db:
        stored = {k: v for k, v in balance.read_counts(db, ctx.study_id).items() if v}
        assert stored == balance.recount(db, ctx)
    return stored


def test_withdrawal_deletes_every_row_of_the_participant_only(client, small_study,
                                                              leaver_and_stayer):
    sid = small_study.study_id
    ext = LEAVER["PROLIFIC_PID"]
    before, mine = counts(client), counts(client, ext)
    stayer = counts(client, STAYER["PROLIFIC_PID"])
    assert mine["participant"] == 2 and all(mine.values())  # both attempts, every table
    held = balance_is_exact(client, leaver_and_stayer)
    r = client.post("/api/researcher/withdrawals", json={"study_id": sid, "external_id": ext},
                    headers=ADMIN)
    assert r.status_code == 201, r.text
    line = r.json()
    after = counts(client)
    assert line["row_counts"] == mine == {t: before[t] - after[t] for t in before}
    assert counts(client, ext) == dict.fromkeys(mine, 0)
    assert counts(client, STAYER["PROLIFIC_PID"]) == stayer
    assert ext not in json.dumps(line) and line["via"] == "api"
    assert line["id_sha256"] == id_hash(line["salt"], ext) and len(line["salt"]) == 32
    assert ext not in r.text
    released = balance_is_exact(client, leaver_and_stayer)
    assert sum(released.values()) < sum(held.values())  # the completed attempt was counted
    listed = client.get(f"/api/researcher/withdrawals/audit?study_id={sid}", headers=ADMIN)
    backend = client.app.state.engine.dialect.name
    assert line.pop("storage").startswith({"sqlite": "sqlite: deleted rows overwritten",
                                           "postgresql": "postgresql: deleted rows stay"}[backend])
    assert line.pop("archives") == []  # the answer's, not the audit row's: no archive holds them
    assert listed.json() == [line]
    with Session(client.app.state.engine) as db:
        stored = db.execute(select(WithdrawalAudit)).scalars().one()
        assert ext not in json.dumps(stored.model_dump(mode="json"))


def test_an_unknown_id_is_a_404_naming_the_field(client, small_study, leaver_and_stayer):
    before = counts(client)
    r = client.post("/api/researcher/withdrawals", headers=ADMIN,
                    json={"study_id": small_study.study_id, "external_id": "nobody"})
    assert r.status_code == 404 and r.json()["detail"].startswith("external_id:")
    assert "nobody" not in r.text and counts(client) == before
    r = client.post("/api/researcher/withdrawals", headers=ADMIN,
                    json={"study_id": "nope", "external_id": "nobody"})
    assert r.status_code == 404 and r.json()["detail"].startswith("study_id:")
    with Session(client.app.state.engine) as db:
        assert db.execute(select(func.count()).select_from(WithdrawalAudit)).scalar_one() == 0


def test_a_withdrawn_id_may_start_again_as_a_new_person(client, small_study, leaver_and_stayer,
                                                        bank):
    sid = small_study.study_id
    ext = LEAVER["PROLIFIC_PID"]
    client.post("/api/researcher/withdrawals", json={"study_id": sid, "external_id": ext},
                headers=ADMIN)
    again = Driver(client, sid)
    body = again.start(**LEAVER)
    assert again.status == 201 and body["resumed"] is False  # not the completed one: a 409 before
    assert again.state()["phase"] == Phase.CONSENT
    assert counts(client, ext) == {"participant": 1, "submission": 0, "trialresponse": 0,
                                   "predictionrow": 0, "event": 0, "trialdraft": 0}
    balance_is_exact(client, leaver_and_stayer)


def test_tomstudy_withdraw(client, small_study, leaver_and_stayer, db_url, monkeypatch):
    for key, value in small_study.env(db_url).items():
        monkeypatch.setenv(key, value)
    get_settings.cache_clear()
    try:
        runner = CliRunner()
        sid, ext = small_study.study_id, STAYER["PROLIFIC_PID"]
        unknown = runner.invoke(cli, ["withdraw", "--study", sid, "--external-id", "nobody"])
        assert unknown.exit_code == 1 and "--external-id: no session" in unknown.output
        done = runner.invoke(cli, ["withdraw", "--study", sid, "--external-id", ext])
        assert done.exit_code == 0, done.output
    finally:
        get_settings.cache_clear()
    line = json.loads(done.stdout)
    assert line["via"] == "cli" and ext not in done.stdout
    assert line["row_counts"] == {"predictionrow": 15, "trialresponse": 1, "event": 1,
                                  "submission": 4, "trialdraft": 0, "participant": 1}
    assert counts(client, ext)["participant"] == 0
    balance_is_exact(client, leaver_and_stayer)


def test_the_schema_declares_what_the_new_routes_answer():
    spec = create_app(Settings(production=False, admin_token="test-token")).openapi()
    declared = {f"{method.upper()} {path}": sorted(int(s) for s in op["responses"])
                for path, ops in spec["paths"].items() for method, op in ops.items()}
    assert declared["POST /api/researcher/withdrawals"] == [
        201, 400, 401, 403, 404, 413, 422, 429, 503]
    assert declared["GET /api/researcher/withdrawals/audit"] == [
        200, 401, 403, 404, 422, 429, 503]
    assert declared["GET /api/researcher/export/{what}.csv"] == [
        200, 401, 403, 404, 422, 429, 503]


def test_open_and_pilot_sessions_are_withdrawn_by_their_public_id(client, small_study,
                                                                  leaver_and_stayer):
    sid = small_study.study_id
    lab = Driver(client, sid)
    lab.start(preview=preview_key(TOKEN, sid))
    lab.pass_intro()
    with_recruitment(client, sid, platform="open")
    visitor = Driver(client, sid)
    visitor.start()
    visitor.pass_intro()
    before = counts(client)
    for p in (lab, visitor):
        public_id = public_id_of(client, p.token)
        r = client.post("/api/researcher/withdrawals", headers=ADMIN,
                        json={"study_id": sid, "participant_id": public_id})
        assert r.status_code == 201, r.text
        line = r.json()
        assert line["id_kind"] == "participant_id"
        assert line["id_sha256"] == id_hash(line["salt"], public_id)
        assert p.get("state").status_code == 404
    assert counts(client)["participant"] == before["participant"] - 2
    both = client.post("/api/researcher/withdrawals", headers=ADMIN, json={
        "study_id": sid, "external_id": "x", "participant_id": "y"})
    assert both.status_code == 422 and "participant_id" in both.json()["message"]


def test_any_spelling_of_a_platform_id_withdraws_the_person(client, small_study,
                                                            leaver_and_stayer):
    sid, ext = small_study.study_id, LEAVER["PROLIFIC_PID"]
    r = client.post("/api/researcher/withdrawals", headers=ADMIN,
                    json={"study_id": sid, "external_id": ext.upper()})
    assert r.status_code == 201 and r.json()["row_counts"]["participant"] == 2
    assert r.json()["id_sha256"] == id_hash(r.json()["salt"], ext)  # the id as normalised


def test_a_withdrawn_id_leaves_the_sqlite_files(small_study, tmp_path, bank):
    """No copy of the withdrawn id stays in study.db or its write-ahead log: deleted rows
    are overwritten (secure_delete) and the log is checkpointed and truncated."""
    db_path = tmp_path / "study.db"
    marker = "ee" * 12  # a PROLIFIC_PID that is easy to find in the raw bytes
    with make_client(small_study, f"sqlite:///{db_path}") as client:
        sid = small_study.study_id
        p = at_first_trial(client, sid, **(prolific("x") | {"PROLIFIC_PID": marker}))
        p.finish(bank)
        assert marker.encode() in raw_bytes(db_path)
        r = client.post("/api/researcher/withdrawals", headers=ADMIN,
                        json={"study_id": sid, "external_id": marker})
        assert r.json()["storage"] == ("sqlite: deleted rows overwritten, write-ahead log "
                                       "checkpointed and truncated")
        assert marker.encode() not in raw_bytes(db_path)
        assert db_path.with_name("study.db-wal").stat().st_size == 0


def raw_bytes(db_path) -> bytes:
    """The database file and its write-ahead log, as stored on disk."""
    wal = db_path.with_name(db_path.name + "-wal")
    return db_path.read_bytes() + (wal.read_bytes() if wal.exists() else b"")


def public_id_of(client, token: str) -> str:
    with Session(client.app.state.engine) as db:
        return db.execute(select(Participant.public_id)
                          .where(Participant.session_token == token)).scalar_one()
