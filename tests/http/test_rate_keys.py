"""Rate limits key an IPv6 client by its /64, so one subscriber's many addresses share one
limit; IPv4 addresses and names stay as they are."""

import asyncio

from limits import parse

from app.http.ratelimit import RateLimit, client_key


def test_an_ipv6_client_is_keyed_by_its_64():
    assert client_key("2001:db8:1:2:aaaa::1") == client_key("2001:db8:1:2:ffff:1:2:3") == (
        "2001:db8:1:2::/64")
    assert client_key("2001:db8:1:3::1") == "2001:db8:1:3::/64"
    assert client_key("::ffff:192.0.2.7") == "192.0.2.7"  # an IPv4 client over IPv6
    assert client_key("192.0.2.7") == "192.0.2.7"
    assert client_key("testclient") == "testclient"


def start_status(limiter: RateLimit, host: str) -> int:
    """The status a session start from `host` gets through the middleware."""
    sent: list[dict] = []

    async def app(scope, receive, send):
        await send({"type": "http.response.start", "status": 201, "headers": []})
        await send({"type": "http.response.body", "body": b""})

    async def receive():
        return {"type": "http.request", "body": b""}

    async def send(message):
        sent.append(message)

    limiter.app = app
    scope = {"type": "http", "method": "POST", "path": "/api/sessions", "client": (host, 1),
             "headers": []}
    asyncio.run(limiter(scope, receive, send))
    return sent[0]["status"]


def test_addresses_of_one_64_share_a_limit_and_another_64_has_its_own():
    limiter = RateLimit(None, parse("2/minute"), None)
    same_64 = [f"2001:db8:1:2::{i:x}" for i in range(1, 4)]
    assert [start_status(limiter, host) for host in same_64] == [201, 201, 429]
    assert start_status(limiter, "2001:db8:1:3::1") == 201
