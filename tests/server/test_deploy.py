"""compose.yaml and the image's entrypoint: real settings and commands, no secrets, two app
containers sharing PostgreSQL and Redis behind the only published service, a proxy."""

import ipaddress
import os
import re
import subprocess

import pytest
import typer
import yaml
from sqlalchemy.engine import make_url

from app.cli import cli
from app.http.limitstore import LimitStore
from app.settings import Settings
from tests.conftest import REPO, patience

COMPOSE = yaml.safe_load((REPO / "compose.yaml").read_text())
SERVER = COMPOSE["services"]["server"]
DB = COMPOSE["services"]["db"]
REDIS = COMPOSE["services"]["redis"]
PROXY = COMPOSE["services"]["proxy"]
APPS = {name: service for name, service in COMPOSE["services"].items()
        if "build" in service}  # the app containers: the image this repository builds
ENTRYPOINT = REPO / "app" / "server" / "entrypoint.sh"
REQUIRED = re.compile(r"\$\{(\w+):\?[^}]+\}")  # compose's ${VAR:?message}: unset stops `up`


def settings_env_names() -> set[str]:
    """Every environment variable app/settings.py reads."""
    prefix = Settings.model_config["env_prefix"]
    return {field.validation_alias or f"{prefix}{name}".upper()
            for name, field in Settings.model_fields.items()}


def serve_command():
    """The click command behind `tomstudy serve`."""
    return typer.main.get_command(cli).commands["serve"]


def serve_options() -> set[str]:
    return {opt for param in serve_command().params for opt in param.opts}


def test_the_server_environment_names_only_settings_the_app_reads():
    env = SERVER["environment"]
    assert set(env) <= settings_env_names()
    assert {"DATABASE_URL", "TOMSTUDY_ADMIN_TOKEN_FILE", "TOMSTUDY_DATABASE_PASSWORD_FILE",
            "TOMSTUDY_ALLOWED_HOSTS"} <= set(env)
    # production refuses bot clocks; the image sets production itself
    assert not {"TOMSTUDY_TRUST_CLIENT_CLOCK", "TOMSTUDY_PRODUCTION"} & set(env)


def test_secrets_come_from_files_never_from_the_environment():
    env, db_env = SERVER["environment"], DB["environment"]
    files = {name: spec["file"] for name, spec in COMPOSE["secrets"].items()}
    assert files == {"admin_token": "./secrets/admin_token",
                     "postgres_password": "./secrets/postgres_password"}
    assert set(SERVER["secrets"]) == set(files) and DB["secrets"] == ["postgres_password"]
    assert env["TOMSTUDY_ADMIN_TOKEN_FILE"] == "/run/secrets/admin_token"
    assert env["TOMSTUDY_DATABASE_PASSWORD_FILE"] == "/run/secrets/postgres_password"
    assert db_env["POSTGRES_PASSWORD_FILE"] == "/run/secrets/postgres_password"
    url = make_url(env["DATABASE_URL"])
    assert (url.drivername, url.host, url.password) == ("postgresql+psycopg", "db", None)
    assert (url.username, url.database) == (db_env["POSTGRES_USER"], db_env["POSTGRES_DB"])
    assert REQUIRED.fullmatch(env["TOMSTUDY_ALLOWED_HOSTS"])  # `up` stops until it is set


def test_no_secret_literal_in_any_service():
    secrets = [(name, value) for service in COMPOSE["services"].values()
               for name, value in service.get("environment", {}).items()
               if re.search("PASSWORD|TOKEN|SECRET|KEY", name)]
    assert {"TOMSTUDY_DATABASE_PASSWORD_FILE", "POSTGRES_PASSWORD_FILE"} <= {n for n, _ in secrets}
    for name, value in secrets:
        assert name.endswith("_FILE") and value.startswith("/run/secrets/"), name
    text = (REPO / "compose.yaml").read_text()
    # a long random-looking word outside ${...} and digests would be a pasted secret
    words = re.findall(r"[A-Za-z0-9_-]{24,}", re.sub(r"sha256:\w+", "", REQUIRED.sub("", text)))
    assert [w for w in words if re.search(r"\d", w) and re.search("[a-z]", w)
            and re.search("[A-Z]", w)] == []


