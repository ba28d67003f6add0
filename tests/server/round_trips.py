"""Database round trips per HTTP route, counted with SQLAlchemy's engine and pool events.

`RouteCounter` wraps an ASGI app: each request names its route (`METHOD /path`, or a label
the test sets) in a context variable, and the engine's events count, for that route only
(the stale sweep's statements run outside any request and are not counted):
- statements: every cursor execution SQLAlchemy makes (an executemany counts once);
- commits and rollbacks of a transaction;
- checkouts of a pooled connection. On PostgreSQL each costs two more round trips: the pool's
  pre-ping (`SELECT 1`, db.make_engine) and the `BEGIN` psycopg sends before it.
`round_trips` adds them up as the server pays them: on SQLite a statement or commit is a call
into the library, not a network exchange, so there a checkout costs nothing.
"""

from contextvars import ContextVar
from dataclasses import dataclass, field

from sqlalchemy import event
from sqlalchemy.engine import Engine

_ROUTE: ContextVar[str | None] = ContextVar("round_trip_route", default=None)
KINDS = ("statements", "commits", "rollbacks", "checkouts")


@dataclass
class Tally:
    """What one request cost."""

    statements: int = 0
    commits: int = 0
    rollbacks: int = 0
    checkouts: int = 0

    def round_trips(self, backend: str) -> int:
        """Exchanges with the database: statements and transaction ends, plus on PostgreSQL
        the pre-ping and BEGIN of each checkout."""
        pings = 2 * self.checkouts if backend == "postgresql" else 0
        return self.statements + self.commits + self.rollbacks + pings


@dataclass
class RouteCounter:
    """An ASGI app that counts its requests' database work per route (see the module)."""

    app: object
    label: str | None = None  # the next requests' route name, instead of METHOD /path
    requests: dict[str, list[Tally]] = field(default_factory=dict)

    async def __call__(self, scope, receive, send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        route = self.label or f"{scope['method']} {scope['path']}"
        tally = Tally()
        self.requests.setdefault(route, []).append(tally)
        token = _ROUTE.set(route)
        try:
            await self.app(scope, receive, send)
        finally:
            _ROUTE.reset(token)

    def listen(self, engine: Engine) -> None:
        """Count `engine`'s work for the request that does it."""
        event.listen(engine, "before_cursor_execute", self._counter("statements"))
        event.listen(engine, "commit", self._counter("commits"))
        event.listen(engine, "rollback", self._counter("rollbacks"))
        event.listen(engine.pool, "checkout", self._counter("checkouts"))

    def _counter(self, kind: str):
        def count(*_args, **_kwargs) -> None:
            route = _ROUTE.get()
            if route is not None:
                tally = self.requests[route][-1]
                setattr(tally, kind, getattr(tally, kind) + 1)
        return count

    def table(self, backend: str) -> dict[str, dict[str, int]]:
        """route -> the most any one request of it cost, per kind and in round trips."""
        return {route: {**{kind: max(getattr(t, kind) for t in tallies) for kind in KINDS},
                        "round_trips": max(t.round_trips(backend) for t in tallies),
                        "requests": len(tallies)}
                for route, tallies in sorted(self.requests.items())}


def format_table(backend: str, baseline: dict[str, dict], now: dict[str, dict]) -> str:
    """The baseline's and this run's statements and round trips per route, as text."""
    head = (f"{backend}: {'route':36} | baseline stmts trips | now stmts commits checkouts "
            "trips")
    lines = [head, "-" * len(head)]
    for route in sorted(set(baseline) | set(now)):
        was, row = baseline.get(route), now.get(route)
        before = f"{was['statements']:14} {was['round_trips']:5}" if was else f"{'-':>20}"
        after = (f"{row['statements']:9} {row['commits']:7} {row['checkouts']:9} "
                 f"{row['round_trips']:5}" if row else f"{'-':>34}")
        lines.append(f"{' ' * (len(backend) + 2)}{route:36} | {before} | {after}")
    return "\n".join(lines)
