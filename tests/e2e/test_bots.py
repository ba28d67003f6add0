"""Pilot bots take the real study over HTTP against a real server on 127.0.0.1."""

import asyncio
import subprocess

import httpx
import pytest
from sqlalchemy import create_engine, func, select, text

from analysis.load import load_csv, load_database
from app.study.bots import run_bots
from app.study.tables import Participant, PredictionRow, Submission, TrialResponse
from tests.conftest import free_port, start_server

pytestmark = pytest.mark.slow
BOUND_S = 240  # the whole 50-bot run must finish within this


@pytest.fixture
def fresh_server(small_study, tmp_path):
    """A server of the small study on its own new SQLite database: (url, db_url)."""
    db_url = f"sqlite:///{tmp_path / 'study.db'}"
    port = free_port()
    proc = start_server(small_study, db_url, port, log=tmp_path / "server.log")
    yield f"http://127.0.0.1:{port}", db_url
    proc.terminate()
    try:
        proc.wait(timeout=10)
    except subprocess.TimeoutExpired:  # a stuck server must not outlive the test
        proc.kill()
        proc.wait(timeout=10)


def _count(engine, table) -> int:
    with engine.connect() as conn:
        return conn.execute(select(func.count()).select_from(table.__table__)).scalar_one()


def _export(url: str, study_id: str, tmp_path):
    response = httpx.get(f"{url}/api/researcher/export.csv", params={"study_id": study_id},
                         headers={"Authorization": "Bearer test-token"}, timeout=60)
    response.raise_for_status()
    path = tmp_path / "export.csv"
    path.write_bytes(response.content)
    return load_csv(path)


def test_fifty_concurrent_bots_complete_and_counts_match(small_study, fresh_server, tmp_path):
    url, db_url = fresh_server
    study = small_study.study_id
    results = asyncio.run(asyncio.wait_for(
        run_bots(url, study, "coarse", 50, concurrency=50, seed=1), BOUND_S))
    assert [r.error for r in results if r.error] == []
    assert all(r.completion_code for r in results)
    answered = sum(r.trials for r in results)
    engine = create_engine(db_url)
    try:
        assert _count(engine, Participant) == 50
        with engine.connect() as conn:
            done = conn.execute(text("select count(*) from participant where completed")).scalar()
        assert done == 50
        assert _count(engine, TrialResponse) == answered
        rows_in_db = _count(engine, PredictionRow)
        assert rows_in_db == answered * 5 * 3
        assert _count(engine, Submission) >= answered + 50 * 3  # + consent, instructions, survey
    finally:
        engine.dispose()
    exported = _export(url, study, tmp_path)
    assert len(exported) == rows_in_db
    assert exported["participant_id"].nunique() == 50
    assert exported["submission_id"].nunique() == answered
    from_db = load_database(db_url, study)
    assert from_db.equals(exported)


def test_precise_and_random_bots_complete(small_study, fresh_server):
    url, _ = fresh_server
    bank = small_study.data_dir / "trials" / small_study.study_id / "bank.json"
    for kind in ("precise", "random"):
        results = asyncio.run(asyncio.wait_for(
            run_bots(url, small_study.study_id, kind, 3, concurrency=3, bank_path=bank), 120))
        assert [r.error for r in results if r.error] == []
        assert all(r.completion_code for r in results)
