"""Anonymous traffic is bounded: per-client rate limits, a cap on live sessions per study,
and stale sessions released in bounded set-based batches off the request path."""

import asyncio
import secrets
import time
from datetime import timedelta

import httpx
import pytest
from sqlalchemy import func, select, update
from sqlmodel import Session

from app.http.ratelimit import SESSIONS_PER_ADDRESS
from app.main import create_app
from app.server.flow import balance
from app.server.flow.recruitment import preview_key
from app.server.flow.sessions import SESSION_HEADER
from app.server.storage.tables import Participant, utcnow
from tests.conftest import free_port, local_client, patience, start_server
from tests.server.flow import TOKEN, new_id, prolific, with_cap
from tests.server.flow import Participant as Client


def limited_app(small_study, tmp_path, starts: str = "", requests: str = ""):
    """The small study's app with these rate limits (\"\" = none)."""
    settings = small_study.settings(f"sqlite:///{tmp_path / 'study.db'}",
                                    rate_limit_starts=starts, rate_limit_requests=requests)
    return create_app(settings, [small_study.study_id])


# ---------------------------------------------------------------- rate limits

def test_session_starts_are_limited_per_client_address(small_study, tmp_path):
    app = limited_app(small_study, tmp_path, starts="3/minute")
    with local_client(app, client=("203.0.113.7", 5000)) as one:
        statuses = [Client(one, small_study.study_id) for _ in range(4)]
        for p in statuses:
            p.start()
        assert [p.status for p in statuses] == [201, 201, 201, 429]
        refused = one.post("/api/sessions", json={"study_id": small_study.study_id,
                                                  "recruitment": prolific("x")})
        assert refused.json()["detail"].startswith("rate: too many session starts")
        assert 1 <= int(refused.headers["retry-after"]) <= 60
        other = local_client(app, client=("198.51.100.9", 5000))  # same app, another address
        p = Client(other, small_study.study_id)
        p.start()
        assert p.status == 201
        assert one.get(f"/s/{small_study.study_id}").status_code == 200  # pages: no limit


def test_session_requests_are_limited_per_session_not_per_address(small_study, tmp_path):
    app = limited_app(small_study, tmp_path, requests="5/minute")
    with local_client(app, client=("203.0.113.8", 5000)) as c:
        first, second = Client(c, small_study.study_id), Client(c, small_study.study_id)
        for p in (first, second):  # starts have their own limit
            p.start()
            assert p.consent().status_code == 200  # a request too: events come from consent on

        def events(p: Client) -> int:
            return p.post("events", {"events": [{
                "submission_id": new_id(), "kind": "visibility_hidden", "t_client_ms": 1.0,
                "data": {}}]}).status_code

        assert [events(first) for _ in range(5)] == [202] * 4 + [429]
        refused = first.post("events", {"events": []})
        assert refused.json()["detail"].startswith("rate: too many requests from this session")
        assert [events(second) for _ in range(4)] == [202] * 4  # same address, own budget
        tokenless = [c.get("/api/session/state").status_code for _ in range(6)]
        assert tokenless == [422] * 5 + [429]  # without a session: keyed by the address


def test_made_up_session_tokens_share_one_ceiling_per_address(small_study, tmp_path):
    app = limited_app(small_study, tmp_path, requests="1/minute")
    with local_client(app, client=("203.0.113.9", 5000)) as c:
        made_up = [c.get("/api/session/state", headers={SESSION_HEADER: secrets.token_urlsafe(24)})
                   for _ in range(SESSIONS_PER_ADDRESS + 1)]
    assert [r.status_code for r in made_up] == [404] * SESSIONS_PER_ADDRESS + [429]
    assert made_up[-1].json()["detail"].startswith("rate: too many requests from this address")
    with local_client(app, client=("203.0.113.10", 5000)) as other:  # another address: its own
        assert other.get("/api/session/state", headers={
            SESSION_HEADER: secrets.token_urlsafe(24)}).status_code == 404


def test_the_limit_follows_the_address_a_local_proxy_forwards(small_study, tmp_path):
    """uvicorn takes X-Forwarded-For from a proxy on 127.0.0.1 (FORWARDED_ALLOW_IPS): each
    participant behind docs/run/hosting.md's Caddy or nginx has their own limit."""
    port = free_port()
    proc = start_server(small_study, f"sqlite:///{tmp_path / 'proxy.db'}", port,
                        log=tmp_path / "server.log", TOMSTUDY_RATE_LIMIT_STARTS="2/minute")
    try:
        def starts(address: str) -> list[int]:
            return [httpx.post(f"http://127.0.0.1:{port}/api/sessions",
                               headers={"X-Forwarded-For": address},
                               json={"study_id": small_study.study_id,
                                     "recruitment": prolific(new_id())},
                               timeout=patience(30)).status_code
                    for _ in range(3)]

        assert starts("192.0.2.10") == [201, 201, 429]
        assert starts("192.0.2.11") == [201, 201, 429]
    finally:
        proc.terminate()
        proc.wait(timeout=patience(10))


