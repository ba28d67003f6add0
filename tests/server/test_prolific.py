"""Issue 32 item 2: with a Prolific API token, only submissions Prolific confirms take places.

Every test runs the real client (app/server/prolific.py) against the local stand-in of
Prolific's API (tests/server/prolific_standin.py) on 127.0.0.1, never the live Prolific: a forged
SESSION_ID never counts, a real one does, and an unreachable Prolific admits the participant
uncounted until a re-check confirms them. The payment sheet approves and asks to return
through the same API, with an audit line per action.
"""

import asyncio
import io

import pytest
from sqlmodel import Session, select
from typer.testing import CliRunner

from analysis.exports import read_export
from analysis.load import load_csv
from analysis.metrics import apply_exclusions
from app.cli import cli
from app.server.flow import balance
from app.server.flow.prolific_check import recheck_pending
from app.server.prolific import CONFIRMED, PENDING, UNKNOWN, ProlificClient
from app.server.storage.tables import Participant, PaymentAudit
from tests.conftest import free_port, local_client
from tests.server.flow import ADMIN, prolific
from tests.server.flow import Participant as Browser
from tests.server.flow import make_client as plain_client
from tests.server.prolific_standin import ProlificStandIn, serve


@pytest.fixture
def standin():
    """The stand-in on a free port: (its state, its API URL)."""
    state = ProlificStandIn()
    with serve(state, free_port()) as url:
        yield state, url


def checked_client(study, db_url: str, api_url: str, token: str = "standin-token"):
    """The app with a Prolific API token, asking `api_url`."""
    from app.main import create_app

    settings = study.settings(db_url, trust_client_clock=True, prolific_token=token,
                              prolific_api_url=api_url)
    return local_client(create_app(settings, [study.study_id]))


def known(standin: ProlificStandIn, name: str) -> dict:
    """Link parameters of `name`, whose submission the stand-in holds."""
    params = prolific(name)
    standin.add(params["SESSION_ID"], params["STUDY_ID"], params["PROLIFIC_PID"])
    return params


def rows(client) -> list[Participant]:
    with Session(client.app.state.engine) as db:
        return list(db.execute(select(Participant).order_by(Participant.id)).scalars())


def counted_total(client, study_id: str) -> int:
    with Session(client.app.state.engine) as db:
        return sum(balance.read_counts(db, study_id).values())


def export(client, study_id: str, what: str):
    r = client.get(f"/api/researcher/export/{what}.csv", params={"study_id": study_id},
                   headers=ADMIN)
    assert r.status_code == 200, r.text
    return r.text


def test_a_forged_session_id_never_gets_a_session_or_a_place(small_study, db_url, standin):
    state, url = standin
    other = known(state, "someone else")
    with checked_client(small_study, db_url, url) as client:
        forged = prolific("forger")  # well formed, but Prolific has no such submission
        not_theirs = prolific("forger") | {"SESSION_ID": other["SESSION_ID"]}
        other_study = known(state, "elsewhere") | {"STUDY_ID": "ab" * 12}
        for params in (forged, not_theirs, other_study):
            p = Browser(client, small_study.study_id)
            body = p.start(**params)
            assert p.status == 403, body
            assert body["detail"].startswith("recruitment.SESSION_ID: Prolific has no")
            assert body["notice"]["title"] == "Prolific does not know this link"
        assert rows(client) == []
        assert counted_total(client, small_study.study_id) == 0
    assert ("GET", f"/api/v1/submissions/{forged['SESSION_ID']}/") in state.requests


def test_a_submission_prolific_confirms_counts_and_is_asked_about_once(small_study, db_url,
                                                                         standin):
    state, url = standin
    with checked_client(small_study, db_url, url) as client:
        p = Browser(client, small_study.study_id)
        params = known(state, "real person")
        p.start(**params)
        assert p.status == 201
        p.start(**params)  # a reload resumes without asking Prolific again
        assert p.status == 200
        [row] = rows(client)
        assert (row.prolific_check, row.counted) == (CONFIRMED, False)  # a place from consent
        assert p.consent().status_code == 200
        [row] = rows(client)
        assert (row.prolific_check, row.counted) == (CONFIRMED, True)
        assert counted_total(client, small_study.study_id) > 0
    assert len(state.requests) == 1


