"""Real `tomstudy serve` processes: SIGKILL mid-session, and several workers on PostgreSQL."""

import asyncio
import http.client
import io
import os
import signal
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from urllib.parse import urlsplit

import httpx
import pandas as pd
import pytest

from app.server.flow.plan import PART_PHASES, TRIAL_PHASES
from tests.conftest import (
    free_port,
    fresh_database,
    patience,
    researcher_get,
    start_server,
    wait_for_log,
)
from tests.server.flow import Participant, new_id, prediction_body, prolific

pytestmark = pytest.mark.slow


def export(base_url: str, study_id: str, what: str = "predictions") -> pd.DataFrame:
    """One researcher export as a DataFrame."""
    r = researcher_get(f"{base_url}/api/researcher/export/{what}.csv?study_id={study_id}")
    assert r.status_code == 200, r.text
    return pd.read_csv(io.StringIO(r.text), dtype={"participant_id": str, "external_id": str})


def test_sigkill_mid_session_loses_no_acknowledged_submission(small_study, tmp_path):
    db_url = f"sqlite:///{tmp_path / 'study.db'}"
    port = free_port()
    base = f"http://127.0.0.1:{port}"
    proc = start_server(small_study, db_url, port, log=tmp_path / "server.log")
    try:
        with httpx.Client(base_url=base, timeout=patience(10)) as client:
            p = Participant(client, small_study.study_id)
            p.start(**prolific("killed"))
            p.pass_intro()
            acknowledged = [p.answer_trial()["phase"] for _ in range(3)]
            current = p.state()["step"]["trial_id"]
            proc.send_signal(signal.SIGKILL)  # right after the last 201, no clean shutdown
            proc.wait(timeout=patience(10))
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == -signal.SIGKILL

    proc = start_server(small_study, db_url, port, log=tmp_path / "server.log")
    try:
        with httpx.Client(base_url=base, timeout=patience(10)) as client:
            again = Participant(client, small_study.study_id)
            body = again.start(**prolific("killed"))
            assert again.status == 200 and body["resumed"] and again.token == p.token
            state = again.state()
            assert state["step"]["trial_id"] == current
            assert state["progress"]["done"] == len(acknowledged)
            frame = export(base, small_study.study_id)
            assert len(frame) == len(acknowledged) * 15
            assert frame["submission_id"].nunique() == len(acknowledged)
            again.finish()
    finally:
        proc.terminate()
        proc.wait(timeout=patience(10))


def test_sigkill_under_load_keeps_every_acknowledged_submission(small_study, tmp_path):
    """Participants submit without pause while the server is killed; after a restart every
    acknowledged submission is stored and each participant resumes where the rows end."""
    db_url = f"sqlite:///{tmp_path / 'study.db'}"
    port = free_port()
    base = f"http://127.0.0.1:{port}"
    proc = start_server(small_study, db_url, port, log=tmp_path / "server.log")
    acknowledged: dict[str, list[str]] = {}
    stop = threading.Event()

    def keep_submitting(i: int) -> None:
        with httpx.Client(base_url=base, timeout=patience(5)) as client:
            p = Participant(client, small_study.study_id)
            p.start(**prolific(f"load{i}"))
            p.pass_intro()
            acknowledged[p.token] = []
            while not stop.is_set():
                try:
                    state = p.pass_screens()
                    if state["phase"] not in TRIAL_PHASES:
                        return
                    body = prediction_body(state["step"])
                    if p.post("predictions", body).status_code == 201:
                        acknowledged[p.token].append(body["submission_id"])
                except httpx.TransportError:
                    return

    threads = [threading.Thread(target=keep_submitting, args=(i,)) for i in range(4)]
    try:
        for t in threads:
            t.start()
        while sum(map(len, acknowledged.values())) < 6:
            assert any(t.is_alive() for t in threads), "every participant stopped before 6 answers"
            time.sleep(0.02)
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=patience(10))
    finally:
        stop.set()
        for t in threads:
            t.join(timeout=patience(30))
        if proc.poll() is None:
            proc.kill()

    proc = start_server(small_study, db_url, port, log=tmp_path / "server.log")
    try:
        frame = export(base, small_study.study_id)
        stored = set(frame["submission_id"])
        with httpx.Client(base_url=base, timeout=patience(10)) as client:
            for token, ids in acknowledged.items():
                assert set(ids) <= stored  # nothing acknowledged was lost
                state = client.get("/api/session/state",
                                   headers={"X-Session-Token": token}).json()
                # at most one more than acknowledged: committed, answer lost in the kill
                assert state["progress"]["done"] in (len(ids), len(ids) + 1)
        assert frame.groupby("submission_id").size().eq(15).all()
    finally:
        proc.terminate()
        proc.wait(timeout=patience(10))


