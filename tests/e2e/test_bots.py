"""Pilot bots take the real study over HTTP against a real server on 127.0.0.1."""

import asyncio

import pytest

from app.pilot.bots import run_bots
from tests.conftest import free_port, fresh_database, patience, start_server, stop_server
from tests.e2e.crowd import crowd_in_exact_balance

pytestmark = pytest.mark.slow
BOUND_S = 120  # a crowd must finish within this on a quiet machine (patience scales it)
FEW_BOTS_BOUND_S = 120


@pytest.fixture
def fresh_server(small_study, tmp_path):
    """A server of the small study on its own new SQLite database: (url, db_url)."""
    db_url = f"sqlite:///{tmp_path / 'study.db'}"
    port = free_port()
    proc = start_server(small_study, db_url, port, log=tmp_path / "server.log")
    yield f"http://127.0.0.1:{port}", db_url
    stop_server(proc)


CROWD = 40  # all at once: concurrency, not scale (the benchmark runs 200)


@pytest.fixture(params=["sqlite", pytest.param("postgres", marks=pytest.mark.postgres)])
def crowd_server(request, small_study, tmp_path):
    """The small study on SQLite with 1 worker or PostgreSQL with 2: (url, db_url).

    It trusts the bots' simulated clocks, so every bot completes as a valid (counted)
    participant and the balance over all of them can be checked exactly.
    """
    if request.param == "sqlite":
        db_url, workers = f"sqlite:///{tmp_path / 'study.db'}", 1
    else:
        db_url, workers = fresh_database(request.getfixturevalue("postgres_url"), "crowd"), 2
    port = free_port()
    proc = start_server(small_study, db_url, port, workers=workers, log=tmp_path / "server.log",
                        TOMSTUDY_TRUST_CLIENT_CLOCK="1")
    yield f"http://127.0.0.1:{port}", db_url
    stop_server(proc)


def test_a_concurrent_crowd_completes_in_exact_balance(small_study, crowd_server, tmp_path):
    """CROWD bots at once: every one completes and counts, orders split evenly, every trial's
    exposure within 1 (benchmarks/crowd_balance.py runs 200 and times them)."""
    url, db_url = crowd_server
    crowd_in_exact_balance(small_study, url, db_url, CROWD, patience(BOUND_S), tmp_path)


def test_precise_and_random_bots_complete(small_study, fresh_server):
    url, _ = fresh_server
    bank = small_study.data_dir / "trials" / small_study.study_id / "bank.json"
    for kind in ("precise", "random"):
        results = asyncio.run(asyncio.wait_for(
            run_bots(url, small_study.study_id, kind, 3, concurrency=3, bank_path=bank),
            patience(FEW_BOTS_BOUND_S)))
        assert [r.error for r in results if r.error] == []
        assert all(r.completion_code for r in results)
