"""Database transactions of a participant's steps: each write, and the reads it depends on.

What a step is and whether an answer is acceptable are decided elsewhere (plan.py,
validation.py); this module stores (a trial's answer: predictions.py). A step is
advanced by a conditional UPDATE (`WHERE position = expected`), so two workers racing on
one participant cannot both advance it, and a client UUID (`submission_id`, unique, bound
to its submission kind and body hash) makes a retried request a no-op that answers the
current state. Every write commits before the route answers, so a 2xx means the answer is stored.
"""

import hashlib
from collections.abc import Callable
from contextlib import contextmanager

from sqlalchemy import delete, select, update
from sqlalchemy.exc import IntegrityError
from sqlmodel import Session

from app.server.flow import balance, endings, places
from app.server.flow.context import StudyContext
from app.server.flow.plan import BEFORE_TRIALS, Phase, expect_phase, has_consented
from app.server.flow.validation import validate_survey
from app.server.schemas import (
    ConsentCreate,
    ContinueCreate,
    DeclineCreate,
    ScreenOutCreate,
    SubmissionBody,
    SurveyCreate,
)
from app.server.storage.tables import Event, Participant, Submission, keep_loaded, utcnow
from app.study.errors import Refused

# ---------------------------------------------------------------- step writes

def body_hash(body: SubmissionBody) -> str:
    """SHA-256 of the body as the server parsed it: a retry must send the same one."""
    return hashlib.sha256(body.model_dump_json().encode()).hexdigest()


def already_stored(db: Session, participant: Participant, body: SubmissionBody,
                   submission_kind: str) -> bool:
    """True if this UUID was stored for this same request (a retry); else 409 or 422."""
    stored = db.execute(select(Submission.participant_id, Submission.kind,
                               Submission.body_sha256)
                        .where(Submission.submission_id == str(body.submission_id))).first()
    if stored is None:
        return False
    if stored.participant_id != participant.id:
        raise Refused(409, "submission_id: already used by another session")
    if stored.kind != submission_kind or stored.body_sha256 != body_hash(body):
        raise Refused(422, f"submission_id: already used for a different {stored.kind} "
                           "request; a retry must resend the same body, a new answer needs "
                           "a new submission_id")
    return True


def advance(db: Session, participant: Participant, body: SubmissionBody, submission_kind: str,
            payload: dict, extra_inserts: list[tuple[object, list[dict]]] = (),
            ending: dict | None = None,
            before_commit: Callable[[], None] | None = None,
            updates: dict | None = None) -> bool:
    """Store the submission and its rows and move one step on, in one transaction.

    With `ending` (ending_values) the session is done and the ending's receipt is stored
    in the same commit, before the browser is told where to go; `updates` are other
    Participant columns to set with the step. A replaced session moves no more. An ending
    before the plan is through (declined, screened out) leaves the position at the step
    that ended it, so the session counts only the steps it took (plan.current_step shows it
    done).
    Returns False when a concurrent retry of the same UUID won the race (nothing stored).
    """
    expected = participant.position
    now = utcnow()
    values = {**(updates or {}), "position": expected + 1, "updated_at": now}
    if ending is not None:
        values.update(ending, ended_at=now)
        if ending["completed"]:
            values["completed_at"] = now
        else:
            values["position"] = expected
    if payload.get("attention_ok") is False:
        values["attention_failed"] = Participant.attention_failed + 1
    conn = db.connection()
    try:
        conn.execute(Submission.__table__.insert(), [{
            "submission_id": str(body.submission_id), "participant_id": participant.id,
            "kind": submission_kind, "body_sha256": body_hash(body), "step_index": expected,
            "payload": payload, "received_at": now}])
        for table, rows in extra_inserts:
            conn.execute(table.__table__.insert(), rows)
        moved = conn.execute(update(Participant.__table__)
                             .where(Participant.id == participant.id,
                                    Participant.position == expected,
                                    Participant.replaced_at.is_(None)).values(**values))
        if moved.rowcount != 1:
            raise Refused(409, "position: the session moved on in another request; reload")
        _mirror(participant, values)
        if before_commit is not None:
            before_commit()
        db.commit()
    except IntegrityError:
        db.rollback()
        if already_stored(db, participant, body, submission_kind):
            return False
        raise
    except BaseException:
        db.rollback()
        raise
    return True