@pytest.mark.postgres
def test_two_workers_on_postgres_serve_concurrent_participants(small_study, postgres_url,
                                                               tmp_path):
    port = free_port()
    base = f"http://127.0.0.1:{port}"
    db_url = fresh_database(postgres_url, "two_workers")
    proc = start_server(small_study, db_url, port, workers=2, log=tmp_path / "server.log")

    def one(i: int) -> int:
        with httpx.Client(base_url=base, timeout=patience(30)) as client:
            p = Participant(client, small_study.study_id)
            p.start(**prolific(f"w2-{i}"))
            p.pass_intro()
            p.answer_trial()
            body = prediction_body(p.pass_screens()["step"])
            statuses = [p.post("predictions", body).status_code for _ in range(2)]  # + a retry
            assert statuses == [201, 200]
            return p.state()["progress"]["done"]

    try:
        with ThreadPoolExecutor(6) as pool:
            done = list(pool.map(one, range(6)))
        assert done == [2] * 6
        frame = export(base, small_study.study_id)
        assert len(frame) == 6 * 2 * 15
        assert frame.groupby("participant_id")["submission_id"].nunique().eq(2).all()
    finally:
        proc.terminate()
        proc.wait(timeout=patience(15))



@pytest.mark.postgres
def test_worker_starts_and_replacements_are_logged(small_study, postgres_url, tmp_path):
    log = tmp_path / "server.log"
    proc = start_server(small_study, fresh_database(postgres_url, "worker_log"), free_port(),
                        workers=2, log=log)
    started = r"Started server process \[(\d+)\]"
    try:
        pids = wait_for_log(log, started, 2)
        assert len(pids) == 2, log.read_text()
        os.kill(int(pids[0]), signal.SIGKILL)
        assert len(wait_for_log(log, started, 3)) == 3, log.read_text()
        assert f"Child process [{pids[0]}] died" in log.read_text()
    finally:
        proc.terminate()
        proc.wait(timeout=patience(15))
    assert "GET /s/" not in log.read_text()  # no access log: client addresses stay out


def test_an_idle_connection_outlives_uvicorns_default_keep_alive(live_server):
    """One connection, idle past uvicorn's 5 s default, still answers: the server keeps idle
    connections longer than a reverse proxy keeps its own (settings.keep_alive_s), so the proxy
    never sends a request into a connection the server is closing (a 502 for a participant)."""
    connection = http.client.HTTPConnection(urlsplit(live_server).netloc, timeout=patience(20))
    try:
        connection.request("GET", "/healthz")
        assert connection.getresponse().read() and connection.sock is not None
        first_socket = connection.sock
        time.sleep(6)
        connection.request("GET", "/healthz")  # RemoteDisconnected if the server closed it
        assert connection.getresponse().status == 200
        assert connection.sock is first_socket
    finally:
        connection.close()


def test_many_concurrent_participants_on_one_sqlite_worker(small_study, live_server):
    """More clients than pooled connections and worker threads: nothing may wait on the
    pool (a regression: sync dependencies held connections until a thread-pool clean-up
    that could not run while the thread pool waited for connections)."""
    crowd = 60

    async def one(client: httpx.AsyncClient, i: int) -> int:
        r = await client.post("/api/sessions", json={
            "study_id": small_study.study_id, "recruitment": prolific(f"crowd-{i}")})
        session = {"X-Session-Token": r.json()["session_token"]}
        await client.post("/api/session/consent", headers=session,
                          json={"submission_id": new_id(), "agree": True})
        await client.post("/api/session/instructions", headers=session,
                          json={"submission_id": new_id()})
        for _ in range(2):
            state = (await client.get("/api/session/state", headers=session)).json()
            while state["phase"] in PART_PHASES:  # a part's introduction, practice over
                state = (await client.post("/api/session/continue", headers=session, json={
                    "submission_id": new_id(), "phase": state["phase"]})).json()
            r = await client.post("/api/session/predictions", headers=session,
                                  json=prediction_body(state["step"]))
            assert r.status_code == 201, r.text
        state = (await client.get("/api/session/state", headers=session)).json()
        return state["progress"]["done"]

    async def run() -> list[int]:
        limits = httpx.Limits(max_connections=crowd)
        async with httpx.AsyncClient(base_url=live_server, timeout=patience(20),
                                     limits=limits) as client:
            return await asyncio.gather(*(one(client, i) for i in range(crowd)))

    assert asyncio.run(run()) == [2] * crowd
    frame = export(live_server, small_study.study_id)
    crowd_ids = {prolific(f"crowd-{i}")["PROLIFIC_PID"] for i in range(crowd)}
    sheet = export(live_server, small_study.study_id, "participants")
    crowd_public = sheet.loc[sheet["external_id"].isin(crowd_ids), "participant_id"]
    mine = frame[frame["participant_id"].isin(crowd_public)]
    assert len(mine) == crowd * 2 * 15
