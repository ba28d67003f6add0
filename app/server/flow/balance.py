"""Balance counts kept in the database, so assigning a plan costs the same at any study size.

BalanceCount holds, per study, how many counted sessions use each world order
(`order:a,b`) and each trial (`trial:<id>`). A session is counted from its consent
(places.take_place) while it runs; it stops counting when it goes stale (unfinished past
`in_progress_timeout_min`, released in bounded batches by each worker's `sweep_stale`, off
the request path) or completes excluded (failed attention check, too many too-fast
trials); a stale session that comes back and completes validly counts again. Pilot
sessions never count. On PostgreSQL a transaction-scoped advisory lock (`lock_study`) makes a
consent's read-choose-increment atomic across workers; SQLite serialises writers itself and
the server refuses several workers on it.
"""

import asyncio
import hashlib
import logging
from collections import Counter
from datetime import datetime, timedelta

from sqlalchemy import String, bindparam, case, func, literal, select, text, union_all, update
from sqlalchemy.engine import Engine
from sqlmodel import Session

from app.core.contracts import PROLIFIC_UNCONFIRMED, ExclusionRules, too_fast_share_exceeds
from app.server.flow.context import StudyContext
from app.server.flow.plan import TrialStep, Usage, parse_plan, world_orders
from app.server.storage.db import insert_skipping_duplicates
from app.server.storage.tables import BalanceCount, Participant, TrialResponse, keep_loaded, utcnow
from app.study.config import StudyConfig, live_session_cap

ORDER = "order:"
TRIAL = "trial:"


def order_key(order: tuple[str, ...]) -> str:
    """The BalanceCount key of a world order."""
    return ORDER + ",".join(order)


def plan_keys(world_order: str, plan: list[dict]) -> list[str]:
    """The keys a session holds: its world order and every trial of its stored plan."""
    steps = parse_plan(plan)
    return [ORDER + world_order] + [TRIAL + s.trial_id for s in steps if isinstance(s, TrialStep)]


def ensure_rows(engine: Engine, ctx: StudyContext) -> None:
    """Create a zero count for every order and trial of the study (existing ones kept)."""
    keys = [order_key(o) for o in world_orders(ctx.config)]
    keys += [TRIAL + t.trial_id for w in ctx.bank.data.worlds.values() for t in w.trials]
    rows = [{"study_id": ctx.study_id, "key": k, "count": 0} for k in keys]
    with engine.begin() as conn:
        conn.execute(insert_skipping_duplicates(conn, BalanceCount.__table__), rows)


def lock_study(db: Session, study_id: str) -> None:
    """Serialise what reads or changes one study's places (consents, withdrawals, Prolific's
    verdicts) until the transaction ends: PostgreSQL's advisory lock, SQLite's write lock."""
    if db.get_bind().dialect.name == "postgresql":
        key = int.from_bytes(hashlib.sha256(f"tomstudy:{study_id}".encode()).digest()[:8],
                             "big", signed=True)
        db.execute(text("SELECT pg_advisory_xact_lock(:key)"), {"key": key})
    elif not db.connection().connection.dbapi_connection.in_transaction:
        # sqlite3 begins a transaction only at the first write: the reads after the lock
        # must already be inside it, or a write elsewhere could slip in between
        db.execute(text("BEGIN IMMEDIATE"))


def read_counts(db: Session, study_id: str) -> dict[str, int]:
    """key -> count for one study."""
    rows = db.execute(select(BalanceCount.key, BalanceCount.count)
                      .where(BalanceCount.study_id == study_id))
    return dict(rows.all())


LIVE = "live"  # the row of read_standing holding the live-session count (not a count key)


