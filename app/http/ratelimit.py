"""Rate limits on the participant API, with the `limits` library.

Session starts are limited per client address; every request of a started session
(/api/session/...) per session token, so a classroom or a lab behind one address (one NAT)
is not throttled as one client: each participant has their own budget, and the address's
budget is spent only on starts. Each is a sliding window counted in the store
TOMSTUDY_RATE_LIMIT_STORAGE names (limitstore.py): this worker's memory by default (with N
workers a client gets up to N times a limit), or a Redis every worker and host shares (one
limit), which fails open while it cannot be reached. The client address is the TCP peer, or
the one a trusted reverse proxy forwards (uvicorn's proxy headers, trusted from
TOMSTUDY_TRUSTED_PROXIES: 127.0.0.1 by default). An IPv6 client is keyed by its /64: one
subscriber is routinely given a whole /64, so its single addresses would be unlimited keys.
A session request without a token of a session's shape is keyed by its address, and one
address's session requests together stop at SESSIONS_PER_ADDRESS sessions' worth: made-up
tokens of the right shape would otherwise each get a budget of their own. Beyond a limit the
answer is 429 with `Retry-After`; the browser retries such writes with the same body.
"""

import ipaddress
import re

from fastapi.responses import JSONResponse
from limits import RateLimitItem, parse
from starlette.types import ASGIApp, Receive, Scope, Send

from app.http.limitstore import LimitStore

PARTICIPANT_PREFIX = "/api/session"  # /api/sessions (starts) and /api/session/... (a session)
START_PATH = "/api/sessions"
TOKEN_HEADER = b"x-session-token"  # sessions.SESSION_HEADER, as ASGI spells header names
# what sessions.start_session hands out (secrets.token_urlsafe(24)), with room to change it
TOKEN_SHAPE = re.compile(rb"[A-Za-z0-9_-]{16,64}")
# the sessions' worth of requests one address may send together: a classroom of 30 behind one
# NAT, with room to spare
SESSIONS_PER_ADDRESS = 40
ALL_SESSIONS = "session requests of one address"  # the ceiling's window name


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


def session_key(scope: Scope) -> str | None:
    """The rate-limit key of a session request: its session token, if it has one of the
    shape the server hands out."""
    for name, value in scope.get("headers", ()):
        if name == TOKEN_HEADER:
            return "session:" + value.decode("ascii") if TOKEN_SHAPE.fullmatch(value) else None
    return None


class RateLimit:
    """ASGI middleware: 429 once a client address exceeds its limit of session starts
    (`starts`), or a session its limit of requests (`requests`); None is no limit. The
    counts live in `store` (this process's memory if None)."""

    def __init__(self, app: ASGIApp, starts: RateLimitItem | None,
                 requests: RateLimitItem | None, store: LimitStore | None = None) -> None:
        self.app = app
        self.starts = starts
        self.requests = requests
        self.address_ceiling = None if requests is None else type(requests)(
            requests.amount * SESSIONS_PER_ADDRESS, requests.multiples,
            namespace=requests.namespace)
        self.store = store or LimitStore()

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http" or not scope["path"].startswith(PARTICIPANT_PREFIX):
            return await self.app(scope, receive, send)
        is_start = scope["method"] == "POST" and scope["path"] == START_PATH
        limit = self.starts if is_start else self.requests
        if limit is None:
            return await self.app(scope, receive, send)
        address = client_key((scope.get("client") or ("unknown",))[0])
        token = None if is_start else session_key(scope)
        key = token or address
        what = ("session starts from this address" if is_start
                else "requests from this session" if token else "requests from this address")
        if token and not await self.hit(self.address_ceiling, ALL_SESSIONS, address):
            return await self.refuse(self.address_ceiling, (ALL_SESSIONS, address),
                                     "requests from this address", scope, receive, send)
        if await self.hit(limit, what, key):
            return await self.app(scope, receive, send)
        await self.refuse(limit, (what, key), what, scope, receive, send)

    async def hit(self, limit: RateLimitItem, *identifiers: str) -> bool:
        """Count one request against `limit`; False once it is spent (True if the store is
        down)."""
        return await self.store.ask(lambda: self.store.sliding.hit(limit, *identifiers),
                                    if_down=True)

    async def refuse(self, limit: RateLimitItem, identifiers: tuple[str, str], what: str,
                     scope: Scope, receive: Receive, send: Send) -> None:
        """429 with Retry-After: when the window of `limit` under `identifiers` has room."""
        wait_s = await self.store.wait_s(self.store.sliding, limit, *identifiers)
        response = JSONResponse({"detail": f"rate: too many {what}; try again in {wait_s} s"},
                                status_code=429, headers={"Retry-After": str(wait_s)})
        await response(scope, receive, send)
