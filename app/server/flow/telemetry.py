"""Telemetry writes: each client UUID stored once, at most MAX_EVENTS_PER_SESSION a session.

The participant row counts its stored events (`events_stored`). A batch is inserted with
ON CONFLICT DO NOTHING, and the rows it really stored (the INSERT's rowcount) move that
counter by a conditional UPDATE in the same transaction. The UPDATE locks the row, so
concurrent batches, on several workers too, cannot pass the cap together, and no request
counts rows with COUNT(*).
"""

import uuid

from sqlalchemy import update
from sqlalchemy.engine import Connection
from sqlmodel import Session

from app.server.flow.plan import has_consented
from app.server.flow.sessions import has_ended
from app.server.schemas import EventsCreate
from app.server.storage.db import insert_skipping_duplicates
from app.server.storage.tables import Event, Participant, keep_loaded, utcnow
from app.study.errors import Refused

MAX_EVENTS_PER_SESSION = 1000  # the browser sends about 3 per trial; 1000 is far above that
SESSION_COMPLETE = "phase: the session is complete; no more events"
BEFORE_CONSENT = "phase: no events are taken before consent; nothing was stored"


def record_events(db: Session, participant: Participant, body: EventsCreate) -> int:
    """Store a batch of events, skipping UUIDs already stored; returns how many were new.

    Refused with 409 before consent and once the session is complete, and whole (422,
    nothing stored) when it would take the session past MAX_EVENTS_PER_SESSION.
    """
    if has_ended(participant):
        raise Refused(409, SESSION_COMPLETE)
    if not has_consented(participant):
        raise Refused(409, BEFORE_CONSENT)
    conn = db.connection()
    stored = conn.execute(_insert_new_events(conn, participant, body)).rowcount
    if stored and not _count_stored(conn, participant.id, stored):
        db.rollback()
        raise _refusal(db, participant)
    db.commit()
    return stored


def record_server_event(db: Session, participant: Participant, kind: str,
                        t_client_ms: float, data: dict) -> bool:
    """Store an event the server itself saw (e.g. a page opened), within the same cap as
    telemetry; False (nothing stored) before consent or once the session has reached the
    cap. Does not commit."""
    if not has_consented(participant):
        return False
    conn = db.connection()
    if not _count_stored(conn, participant.id, 1):
        return False
    conn.execute(Event.__table__.insert(), [{
        "submission_id": str(uuid.uuid4()), "participant_id": participant.id, "kind": kind,
        "t_client_ms": t_client_ms, "data": data, "received_at": utcnow()}])
    keep_loaded(participant, events_stored=participant.events_stored + 1)
    return True


def _insert_new_events(conn: Connection, participant: Participant, body: EventsCreate):
    """One multi-row INSERT that skips stored UUIDs (so its rowcount is what it stored)."""
    now = utcnow()
    rows = {str(e.submission_id): {"submission_id": str(e.submission_id),
                                   "participant_id": participant.id, "kind": e.kind,
                                   "t_client_ms": e.t_client_ms, "data": e.data,
                                   "received_at": now}
            for e in body.events}  # a UUID twice in one batch counts once
    # SQLAlchemy drops an INSERT's rowcount when it closes the cursor unless asked to keep it
    return (insert_skipping_duplicates(conn, Event.__table__).values(list(rows.values()))
            .execution_options(preserve_rowcount=True))


def _count_stored(conn: Connection, participant_id: int, n: int) -> bool:
    """Add `n` to the participant's event count if it stays within the cap (and the session
    is still running); False if not."""
    table = Participant.__table__
    claimed = conn.execute(
        update(table)
        .where(table.c.id == participant_id, table.c.completed.is_(False),
               table.c.ended_at.is_(None), table.c.replaced_at.is_(None),
               table.c.events_stored + n <= MAX_EVENTS_PER_SESSION)
        .values(events_stored=table.c.events_stored + n))
    return claimed.rowcount == 1


def _refusal(db: Session, participant: Participant) -> Refused:
    """Why a batch could not be counted: the session completed meanwhile, or the cap."""
    db.refresh(participant)
    db.commit()
    if has_ended(participant):
        return Refused(409, SESSION_COMPLETE)
    return Refused(422, f"events: at most {MAX_EVENTS_PER_SESSION} events per session")