def read_standing(db: Session, ctx: StudyContext) -> tuple[Usage, int]:
    """The study's counts per world order and per trial (as a plan's assignment reads them)
    and its live sessions counted up to its cap, in one statement."""
    cap = live_session_cap(ctx.config)
    counts = (select(BalanceCount.key, BalanceCount.count)
              .where(BalanceCount.study_id == ctx.study_id))
    live = select(literal(LIVE, String), func.count()).select_from(_live(ctx, cap).subquery())
    rows = dict(db.execute(union_all(counts, live)).all())
    return usage_of(rows), rows[LIVE]


def _live(ctx: StudyContext, at_most: int):
    """Counted unfinished sessions written to within the timeout, up to `at_most` of them."""
    return (select(Participant.id)
            .where(Participant.study_id == ctx.study_id, Participant.counted.is_(True),
                   Participant.completed.is_(False),
                   Participant.updated_at >= in_progress_cutoff(ctx.config))
            .limit(at_most))


def usage_of(counts: dict[str, int]) -> Usage:
    """Counts by key as usage per world order and per trial (other keys ignored)."""
    orders = {tuple(k[len(ORDER):].split(",")): v for k, v in counts.items()
              if k.startswith(ORDER)}
    trials = {k[len(TRIAL):]: v for k, v in counts.items() if k.startswith(TRIAL)}
    return Usage(orders=orders, trials=trials)


def _add(db: Session, study_id: str, keys: list[str], delta: int) -> None:
    for times, group in _by_multiplicity(keys).items():
        db.execute(update(BalanceCount.__table__)
                   .where(BalanceCount.study_id == study_id, BalanceCount.key.in_(group))
                   .values(count=BalanceCount.count + delta * times))


def _by_multiplicity(keys: list[str]) -> dict[int, list[str]]:
    groups: dict[int, list[str]] = {}
    for key, times in Counter(keys).items():
        groups.setdefault(times, []).append(key)
    return groups


def _set_counted(db: Session, participant: Participant, counted: bool) -> bool:
    """Flip `counted` if it is not already so; True if this call flipped it."""
    moved = db.execute(update(Participant.__table__)
                       .where(Participant.id == participant.id,
                              Participant.counted.is_(not counted))
                       .values(counted=counted))
    flipped = moved.rowcount == 1
    if flipped:
        keep_loaded(participant, counted=counted)
    return flipped


def may_count(participant: Participant) -> bool:
    """False for a session Prolific has not confirmed: it never counts
    (app/server/flow/prolific_check.py)."""
    return participant.prolific_check not in PROLIFIC_UNCONFIRMED


def hold(db: Session, participant: Participant) -> None:
    """Add the session's order and trials to the counts (inside the caller's transaction)."""
    if may_count(participant) and _set_counted(db, participant, True):
        add_held(db, participant)


def add_held(db: Session, participant: Participant) -> None:
    """Add a session whose `counted` was just set (with its step, places.take_place) to the
    counts; nothing for one that does not count."""
    if participant.counted:
        _add(db, participant.study_id, plan_keys(participant.world_order, participant.plan), 1)


def release(db: Session, participant: Participant) -> None:
    """Take the session's order and trials out of the counts, once."""
    if _set_counted(db, participant, False):
        _add(db, participant.study_id, plan_keys(participant.world_order, participant.plan), -1)


def in_progress_cutoff(config: StudyConfig) -> datetime:
    """Unfinished sessions last updated before this are abandoned (stale)."""
    return utcnow() - timedelta(minutes=config.in_progress_timeout_min)


STALE_BATCH = 50  # sessions released per transaction: SQLite's write lock held ~10 ms
BATCH_PAUSE_S = 0.05  # between batches, so participants' writes go first