def test_base_images_are_pinned_by_digest_and_the_database_is_checked_over_tcp():
    assert re.fullmatch(r"postgres:15@sha256:[0-9a-f]{64}", DB["image"])
    python = SERVER["build"]["args"]["PYTHON_IMAGE"]
    assert re.fullmatch(r"python:3\.11-slim@sha256:[0-9a-f]{64}", python)
    assert DB["healthcheck"]["test"][:4] == ["CMD", "pg_isready", "-h", "127.0.0.1"]


def test_only_the_proxy_publishes_a_port():
    assert set(APPS) == {"server", "server_b"}
    published = {name for name, service in COMPOSE["services"].items() if "ports" in service}
    assert published == {"proxy"}
    assert COMPOSE["networks"]["backend"]["internal"] is True
    for service in (DB, REDIS):
        assert service["networks"] == ["backend"]


def test_every_app_container_shares_the_database_and_the_rate_limit_store():
    for name, app in APPS.items():
        env = app["environment"]
        assert env["DATABASE_URL"] == SERVER["environment"]["DATABASE_URL"], name
        assert env["TOMSTUDY_RATE_LIMIT_STORAGE"] == "redis://redis:6379/0", name
        assert LimitStore(env["TOMSTUDY_RATE_LIMIT_STORAGE"]).shared  # a URI limits knows
        assert app["secrets"] == SERVER["secrets"] and app["command"] == SERVER["command"]
        assert set(app["networks"]) == {"backend", "frontend"}
    assert REDIS["healthcheck"]["test"] == ["CMD", "redis-cli", "ping"]
    assert re.fullmatch(r"redis:\d+\.\d+\.\d+(@sha256:[0-9a-f]{64})?", REDIS["image"])


def test_the_start_order_is_stores_then_one_app_then_the_other_then_the_proxy():
    healthy = {"condition": "service_healthy"}
    assert SERVER["depends_on"] == {"db": healthy, "redis": healthy}
    # one container builds a first start's study into the shared `var` volume, then the other
    assert APPS["server_b"]["depends_on"] == {"db": healthy, "redis": healthy, "server": healthy}
    assert PROXY["depends_on"] == {name: healthy for name in APPS}
    assert all(app["volumes"] == SERVER["volumes"] for app in APPS.values())


def test_the_proxy_balances_both_app_containers_and_the_apps_trust_only_it():
    caddyfile = (REPO / "deploy" / "Caddyfile").read_text()
    upstreams = re.search(r"^\s*reverse_proxy (.+?) \{", caddyfile, re.M).group(1).split()
    assert upstreams == [f"{name}:8000" for name in APPS]
    assert "./deploy/Caddyfile:/etc/caddy/Caddyfile:ro" in PROXY["volumes"]
    address = PROXY["networks"]["frontend"]["ipv4_address"]
    subnet = COMPOSE["networks"]["frontend"]["ipam"]["config"][0]["subnet"]
    assert ipaddress.ip_address(address) in ipaddress.ip_network(subnet)
    for app in APPS.values():
        assert app["environment"]["TOMSTUDY_TRUSTED_PROXIES"] == address
    assert re.fullmatch(r"caddy:\d+\.\d+\.\d+(@sha256:[0-9a-f]{64})?", PROXY["image"])


def test_server_waits_for_a_healthy_database_and_keeps_its_data_in_a_named_volume():
    assert DB["healthcheck"]["test"]
    assert SERVER["depends_on"]["db"]["condition"] == "service_healthy"
    data_dir = re.search(r"TOMSTUDY_DATA_DIR=(\S+)", (REPO / "Dockerfile").read_text()).group(1)
    for service, target in ((SERVER, data_dir), (DB, "/var/lib/postgresql/data")):
        volume = next(v for v in service["volumes"] if v.endswith(f":{target}"))
        assert volume.split(":")[0] in COMPOSE["volumes"]


def test_compose_command_and_entrypoint_call_real_serve_options():
    options = serve_options()
    assert {a for a in SERVER["command"] if a.startswith("-")} <= options
    calls = re.findall(r"^\s*exec tomstudy (\S+)(.*)$", ENTRYPOINT.read_text(), re.M)
    assert [name for name, _ in calls] == ["serve"]
    assert set(re.findall(r"--[\w-]+", calls[0][1])) <= options
    assert "--prepare" in options


def test_the_image_runs_the_entrypoint_and_the_build_context_leaves_secrets_out():
    dockerfile = (REPO / "Dockerfile").read_text()
    assert 'ENTRYPOINT ["dumb-init", "--", "/app/app/server/entrypoint.sh"]' in dockerfile
    assert "COPY app ./app" in dockerfile  # the entrypoint comes with the package
    assert os.access(ENTRYPOINT, os.X_OK)
    ignored = (REPO / ".dockerignore").read_text().split()
    assert {"var", ".venv", "*.env"} <= set(ignored)


