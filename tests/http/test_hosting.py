"""Hosting on the internet: fail-closed researcher auth, headers, docs, health, database limits."""

import re
import socket
import subprocess
import time
from contextlib import contextmanager

import httpx
import pytest
from sqlalchemy import event
from sqlalchemy.engine import make_url

from app.http.preflight import (
    STUDY_ENV,
    hand_to_workers,
    serve_settings,
    worker_environment,
)
from app.main import (
    FRONTEND_DIR,
    MAX_BODY_BYTES,
    UnsafeSettings,
    app_from_env,
    check_production,
    create_app,
)
from app.server.storage.db import CONNECT_TIMEOUT_S, make_engine, server_connect_args
from app.settings import Settings, get_settings, is_loopback
from tests.conftest import (
    ADMIN_TOKEN,
    REPO,
    TOMSTUDY,
    free_port,
    local_client,
    patience,
    researcher_get,
)
from tests.http.serve_preflight import run_serve
from tests.server.flow import ADMIN, Participant

STRONG_TOKEN = "x" * 40
OLD_DEFAULT_TOKEN = "change-me-researcher-token"  # the default before issue 22 removed it
LIMITS_ON = {"rate_limit_starts": "20/minute", "rate_limit_requests": "300/minute"}
PRODUCTION = {"production": True, "admin_token": STRONG_TOKEN, **LIMITS_ON}


def study_settings(small_study, tmp_path, **overrides) -> Settings:
    """Settings of the small study on a fresh SQLite file."""
    return small_study.settings(f"sqlite:///{tmp_path / 'study.db'}", **overrides)


# ---------------------------------------------------------------- researcher token

@pytest.mark.parametrize(("host", "loopback"), [
    ("127.0.0.1", True), ("127.8.9.10", True), ("::1", True), ("[::1]", True),
    ("localhost", True), ("LOCALHOST", True), ("0.0.0.0", False), ("::", False),
    ("192.168.1.20", False), ("example.org", False), ("", False)])
def test_only_loopback_hosts_count_as_private(host, loopback):
    assert is_loopback(host) is loopback
    assert Settings().for_host(host).production is not loopback


@pytest.mark.parametrize(("token", "problem"), [
    ("", "is not set"), (OLD_DEFAULT_TOKEN, "has 26 characters"),
    ("test-token", "has 10 characters"), (" " * 40 + "short", "has 5 characters")])
def test_production_refuses_an_unset_or_short_token(small_study, tmp_path, token, problem):
    settings = study_settings(small_study, tmp_path, **PRODUCTION | {"admin_token": token})
    with pytest.raises(UnsafeSettings) as refused:
        create_app(settings, [small_study.study_id])
    message = str(refused.value)
    assert "TOMSTUDY_ADMIN_TOKEN" in message and problem in message
    assert "secrets.token_urlsafe(32)" in message


def test_production_accepts_a_long_token_and_loopback_any_token(small_study, tmp_path):
    check_production(study_settings(small_study, tmp_path, **PRODUCTION))
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
    monkeypatch.setenv(STUDY_ENV, "paper_study")  # and the study it hands over
    get_settings.cache_clear()
    try:
        settings = serve_settings(get_settings(), "0.0.0.0")
        assert settings.production
        hand_to_workers(settings, ["paper_study"])
        app = app_from_env()  # what uvicorn calls, in this process or in each worker
        assert app.state.settings.production and app.docs_url is None
    finally:
        get_settings.cache_clear()


def test_workers_get_what_serve_decided_but_never_a_token_kept_in_a_file(tmp_path):
    settings = serve_settings(Settings(admin_token=STRONG_TOKEN), "0.0.0.0",
                              allow_bank_change=True)
    assert worker_environment(settings, ["a", "b"]) == {
        STUDY_ENV: "a,b", "TOMSTUDY_ALLOW_BANK_CHANGE": "1", "TOMSTUDY_PRODUCTION": "1",
        "TOMSTUDY_ADMIN_TOKEN": STRONG_TOKEN}
    (tmp_path / "token").write_text(STRONG_TOKEN)
    from_file = Settings(admin_token_file=tmp_path / "token").for_host("127.0.0.1")
    assert worker_environment(from_file, ["a"]) == {STUDY_ENV: "a"}


