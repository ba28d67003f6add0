"""Pilot bots take the real study over HTTP against a real server on 127.0.0.1."""

import asyncio
from collections import Counter

import httpx
import pytest
from sqlalchemy import create_engine, func, select, text

from analysis.load import load_csv, load_database
from app.pilot.bots import run_bots
from app.server.tables import Participant, PredictionRow, Submission, TrialResponse
from tests.conftest import free_port, fresh_database, start_server, stop_server

pytestmark = pytest.mark.slow
BOUND_S = 300  # a whole bot run must finish within this


@pytest.fixture
def fresh_server(small_study, tmp_path):
    """A server of the small study on its own new SQLite database: (url, db_url)."""
    db_url = f"sqlite:///{tmp_path / 'study.db'}"
    port = free_port()
    proc = start_server(small_study, db_url, port, log=tmp_path / "server.log")
    yield f"http://127.0.0.1:{port}", db_url
    stop_server(proc)


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


CROWD = 200


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


def test_two_hundred_concurrent_participants_complete_in_exact_balance(small_study,
                                                                       crowd_server, tmp_path):
    url, db_url = crowd_server
    study = small_study.study_id
    bank = small_study.data_dir / "trials" / study / "bank.json"
    results = asyncio.run(asyncio.wait_for(
        run_bots(url, study, "precise", CROWD, concurrency=CROWD, seed=1, bank_path=bank),
        BOUND_S))
    assert [r.error for r in results if r.error] == []
    assert all(r.completion_code for r in results)
    answered = sum(r.trials for r in results)
    engine = create_engine(db_url)
    try:
        assert _count(engine, Participant) == CROWD
        with engine.connect() as conn:
            done = conn.execute(text("select count(*) from participant where completed "
                                     "and counted")).scalar()
            plans = conn.execute(select(Participant.world_order, Participant.plan)).all()
        assert done == CROWD
        assert _count(engine, TrialResponse) == answered
        rows_in_db = _count(engine, PredictionRow)
        assert rows_in_db == answered * 5 * 3
        assert _count(engine, Submission) >= answered + CROWD * 3  # + consent, instr., survey
    finally:
        engine.dispose()
    orders = Counter(order for order, _ in plans)
    assert sorted(orders.values()) == [CROWD // 2, CROWD // 2]
    for kind, counts in exposure(plans, bank).items():
        assert max(counts) - min(counts) <= 1, (kind, counts)
    assert arms_given(plans, bank) == {(1, 2)}  # per world 1 random + 2 models_disagree trials
    exported = _export(url, study, tmp_path)
    assert len(exported) == rows_in_db
    assert exported["participant_id"].nunique() == CROWD
    assert exported["submission_id"].nunique() == answered
    from_db = load_database(db_url, study)
    assert from_db.equals(exported)


def exposure(plans: list, bank_path) -> dict[tuple[str, str, str], list[int]]:
    """(world, trial kind, arm) -> how many sessions were given each bank trial of that kind
    (main trials are balanced within their selection arm; each arm gives its own quota)."""
    import json

    bank = json.loads(bank_path.read_text())
    given = Counter(s["trial_id"] for _, plan in plans for s in plan if "trial_id" in s)
    out: dict[tuple[str, str, str], list[int]] = {}
    for world, trials in ((w, b["trials"]) for w, b in bank["worlds"].items()):
        for t in trials:
            out.setdefault((world, t["kind"], t["arm"]), []).append(given[t["trial_id"]])
    return out


def arms_given(plans: list, bank_path) -> set[tuple[int, ...]]:
    """Every (random, models_disagree) count of main trials a session got in one world."""
    import json

    arm = {t["trial_id"]: t["arm"] for w in json.loads(bank_path.read_text())["worlds"].values()
           for t in w["trials"] if t["kind"] == "main"}
    seen = set()
    for _, plan in plans:
        for world in {s["world"] for s in plan if "trial_id" in s}:
            mine = [arm[s["trial_id"]] for s in plan
                    if s.get("world") == world and s.get("trial_id") in arm]
            seen.add((mine.count("random"), mine.count("models_disagree")))
    return seen


def test_precise_and_random_bots_complete(small_study, fresh_server):
    url, _ = fresh_server
    bank = small_study.data_dir / "trials" / small_study.study_id / "bank.json"
    for kind in ("precise", "random"):
        results = asyncio.run(asyncio.wait_for(
            run_bots(url, small_study.study_id, kind, 3, concurrency=3, bank_path=bank), 120))
        assert [r.error for r in results if r.error] == []
        assert all(r.completion_code for r in results)
