"""Starting, resuming and replacing a participant's session, with a balanced plan.

A session start is checked against the study's platform (recruitment.py), then either
resumes the live session of that external id (same attempt key), replaces it (a new attempt
after it went stale), or creates a new one whose plan takes the least-used world order and
the least-exposed trials (plan.py, from the counts balance.py keeps), unless the study is
closed, full or already runs `live_session_cap` unfinished sessions. A start takes no place:
a session counts from consent on (places.py), and one that never consents frees its external
id after `consent_timeout_min`.

A start takes no lock, since nothing it decides has to be exact: the consent decides the
room, "full" and the plan again under the study's lock (places.take_place), and a pilot's
plan never counts. Two starts of one external id at once are kept apart by the database's
unique index of live external ids (the later one resumes or is refused, start_session). So a
new session costs three statements (the live session of the id; the counts with the live
sessions; the INSERT) and a commit, at any study size; stale sessions are released elsewhere
(balance.release_stale_batch, off the request path).
"""

import secrets
from datetime import datetime

import numpy as np
from sqlalchemy import select, update
from sqlalchemy.exc import IntegrityError
from sqlmodel import Session

from app import __version__
from app.server.flow import balance, notices, places
from app.server.flow.context import StudyContext
from app.server.flow.plan import assign_plan, dump_plan, has_consented
from app.server.flow.recruitment import ATTEMPT_KEYS, Identity, identify
from app.server.schemas import SessionCreate
from app.server.storage.tables import Participant, utcnow
from app.study.errors import Refused

# a started session's routes are SESSION_PATH/...; its token travels in this header
SESSION_HEADER = "X-Session-Token"
SESSION_PATH = "/api/session"


def start_session(db: Session, ctx: StudyContext, body: SessionCreate,
                  rng: np.random.Generator | None = None,
                  prolific_check: str | None = None) -> tuple[Participant, bool]:
    """A new participant with a balanced plan, or (resumed=True) their live session;
    `prolific_check` is what Prolific said of a new one (prolific_check.check_start)."""
    who = identify(ctx.config, body, ctx.preview_key)
    try:
        return _start(db, ctx, body, who, rng or np.random.default_rng(), prolific_check)
    except IntegrityError:  # the same external id started in another process at once
        db.rollback()
        existing = live_participant(db, ctx.study_id, who.external_id)
        db.commit()
        if existing is None or not _resumable(existing, who, ctx):
            raise Refused(409, "recruitment: a session for this participant id was started "
                               "at the same moment; reload the page",
                          notices.started_twice()) from None
        return existing, True
    except BaseException:
        db.rollback()
        raise


def _start(db: Session, ctx: StudyContext, body: SessionCreate, who: Identity,
           rng: np.random.Generator, prolific_check: str | None) -> tuple[Participant, bool]:
    existing = live_participant(db, ctx.study_id, who.external_id)
    if existing is not None:
        if _resumable(existing, who, ctx):
            db.commit()
            return existing, True
        _replace(db, existing)
    usage, live = balance.read_standing(db, ctx)
    if not who.pilot:  # no place is taken yet (places.take_place, at consent)
        places.admit(ctx, usage, live)
    order, steps = assign_plan(ctx.config, ctx.bank, usage, rng)
    participant = Participant(
        study_id=ctx.study_id, recruitment=who.recruitment, external_id=who.external_id,
        attempt_key=who.attempt_key, pilot=who.pilot, public_id=secrets.token_hex(8),
        session_token=secrets.token_urlsafe(24), recruitment_params=who.params,
        world_order=",".join(order), plan=dump_plan(steps),
        config_sha256=ctx.config_sha256, bank_sha256=ctx.bank.sha256, app_version=__version__,
        prolific_check=prolific_check)
    db.add(participant)
    db.commit()
    return participant, False