@pytest.mark.parametrize("token", ["", OLD_DEFAULT_TOKEN, "test-token"])
def test_serve_off_loopback_refuses_an_unset_or_weak_token(small_study, tmp_path, token):
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
    with local_client(create_app(settings, [small_study.study_id])) as c:
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
        "api": p.get("state"),
        "static js": client.get("/static/js/app.js"),
        "static css": client.get("/static/css/style.css"),
        "unknown session": client.get("/api/session/state", headers={"X-Session-Token": "no"}),
        "unknown path": client.get("/no/such/page"),
        "too large": p.post("events", None, content=b"[" * (MAX_BODY_BYTES + 1),
                            headers={"content-type": "application/json"}),
        "invalid": p.post("consent", {"agree": "maybe"}),
    }
    statuses = {what: r.status_code for what, r in answers.items()}
    assert statuses == {"page": 200, "landing": 200, "api": 200, "static js": 200,
                        "static css": 200, "unknown session": 404, "unknown path": 404,
                        "too large": 413, "invalid": 422}
    for response in answers.values():
        assert_security_headers(response)


def test_templates_need_no_inline_script_or_style():
    """What lets the policy say script-src 'self' and style-src 'self' and nothing more (a
    JSON data block is never run, so the policy does not cover it)."""
    templates = sorted((FRONTEND_DIR / "templates").glob("*.html"))
    assert {t.name for t in templates} >= {"base.html", "index.html", "study.html",
                                           "researcher.html", "notice.html",
                                           "mturk_preview.html"}
    for template in templates:
        html = template.read_text()
        assert not re.search(r"<script(?![^>]*\b(src=|type=\"application/json\"))[^>]*>", html), \
            template.name
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
    settings = study_settings(small_study, tmp_path, **PRODUCTION)
    with local_client(create_app(settings, [small_study.study_id])) as production:
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
    with local_client(create_app(study_settings(small_study, tmp_path),
                               [small_study.study_id])) as c:
        c.app.state.engine = make_engine(f"postgresql://nobody@127.0.0.1:{free_port()}/gone")
        r = c.get("/healthz")
    assert r.status_code == 503
    assert r.json() == {"status": "error", "database": "unavailable (OperationalError)"}
    assert "127.0.0.1" not in r.text and "nobody" not in r.text


class _Dialled(Exception):
    """Raised in place of the driver's connect, once its arguments are seen."""


def driver_arguments(url: str) -> dict:
    """The keyword arguments make_engine's engine hands the database driver on connect."""
    engine, seen = make_engine(url), {}

    def capture(_dialect, _record, _cargs, cparams):
        seen.update(cparams)
        raise _Dialled

    event.listen(engine, "do_connect", capture)
    with pytest.raises(_Dialled):
        engine.connect()
    return seen


def test_postgres_engines_get_a_connect_timeout(tmp_path):
    # docs/run/hosting.md's "its connections give up after 10 s"
    assert driver_arguments("postgresql://u@db/x")["connect_timeout"] == CONNECT_TIMEOUT_S == 10
    assert driver_arguments("postgresql://u@db/x?connect_timeout=3")["connect_timeout"] == "3"
    assert "connect_timeout" not in driver_arguments(f"sqlite:///{tmp_path / 'study.db'}")
    assert server_connect_args(make_url("postgresql+psycopg://u@db/x"), 10) == {
        "connect_timeout": 10}
    assert server_connect_args(make_url("postgresql+psycopg://u@db/x?connect_timeout=3"),
                               10) == {}  # the URL's own wins
    assert server_connect_args(make_url("sqlite:///study.db"), 10) == {}


