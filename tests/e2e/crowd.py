"""A crowd of pilot bots taking the small study at once, and the checks that every one of
them completed, was stored and was assigned in exact balance (tests/e2e/test_bots.py checks
a crowd of 40; benchmarks/crowd_balance.py times 200)."""

import asyncio
import json
import time
from collections import Counter
from pathlib import Path

from sqlalchemy import create_engine, func, select, text

from analysis.load import load_csv, load_database
from app.pilot.bots import run_bots
from app.server.storage.tables import Participant, PredictionRow, Submission, TrialResponse
from tests.conftest import SmallStudy, patience, researcher_get


def crowd_in_exact_balance(study: SmallStudy, url: str, db_url: str, crowd: int,
                           bound_s: float, tmp_path: Path) -> float:
    """`crowd` precise bots at once against the server at `url`; asserts every completion,
    row, balance and export; returns the crowd's wall time in seconds."""
    bank = study.data_dir / "trials" / study.study_id / "bank.json"
    start = time.monotonic()
    results = asyncio.run(asyncio.wait_for(
        run_bots(url, study.study_id, "precise", crowd, concurrency=crowd, seed=1,
                 bank_path=bank), bound_s))
    wall_s = time.monotonic() - start
    assert [r.error for r in results if r.error] == []
    assert all(r.completion_code for r in results)
    answered = sum(r.trials for r in results)
    engine = create_engine(db_url)
    try:
        assert _count(engine, Participant) == crowd
        with engine.connect() as conn:
            done = conn.execute(text("select count(*) from participant where completed "
                                     "and counted")).scalar()
            plans = conn.execute(select(Participant.world_order, Participant.plan)).all()
        assert done == crowd
        assert _count(engine, TrialResponse) == answered
        rows_in_db = _count(engine, PredictionRow)
        assert rows_in_db == answered * 5 * 3
        assert _count(engine, Submission) >= answered + crowd * 3  # + consent, instr., survey
    finally:
        engine.dispose()
    orders = Counter(order for order, _ in plans)
    assert sorted(orders.values()) == [crowd // 2, crowd // 2]
    for kind, counts in exposure(plans, bank).items():
        assert max(counts) - min(counts) <= 1, (kind, counts)
    assert arms_given(plans, bank) == {(1, 2)}  # per world 1 random + 2 models_disagree trials
    exported = _export(url, study.study_id, tmp_path)
    assert len(exported) == rows_in_db
    assert exported["participant_id"].nunique() == crowd
    assert exported["submission_id"].nunique() == answered
    assert load_database(db_url, study.study_id).equals(exported)
    return wall_s


def _count(engine, table) -> int:
    with engine.connect() as conn:
        return conn.execute(select(func.count()).select_from(table.__table__)).scalar_one()


def _export(url: str, study_id: str, tmp_path: Path):
    response = researcher_get(f"{url}/api/researcher/export.csv", params={"study_id": study_id},
                              timeout=patience(60))
    response.raise_for_status()
    path = tmp_path / "export.csv"
    path.write_bytes(response.content)
    return load_csv(path)


def exposure(plans: list, bank_path: Path) -> dict[tuple[str, str, str], list[int]]:
    """(world, trial kind, arm) -> how many sessions were given each bank trial of that kind
    (main trials are balanced within their selection arm; each arm gives its own quota)."""
    bank = json.loads(bank_path.read_text())
    given = Counter(s["trial_id"] for _, plan in plans for s in plan if "trial_id" in s)
    out: dict[tuple[str, str, str], list[int]] = {}
    for world, trials in ((w, b["trials"]) for w, b in bank["worlds"].items()):
        for t in trials:
            out.setdefault((world, t["kind"], t["arm"]), []).append(given[t["trial_id"]])
    return out


def arms_given(plans: list, bank_path: Path) -> set[tuple[int, ...]]:
    """Every (random, models_disagree) count of main trials a session got in one world."""
    arm = {t["trial_id"]: t["arm"] for w in json.loads(bank_path.read_text())["worlds"].values()
           for t in w["trials"] if t["kind"] == "main"}
    seen = set()
    for _, plan in plans:
        for world in {s["world"] for s in plan if "trial_id" in s}:
            mine = [arm[s["trial_id"]] for s in plan
                    if s.get("world") == world and s.get("trial_id") in arm]
            seen.add((mine.count("random"), mine.count("models_disagree")))
    return seen
