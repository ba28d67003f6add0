"""The interaction study (recorded worlds, GENERATED recordings) taken by pilot bots over HTTP
against a real server, then analysed with every predictor side by side."""

import asyncio
import subprocess
from itertools import combinations

import pandas as pd
import pytest
from sqlalchemy import create_engine, func, select

from app.core.contracts import COARSE_OBSERVERS
from app.pilot.bots import run_bots
from app.server.storage.tables import PredictionRow
from tests.conftest import TOMSTUDY, free_port, patience, start_server, stop_server

pytestmark = pytest.mark.slow
KINDS = ("coarse", "precise", "random")
BOTS = 3


@pytest.fixture
def recorded_server(interaction_study, tmp_path):
    """The interaction study on its own new SQLite database, trusting the bots' clocks."""
    db_url = f"sqlite:///{tmp_path / 'study.db'}"
    port = free_port()
    proc = start_server(interaction_study, db_url, port, log=tmp_path / "server.log",
                        TOMSTUDY_TRUST_CLIENT_CLOCK="1")
    yield f"http://127.0.0.1:{port}", db_url
    stop_server(proc)


def test_bots_take_the_recorded_study_and_every_predictor_is_compared(
        interaction_study, recorded_server, tmp_path):
    url, db_url = recorded_server
    bank = interaction_study.layout.bundle_dir(interaction_study.study_id) / "bank.json.gz"
    for kind in KINDS:
        results = asyncio.run(asyncio.wait_for(
            run_bots(url, interaction_study.study_id, kind, BOTS, concurrency=BOTS,
                     bank_path=bank), patience(120)))
        assert [r.error for r in results if r.error] == [] and all(r.completion_code
                                                                    for r in results)
    with create_engine(db_url).connect() as conn:
        rows = conn.execute(select(func.count()).select_from(PredictionRow.__table__)).scalar()
    trials = 2 * (3 + 1 + 1)  # per world: 3 main, 1 practice, 1 attention check
    assert rows == len(KINDS) * BOTS * trials * 5 * 3

    out = tmp_path / "report"
    subprocess.run([TOMSTUDY, "analyze", "--study", interaction_study.study_id,
                    "--database-url", db_url, "--out", str(out),
                    "--waive", "failed_attention_check"],
                   env=interaction_study.env(db_url), check=True, capture_output=True,
                   timeout=patience(300))
    pairwise = pd.read_csv(out / "pairwise.csv")
    assert set(pairwise["world"]) == {"roundabout", "intersection"}
    pairs = {frozenset((a, b)) for a, b in zip(pairwise["a"], pairwise["b"], strict=True)}
    names = ("ours", "vae", "cv", *COARSE_OBSERVERS, "ctrv")
    assert pairs == {frozenset(p) for p in combinations(names, 2)}
    means = pd.read_csv(out / "predictors.csv")
    assert {"err_ours", "err_vae", "err_cv", "err_ctrv"} <= set(means.columns)
    assert "ctrv" in (out / "report.html").read_text().lower()
