"""The server refuses a study whose trial bank changed under its sessions, unless told to."""

import json
import shutil
import subprocess

import httpx
import pytest

from app.core.files import sha256_file
from app.layout import Layout
from app.main import create_app
from app.server.bank_guard import BankChanged, banks_run
from app.server.flow.recruitment import preview_key
from app.server.storage.db import make_engine
from tests.conftest import (
    TOMSTUDY,
    SmallStudy,
    free_port,
    freeze_bundle_of,
    local_client,
    patience,
    start_server,
)
from tests.server.flow import TOKEN, Participant, make_client, new_id


@pytest.fixture
def rebuilt(small_study, tmp_path) -> SmallStudy:
    """The small study with a bundle whose bank has other bytes, as after a researcher rebuilt
    and froze it."""
    data_dir = tmp_path / "var"
    shutil.copytree(small_study.data_dir, data_dir)
    bank = Layout(data_dir).bank(small_study.study_id)
    bank.write_text(json.dumps(json.loads(bank.read_text()), indent=1))
    meta = bank.with_name("meta.json")
    meta.write_text(json.dumps(json.loads(meta.read_text()) | {"bank_sha256": sha256_file(bank)}))
    study = SmallStudy(data_dir, small_study.configs_dir)
    freeze_bundle_of(study)
    return study


def run_sessions(study: SmallStudy, db_url: str, n: int, pilots: int = 0) -> str:
    """`n` participants and `pilots` preview sessions start on `study`'s bank; its sha256."""
    with make_client(study, db_url) as client:
        for _ in range(n):
            Participant(client, study.study_id).start()
        for _ in range(pilots):
            Participant(client, study.study_id).start(preview=preview_key(TOKEN, study.study_id))
        return client.app.state.studies[study.study_id].bank.sha256


def test_a_changed_bank_is_refused_naming_the_sessions_and_the_override(small_study, rebuilt,
                                                                         db_url):
    old = run_sessions(small_study, db_url, n=2, pilots=1)
    app = create_app(rebuilt.settings(db_url), [rebuilt.study_id])
    with pytest.raises(BankChanged) as refused, local_client(app):
        pass
    message = str(refused.value)
    new = json.loads(
        Layout(rebuilt.data_dir).bank_meta(rebuilt.study_id).read_text())["bank_sha256"]
    assert message.startswith(f"{rebuilt.study_id}: the trial bank changed")
    assert f"2 ran bank {old[:12]}" in message and f"loaded bank is {new[:12]}" in message
    assert "--allow-bank-change" in message and "TOMSTUDY_ALLOW_BANK_CHANGE=1" in message
    engine = make_engine(db_url)
    assert banks_run(engine, rebuilt.study_id) == {old: 2}  # the pilot is left out
    engine.dispose()


def test_the_override_serves_the_changed_bank(small_study, rebuilt, db_url, monkeypatch):
    old = run_sessions(small_study, db_url, n=1)
    monkeypatch.setenv("TOMSTUDY_ALLOW_BANK_CHANGE", "1")
    settings = rebuilt.settings(db_url)
    assert settings.allow_bank_change
    with local_client(create_app(settings, [rebuilt.study_id])) as client:
        Participant(client, rebuilt.study_id).start()
        new = client.app.state.studies[rebuilt.study_id].bank.sha256
    engine = make_engine(db_url)
    assert banks_run(engine, rebuilt.study_id) == {old: 1, new: 1}
    engine.dispose()


def test_pilots_and_the_same_bank_never_block(small_study, rebuilt, db_url):
    run_sessions(small_study, db_url, n=0, pilots=2)  # the lab tried the old bank itself
    with make_client(rebuilt, db_url) as client:
        assert Participant(client, rebuilt.study_id).start()["resumed"] is False
    with make_client(rebuilt, db_url) as client:  # now its own sessions ran the loaded bank
        assert client.get("/healthz").status_code == 200


def test_serve_refuses_a_changed_bank_unless_allowed(small_study, rebuilt, tmp_path):
    db_url = f"sqlite:///{tmp_path / 'study.db'}"
    old = run_sessions(small_study, db_url, n=3)
    run = subprocess.run([TOMSTUDY, "serve", "--port", "1",
                          "--study", rebuilt.study_id], env=rebuilt.env(db_url),
                         capture_output=True, text=True, timeout=patience(120))
    assert run.returncode == 2 and "Traceback" not in run.stderr
    assert f"{rebuilt.study_id}: the trial bank changed" in run.stderr
    assert f"3 ran bank {old[:12]}" in run.stderr
    port = free_port()
    proc = start_server(rebuilt, db_url, port, log=tmp_path / "server.log",
                        args=("--allow-bank-change",))
    try:
        assert httpx.get(f"http://127.0.0.1:{port}/healthz", timeout=patience(5)).status_code == 200
    finally:
        proc.terminate()
        proc.wait(timeout=patience(10))


def test_sessions_of_a_replaced_bank_are_told_plainly_and_finished_ones_keep_their_code(
        small_study, rebuilt, db_url, bank):
    with make_client(small_study, db_url) as client:
        running = Participant(client, small_study.study_id)
        running.start()
        running.pass_intro()
        done = Participant(client, small_study.study_id)
        done.start()
        done.pass_intro()
        code = done.finish(bank)["step"]["completion_code"]
    settings = rebuilt.settings(db_url, allow_bank_change=True)
    with local_client(create_app(settings, [rebuilt.study_id])) as client:
        running.client = done.client = client
        answers = [running.get("state"), running.post("events", {"events": [{
            "submission_id": new_id(), "kind": "resize", "t_client_ms": 1.0,
            "data": {"w": 1, "h": 1}}]})]
        assert [r.status_code for r in answers] == [410, 410]  # not 500s, and not forever
        assert "the study was changed after this session started" in answers[0].json()["detail"]
        assert "return the study" in answers[0].json()["detail"]
        assert done.state()["step"]["completion_code"] == code
