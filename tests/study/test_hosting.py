"""Hosting on the internet: fail-closed researcher auth, headers, docs, health, database limits."""

import re
import socket
import subprocess
import time
from contextlib import contextmanager

import pytest
from fastapi.testclient import TestClient
from sqlalchemy.engine import make_url

from app.cli import server_settings
from app.settings import DEFAULT_ADMIN_TOKEN, Settings, get_settings, is_loopback
from app.study.db import CONNECT_TIMEOUT_S, make_engine, server_connect_args
from app.study.main import (
    FRONTEND_DIR,
    MAX_BODY_BYTES,
    UnsafeSettings,
    app_from_env,
    check_production,
    create_app,
)
from tests.conftest import REPO, TOMSTUDY, free_port
from tests.study.flow import Participant

STRONG_TOKEN = "x" * 40


def study_settings(small_study, tmp_path, **overrides) -> Settings:
    """Settings of the small study on a fresh SQLite file."""
    return small_study.settings(f"sqlite:///{tmp_path / 'study.db'}", **overrides)


def run_serve(small_study, tmp_path, *args: str, **env: str) -> subprocess.CompletedProcess:
    """`tomstudy serve ARGS` on a fresh database; a refusal must come before it serves."""
    environment = small_study.env(f"sqlite:///{tmp_path / 'serve.db'}", **env)
    return subprocess.run([TOMSTUDY, "serve", "--port", str(free_port()), "--study",
                           small_study.study_id, *args], env=environment, cwd=REPO,
                          capture_output=True, text=True, timeout=60)


# ---------------------------------------------------------------- researcher token

@pytest.mark.parametrize(("host", "loopback"), [
    ("127.0.0.1", True), ("127.8.9.10", True), ("::1", True), ("[::1]", True),
    ("localhost", True), ("LOCALHOST", True), ("0.0.0.0", False), ("::", False),
    ("192.168.1.20", False), ("example.org", False), ("", False)])
def test_only_loopback_hosts_count_as_private(host, loopback):
    assert is_loopback(host) is loopback
    assert Settings().for_host(host).production is not loopback


@pytest.mark.parametrize(("token", "problem"), [
    (DEFAULT_ADMIN_TOKEN, "is the default"), ("test-token", "has 10 characters"),
    (" " * 40 + "short", "has 5 characters")])
def test_production_refuses_a_default_or_short_token(small_study, tmp_path, token, problem):
    settings = study_settings(small_study, tmp_path, admin_token=token, production=True)
    with pytest.raises(UnsafeSettings) as refused:
        create_app(settings, [small_study.study_id])
    message = str(refused.value)
    assert "TOMSTUDY_ADMIN_TOKEN" in message and problem in message
    assert "secrets.token_urlsafe(32)" in message


def test_production_accepts_a_long_token_and_loopback_any_token(small_study, tmp_path):
    check_production(study_settings(small_study, tmp_path, admin_token=STRONG_TOKEN,
                                    production=True))
    check_production(study_settings(small_study, tmp_path).for_host("127.0.0.1"))


def test_production_env_refuses_the_uvicorn_factory_too(monkeypatch):
    monkeypatch.setenv("TOMSTUDY_PRODUCTION", "1")
    monkeypatch.setenv("TOMSTUDY_ADMIN_TOKEN", "test-token")
    get_settings.cache_clear()
    try:
        with pytest.raises(UnsafeSettings, match="TOMSTUDY_ADMIN_TOKEN has 10 characters"):
            app_from_env()
    finally:
        get_settings.cache_clear()


def test_serve_off_loopback_hands_production_mode_to_the_app(small_study, monkeypatch):
    monkeypatch.setenv("TOMSTUDY_ADMIN_TOKEN", STRONG_TOKEN)
    monkeypatch.setenv("TOMSTUDY_DATA_DIR", str(small_study.data_dir))
    monkeypatch.setenv("TOMSTUDY_PRODUCTION", "0")  # so monkeypatch undoes serve's "1"
    get_settings.cache_clear()
    try:
        assert server_settings("0.0.0.0", workers=1).production
        app = app_from_env()  # what uvicorn calls, in this process or in each worker
        assert app.state.settings.production and app.docs_url is None
    finally:
        get_settings.cache_clear()


@pytest.mark.parametrize("token", [DEFAULT_ADMIN_TOKEN, "test-token"])
def test_serve_off_loopback_refuses_a_weak_token(small_study, tmp_path, token):
    run = run_serve(small_study, tmp_path, "--host", "0.0.0.0", TOMSTUDY_ADMIN_TOKEN=token)
    assert run.returncode == 2, run.stderr
    assert run.stderr.startswith("error: refusing to start in production mode")
    assert "TOMSTUDY_ADMIN_TOKEN=$(python -c 'import secrets" in run.stderr
    assert "Traceback" not in run.stderr



