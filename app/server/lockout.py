"""Researcher routes lock a client out after repeated wrong tokens.

Each wrong bearer token counts against the client's rate-limit key (ratelimit.client_key:
the address, an IPv6 client's /64) in a moving window kept in this worker's memory; once the
window holds `limit` failures every researcher request from that key answers 429 with
Retry-After, right token or not, until the oldest failure leaves the window. A missing token
is not a guess and does not count. With N workers a client gets up to N times the limit.
"""

import math
import time

from limits import RateLimitItem
from limits.storage import MemoryStorage
from limits.strategies import MovingWindowRateLimiter

from app.study.errors import Refused

WHAT = "researcher token failures"


class TokenLockout:
    """Wrong researcher tokens per client key; `limit` None turns the lockout off."""

    def __init__(self, limit: RateLimitItem | None) -> None:
        self.limit = limit
        self.limiter = MovingWindowRateLimiter(MemoryStorage())

    def check(self, key: str) -> None:
        """Refused (429, Retry-After) while `key` is locked out."""
        if self.limit is None or self.limiter.test(self.limit, WHAT, key):
            return
        reset_at = self.limiter.get_window_stats(self.limit, WHAT, key).reset_time
        wait_s = max(1, math.ceil(reset_at - time.time()))
        raise Refused(429, f"authorization: too many wrong researcher tokens from this "
                           f"address; try again in {wait_s} s",
                      headers={"Retry-After": str(wait_s)})

    def failed(self, key: str) -> None:
        """Count one wrong token from `key`."""
        if self.limit is not None:
            self.limiter.hit(self.limit, WHAT, key)
