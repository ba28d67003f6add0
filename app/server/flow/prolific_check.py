"""Only Prolific's own submissions count: the link's SESSION_ID is checked with Prolific's API.

With a Prolific API token configured (TOMSTUDY_PROLIFIC_TOKEN_FILE), a new session of a
Prolific study asks Prolific whether its SESSION_ID is a submission of its STUDY_ID by its
PROLIFIC_PID before it is stored:
- confirmed: the session starts and counts as any other;
- unknown (Prolific has no such submission, or it is another study's or person's): refused
  with a notice, so it never gets a session, a place or a row;
- Prolific unreachable: the participant is admitted (a real participant must not lose their
  place to our network), the session is stored as `pending` and does not count (balance.hold
  skips it) until a re-check confirms it; `recheck_loop` asks again every
  `prolific_recheck_s`, and a session Prolific then does not know stays uncounted and the
  analysis excludes it (`prolific_unknown`), as it does a session still pending.
A resumed session (same SESSION_ID) is not asked again. Without a token nothing is asked and
`prolific_check` stays NULL.
"""

import asyncio
import logging

from sqlalchemy import select, update
from sqlalchemy.engine import Engine
from sqlmodel import Session

from app.server.flow import balance, notices
from app.server.flow.context import StudyContext
from app.server.flow.plan import has_consented
from app.server.flow.recruitment import identify
from app.server.flow.sessions import as_utc, has_ended, live_participant
from app.server.prolific import (
    CONFIRMED,
    PENDING,
    UNKNOWN,
    ProlificClient,
    ProlificRefused,
    ProlificUnreachable,
)
from app.server.schemas import SessionCreate
from app.server.storage.tables import Participant
from app.study.config import StudyConfig
from app.study.errors import Refused

logger = logging.getLogger(__name__)
RECHECK_BATCH = 50  # pending sessions asked about per study and round


async def check_start(client: ProlificClient | None, db: Session, ctx: StudyContext,
                      body: SessionCreate) -> str | None:
    """What Prolific says of a session start (CONFIRMED or PENDING; None when not asked);
    403 with a notice when Prolific does not know the link's submission."""
    if client is None:
        return None
    who = identify(ctx.config, body, ctx.preview_key)  # malformed links are refused first
    if who.recruitment != "prolific":
        return None
    existing = live_participant(db, ctx.study_id, who.external_id)
    db.commit()  # end the read transaction before waiting on Prolific
    if existing is not None and existing.attempt_key == who.attempt_key:
        return existing.prolific_check  # resuming: asked when it started
    verdict = await ask(client, who.params["SESSION_ID"], who.params["STUDY_ID"],
                        who.external_id)
    if verdict == UNKNOWN:
        raise Refused(403, "recruitment.SESSION_ID: Prolific has no submission with this id "
                           "in this study by this participant", notices.not_on_prolific())
    return verdict


async def ask(client: ProlificClient, session_id: str, study_id: str, pid: str) -> str:
    """CONFIRMED, UNKNOWN, or PENDING when Prolific cannot be asked now (logged)."""
    try:
        return await client.check_submission(session_id, study_id, pid)
    except (ProlificUnreachable, ProlificRefused) as err:
        logger.warning("Prolific did not answer about a submission (admitted as pending): %s",
                       err)
        return PENDING


async def recheck_pending(engine: Engine, client: ProlificClient, study_id: str,
                          config: StudyConfig, limit: int = RECHECK_BATCH) -> dict[str, int]:
    """Ask Prolific again about up to `limit` pending sessions of the study; confirmed ones
    count from now (if they would count now), unknown ones never. Answers how many became
    confirmed, unknown, or stay pending."""
    pending = await asyncio.to_thread(_pending, engine, study_id, limit)
    tally = {CONFIRMED: 0, UNKNOWN: 0, PENDING: 0}
    for row_id, params in pending:
        verdict = await ask(client, params["SESSION_ID"], params["STUDY_ID"],
                            params["PROLIFIC_PID"])
        if verdict != PENDING:
            await asyncio.to_thread(settle, engine, study_id, config, row_id, verdict)
        tally[verdict] += 1
    return tally


def _pending(engine: Engine, study_id: str, limit: int) -> list:
    with Session(engine) as db:
        return db.execute(select(Participant.id, Participant.recruitment_params)
                          .where(Participant.study_id == study_id,
                                 Participant.prolific_check == PENDING)
                          .order_by(Participant.id).limit(limit)).all()


def settle(engine: Engine, study_id: str, config: StudyConfig, row_id: int,
           verdict: str) -> None:
    """Store Prolific's verdict on a pending session; a confirmed one counts if it would
    count now (the same rule as at start and completion), an unknown one never."""
    with Session(engine) as db:
        balance.lock_study(db, study_id)
        moved = db.execute(update(Participant.__table__)
                           .where(Participant.id == row_id,
                                  Participant.prolific_check == PENDING)
                           .values(prolific_check=verdict))
        participant = db.get(Participant, row_id)
        if moved.rowcount == 1 and verdict == UNKNOWN:
            balance.release(db, participant)
        elif moved.rowcount == 1 and _counts_now(db, config, participant):
            balance.hold(db, participant)
        db.commit()


def _counts_now(db: Session, config: StudyConfig, participant: Participant) -> bool:
    """What counting a session would be had Prolific answered at its start: a consented live
    unfinished one or one completed validly (balance's and places' rule)."""
    if participant.pilot or participant.replaced_at is not None:
        return False
    if not has_consented(participant):
        return False
    if participant.completed:
        return not balance.is_excluded(db, config, participant)
    return not has_ended(participant) and (
        as_utc(participant.updated_at) >= balance.in_progress_cutoff(config))


async def recheck_loop(engine: Engine, client: ProlificClient, studies: list[StudyContext],
                       interval_s: float) -> None:
    """Forever: every `interval_s`, re-check each Prolific study's pending sessions (cancel to
    stop); a failure is logged and the loop goes on."""
    prolific_studies = [c for c in studies if c.config.recruitment.platform == "prolific"]
    while True:
        await asyncio.sleep(interval_s)
        for ctx in prolific_studies:
            try:
                await recheck_pending(engine, client, ctx.study_id, ctx.config)
            except Exception as err:  # a database hiccup must not end the loop
                logger.warning("re-checking %s's pending sessions failed: %s", ctx.study_id,
                               err)