def test_prolific_down_admits_uncounted_until_a_recheck_confirms(small_study, tmp_path, bank):
    db_url = f"sqlite:///{tmp_path / 'study.db'}"
    port = free_port()  # nothing listens here yet: Prolific is down
    state = ProlificStandIn()
    real, forged = prolific("real while down"), prolific("forger while down")
    with checked_client(small_study, db_url, f"http://127.0.0.1:{port}/api/v1/") as client:
        study_id = small_study.study_id
        people = [Browser(client, study_id), Browser(client, study_id)]
        public_ids = []
        for p, params in zip(people, (real, forged), strict=True):
            public_ids.append(p.start(**params)["participant_id"])
            assert p.status == 201  # nobody loses their place to our network
            p.pass_intro()
            p.finish(bank)
        assert [(r.prolific_check, r.counted, r.completed) for r in rows(client)] == [
            (PENDING, False, True)] * 2
        assert counted_total(client, study_id) == 0
        sheet = read_export(io.StringIO(export(client, study_id, "participants")),
                            "participants")
        assert sheet["exclusion_reasons"].tolist() == ["prolific_unknown"] * 2
        assert sheet["prolific_check"].tolist() == [PENDING] * 2
        (tmp_path / "predictions.csv").write_text(export(client, study_id, "predictions"))
        before = apply_exclusions(load_csv(tmp_path / "predictions.csv"),
                                  small_study_rules(client, study_id))
        assert len(before.participants_excluded["prolific_unknown"]) == 2
        assert before.counts()["participants_kept"] == 0

        state.add(real["SESSION_ID"], real["STUDY_ID"], real["PROLIFIC_PID"])
        ctx = client.app.state.studies[study_id]
        with serve(state, port):
            tally = asyncio.run(recheck_pending(client.app.state.engine,
                                                client.app.state.prolific, study_id,
                                                ctx.config))
        assert tally == {CONFIRMED: 1, UNKNOWN: 1, PENDING: 0}
        assert [(r.prolific_check, r.counted) for r in rows(client)] == [
            (CONFIRMED, True), (UNKNOWN, False)]
        (tmp_path / "predictions.csv").write_text(export(client, study_id, "predictions"))
        after = apply_exclusions(load_csv(tmp_path / "predictions.csv"),
                                 small_study_rules(client, study_id))
        assert after.participants_excluded["prolific_unknown"] == [public_ids[1]]
        assert after.counts()["participants_kept"] == 1


def small_study_rules(client, study_id: str):
    return client.app.state.studies[study_id].config.exclusions


def test_a_refused_token_admits_as_pending_rather_than_refusing(small_study, tmp_path,
                                                                 standin):
    state, url = standin
    with checked_client(small_study, f"sqlite:///{tmp_path / 'db.sqlite'}", url,
                        token="not-the-token") as client:
        p = Browser(client, small_study.study_id)
        p.start(**known(state, "real, wrong token"))
        assert p.status == 201
        assert [(r.prolific_check, r.counted) for r in rows(client)] == [(PENDING, False)]


def test_without_a_token_nothing_is_asked(small_study, tmp_path):
    with plain_client(small_study, f"sqlite:///{tmp_path / 'db.sqlite'}") as client:
        p = Browser(client, small_study.study_id)
        public_id = p.start(**prolific("unchecked"))["participant_id"]
        assert p.status == 201 and p.consent().status_code == 200
        assert [(r.prolific_check, r.counted) for r in rows(client)] == [(None, True)]
        r = client.post("/api/researcher/prolific/approve", headers=ADMIN,
                        json={"study_id": small_study.study_id, "participant_ids": [public_id]})
        assert r.status_code == 409 and "TOMSTUDY_PROLIFIC_TOKEN_FILE" in r.json()["detail"]


