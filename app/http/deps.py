"""FastAPI dependencies: database session, study context, participant, researcher token.

The participant path is async end to end: its database work runs in synchronous code on
the event loop, from the participant's lookup (which opens the request's one transaction)
to the route's commit, with nothing awaited in between, so the pooled connection is held
for that work alone and goes back at the commit (one checkout, and on PostgreSQL one
pre-ping and BEGIN, per request). A route that refuses before its commit leaves the
rollback to get_db's clean-up. Sync dependencies would run in the thread pool and hold a
connection from lookup until clean-up; under many concurrent requests the pool and the
thread pool then wait on each other until the pool times out.
"""

import secrets
from collections.abc import AsyncIterator
from typing import Annotated

from fastapi import Depends, Header, Request
from sqlmodel import Session

from app.http.lockout import TokenLockout
from app.http.ratelimit import client_key
from app.server.flow import notices, tabs
from app.server.flow.context import StudyContext
from app.server.flow.sessions import SESSION_HEADER, check_can_continue, participant_by_token
from app.server.storage.tables import Participant
from app.settings import Settings
from app.study.errors import Refused


async def get_db(request: Request) -> AsyncIterator[Session]:
    """One database session per request; objects stay readable after commit (crud keeps
    them in step with what it wrote, saving a read-back per request)."""
    with Session(request.app.state.engine, expire_on_commit=False) as session:
        yield session


SessionDep = Annotated[Session, Depends(get_db)]


async def get_settings_dep(request: Request) -> Settings:
    """The settings the app was created with."""
    return request.app.state.settings


SettingsDep = Annotated[Settings, Depends(get_settings_dep)]
# the session token travels in a header, never in the URL (proxies and browsers log URLs)
SessionTokenHeader = Annotated[str, Header(alias=SESSION_HEADER, min_length=1, max_length=64)]


def study_context(request: Request, study_id: str) -> StudyContext:
    """The loaded study with this id, or 404."""
    ctx = request.app.state.studies.get(study_id)
    if ctx is None:
        known = ", ".join(sorted(request.app.state.studies))
        raise Refused(404, f"study_id: unknown study {study_id!r} (served: {known})",
                      notices.unknown_study())
    return ctx


async def get_participant(request: Request, db: SessionDep,
                          x_session_token: SessionTokenHeader) -> Participant:
    """The participant whose session token is in the X-Session-Token header, read in the
    transaction the route goes on with; 410 once the session can no longer continue
    (replaced by a newer attempt, or its bank is gone)."""
    participant = participant_by_token(db, x_session_token)
    ctx = study_context(request, participant.study_id)
    check_can_continue(participant, ctx.bank.sha256, ctx.config.recruitment.platform)
    return participant


ParticipantDep = Annotated[Participant, Depends(get_participant)]


async def get_writer(participant: ParticipantDep,
                     x_tab_id: Annotated[str | None, Header(max_length=64)] = None
                     ) -> Participant:
    """The participant of a write, refused (409) when it comes from a tab that is not the
    session's live one (tabs.py; a request without the header is not checked)."""
    tabs.check_live_tab(participant, x_tab_id)
    return participant


WriterDep = Annotated[Participant, Depends(get_writer)]


async def participant_context(request: Request, participant: ParticipantDep) -> StudyContext:
    """The study the participant belongs to."""
    return study_context(request, participant.study_id)


ContextDep = Annotated[StudyContext, Depends(participant_context)]


async def require_admin(request: Request, settings: SettingsDep,
                        authorization: Annotated[str | None, Header()] = None) -> None:
    """Bearer token check: 401 when missing, 403 when wrong, 429 once this client sent too
    many wrong ones (lockout.py)."""
    lockout: TokenLockout = request.app.state.token_lockout
    client = client_key(request.client.host if request.client else "unknown")
    await lockout.check(client)
    if not authorization or not authorization.lower().startswith("bearer "):
        raise Refused(401, "authorization: missing bearer token (Authorization: Bearer <token>)")
    token = authorization[7:].strip()
    if not secrets.compare_digest(token.encode(), settings.admin_token.encode()):
        await lockout.failed(client)
        raise Refused(403, "authorization: wrong researcher token")


AdminDep = Annotated[None, Depends(require_admin)]