def _mirror(participant: Participant, values: dict) -> None:
    """Keep the loaded row in step with the UPDATE instead of reading it back."""
    stored = {key: value for key, value in values.items() if key != "attention_failed"}
    if "attention_failed" in values:
        stored["attention_failed"] = participant.attention_failed + 1
    keep_loaded(participant, **stored)


def record_consent(db: Session, ctx: StudyContext, participant: Participant,
                   body: ConsentCreate) -> None:
    """The participant agreed to take part: the session takes its place in the study
    (places.take_place) and their device info is stored from now on."""
    with replay_if_stored(db, participant, body, "consent") as fresh:
        expect_phase(participant, Phase.CONSENT)
        place = places.take_place(db, ctx, participant)  # the study's lock, then the row's
        fresh.stored = advance(db, participant, body, "consent", {"agree": True},
                               updates={"client": body.client.model_dump(), **place},
                               before_commit=lambda: balance.add_held(db, participant))


def record_instructions(db: Session, participant: Participant, body: SubmissionBody) -> None:
    """The participant has read the instructions."""
    with replay_if_stored(db, participant, body, "instructions") as fresh:
        expect_phase(participant, Phase.INSTRUCTIONS)
        fresh.stored = advance(db, participant, body, "instructions", {})


def record_continue(db: Session, participant: Participant, body: ContinueCreate) -> None:
    """The participant read a part's screen (its world's introduction, or practice over)."""
    with replay_if_stored(db, participant, body, "continue") as fresh:
        expect_phase(participant, Phase(body.phase))
        fresh.stored = advance(db, participant, body, "continue", {"phase": body.phase})


def record_survey(db: Session, ctx: StudyContext, participant: Participant,
                  body: SurveyCreate) -> None:
    """Closing answers; the session is then complete and settles its balance counts."""
    with replay_if_stored(db, participant, body, "survey") as fresh:
        expect_phase(participant, Phase.SURVEY)
        answers = validate_survey(ctx.config.survey, body.answers)
        ending, excluded = endings.survey_ending(db, ctx.config, participant)
        fresh.stored = advance(
            db, participant, body, "survey", {"answers": answers}, ending=ending,
            before_commit=lambda: balance.settle_completion(db, participant, excluded))


def record_decline(db: Session, ctx: StudyContext, participant: Participant,
                   body: DeclineCreate) -> None:
    """The participant does not consent: the session ends and keeps only its receipt."""
    with replay_if_stored(db, participant, body, "decline") as fresh:
        expect_phase(participant, Phase.CONSENT)
        fresh.stored = advance(db, participant, body, "decline", {},
                               ending=endings.ending_values(ctx.config, "declined_consent"),
                               updates=FORGOTTEN, before_commit=lambda: _forget(db, participant))


def record_screen_out(db: Session, ctx: StudyContext, participant: Participant,
                      body: ScreenOutCreate) -> None:
    """The device check failed before any trial: the session ends with that outcome."""
    with replay_if_stored(db, participant, body, "screen_out") as fresh:
        expect_phase(participant, *BEFORE_TRIALS)
        fresh.stored = advance(db, participant, body, "screen_out", {"reason": body.reason},
                               ending=endings.ending_values(ctx.config, "screened_out"),
                               updates=FORGOTTEN, before_commit=lambda: _forget(db, participant))


FORGOTTEN = {"client": {}, "events_stored": 0}  # what an ending before taking part clears


def _forget(db: Session, participant: Participant) -> None:
    """Keep nothing of a session that ends before taking part but its receipt (its columns
    go with the ending's step: FORGOTTEN). Before consent there is nothing to delete: events
    and counting start at consent (telemetry.py, places.take_place)."""
    if has_consented(participant):
        db.execute(delete(Event.__table__).where(Event.participant_id == participant.id))
        balance.release(db, participant)


class _Outcome:
    stored = False


@contextmanager
def replay_if_stored(db: Session, participant: Participant, body: SubmissionBody,
                     submission_kind: str):
    """Run a write; if it is refused, a retry of a stored UUID is not an error.

    The common first-time path costs no lookup: a retry is recognised only when the
    write is refused (the session has moved on), and a concurrent duplicate by the
    unique key inside `advance`.
    """
    outcome = _Outcome()
    try:
        yield outcome
    except Refused:
        if already_stored(db, participant, body, submission_kind):
            outcome.stored = False
            return
        raise
