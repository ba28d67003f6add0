"""Which sessions take a place in a study: count toward the live cap, "full", balance and
progress.

A session takes a place from consent on, never at its start. A start proves nothing (any
script can send a Prolific-shaped id), so counting it let one address fill the live cap and
`max_counted_sessions` with made-up ids. `take_place` is the one function that makes a
session count, in its consent's transaction and under the study's lock, so the cap, "full"
and the balance are exact there: a check that must pass before a session counts (the platform
confirming the submission, say) belongs there. A session that has not consented holds
nothing, and `consent_timeout_min` after its start its external id may start again
(sessions.py replaces it).
"""

from dataclasses import dataclass
from datetime import datetime, timedelta

import numpy as np
from sqlmodel import Session

from app.server.flow import balance, notices
from app.server.flow.context import StudyContext
from app.server.flow.plan import Usage, assign_plan, dump_plan
from app.server.storage.tables import Participant, utcnow
from app.study.config import StudyConfig, live_session_cap
from app.study.errors import Refused

ROOM_RETRY_S = 60
def consent_cutoff(config: StudyConfig) -> datetime:
    """A session started before this that has not consented holds nothing any more."""
    return utcnow() - timedelta(minutes=config.consent_timeout_min)


@dataclass(frozen=True)
class Cutoffs:
    """The moments a session's status is judged by (status_cutoffs)."""

    in_progress: datetime  # a consented session written to since is in progress
    consent: datetime  # an unconsented session started since awaits consent


def status_cutoffs(config: StudyConfig) -> Cutoffs:
    """The study's cutoffs as of now."""
    return Cutoffs(balance.in_progress_cutoff(config), consent_cutoff(config))


def take_place(db: Session, ctx: StudyContext, participant: Participant,
               rng: np.random.Generator | None = None) -> dict:
    """The Participant columns that make a consenting session count (none for a pilot), to
    store with the consent's step in its transaction, whose end releases the study's lock
    taken here: admitted (503 while the study runs its cap, 409 closed or full), the plan the
    balance now asks for (nothing of the start's plan was shown yet) and `counted`; then
    balance.add_held adds it to the counts."""
    if participant.pilot:
        return {}
    balance.lock_study(db, ctx.study_id)
    usage, live = balance.read_standing(db, ctx)
    try:
        admit(ctx, usage, live)
    except Refused:
        db.rollback()  # the study's lock goes before the refusal is answered
        raise
    order, steps = assign_plan(ctx.config, ctx.bank, usage, rng or np.random.default_rng())
    return {"world_order": ",".join(order), "plan": dump_plan(steps),
            "counted": balance.may_count(participant)}


def admit(ctx: StudyContext, usage: Usage, live: int) -> None:
    """Refuse a new place while the study runs its cap of unfinished sessions (503: `live`
    of them run), or is closed or full (409), each with a notice."""
    check_room(ctx, live)
    recruitment = ctx.config.recruitment
    if recruitment.closed:
        raise Refused(409, "study_id: the study is closed to new participants "
                           "(recruitment.closed)", notices.closed(recruitment.platform))
    counted = sum(usage.orders.values())
    if recruitment.max_counted_sessions is not None and counted >= recruitment.max_counted_sessions:
        raise Refused(409, f"study_id: the study is full ({counted} counted sessions, "
                           "recruitment.max_counted_sessions)", notices.full(recruitment.platform))


def check_room(ctx: StudyContext, live: int) -> None:
    """503 while the study runs (`live`) as many unfinished counted sessions as it takes at
    once."""
    cap = live_session_cap(ctx.config)
    if live >= cap:
        raise Refused(503, f"study: {cap} sessions are running, the most this study takes at "
                           "once; please try again in a few minutes",
                      notices.busy(), headers={"Retry-After": str(ROOM_RETRY_S)})
