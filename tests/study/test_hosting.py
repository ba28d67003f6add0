"""Hosting on the internet: fail-closed researcher auth, headers, docs, health, database limits."""

import subprocess
import sys
from pathlib import Path

import pytest

from app.settings import DEFAULT_ADMIN_TOKEN, Settings, get_settings, is_loopback
from app.study.main import UnsafeSettings, app_from_env, check_production, create_app
from tests.conftest import REPO, free_port

STRONG_TOKEN = "x" * 40
TOMSTUDY = str(Path(sys.executable).parent / "tomstudy")


def study_settings(small_study, tmp_path, **overrides) -> Settings:
    """Settings of the small study on a fresh SQLite file."""
    values = dict(data_dir=small_study.data_dir, configs_dir=small_study.configs_dir,
                  database_url=f"sqlite:///{tmp_path / 'study.db'}", admin_token="test-token")
    return Settings(**values | overrides)


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


@pytest.mark.parametrize("token", [DEFAULT_ADMIN_TOKEN, "test-token"])
def test_serve_off_loopback_refuses_a_weak_token(small_study, tmp_path, token):
    run = run_serve(small_study, tmp_path, "--host", "0.0.0.0", TOMSTUDY_ADMIN_TOKEN=token)
    assert run.returncode == 2, run.stderr
    assert run.stderr.startswith("error: refusing to start in production mode")
    assert "TOMSTUDY_ADMIN_TOKEN=$(python -c 'import secrets" in run.stderr
    assert "Traceback" not in run.stderr
