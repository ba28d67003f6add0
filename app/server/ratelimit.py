"""Per-client rate limits on the participant API, with the `limits` library.

Session starts and every other participant API request have a limit each, per client
address, in a sliding window kept in this worker's memory (`limits`' MemoryStorage): with
N workers a client gets up to N times the limit, which still bounds it. The client
address is the TCP peer, or the one a trusted reverse proxy forwards (uvicorn's proxy
headers, trusted from TOMSTUDY_TRUSTED_PROXIES: 127.0.0.1 by default). An IPv6 client is keyed
by its /64: one subscriber is routinely given a whole /64, so its single addresses would be
unlimited keys. Beyond a limit the answer is 429 with `Retry-After`; the browser retries such
writes with the same body.
"""

import ipaddress
import math
import time

from fastapi.responses import JSONResponse
from limits import RateLimitItem, parse
from limits.storage import MemoryStorage
from limits.strategies import SlidingWindowCounterRateLimiter
from starlette.types import ASGIApp, Receive, Scope, Send

PARTICIPANT_PREFIX = "/api/session"  # /api/sessions (starts) and /api/session/... (a session)
START_PATH = "/api/sessions"


def parse_limit(setting: str, value: str) -> RateLimitItem | None:
    """`value` such as "20/minute" as a limit, None for ""; ValueError naming `setting`."""
    if not value.strip():
        return None
    try:
        return parse(value)
    except ValueError:
        raise ValueError(f"{setting}: {value!r} is not a rate such as 20/minute or "
                         "5/second") from None


def client_key(host: str) -> str:
    """The rate-limit key of a client address: an IPv6 address's /64 network, anything else
    (IPv4, a test client's name) as it is."""
    try:
        address = ipaddress.ip_address(host)
    except ValueError:
        return host
    if address.version == 4:
        return str(address)
    if address.ipv4_mapped is not None:  # an IPv4 client over an IPv6 socket
        return str(address.ipv4_mapped)
    return str(ipaddress.ip_network(f"{address}/64", strict=False))


class RateLimit:
    """ASGI middleware: 429 once a client address exceeds its limit of session starts
    (`starts`) or of other participant API requests (`requests`); None is no limit."""

    def __init__(self, app: ASGIApp, starts: RateLimitItem | None,
                 requests: RateLimitItem | None) -> None:
        self.app = app
        self.starts = starts
        self.requests = requests
        self.limiter = SlidingWindowCounterRateLimiter(MemoryStorage())

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http" or not scope["path"].startswith(PARTICIPANT_PREFIX):
            return await self.app(scope, receive, send)
        is_start = scope["method"] == "POST" and scope["path"] == START_PATH
        limit, what = (self.starts, "session starts") if is_start else (self.requests,
                                                                         "requests")
        client = client_key((scope.get("client") or ("unknown",))[0])
        if limit is None or self.limiter.hit(limit, what, client):
            return await self.app(scope, receive, send)
        reset_at = self.limiter.get_window_stats(limit, what, client).reset_time
        wait_s = max(1, math.ceil(reset_at - time.time()))
        response = JSONResponse(
            {"detail": f"rate: too many {what} from this address; try again in {wait_s} s"},
            status_code=429, headers={"Retry-After": str(wait_s)})
        await response(scope, receive, send)