# ---------------------------------------------------------------- the entrypoint, run

@pytest.fixture
def run_entrypoint(tmp_path):
    """Run app/server/entrypoint.sh with a stand-in `tomstudy` that prints its arguments."""
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    fake = bin_dir / "tomstudy"
    fake.write_text('#!/bin/sh\necho "tomstudy $*"\n')
    fake.chmod(0o755)
    data_dir = tmp_path / "var"

    def run(*args: str) -> list[str]:
        env = dict(os.environ, PATH=f"{bin_dir}:{os.environ['PATH']}",
                   TOMSTUDY_DATA_DIR=str(data_dir), TOMSTUDY_HEALTHZ_FILE=str(run.healthz))
        done = subprocess.run(["sh", str(ENTRYPOINT), *args], env=env, capture_output=True,
                              text=True, timeout=patience(10), check=True)
        return done.stdout.splitlines()

    run.data_dir = data_dir
    run.healthz = tmp_path / "healthz"
    return run


@pytest.mark.parametrize("args", [[], ["--workers", "2"], ["--study", "paper_study,other"],
                                  ["--study=paper_study,other"]])
def test_every_start_prepares_then_serves_with_the_options_given(run_entrypoint, args):
    # --prepare builds nothing for a shipped bundle or a built one that exists
    # (tests/bank/test_bundle.py): only a `built` study without its bundle is built first
    assert run_entrypoint(*args) == [" ".join(["tomstudy serve --host 0.0.0.0 --port 8000 "
                                               "--prepare", *args])]


def test_a_command_instead_of_options_runs_that_command(run_entrypoint):
    assert run_entrypoint("tomstudy", "preview-link") == ["tomstudy preview-link"]


def test_the_image_installs_pinned_dependencies_before_its_code_and_runs_as_a_user():
    dockerfile = (REPO / "Dockerfile").read_text()
    steps = [line.split()[0] + " " + line.split()[1] for line in dockerfile.splitlines()
             if line.startswith(("COPY", "RUN"))]
    assert steps[:2] == ["COPY requirements/runtime.txt", "RUN pip"]  # no code yet
    assert "pip install -r requirements/runtime.txt" in dockerfile
    assert "pip install --no-deps --no-build-isolation -e ." in dockerfile
    # compiled as root after the code is in, so no worker start compiles it again
    assert steps.index("RUN python") > steps.index("COPY analysis")
    assert "RUN python -m compileall -q app analysis" in dockerfile.split("USER 10001")[0]
    assert re.search(r"^USER 10001$", dockerfile, re.M)
    pins = [line for line in (REPO / "requirements" / "runtime.txt").read_text().splitlines()
            if line and not line.startswith(("#", " "))]
    assert pins and all(re.fullmatch(r"[\w.-]+==[\w.]+", pin) for pin in pins)
    assert "torch==2.13.0" in pins


@pytest.mark.parametrize(("args", "asked"), [
    ((), "http://127.0.0.1:8000/healthz"),
    (("--port", "18800"), "http://127.0.0.1:18800/healthz"),
    (("--host", "127.0.0.1", "--port=9000"), "http://127.0.0.1:9000/healthz"),
    (("--host", "::1"), "http://[::1]:8000/healthz")])
def test_the_healthcheck_asks_where_the_server_listens(run_entrypoint, args, asked):
    run_entrypoint(*args)
    assert run_entrypoint.healthz.read_text().strip() == asked


def test_the_entrypoint_makes_private_files(run_entrypoint):
    run_entrypoint()
    assert run_entrypoint.healthz.stat().st_mode & 0o077 == 0  # umask 077


def test_the_image_trusts_forwarded_addresses_only_from_a_named_proxy():
    dockerfile = (REPO / "Dockerfile").read_text()
    settings = [line for line in dockerfile.splitlines() if not line.startswith("#")]
    assert not any("FORWARDED_ALLOW_IPS" in line for line in settings)  # it was `*`
    assert "TOMSTUDY_TRUSTED_PROXIES" in dockerfile  # the comment says how to name the proxy
    assert SERVER["environment"]["TOMSTUDY_TRUSTED_PROXIES"] == (
        PROXY["networks"]["frontend"]["ipv4_address"])
    assert "TOMSTUDY_TRUSTED_PROXIES" in settings_env_names()
