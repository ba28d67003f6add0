"""Production by default when public (issue 32 item 5): a public name in
TOMSTUDY_ALLOWED_HOSTS implies production's checks; wrong researcher tokens lock an address
out; forwarded client addresses are trusted only from a named proxy."""

import subprocess

import httpx
import pytest

from app.http.preflight import NotServable, forwarded_allow_ips
from app.main import UnsafeSettings, create_app
from app.settings import Settings
from tests.conftest import REPO, TOMSTUDY, free_port, local_client, patience, start_server
from tests.server.flow import ADMIN, prolific

STRONG = "x" * 40
LIMITS_ON = {"rate_limit_starts": "20/minute", "rate_limit_requests": "300/minute"}
PUBLIC = {"allowed_hosts": "study.example.org"}


def test_a_public_host_name_makes_the_server_production():
    assert Settings(**PUBLIC).production
    assert Settings(allowed_hosts="localhost, 127.0.0.1,[::1]").production is False
    assert Settings(allowed_hosts="10.0.0.5").production  # an address others reach


@pytest.mark.parametrize(("extra", "refusal"), [
    ({"admin_token": "abc", **LIMITS_ON}, "TOMSTUDY_ADMIN_TOKEN has 3 characters"),
    ({"admin_token": STRONG, "trust_client_clock": True, **LIMITS_ON},
     "TOMSTUDY_TRUST_CLIENT_CLOCK"),
    ({"admin_token": STRONG, "rate_limit_starts": "", "rate_limit_requests": "300/minute"},
     "TOMSTUDY_RATE_LIMIT_STARTS is empty"),
    ({"admin_token": STRONG, "researcher_lockout": "", **LIMITS_ON},
     "TOMSTUDY_RESEARCHER_LOCKOUT is empty"),
])
def test_a_public_name_refuses_what_production_refuses(small_study, tmp_path, extra, refusal):
    settings = small_study.settings(f"sqlite:///{tmp_path / 's.db'}", **PUBLIC, **extra)
    with pytest.raises(UnsafeSettings, match=refusal):
        create_app(settings, [small_study.study_id])


def test_a_public_name_turns_the_api_docs_off(small_study, tmp_path):
    settings = small_study.settings(f"sqlite:///{tmp_path / 's.db'}", **PUBLIC,
                                    admin_token=STRONG, **LIMITS_ON)
    with local_client(create_app(settings, [small_study.study_id])) as c:
        assert c.get("/docs").status_code == 404 and c.get("/openapi.json").status_code == 404


def test_serve_on_loopback_with_a_public_name_refuses_a_weak_token(small_study, tmp_path):
    env = small_study.env(f"sqlite:///{tmp_path / 's.db'}", TOMSTUDY_ADMIN_TOKEN="abc",
                          TOMSTUDY_ALLOWED_HOSTS="study.example.org")
    run = subprocess.run([TOMSTUDY, "serve", "--host", "127.0.0.1", "--port", "1", "--study",
                          small_study.study_id], env=env, cwd=REPO, capture_output=True,
                         text=True, timeout=patience(60))
    assert run.returncode == 2 and "Traceback" not in run.stderr
    assert "public name in TOMSTUDY_ALLOWED_HOSTS" in run.stderr
    assert "TOMSTUDY_ADMIN_TOKEN has 3 characters" in run.stderr


# ---------------------------------------------------------------- researcher lockout

def test_wrong_researcher_tokens_lock_the_address_out(small_study, tmp_path):
    sid = small_study.study_id
    app = create_app(small_study.settings(f"sqlite:///{tmp_path / 's.db'}"), [sid])
    summary = f"/api/researcher/summary?study_id={sid}"
    wrong = {"Authorization": "Bearer guess"}
    with local_client(app, client=("203.0.113.7", 5000)) as guesser:
        assert {guesser.get(summary).status_code for _ in range(15)} == {401}  # no guess
        answers = [guesser.get(summary, headers=wrong).status_code for _ in range(10)]
        assert answers == [403] * 10
        locked = guesser.get(summary, headers=wrong)
        assert locked.status_code == 429 and 590 <= int(locked.headers["Retry-After"]) <= 600
        assert locked.json()["detail"].startswith("authorization: too many wrong researcher")
        assert guesser.get(summary, headers=ADMIN).status_code == 429  # no more guesses
        assert guesser.post("/api/researcher/withdrawals", headers=ADMIN, json={
            "study_id": sid, "participant_id": "x"}).status_code == 429
        lab = local_client(app, client=("198.51.100.9", 5000))  # another address
        assert lab.get(summary, headers=ADMIN).status_code == 200
        ipv6 = [local_client(app, client=(f"2001:db8:1:2::{i}", 5000)) for i in (1, 2)]
        assert [ipv6[0].get(summary, headers=wrong).status_code for _ in range(10)] == [403] * 10
        assert ipv6[1].get(summary, headers=ADMIN).status_code == 429  # the same /64


# ---------------------------------------------------------------- forwarded addresses

def test_forwarded_addresses_are_trusted_only_from_named_proxies(monkeypatch):
    monkeypatch.delenv("FORWARDED_ALLOW_IPS", raising=False)
    assert forwarded_allow_ips(Settings()) == "127.0.0.1"
    proxies = Settings(trusted_proxies="172.17.0.1, 10.0.0.0/16")
    assert forwarded_allow_ips(proxies) == "172.17.0.1,10.0.0.0/16"
    for bad, message in (("*", "'*' lets any client name its own address"),
                         ("10.0.0.1,*", "'*'"), ("proxy.internal", "not an IP address")):
        with pytest.raises(NotServable, match=f"TOMSTUDY_TRUSTED_PROXIES: .*{message}"):
            forwarded_allow_ips(Settings(trusted_proxies=bad))
    monkeypatch.setenv("FORWARDED_ALLOW_IPS", "*")
    with pytest.raises(NotServable, match="FORWARDED_ALLOW_IPS: tomstudy serve does not"):
        forwarded_allow_ips(Settings())


def test_a_client_cannot_pick_its_rate_key_behind_a_proxy_that_appends(small_study, tmp_path):
    """The proxy (this machine, trusted) appends the address it saw to whatever the client
    sent: the key is that address, so made-up entries in front of it change nothing."""
    port = free_port()
    proc = start_server(small_study, f"sqlite:///{tmp_path / 's.db'}", port,
                        log=tmp_path / "server.log", TOMSTUDY_RATE_LIMIT_STARTS="3/minute",
                        TOMSTUDY_TRUSTED_PROXIES="127.0.0.1")
    try:
        url = f"http://127.0.0.1:{port}/api/sessions"

        def start(name: str, forwarded: str) -> int:
            return httpx.post(url, json={"study_id": small_study.study_id,
                                         "recruitment": prolific(name)},
                              headers={"X-Forwarded-For": forwarded},
                              timeout=patience(30)).status_code

        forged = [start(f"p{i}", f"198.51.100.{i}, 203.0.113.50") for i in range(5)]
        assert forged == [201, 201, 201, 429, 429]
        assert start("other", "203.0.113.51") == 201  # another real client
    finally:
        proc.terminate()
        proc.wait(timeout=patience(10))