def live_participant(db: Session, study_id: str, external_id: str | None) -> Participant | None:
    """The not-replaced session of this external id in this study (None for anonymous)."""
    if external_id is None:
        return None
    query = select(Participant).where(Participant.study_id == study_id,
                                      Participant.external_id == external_id,
                                      Participant.replaced_at.is_(None))
    return db.execute(query).scalars().first()


def _resumable(existing: Participant, who: Identity, ctx: StudyContext) -> bool:
    """True to resume (the same link: its session, or its ending and code once it ended);
    False to replace a stale session; 409 otherwise."""
    if existing.attempt_key == who.attempt_key:
        return True
    platform = ctx.config.recruitment.platform
    if has_ended(existing):
        done = "completed" if existing.completed else "ended"
        raise Refused(409, f"recruitment: this participant has already {done} the study",
                      notices.already_taken_part(platform))
    if _is_stale(existing, ctx):
        return False
    key = ATTEMPT_KEYS[who.recruitment]
    raise Refused(409, f"recruitment.{key}: does not match the session in progress for this "
                       "participant id; reopen the study from the original link",
                  notices.running_elsewhere(platform, ctx.config.in_progress_timeout_min))


def _is_stale(participant: Participant, ctx: StudyContext) -> bool:
    """Unfinished and past its timeout: consent's from the start, then the session's."""
    if not has_consented(participant):
        return as_utc(participant.created_at) < places.consent_cutoff(ctx.config)
    return as_utc(participant.updated_at) < balance.in_progress_cutoff(ctx.config)


def _replace(db: Session, old: Participant) -> None:
    """Retire a stale session (its rows stay) so a new attempt can take the external id."""
    db.execute(update(Participant.__table__)
               .where(Participant.id == old.id, Participant.replaced_at.is_(None))
               .values(replaced_at=utcnow()))
    balance.release(db, old)
    db.flush()


def as_utc(moment: datetime) -> datetime:
    """SQLite returns naive datetimes; they were written in UTC."""
    return moment if moment.tzinfo else moment.replace(tzinfo=utcnow().tzinfo)


def participant_by_token(db: Session, token: str) -> Participant:
    """The participant holding this session token, or 404."""
    found = db.execute(select(Participant).where(Participant.session_token == token))
    participant = found.scalars().first()
    if participant is None:
        raise Refused(404, f"{SESSION_HEADER}: unknown session")
    return participant


REPLACED = (f"{SESSION_HEADER}: this attempt was replaced by a newer one of the same "
            "participant, so this page can no longer save answers. The study continues in "
            "the other tab or attempt: please close this one.")
BANK_GONE = (f"{SESSION_HEADER}: the study was changed after this session started, so it "
             "cannot continue. Your answers so far are saved. Please return the study on the "
             "recruiting platform and contact the researchers there.")


def check_can_continue(participant: Participant, bank_sha256: str, platform: str) -> None:
    """410 for a replaced session, and for an unfinished one whose trial bank is not loaded
    any more (served with --allow-bank-change); an ended session still shows its ending."""
    if participant.replaced_at is not None:
        raise Refused(410, REPLACED, notices.replaced())
    ran = participant.bank_sha256
    if ran and ran != bank_sha256 and not has_ended(participant):
        raise Refused(410, BANK_GONE, notices.study_changed(platform))


def has_ended(participant: Participant) -> bool:
    """Completed, or ended another way (declined consent, screened out)."""
    return participant.completed or participant.ended_at is not None


def session_status(participant: Participant, cutoffs: places.Cutoffs) -> str:
    """replaced (a new attempt took over), ended, awaiting_consent (started since the consent
    cutoff), in_progress (consented, written since the in-progress cutoff), stale."""
    if participant.replaced_at is not None:
        return "replaced"
    if has_ended(participant):
        return "ended"
    if not has_consented(participant):
        fresh = as_utc(participant.created_at) >= cutoffs.consent
        return "awaiting_consent" if fresh else "stale"
    return "in_progress" if as_utc(participant.updated_at) >= cutoffs.in_progress else "stale"