def test_serve_refuses_several_workers_on_sqlite(small_study, tmp_path):
    run = run_serve(small_study, tmp_path, "--workers", "2")
    assert run.returncode == 2, run.stderr
    assert "--workers 2" in run.stderr and "DATABASE_URL" in run.stderr
    assert "Traceback" not in run.stderr


# ---------------------------------------------------------------- security headers

@pytest.fixture(scope="module")
def client(small_study, tmp_path_factory):
    """The small study's app (not production) on a fresh SQLite file."""
    settings = study_settings(small_study, tmp_path_factory.mktemp("hosting"))
    with TestClient(create_app(settings, [small_study.study_id])) as c:
        yield c


def assert_security_headers(response) -> None:
    """The strict policy and the fixed headers, once each."""
    csp = response.headers["content-security-policy"]
    directives = dict(d.strip().split(" ", 1) for d in csp.split(";"))
    assert directives["default-src"] == "'none'"
    assert directives["script-src"] == "'self'" and directives["style-src"] == "'self'"
    assert directives["connect-src"] == "'self'" and directives["img-src"] == "'self' data:"
    assert directives["frame-ancestors"] == "'none'"
    assert directives["form-action"].split() == [
        "'self'", "https://app.prolific.com", "https://www.mturk.com",
        "https://workersandbox.mturk.com"]
    assert response.headers["x-content-type-options"] == "nosniff"
    assert response.headers["referrer-policy"] == "no-referrer"
    assert response.headers["x-frame-options"] == "DENY"
    assert response.headers["cross-origin-opener-policy"] == "same-origin"
    assert len(response.headers.get_list("content-security-policy")) == 1


def test_security_headers_on_pages_api_static_files_and_errors(client, small_study):
    p = Participant(client, small_study.study_id)
    p.start()
    answers = {
        "page": client.get(f"/s/{small_study.study_id}"),
        "landing": client.get("/"),
        "api": client.get(p.url("state")),
        "static js": client.get("/static/js/app.js"),
        "static css": client.get("/static/css/style.css"),
        "unknown session": client.get("/api/sessions/nope/state"),
        "unknown path": client.get("/no/such/page"),
        "too large": client.post(p.url("events"), content=b"[" * (MAX_BODY_BYTES + 1),
                                 headers={"content-type": "application/json"}),
        "invalid": client.post(p.url("consent"), json={"agree": "maybe"}),
    }
    statuses = {what: r.status_code for what, r in answers.items()}
    assert statuses == {"page": 200, "landing": 200, "api": 200, "static js": 200,
                        "static css": 200, "unknown session": 404, "unknown path": 404,
                        "too large": 413, "invalid": 422}
    for response in answers.values():
        assert_security_headers(response)


def test_templates_need_no_inline_script_or_style():
    """What lets the policy say script-src 'self' and style-src 'self' and nothing more."""
    for template in (FRONTEND_DIR / "templates").glob("*.html"):
        html = template.read_text()
        assert not re.search(r"<script(?![^>]*\bsrc=)[^>]*>", html), template.name
        assert not re.search(r"<style|\sstyle=|\son[a-z]+=|javascript:", html, re.I), template.name


def test_docs_pages_get_the_docs_policy_only(client):
    docs = client.get("/docs")
    assert docs.status_code == 200
    assert "https://cdn.jsdelivr.net" in docs.headers["content-security-policy"]
    assert docs.headers["x-frame-options"] == "DENY"
    assert "cdn.jsdelivr.net" not in client.get("/").headers["content-security-policy"]


# ---------------------------------------------------------------- API docs

DOCS = ("/docs", "/redoc", "/openapi.json")


def test_api_docs_are_off_in_production(small_study, tmp_path):
    settings = study_settings(small_study, tmp_path, admin_token=STRONG_TOKEN, production=True)
    with TestClient(create_app(settings, [small_study.study_id])) as production:
        assert {path: production.get(path).status_code for path in DOCS} == dict.fromkeys(DOCS, 404)
        assert production.get(f"/s/{small_study.study_id}").status_code == 200


def test_api_docs_are_served_outside_production(client):
    assert {path: client.get(path).status_code for path in DOCS} == dict.fromkeys(DOCS, 200)


# ---------------------------------------------------------------- health and database

@contextmanager
def silent_port():
    """A port that accepts TCP connections and never answers (a hung database server)."""
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        sock.listen(8)
        yield sock.getsockname()[1]