def test_the_payment_sheet_approves_and_asks_to_return_with_an_audit_line(
        small_study, tmp_path, standin, bank):
    state, url = standin
    study_id = small_study.study_id
    with checked_client(small_study, f"sqlite:///{tmp_path / 'db.sqlite'}", url) as client:
        done, quit_ = Browser(client, study_id), Browser(client, study_id)
        done_params, quit_params = known(state, "finished"), known(state, "stopped")
        done_id = done.start(**done_params)["participant_id"]
        quit_id = quit_.start(**quit_params)["participant_id"]
        done.pass_intro()
        done.finish(bank)
        state.submissions[done_params["SESSION_ID"]]["status"] = "AWAITING_REVIEW"

        def act(action: str, ids: list[str], **extra):
            return client.post(f"/api/researcher/prolific/{action}", headers=ADMIN,
                               json={"study_id": study_id, "participant_ids": ids} | extra)

        assert client.post("/api/researcher/prolific/approve",
                           json={"study_id": study_id, "participant_ids": [done_id]}
                           ).status_code == 401
        refused = act("approve", [quit_id])
        assert refused.status_code == 409
        assert refused.json()["detail"].startswith(f"participant_ids: {quit_id} did not complete")
        assert act("return", [quit_id]).json()["detail"].startswith("reason:")
        assert act("approve", ["nobody"]).status_code == 404

        first = act("approve", [done_id])
        assert first.status_code == 201
        assert [(x["ok"], x["result"]) for x in first.json()] == [(True, "status APPROVED")]
        assert state.submissions[done_params["SESSION_ID"]]["status"] == "APPROVED"
        again = act("approve", [done_id]).json()  # Prolific refuses: no longer awaiting review
        assert again[0]["ok"] is False and "HTTP 400" in again[0]["result"]
        returned = act("return", [quit_id], reason="Didn't finish the study").json()
        assert returned[0]["ok"] is True
        assert state.submissions[quit_params["SESSION_ID"]]["return_requested"]

        audit = client.get("/api/researcher/prolific/audit", params={"study_id": study_id},
                           headers=ADMIN).json()
        assert [(a["participant_id"], a["action"], a["via"], a["ok"]) for a in audit] == [
            (done_id, "approve", "api", True), (done_id, "approve", "api", False),
            (quit_id, "return", "api", True)]


def test_the_cli_approves_and_writes_an_audit_line(small_study, tmp_path, standin, bank,
                                                    monkeypatch):
    state, url = standin
    db_url = f"sqlite:///{tmp_path / 'db.sqlite'}"
    with checked_client(small_study, db_url, url) as client:
        p = Browser(client, small_study.study_id)
        params = known(state, "paid from the shell")
        public_id = p.start(**params)["participant_id"]
        p.pass_intro()
        p.finish(bank)
        engine = client.app.state.engine
    state.submissions[params["SESSION_ID"]]["status"] = "AWAITING_REVIEW"
    token_file = tmp_path / "prolific_token"
    token_file.write_text("standin-token\n")
    env = small_study.env(db_url, TOMSTUDY_PROLIFIC_TOKEN_FILE=str(token_file),
                          TOMSTUDY_PROLIFIC_API_URL=url)
    for key, value in env.items():
        monkeypatch.setenv(key, value)
    from app.settings import get_settings
    get_settings.cache_clear()
    try:
        runner = CliRunner()
        bad = runner.invoke(cli, ["prolific", "approve", "--study", small_study.study_id,
                                  "nobody"])
        assert bad.exit_code == 1 and "PARTICIPANT_IDS: no session nobody" in bad.output
        ok = runner.invoke(cli, ["prolific", "approve", "--study", small_study.study_id,
                                 public_id])
        assert ok.exit_code == 0, ok.output
        assert '"result": "status APPROVED"' in ok.output
    finally:
        get_settings.cache_clear()
    with Session(engine) as db:
        lines = db.execute(select(PaymentAudit)).scalars().all()
    assert [(a.participant_id, a.action, a.via, a.ok) for a in lines] == [
        (public_id, "approve", "cli", True)]


def test_the_client_reads_either_spelling_of_the_participant(standin):
    state, url = standin
    state.add("sub-1", "a" * 24, "b" * 24)
    state.submissions["sub-2"] = {"id": "sub-2", "study_id": "a" * 24,
                                  "participant_id": "B" * 24, "status": "ACTIVE"}
    client = ProlificClient(url, state.token)
    check = client.check_submission
    assert asyncio.run(check("sub-1", "A" * 24, "b" * 24)) == CONFIRMED
    assert asyncio.run(check("sub-2", "a" * 24, "b" * 24)) == CONFIRMED
    assert asyncio.run(check("sub-1", "a" * 24, "c" * 24)) == UNKNOWN
    assert asyncio.run(check("sub-3", "a" * 24, "b" * 24)) == UNKNOWN
