"""Researcher routes lock a client out after repeated wrong tokens.

Each wrong bearer token counts against the client's rate-limit key (ratelimit.client_key:
the address, an IPv6 client's /64) in a moving window kept in the rate-limit store
(limitstore.py: this worker's memory by default, so with N workers a client gets up to N
times the limit; or a Redis every worker and host shares). Once the window holds `limit`
failures every researcher request from that key answers 429 with Retry-After, right token or
not, until the oldest failure leaves the window. A missing token is not a guess and does not
count. While the store cannot be reached the lockout is off (fails open, logged): the token
itself is the guard.
"""

from limits import RateLimitItem

from app.http.limitstore import LimitStore
from app.study.errors import Refused

WHAT = "researcher token failures"


class TokenLockout:
    """Wrong researcher tokens per client key, counted in `store` (this process's memory if
    None); `limit` None turns the lockout off."""

    def __init__(self, limit: RateLimitItem | None, store: LimitStore | None = None) -> None:
        self.limit = limit
        self.store = store or LimitStore()

    async def check(self, key: str) -> None:
        """Refused (429, Retry-After) while `key` is locked out."""
        if self.limit is None:
            return
        limiter, limit = self.store.moving, self.limit
        if await self.store.ask(lambda: limiter.test(limit, WHAT, key), if_down=True):
            return
        wait_s = await self.store.wait_s(limiter, limit, WHAT, key)
        raise Refused(429, f"authorization: too many wrong researcher tokens from this "
                           f"address; try again in {wait_s} s",
                      headers={"Retry-After": str(wait_s)})

    async def failed(self, key: str) -> None:
        """Count one wrong token from `key`."""
        if self.limit is not None:
            limiter, limit = self.store.moving, self.limit
            await self.store.ask(lambda: limiter.hit(limit, WHAT, key), if_down=True)