def test_healthz_is_200_when_the_database_answers(client):
    r = client.get("/healthz")
    assert r.status_code == 200 and r.json() == {"status": "ok", "database": "ok"}
    assert r.headers["cache-control"] == "no-store"
    assert_security_headers(r)


def test_healthz_is_503_with_a_short_reason_when_the_database_is_down(small_study, tmp_path):
    with TestClient(create_app(study_settings(small_study, tmp_path),
                               [small_study.study_id])) as c:
        c.app.state.engine = make_engine(f"postgresql://nobody@127.0.0.1:{free_port()}/gone")
        r = c.get("/healthz")
    assert r.status_code == 503
    assert r.json() == {"status": "error", "database": "unavailable (OperationalError)"}
    assert "127.0.0.1" not in r.text and "nobody" not in r.text


def test_postgres_engines_get_a_connect_timeout():
    assert CONNECT_TIMEOUT_S == 10
    assert server_connect_args(make_url("postgresql+psycopg://u@db/x"), 10) == {
        "connect_timeout": 10}
    assert server_connect_args(make_url("postgresql+psycopg://u@db/x?connect_timeout=3"),
                               10) == {}  # the URL's own wins
    assert server_connect_args(make_url("sqlite:///study.db"), 10) == {}


def test_a_hung_postgres_fails_within_the_connect_timeout_not_forever(small_study, tmp_path):
    with silent_port() as port, TestClient(create_app(study_settings(small_study, tmp_path),
                                                      [small_study.study_id])) as c:
        c.app.state.engine = make_engine(f"postgresql://u@127.0.0.1:{port}/x",
                                         connect_timeout_s=2)  # psycopg's minimum
        started = time.monotonic()
        r = c.get("/healthz")
        assert time.monotonic() - started < 10
    assert r.status_code == 503 and r.json()["database"] == "unavailable (ConnectionTimeout)"


# ---------------------------------------------------------------- OpenAPI

def test_schema_declares_the_error_statuses_and_bodies():
    spec = create_app(Settings(production=False, admin_token="test-token")).openapi()
    declared = {f"{method.upper()} {path}": sorted(int(s) for s in op["responses"])
                for path, ops in spec["paths"].items() for method, op in ops.items()}
    assert declared["POST /api/sessions"] == [200, 201, 400, 403, 404, 409, 413, 422]
    assert declared["GET /api/sessions/{token}/state"] == [200, 404, 422]
    assert declared["POST /api/sessions/{token}/predictions"] == [
        200, 201, 400, 404, 409, 413, 422]
    assert declared["GET /api/researcher/export.csv"] == [200, 401, 403, 404, 422]
    assert declared["GET /healthz"] == [200, 503]
    responses = spec["paths"]["/api/sessions/{token}/events"]["post"]["responses"]
    body = {s: r["content"]["application/json"]["schema"]["$ref"].rsplit("/", 1)[1]
            for s, r in responses.items() if s != "202"}
    assert body == {"400": "ErrorDetail", "404": "ErrorDetail", "409": "ErrorDetail",
                    "413": "ErrorDetail", "422": "ValidationProblem"}
    assert "HTTPValidationError" not in spec["components"]["schemas"]


def test_an_mturk_study_may_be_framed_by_mturk_only():
    from app.study.headers import MTURK_FRAMERS, SecurityHeaders

    framed = dict(SecurityHeaders(None, framed_by=MTURK_FRAMERS).app_headers)
    policy = framed[b"content-security-policy"].decode()
    assert "frame-ancestors 'self' https://worker.mturk.com" in policy
    assert b"x-frame-options" not in framed  # it cannot name MTurk; the CSP directive does
    closed = dict(SecurityHeaders(None).app_headers)
    assert "frame-ancestors 'none'" in closed[b"content-security-policy"].decode()
    assert closed[b"x-frame-options"] == b"DENY"


def test_a_database_of_an_older_schema_is_refused_with_what_to_do(small_study, tmp_path):
    import sqlite3

    db = tmp_path / "old.db"
    with sqlite3.connect(db) as conn:  # the participant table before issue 10
        conn.execute("CREATE TABLE participant (id INTEGER PRIMARY KEY, study_id VARCHAR)")
    run = subprocess.run([TOMSTUDY, "serve", "--port", "1",
                          "--study", small_study.study_id],
                         env=small_study.env(f"sqlite:///{db}"), capture_output=True, text=True,
                         timeout=120)
    assert run.returncode == 2 and "Traceback" not in run.stderr
    assert "older tomstudy" in run.stderr and "`tomstudy db upgrade`" in run.stderr
