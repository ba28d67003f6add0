"""Fixtures of the researcher tests: sessions to export, and `tomstudy` run in process."""

import pytest
from sqlalchemy import update
from typer.testing import CliRunner

from app.server.storage.tables import Participant, TrialResponse, utcnow
from app.settings import get_settings
from tests.researcher.downloads import FORMULA
from tests.server.flow import at_first_trial, new_id, prolific


@pytest.fixture
def study(client, small_study, bank):
    """Three completed sessions (one with a formula survey answer, undo history and a
    recorded ending), one at its first trial with telemetry; returns the public ids."""
    done = []
    for i in range(3):
        p = at_first_trial(client, small_study.study_id, **prolific(f"done{i}"))
        if i == 0:
            ref = p.state()["step"]["trial_id"]
            events = [{"submission_id": new_id(), "kind": "clip_finished", "t_client_ms": 5.0,
                       "data": {"trial_id": ref, "replays": 0}},
                      {"submission_id": new_id(), "kind": "resize", "t_client_ms": 7.0,
                       "data": {"w": 800, "h": 600}}]
            assert p.post("events", {"events": events}).status_code == 202
        p.finish(bank, strategy=FORMULA if i == 0 else "followed the lanes")
        done.append(p)
    running = at_first_trial(client, small_study.study_id, **prolific("running"))
    engine = client.app.state.engine
    with engine.begin() as conn:
        first = conn.execute(TrialResponse.__table__.select().limit(1)).mappings().one()
        conn.execute(update(TrialResponse.__table__).where(TrialResponse.id == first["id"])
                     .values(history=[{"action": "undo", "start_index": 2, "t_ms": 1500.0},
                                      {"action": "reset", "start_index": 0, "t_ms": 2500.0}]))
        conn.execute(update(Participant.__table__)
                     .where(Participant.external_id == prolific("done0")["PROLIFIC_PID"])
                     .values(outcome="completed", completion_code="C1TOMSTUDY",
                             ended_at=utcnow()))
        conn.execute(update(Participant.__table__)  # this session ran a changed config
                     .where(Participant.external_id == prolific("done2")["PROLIFIC_PID"])
                     .values(config_sha256="0" * 64))
    return {"done": done, "running": running, "history_trial": first["trial_id"]}


@pytest.fixture
def cli_env(small_study, db_url, monkeypatch):
    """`tomstudy` run in process on the test's study and database."""
    for key, value in small_study.env(db_url).items():
        monkeypatch.setenv(key, value)
    get_settings.cache_clear()
    yield CliRunner()
    get_settings.cache_clear()