def test_production_refuses_to_run_without_rate_limits(small_study, tmp_path):
    from app.main import UnsafeSettings

    settings = small_study.settings(f"sqlite:///{tmp_path / 'p.db'}", production=True,
                                    admin_token="x" * 40)
    with pytest.raises(UnsafeSettings, match="TOMSTUDY_RATE_LIMIT_STARTS is empty"):
        create_app(settings, [small_study.study_id])
    settings = settings.model_copy(update={"rate_limit_starts": "lots",
                                           "rate_limit_requests": "9/minute"})
    with pytest.raises(UnsafeSettings, match="TOMSTUDY_RATE_LIMIT_STARTS: 'lots' is not a"):
        create_app(settings, [small_study.study_id])


# ---------------------------------------------------------------- live sessions cap

def age(client, token: str, days: float = 1) -> None:
    """Make a session look abandoned `days` ago."""
    with Session(client.app.state.engine) as db:
        db.exec(update(Participant).where(Participant.session_token == token)
                .values(updated_at=utcnow() - timedelta(days=days)))
        db.commit()


def test_a_study_runs_at_most_its_cap_of_unfinished_sessions(client, small_study, bank):
    sid = small_study.study_id
    with_cap(client, sid, per_target=1.5, target=2)  # cap 3
    people = [Client(client, sid) for _ in range(4)]
    for p in people:
        p.start()
    assert [p.status for p in people] == [201] * 4  # a start takes no place: consent does
    assert [p.consent().status_code for p in people] == [200, 200, 200, 503]
    busy = people[3].consent()
    assert busy.json()["detail"].startswith("study: 3 sessions are running")
    assert busy.headers["retry-after"] == "60"
    full = client.post("/api/sessions", json={"study_id": sid, "recruitment": prolific("late")})
    assert full.status_code == 503 and full.json()["detail"].startswith("study: 3 sessions")
    lab = Client(client, sid)
    lab.start(preview=preview_key(TOKEN, sid))
    assert lab.status == 201 and lab.consent().status_code == 200  # a preview is never refused
    assert client.post(people[0].url("instructions"), headers=people[0].headers,
                       json={"submission_id": new_id()}).status_code == 200
    people[0].finish(bank)  # the running ones keep going; a completion makes room
    assert people[3].consent().status_code == 200  # the page's retry gets in
    late = Client(client, sid)
    late.start()
    assert late.status == 503  # the cap is full again
    age(client, people[1].token)  # a session gone stale makes room, before any sweep
    late.start()
    assert late.status == 201 and late.consent().status_code == 200


# ---------------------------------------------------------------- stale sessions

def counted_sessions(engine) -> int:
    with Session(engine) as db:
        return db.execute(select(func.count()).where(Participant.counted.is_(True))).scalar_one()


def test_stale_sessions_are_released_in_bounded_batches_not_by_a_start(small_study, db_url):
    settings = small_study.settings(db_url, stale_sweep_s=3600)  # no background sweep here
    with local_client(create_app(settings, [small_study.study_id])) as client:
        release_in_batches(client, small_study.study_id)


def release_in_batches(client, sid: str) -> None:
    with_cap(client, sid, per_target=100, target=22)
    ctx = client.app.state.studies[sid]
    engine = client.app.state.engine
    tokens = []
    for _ in range(2 * balance.STALE_BATCH + 50):
        p = Client(client, sid)
        p.start()
        assert p.consent().status_code == 200  # counted from consent on
        tokens.append(p.token)
    with Session(engine) as db:
        db.exec(update(Participant).values(updated_at=utcnow() - timedelta(days=1)))
        db.commit()
    late = Client(client, sid)
    late.start()  # neither a start nor a consent does release work
    assert late.consent().status_code == 200
    assert counted_sessions(engine) == len(tokens) + 1
    batches = [balance.release_stale_batch(engine, ctx) for _ in range(4)]
    assert batches == [balance.STALE_BATCH, balance.STALE_BATCH, 50, 0]
    assert counted_sessions(engine) == 1
    with Session(engine) as db:
        counts = {k: v for k, v in balance.read_counts(db, sid).items() if v}
        assert counts == balance.recount(db, ctx)  # exactly the one live session's keys


def test_each_worker_sweeps_stale_sessions_in_the_background(client, small_study):
    sid = small_study.study_id
    ctx = client.app.state.studies[sid]
    engine = client.app.state.engine
    p = Client(client, sid)
    p.start()
    p.consent()
    age(client, p.token)

    async def sweep_a_little() -> None:
        task = asyncio.create_task(balance.sweep_stale(engine, [ctx], interval_s=0.05))
        deadline = time.monotonic() + patience(10)
        while counted_sessions(engine) and time.monotonic() < deadline:
            await asyncio.sleep(0.05)
        task.cancel()

    asyncio.run(sweep_a_little())
    assert counted_sessions(engine) == 0