def test_a_hung_postgres_fails_within_the_connect_timeout_not_forever(small_study, tmp_path):
    with silent_port() as port, local_client(create_app(study_settings(small_study, tmp_path),
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
    assert declared["POST /api/sessions"] == [200, 201, 400, 403, 404, 409, 413, 422, 429,
                                              503]
    assert declared["GET /api/session/state"] == [200, 404, 410, 422, 429, 503]
    assert declared["POST /api/session/predictions"] == [
        200, 201, 400, 404, 409, 410, 413, 422, 429, 503]
    assert declared["GET /api/researcher/export.csv"] == [200, 401, 403, 404, 422, 429, 503]
    assert declared["GET /healthz"] == [200, 503]
    responses = spec["paths"]["/api/session/events"]["post"]["responses"]
    body = {s: r["content"]["application/json"]["schema"]["$ref"].rsplit("/", 1)[1]
            for s, r in responses.items() if s != "202"}
    assert body == {"400": "ErrorDetail", "404": "ErrorDetail", "409": "ErrorDetail",
                    "410": "ErrorDetail", "413": "ErrorDetail", "422": "ValidationProblem",
                    "429": "ErrorDetail", "503": "ErrorDetail"}
    assert "HTTPValidationError" not in spec["components"]["schemas"]


def test_an_mturk_study_may_be_framed_by_mturk_only():
    from app.http.headers import MTURK_FRAMERS, SecurityHeaders

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
                         timeout=patience(120))
    assert run.returncode == 2 and "Traceback" not in run.stderr
    assert "older tomstudy" in run.stderr and "`tomstudy db upgrade`" in run.stderr


# ---------------------------------------------------------------- no default secret (issue 22)

def test_a_loopback_server_without_a_token_makes_one_and_the_old_default_opens_nothing(
        small_study, tmp_path):
    port = free_port()
    env = small_study.env(f"sqlite:///{tmp_path / 'gen.db'}")
    env.pop("TOMSTUDY_ADMIN_TOKEN")
    out = tmp_path / "serve.log"
    with open(out, "wb") as log:
        proc = subprocess.Popen([TOMSTUDY, "serve", "--host", "127.0.0.1", "--port", str(port),
                                 "--study", small_study.study_id], env=env, cwd=REPO,
                                stdout=log, stderr=subprocess.STDOUT)
    try:
        base = f"http://127.0.0.1:{port}"
        wait_for(base)
        printed = re.findall(r"researcher token for this run .*: (\S+)", out.read_text())
        assert len(printed) == 1 and len(printed[0]) >= 40  # printed once, 32 random bytes
        sheet = f"{base}/api/researcher/export/participants.csv?study_id={small_study.study_id}"
        old = researcher_get(sheet, token=OLD_DEFAULT_TOKEN)
        assert old.status_code == 403
        made = researcher_get(sheet, token=printed[0])
        assert made.status_code == 200 and made.text.startswith("export_version,study_id,")
    finally:
        proc.terminate()
        proc.wait(timeout=patience(10))


def wait_for(base: str) -> None:
    """Until the server at `base` answers /healthz (60 s at most)."""
    deadline = time.monotonic() + patience(60)
    while time.monotonic() < deadline:
        try:
            if httpx.get(f"{base}/healthz", timeout=patience(1)).status_code == 200:
                return
        except httpx.TransportError:
            pass
        time.sleep(0.2)
    raise AssertionError(f"{base} did not answer")


def test_the_app_factory_refuses_to_run_without_a_token(monkeypatch):
    monkeypatch.delenv("TOMSTUDY_ADMIN_TOKEN", raising=False)
    monkeypatch.delenv("TOMSTUDY_PRODUCTION", raising=False)
    get_settings.cache_clear()
    try:  # several workers would each make another token: the factory needs one given
        with pytest.raises(UnsafeSettings, match="TOMSTUDY_ADMIN_TOKEN is not set"):
            app_from_env()
    finally:
        get_settings.cache_clear()


def test_secrets_can_come_from_files(small_study, tmp_path):
    (tmp_path / "token").write_text(STRONG_TOKEN + "\n")
    (tmp_path / "pw").write_text("s3cret/+pw\n")
    settings = Settings(admin_token_file=tmp_path / "token", database_password_file=tmp_path / "pw",
                        database_url="postgresql+psycopg://tomstudy@db:5432/tomstudy")
    assert settings.admin_token == STRONG_TOKEN
    url = make_url(settings.resolved_database_url())
    assert url.password == "s3cret/+pw" and url.username == "tomstudy" and url.host == "db"
    run = run_serve(small_study, tmp_path, TOMSTUDY_ADMIN_TOKEN_FILE=str(tmp_path / "nope"))
    assert run.returncode == 2 and "Traceback" not in run.stderr
    assert "TOMSTUDY_ADMIN_TOKEN_FILE: cannot read" in run.stderr


# ---------------------------------------------------------------- Host header and caching

def test_only_configured_and_loopback_host_names_are_answered(small_study, tmp_path):
    settings = study_settings(small_study, tmp_path, allowed_hosts="study.example.org",
                              **PRODUCTION)  # a public name makes the server production
    with local_client(create_app(settings, [small_study.study_id])) as c:
        page = f"/s/{small_study.study_id}"
        answers = {host: c.get(page, headers={"host": host}).status_code
                   for host in ("study.example.org", "127.0.0.1:8000", "localhost",
                                "[::1]:8000", "rebind.attacker.example", "testserver")}
        assert answers == {"study.example.org": 200, "127.0.0.1:8000": 200, "localhost": 200,
                           "[::1]:8000": 200, "rebind.attacker.example": 400,
                           "testserver": 400}
        refused = c.get("/api/researcher/summary", headers={
            "host": "rebind.attacker.example", "authorization": f"Bearer {ADMIN_TOKEN}"})
        assert refused.status_code == 400
        assert_security_headers(refused)


def test_session_and_researcher_answers_are_never_stored_by_caches(client, small_study):
    p = Participant(client, small_study.study_id)
    p.start()
    stored = {"state": p.get("state"), "start": client.post("/api/sessions", json={
        "study_id": small_study.study_id, "recruitment": {}}),
        "summary": client.get(f"/api/researcher/summary?study_id={small_study.study_id}",
                              headers=ADMIN),
        "researcher page": client.get("/researcher")}
    assert {k: r.headers.get("cache-control") for k, r in stored.items()} == dict.fromkeys(
        stored, "no-store")
    assert "cache-control" not in client.get("/static/js/app.js").headers


def test_the_session_token_never_travels_in_a_url(client, small_study):
    p = Participant(client, small_study.study_id)
    p.start()
    paths = list(client.app.openapi()["paths"])
    session_paths = [path for path in paths if path.startswith("/api/session")]
    assert "/api/session/state" in session_paths
    assert not [path for path in session_paths if "{" in path]
    assert client.get(f"/api/sessions/{p.token}/state").status_code in (404, 405)
    assert p.get("state").status_code == 200


def test_serve_names_a_data_dir_it_cannot_write_instead_of_a_traceback(small_study, tmp_path):
    blocked = tmp_path / "a-file"
    blocked.write_text("")  # nothing can be created below a file (as root, too)
    run = run_serve(small_study, tmp_path, TOMSTUDY_DATA_DIR=str(blocked / "var"))
    assert run.returncode == 2 and "Traceback" not in run.stderr
    assert run.stderr.startswith(f"error: TOMSTUDY_DATA_DIR: {blocked / 'var'} is not writable")
    assert "chown" in run.stderr
