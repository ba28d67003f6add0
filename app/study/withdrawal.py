"""Withdrawal: delete every row of one participant in one transaction, leave an audit line.

All sessions of the external id in the study go (a replaced attempt and a pilot session
too): their submissions, trial responses, prediction rows, telemetry events and the
sessions themselves. A session still in the balance counts is released first, so the
next start fills its place. The audit line (WithdrawalAudit) keeps a fresh random salt,
sha256(salt + ":" + external id), the time, how it was asked for and the deleted row
counts per table: enough to confirm a withdrawal to the person who asked, given their
id, and nothing that names them. The same id may start again later, as a new person.
"""

import hashlib
import secrets

from sqlalchemy import delete, select
from sqlmodel import Session

from app.study import balance
from app.study.errors import Refused
from app.study.sessions import as_utc
from app.study.tables import (
    Event,
    Participant,
    PredictionRow,
    Submission,
    TrialDraft,
    TrialResponse,
    WithdrawalAudit,
)

# children first: every one of them points at participant.id
CHILD_TABLES = (PredictionRow, TrialResponse, Event, Submission, TrialDraft)


def id_hash(salt: str, external_id: str) -> str:
    """sha256(salt + ":" + external id), hex."""
    return hashlib.sha256(f"{salt}:{external_id}".encode()).hexdigest()


def withdraw(db: Session, study_id: str, external_id: str, via: str) -> WithdrawalAudit:
    """Delete every session of `external_id` in `study_id` and its rows; 404 if none."""
    try:
        balance.lock_study(db, study_id)  # no session start of this study runs meanwhile
        sessions = _sessions_of(db, study_id, external_id)
        if not sessions:
            raise Refused(404, f"external_id: no session of this id in study {study_id!r}")
        for session in sessions:
            balance.release(db, session)
        salt = secrets.token_hex(16)
        audit = WithdrawalAudit(study_id=study_id, salt=salt, id_sha256=id_hash(salt, external_id),
                                via=via, row_counts=_delete_rows(db, [p.id for p in sessions]))
        db.add(audit)
        db.commit()
    except BaseException:
        db.rollback()
        raise
    return audit


def _sessions_of(db: Session, study_id: str, external_id: str) -> list[Participant]:
    query = select(Participant).where(Participant.study_id == study_id,
                                      Participant.external_id == external_id)
    if db.get_bind().dialect.name == "postgresql":
        query = query.with_for_update()  # a write of this session in flight waits for us
    return list(db.execute(query).scalars().all())


def _delete_rows(db: Session, ids: list[int]) -> dict[str, int]:
    counts = {}
    for table in CHILD_TABLES:
        done = db.execute(delete(table).where(table.participant_id.in_(ids)))
        counts[table.__tablename__] = done.rowcount
    done = db.execute(delete(Participant).where(Participant.id.in_(ids)))
    counts[Participant.__tablename__] = done.rowcount
    return counts


def audit_lines(db: Session, study_id: str) -> list[dict]:
    """Every withdrawal of the study, oldest first, as audit_line dicts."""
    found = db.execute(select(WithdrawalAudit).where(WithdrawalAudit.study_id == study_id)
                       .order_by(WithdrawalAudit.id)).scalars().all()
    return [audit_line(a) for a in found]


def audit_line(audit: WithdrawalAudit) -> dict:
    """An audit row as JSON-able data (no external id in it, only its salted hash)."""
    return {"id": audit.id, "study_id": audit.study_id,
            "withdrawn_at": as_utc(audit.withdrawn_at).isoformat(), "via": audit.via,
            "salt": audit.salt, "id_sha256": audit.id_sha256, "row_counts": audit.row_counts}
