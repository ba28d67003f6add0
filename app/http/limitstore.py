"""The store the participant rate limits and the researcher lockout count in.

TOMSTUDY_RATE_LIMIT_STORAGE names it as a `limits` storage URI. memory:// (the default) keeps
the counts in each worker's memory: right for one worker (SQLite), but with N workers a client
gets up to N times a limit (uvicorn hands each new connection to any worker) and hosts share
nothing. redis://host:6379/0 keeps them in one Redis that every worker of every host asks, so
a limit is one limit wherever the requests land. The store is asked through `limits.aio`
(redis-py's asyncio client), so a Redis round trip never blocks a worker's event loop.

A store that cannot be reached mid-study fails open: the request is served, the failure is
logged, and the store is not asked again for RETRY_S seconds (so an outage costs no request a
timeout each). Failing closed would turn a Redis outage into a paid study refusing every
participant; failing open only lifts, for the outage, a throttle on abuse, while the researcher
routes stay guarded by their token (32+ characters in production, which no lockout-free
guessing reaches: the lockout is the second line, not the first). At start `tomstudy serve`
refuses a store it cannot reach (preflight.check_rate_limit_storage).
"""

import asyncio
import logging
import math
import re
import time
from collections.abc import Awaitable, Callable
from typing import TypeVar
from urllib.parse import urlparse

from limits import RateLimitItem
from limits.aio.storage import MemoryStorage, MovingWindowSupport, Storage
from limits.aio.strategies import (
    MovingWindowRateLimiter,
    RateLimiter,
    SlidingWindowCounterRateLimiter,
)
from limits.errors import ConfigurationError, StorageError
from limits.storage import storage_from_string

SETTING = "TOMSTUDY_RATE_LIMIT_STORAGE"
MEMORY = "memory://"
STORE_TIMEOUT_S = 0.5  # a Redis that answers at all answers in a millisecond or two
RETRY_S = 5.0  # after a failure, how long requests pass without asking the store
logger = logging.getLogger(__name__)
T = TypeVar("T")


def shown(uri: str) -> str:
    """`uri` with any password in it blanked, for messages and logs."""
    return re.sub(r"//[^@/]*@", "//***@", uri)


def async_storage(uri: str) -> Storage:
    """The `limits.aio` storage behind `uri` (memory://, redis://host:port/db, ...; an
    async+ prefix is added); ValueError naming TOMSTUDY_RATE_LIMIT_STORAGE if unusable."""
    if not uri.strip():
        raise ValueError(f"{SETTING} is empty: use {MEMORY} (one worker) or "
                         "redis://host:6379/0 (shared by every worker and host)")
    uri = uri.strip()
    scheme = urlparse(uri).scheme
    async_uri = uri if scheme.startswith("async+") else f"async+{uri}"
    try:
        storage = storage_from_string(async_uri, wrap_exceptions=True,
                                      **client_options(async_uri))
    except (ConfigurationError, ValueError) as err:
        raise ValueError(f"{SETTING}: {shown(uri)!r} is not a rate-limit store the limits "
                         f"library can use ({err}); use {MEMORY} or redis://host:6379/0") from None
    if not isinstance(storage, MovingWindowSupport):
        raise ValueError(f"{SETTING}: {shown(uri)!r} cannot keep moving windows (the "
                         "researcher lockout's); use memory:// or redis://host:6379/0")
    return storage


def client_options(async_uri: str) -> dict:
    """The storage's options: for Redis, redis-py's asyncio client with short timeouts."""
    scheme = urlparse(async_uri).scheme
    if scheme.startswith(("async+redis", "async+valkey")):
        return {"implementation": "redispy", "socket_timeout": STORE_TIMEOUT_S,
                "socket_connect_timeout": STORE_TIMEOUT_S}
    return {}


async def reachable(storage: Storage) -> bool:
    """True if `storage` answers (a PING for Redis), within a few timeouts."""
    try:
        return await asyncio.wait_for(storage.check(), timeout=4 * STORE_TIMEOUT_S)
    except (TimeoutError, StorageError):
        return False


class LimitStore:
    """The counters of every limit of this worker, in the store `uri` names; while the store
    cannot be reached each question gets its `if_down` answer (fail open, logged)."""

    def __init__(self, uri: str = MEMORY) -> None:
        self.uri = uri
        self.storage = async_storage(uri)
        self.sliding = SlidingWindowCounterRateLimiter(self.storage)
        self.moving = MovingWindowRateLimiter(self.storage)
        base = self.storage.base_exceptions
        self.errors = (StorageError, OSError, TimeoutError,
                       *(base if isinstance(base, tuple) else (base,)))
        self.unasked_until = 0.0

    @property
    def shared(self) -> bool:
        """True if the counts live outside this process (every worker and host shares them)."""
        return not isinstance(self.storage, MemoryStorage)

    async def ask(self, question: Callable[[], Awaitable[T]], if_down: T) -> T:
        """The store's answer to `question`, or `if_down` while the store cannot be reached."""
        if time.monotonic() < self.unasked_until:
            return if_down
        try:
            return await question()
        except self.errors as err:
            self.unasked_until = time.monotonic() + RETRY_S
            logger.error("rate-limit store %s cannot be reached (%s: %s): rate limits and the "
                         "researcher lockout are off for %.0f s, then it is asked again",
                         shown(self.uri), type(err).__name__, err, RETRY_S)
            return if_down


    async def wait_s(self, limiter: RateLimiter, limit: RateLimitItem, *identifiers: str) -> int:
        """Whole seconds until `limit`'s window under `identifiers` has room (1 if the store
        cannot be reached)."""
        stats = await self.ask(lambda: limiter.get_window_stats(limit, *identifiers),
                               if_down=None)
        now = time.time()
        return max(1, math.ceil((now if stats is None else stats.reset_time) - now))