def release_stale_batch(engine: Engine, ctx: StudyContext, limit: int = STALE_BATCH) -> int:
    """Release up to `limit` counted unfinished sessions that went stale, in one transaction
    of set-based SQL: one UPDATE flips and returns them, one executemany takes their keys
    out of the counts. Safe beside other workers doing the same; returns how many."""
    table = Participant.__table__
    stale = (select(table.c.id)
             .where(table.c.study_id == ctx.study_id, table.c.counted.is_(True),
                    table.c.completed.is_(False),
                    table.c.updated_at < in_progress_cutoff(ctx.config))
             .limit(limit))
    with engine.begin() as conn:
        released = conn.execute(
            update(table).where(table.c.id.in_(stale.scalar_subquery()),
                                table.c.counted.is_(True))
            .values(counted=False).returning(table.c.world_order, table.c.plan)).all()
        keys = Counter(k for order, plan in released for k in plan_keys(order, plan))
        if keys:
            counts = BalanceCount.__table__
            conn.execute(update(counts).where(counts.c.study_id == ctx.study_id,
                                              counts.c.key == bindparam("released_key"))
                         .values(count=counts.c.count - bindparam("times")),
                         [{"released_key": k, "times": n} for k, n in keys.items()])
    return len(released)


logger = logging.getLogger(__name__)


async def sweep_stale(engine: Engine, studies: list[StudyContext], interval_s: float) -> None:
    """Forever: every `interval_s`, release each study's stale sessions batch by batch, each
    batch in a worker thread so the event loop keeps serving (cancel to stop)."""
    while True:
        for ctx in studies:
            try:
                while await asyncio.to_thread(release_stale_batch, engine, ctx) == STALE_BATCH:
                    await asyncio.sleep(BATCH_PAUSE_S)
            except Exception as err:  # a database hiccup must not end the sweep
                logger.warning("releasing stale sessions of %s failed: %s", ctx.study_id, err)
        await asyncio.sleep(interval_s)


def settle_completion(db: Session, participant: Participant, excluded: bool) -> None:
    """At completion: an excluded session stops counting, a valid one counts (once)."""
    if participant.pilot:
        return
    if excluded:
        release(db, participant)
    else:
        hold(db, participant)


def is_excluded(db: Session, config: StudyConfig, participant: Participant) -> bool:
    """The enabled exclusion rules remove this session (attention check, too fast)."""
    n_fast, n = trial_speeds(db, config.exclusions, Participant.id == participant.id).get(
        participant.id, (0, 0))
    return bool(exclusion_reasons(config.exclusions, participant.attention_failed, n_fast, n))


def exclusion_reasons(rules: ExclusionRules, attention_failed: int, n_fast: int,
                      n_trials: int) -> list[str]:
    """The rules a session's answers break: failed_attention_check, too_fast."""
    reasons = []
    if rules.failed_attention_check and attention_failed > 0:
        reasons.append("failed_attention_check")
    if too_fast_share_exceeds(n_fast, n_trials, rules):
        reasons.append("too_fast")
    return reasons


def trial_speeds(db: Session, rules: ExclusionRules, which) -> dict[int, tuple[int, int]]:
    """Participant id -> (too-fast scored trials, scored trials) of the sessions `which`
    (a condition on Participant) selects; scored = neither practice nor attention check."""
    fast = func.sum(case((rules.too_fast(TrialResponse.duration_ms), 1), else_=0))
    rows = db.execute(
        select(TrialResponse.participant_id, fast, func.count())
        .join(Participant, Participant.id == TrialResponse.participant_id)
        .where(which, TrialResponse.is_practice.is_(False),
               TrialResponse.attention_check.is_(False))
        .group_by(TrialResponse.participant_id))
    return {pid: (int(n_fast or 0), int(n)) for pid, n_fast, n in rows}


def recount(db: Session, ctx: StudyContext) -> dict[str, int]:
    """The counts rebuilt from the counted sessions (an audit of BalanceCount; O(sessions))."""
    counts = Counter()
    rows = db.execute(select(Participant.world_order, Participant.plan).where(
        Participant.study_id == ctx.study_id, Participant.counted.is_(True)))
    for world_order, plan in rows:
        counts.update(plan_keys(world_order, plan))
    return dict(counts)
