"""Rate limits and the researcher lockout counted in one Redis (TOMSTUDY_RATE_LIMIT_STORAGE)
hold once across workers and servers; memory:// counts per process; a Redis gone mid-run
lets requests through (fails open, logged), and serve refuses a store it cannot use."""

import time

import pytest

from app.http.limitstore import RETRY_S
from app.http.preflight import check_rate_limit_storage
from tests.conftest import (
    ADMIN_TOKEN,
    free_port,
    fresh_database,
    start_server,
    stop_server,
    wait_for_log,
)
from tests.http.serve_preflight import run_serve
from tests.server.starts import researcher_status, send_starts, start_once

# a day, not a minute: the starts limit is a sliding-window counter, which lets a start or two
# more through once a window edge passes mid-test (42 of 45 accepted where 40 were due, seen
# in make test); a day's edge falls inside a test's half minute almost never
STARTS_PER_DAY = 20
SENT = 45
LIMITS = {"TOMSTUDY_RATE_LIMIT_STARTS": f"{STARTS_PER_DAY}/day",
          "TOMSTUDY_RESEARCHER_LOCKOUT": "4 per 10 minutes"}


@pytest.fixture
def serving(small_study, postgres_url, tmp_path, request):
    """Start `tomstudy serve` processes on one fresh PostgreSQL database; stopped after."""
    db_url = fresh_database(postgres_url, f"limits_{request.node.name[-40:].lower()}")
    procs = []

    def serve(storage: str, workers: int = 1) -> int:
        port = free_port()
        procs.append(start_server(small_study, db_url, port, workers=workers,
                                  log=tmp_path / f"server-{port}.log",
                                  TOMSTUDY_RATE_LIMIT_STORAGE=storage, **LIMITS))
        return port

    serve.logs = lambda: "".join(p.read_text() for p in tmp_path.glob("server-*.log"))
    serve.log_of = lambda port: tmp_path / f"server-{port}.log"
    yield serve
    for proc in procs:
        stop_server(proc)


@pytest.mark.postgres
def test_two_workers_sharing_redis_accept_one_limit_of_starts(serving, redis_server,
                                                              small_study):
    port = serving(redis_server.url, workers=2)
    # both serving (start_server returns once one answers), so either may take a start
    assert len(wait_for_log(serving.log_of(port), "Application startup complete", 2)) == 2
    statuses = send_starts([port], small_study.study_id, "127.1.0.1", SENT)
    assert statuses.count(201) == STARTS_PER_DAY
    assert statuses.count(429) == SENT - STARTS_PER_DAY
    # another address has its own budget
    assert start_once(port, small_study.study_id, "127.1.0.2", "other") == 201


@pytest.mark.postgres
def test_two_servers_sharing_redis_accept_one_limit_and_memory_two(serving, redis_server,
                                                                   small_study):
    shared = [serving(redis_server.url), serving(redis_server.url)]
    statuses = send_starts(shared, small_study.study_id, "127.1.0.3", SENT)
    assert (statuses.count(201), statuses.count(429)) == (20, 25)
    separate = [serving("memory://"), serving("memory://")]  # the before: one limit each
    statuses = send_starts(separate, small_study.study_id, "127.1.0.4", SENT)
    assert (statuses.count(201), statuses.count(429)) == (40, 5)


@pytest.mark.postgres
def test_the_researcher_lockout_is_shared_through_redis(serving, redis_server, small_study):
    study = small_study.study_id
    ports = [serving(redis_server.url), serving(redis_server.url)]
    wrong = [researcher_status(ports[i % 2], study, "127.1.0.5", "wrong-token")
             for i in range(5)]
    assert wrong == [403] * 4 + [429]  # 4 failures across both servers lock the address out
    assert researcher_status(ports[1], study, "127.1.0.5", ADMIN_TOKEN) == 429  # right one too
    assert researcher_status(ports[0], study, "127.1.0.6", ADMIN_TOKEN) == 200  # another address


@pytest.mark.postgres
def test_a_redis_gone_mid_run_lets_requests_through_and_limits_come_back(
        serving, redis_server, small_study):
    port = serving(redis_server.url)
    assert send_starts([port], small_study.study_id, "127.1.0.7", 5) == [201] * 5
    redis_server.stop()
    statuses = send_starts([port], small_study.study_id, "127.1.0.7", 30)
    assert statuses == [201] * 30  # fails open: more than the limit, none refused
    study = small_study.study_id
    assert [researcher_status(port, study, "127.1.0.8", "wrong-token")
            for _ in range(6)] == [403] * 6  # the lockout (4) is off too
    assert researcher_status(port, study, "127.1.0.8", ADMIN_TOKEN) == 200
    assert "rate-limit store redis://127.0.0.1" in serving.logs()
    assert "cannot be reached" in serving.logs()
    redis_server.start()  # empty again: counting starts over once each worker asks again
    time.sleep(RETRY_S + 1)
    statuses = send_starts([port], small_study.study_id, "127.1.0.7", 25)
    assert (statuses.count(201), statuses.count(429)) == (20, 5)


# ---------------------------------------------------------------- serve's preflight

def test_serve_refuses_a_store_it_cannot_reach_or_does_not_know(small_study, tmp_path):
    for storage, says in (("redis://127.0.0.1:1/0", "cannot reach redis://127.0.0.1:1/0"),
                          ("mongo-ish://x", "is not a rate-limit store"),
                          ("", "is empty")):
        run = run_serve(small_study, tmp_path, TOMSTUDY_RATE_LIMIT_STORAGE=storage)
        assert run.returncode == 2, run.stderr
        assert "TOMSTUDY_RATE_LIMIT_STORAGE" in run.stderr and says in run.stderr
        assert "Traceback" not in run.stderr


@pytest.mark.postgres
def test_several_workers_counting_in_memory_are_refused_in_production(small_study, tmp_path,
                                                                      postgres_url):
    db_url = fresh_database(postgres_url, "limits_production")
    run = run_serve(small_study, tmp_path, "--host", "0.0.0.0", "--workers", "2",
                    DATABASE_URL=db_url, TOMSTUDY_ADMIN_TOKEN="x" * 40, **LIMITS,
                    TOMSTUDY_RATE_LIMIT_REQUESTS="120/minute")
    assert run.returncode == 2, run.stderr
    assert "--workers 2 with TOMSTUDY_RATE_LIMIT_STORAGE=memory://" in run.stderr
    assert "up to 2 times each limit" in run.stderr and "Traceback" not in run.stderr


def test_several_workers_counting_in_memory_on_loopback_are_warned_about(small_study,
                                                                        tmp_path):
    settings = small_study.settings("postgresql+psycopg://u@127.0.0.1:1/db",
                                    rate_limit_starts="20/minute")
    said = []
    check_rate_limit_storage(settings, 2, say=said.append)
    assert said == ["warning: --workers 2 with TOMSTUDY_RATE_LIMIT_STORAGE=memory://: each "
                    "worker counts the rate limits in its own memory, so a client gets up to "
                    "2 times each limit; set it to a Redis every worker shares "
                    "(redis://host:6379/0)"]
    check_rate_limit_storage(settings, 1, say=said.append)  # one worker: nothing to say
    assert len(said) == 1
