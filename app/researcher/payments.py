"""From the payment sheet to Prolific: approve or ask to return submissions, with an audit line.

The researcher names sessions by their public id (`participant_id` in the participants export,
the payment sheet). Every id is checked before anything is sent: it must be a Prolific
session of the study; an approval needs the session `completed` (the sheet's outcome), since
only those earned the pay. Then each submission (the session's SESSION_ID) is sent to
Prolific's API (app/server/prolific.py) and one PaymentAudit line per session records the
action, how it was asked for, whether Prolific accepted it and its answer (the submission's
new status, or why not). A failure on one session does not stop the others.
"""

import asyncio

from sqlalchemy import select
from sqlalchemy.engine import Engine
from sqlmodel import Session

from app.server.queries import (
    Participant,
    PaymentAudit,
    ProlificClient,
    ProlificRefused,
    ProlificUnreachable,
    as_utc,
)
from app.study.errors import Refused

ACTIONS = ("approve", "return")
RESULT_CHARS = 300


async def send_actions(engine: Engine, client: ProlificClient | None, study_id: str,
                       action: str, participant_ids: list[str], reason: str | None,
                       via: str) -> list[dict]:
    """Send `action` for each session to Prolific; the audit lines written (Refused, before
    anything is sent, naming the field at fault)."""
    if client is None:
        raise Refused(409, "prolific: no Prolific API token is configured "
                           "(TOMSTUDY_PROLIFIC_TOKEN_FILE)")
    if action not in ACTIONS:
        raise Refused(404, f"action: {action!r} is not one of {', '.join(ACTIONS)}")
    if action == "return" and not reason:
        raise Refused(422, "reason: a return request needs the reason Prolific shows the "
                           "participant")
    sessions = await asyncio.to_thread(_sessions, engine, study_id, participant_ids)
    _check(action, participant_ids, sessions)
    lines = []
    for public_id in dict.fromkeys(participant_ids):
        ok, result = await _send(client, action, sessions[public_id], reason)
        lines.append(await asyncio.to_thread(_audit, engine, PaymentAudit(
            study_id=study_id, participant_id=public_id, action=action, via=via, ok=ok,
            result=result[:RESULT_CHARS])))
    return lines


def _sessions(engine: Engine, study_id: str, public_ids: list[str]) -> dict[str, Participant]:
    with Session(engine, expire_on_commit=False) as db:
        found = db.execute(select(Participant).where(Participant.study_id == study_id,
                                                     Participant.public_id.in_(public_ids)))
        return {p.public_id: p for p in found.scalars()}


def _check(action: str, public_ids: list[str], sessions: dict[str, Participant]) -> None:
    missing = [p for p in public_ids if p not in sessions]
    if missing:
        raise Refused(404, f"participant_ids: no session {', '.join(missing[:5])} in this study")
    not_prolific = [p for p in public_ids if "SESSION_ID" not in sessions[p].recruitment_params]
    if not_prolific:
        raise Refused(409, f"participant_ids: {', '.join(not_prolific[:5])} did not come from "
                           "Prolific (no SESSION_ID)")
    if action == "approve":
        unfinished = [p for p in public_ids if sessions[p].outcome != "completed"]
        if unfinished:
            raise Refused(409, f"participant_ids: {', '.join(unfinished[:5])} did not complete "
                               "the study (outcome in the payment sheet); approve only "
                               "completed sessions")


async def _send(client: ProlificClient, action: str, session: Participant,
                reason: str | None) -> tuple[bool, str]:
    submission = session.recruitment_params["SESSION_ID"]
    try:
        if action == "approve":
            answer = await client.approve(submission)
        else:
            answer = await client.request_return(submission, [reason])
    except (ProlificUnreachable, ProlificRefused) as err:
        return False, str(err)
    return True, f"status {answer.get('status')}"


def _audit(engine: Engine, line: PaymentAudit) -> dict:
    with Session(engine, expire_on_commit=False) as db:
        db.add(line)
        db.commit()
        return audit_line(line)


def audit_lines(db: Session, study_id: str) -> list[dict]:
    """Every approval and return request of the study, oldest first."""
    found = db.execute(select(PaymentAudit).where(PaymentAudit.study_id == study_id)
                       .order_by(PaymentAudit.id)).scalars().all()
    return [audit_line(a) for a in found]


def audit_line(line: PaymentAudit) -> dict:
    """An audit row as JSON-able data."""
    return {"id": line.id, "study_id": line.study_id, "participant_id": line.participant_id,
            "action": line.action, "via": line.via, "sent_at": as_utc(line.sent_at).isoformat(),
            "ok": line.ok, "result": line.result}
