"""Withdrawal: delete every row of one participant in one transaction, leave an audit line.

A participant is named by their platform id (`external_id`, spelled as the study's
platform normalises it, any case matching) or, for open and pilot sessions that have
none, by the session's public id (`participant_id`). All sessions of that person in the
study go (a replaced attempt too): their submissions, trial responses, prediction rows,
telemetry events and the sessions themselves. A session still in the balance counts is
released first, so the next start fills its place. The audit line (WithdrawalAudit)
keeps which kind of id was given, a fresh random salt, sha256(salt + ":" + id), the
time, how it was asked for and the deleted row counts per table: enough to confirm a
withdrawal to the person who asked, given their id, and nothing that names them. The
same id may start again later, as a new person. The answer also names the archives
(`tomstudy archive`, app/researcher/archive_registry.py) that hold a withdrawn session, so
the lab re-issues them without it; the registry is read before anything is deleted.

Deleted rows must leave the files too: SQLite overwrites them (secure_delete, db.py) and
the write-ahead log is checkpointed and truncated right after (`erase_from_files`).
PostgreSQL keeps them in its table files until VACUUM reuses the space, and in its WAL
and backups until those rotate (docs/reference/exports.md).
"""

import hashlib
import secrets
import time
from dataclasses import dataclass

from sqlalchemy import delete, func, select
from sqlalchemy.engine import Engine
from sqlmodel import Session

from app.layout import Layout
from app.researcher.archive_registry import archives_holding, read_registry
from app.server.queries import (
    Event,
    Participant,
    PredictionRow,
    Submission,
    TrialDraft,
    TrialResponse,
    WithdrawalAudit,
    WithdrawalByExternalId,
    WithdrawalCreate,
    as_utc,
    lock_study,
    normalise_external_id,
    release_counts,
)
from app.study.errors import Refused

CHECKPOINT_TRIES = 5
# children first: every one of them points at participant.id
CHILD_TABLES = (PredictionRow, TrialResponse, Event, Submission, TrialDraft)


@dataclass(frozen=True)
class Withdrawn:
    """A withdrawal done: its audit row and the public ids of the sessions it deleted."""

    audit: WithdrawalAudit
    participant_ids: list[str]


def id_hash(salt: str, external_id: str) -> str:
    """sha256(salt + ":" + external id), hex."""
    return hashlib.sha256(f"{salt}:{external_id}".encode()).hexdigest()


def withdraw(db: Session, study_id: str, who: WithdrawalCreate, platform: str,
             via: str) -> Withdrawn:
    """Delete every session of the person `who` names in `study_id` and its rows; 404 if
    none. `platform` (the study's) says how an external id is spelled."""
    kind, given = id_given(who, platform)
    try:
        lock_study(db, study_id)  # no consent of this study reads the counts meanwhile
        sessions = _sessions_of(db, study_id, kind, given)
        if not sessions:
            raise Refused(404, f"{kind}: no session of this id in study {study_id!r}")
        public_ids = sorted(p.public_id for p in sessions)
        for session in sessions:
            release_counts(db, session)
        salt = secrets.token_hex(16)
        audit = WithdrawalAudit(study_id=study_id, id_kind=kind, salt=salt,
                                id_sha256=id_hash(salt, given), via=via,
                                row_counts=_delete_rows(db, [p.id for p in sessions]))
        db.add(audit)
        db.commit()
    except BaseException:
        db.rollback()
        raise
    return Withdrawn(audit, public_ids)


def id_given(who: WithdrawalCreate, platform: str) -> tuple[str, str]:
    """("external_id", the id as the platform spells it) or ("participant_id", public id)."""
    if isinstance(who, WithdrawalByExternalId):
        return "external_id", normalise_external_id(platform, who.external_id)
    return "participant_id", who.participant_id


def _sessions_of(db: Session, study_id: str, kind: str, given: str) -> list[Participant]:
    if kind == "participant_id":  # a session with a platform id: every session of that id
        one = db.execute(select(Participant.external_id).where(
            Participant.study_id == study_id, Participant.public_id == given)).first()
        if one is None or one.external_id is None:
            return _locked(db, select(Participant).where(Participant.study_id == study_id,
                                                         Participant.public_id == given))
        given = one.external_id
    # any case: rows stored before ids were normalised are the same person's
    return _locked(db, select(Participant).where(
        Participant.study_id == study_id,
        func.lower(Participant.external_id) == given.lower()))


def _locked(db: Session, query) -> list[Participant]:
    if db.get_bind().dialect.name == "postgresql":
        query = query.with_for_update()  # a write of this session in flight waits for us
    return list(db.execute(query).scalars().all())


def withdraw_and_erase(engine: Engine, study_id: str, who: WithdrawalCreate, platform: str,
                       via: str, layout: Layout) -> dict:
    """`withdraw` in a session of its own, then `erase_from_files`: the answer line (the audit
    line and the archives of `layout`'s registry to re-issue) with what happened to the
    deleted rows on disk (Refused if no session matches; RegistryError, before anything is
    deleted, if the registry is unreadable)."""
    archives = read_registry(layout)
    with Session(engine) as db:
        line = answer_line(withdraw(db, study_id, who, platform, via=via), archives)
    return line | {"storage": erase_from_files(engine)}


def answer_line(done: Withdrawn, archives: list[dict]) -> dict:
    """The audit line of a withdrawal and, under `archives`, the registry's archives that hold
    a session it deleted (path, SHA-256, time): those to re-issue without the person."""
    line = audit_line(done.audit)
    return line | {"archives": archives_holding(archives, line["study_id"],
                                                done.participant_ids)}


def erase_from_files(engine: Engine) -> str:
    """After a withdrawal: fold SQLite's write-ahead log into the database and truncate it,
    so the deleted rows' old pages leave the disk; what happened, in a few words."""
    if engine.dialect.name != "sqlite":
        return "postgresql: deleted rows stay in the table files until VACUUM and in WAL " \
               "and backups until they rotate (docs/reference/exports.md)"
    for _ in range(CHECKPOINT_TRIES):
        with engine.connect() as conn:
            busy, _, _ = conn.exec_driver_sql("PRAGMA wal_checkpoint(TRUNCATE)").one()
        if not busy:
            return "sqlite: deleted rows overwritten, write-ahead log checkpointed and truncated"
        time.sleep(0.2)
    return ("sqlite: deleted rows overwritten; the write-ahead log is still being read and "
            "keeps old pages until the next checkpoint (on its own within minutes)")


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
    """An audit row as JSON-able data (no id in it, only its salted hash)."""
    return {"id": audit.id, "study_id": audit.study_id, "id_kind": audit.id_kind,
            "withdrawn_at": as_utc(audit.withdrawn_at).isoformat(), "via": audit.via,
            "salt": audit.salt, "id_sha256": audit.id_sha256, "row_counts": audit.row_counts}
