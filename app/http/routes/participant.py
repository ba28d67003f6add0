"""Participant API: start or resume a session, read its state, submit each step, telemetry.

A started session is addressed by its token in the X-Session-Token header, never in the
URL: request lines end up in proxy access logs and browser history.
"""

from fastapi import APIRouter, Request, Response, status

from app.http.deps import ContextDep, ParticipantDep, SessionDep, WriterDep, study_context
from app.server.flow import drafts, predictions, prolific_check, sessions, tabs, telemetry
from app.server.flow.sessions import SESSION_PATH
from app.server.flow.state import state_json
from app.server.schemas import (
    ConsentCreate,
    ContinueCreate,
    DeclineCreate,
    DraftSave,
    EventsCreate,
    ParticipantPublic,
    PredictionCreate,
    ScreenOutCreate,
    SessionCreate,
    SubmissionBody,
    SurveyCreate,
    TabClaim,
    TabRelease,
)
from app.server.storage import crud

router = APIRouter(tags=["participant"])
STATE_DOC = "`{phase, progress: {done, total}, step}` (app/http/API.md)"


def state_response(ctx, participant, status_code: int = 200, draft: dict | None = None
                   ) -> Response:
    """The participant's state as JSON (trial payloads pre-encoded, see flow/state.py)."""
    return Response(state_json(ctx, participant, draft), status_code=status_code,
                    media_type="application/json")


@router.post("/api/sessions", response_model=ParticipantPublic,
             status_code=status.HTTP_201_CREATED,
             responses={200: {"description": "resumed an unfinished session"},
                        403: {"description": "missing or malformed platform parameters, a "
                                             "wrong preview key, or a submission Prolific "
                                             "does not know"},
                        409: {"description": "this external id already completed the study, "
                                             "or its session in progress has another attempt "
                                             "key"}})
async def create_session(body: SessionCreate, request: Request, response: Response,
                         db: SessionDep) -> ParticipantPublic:
    """Start a session from the recruitment URL parameters, or resume the unfinished one."""
    ctx = study_context(request, body.study_id)
    check = await prolific_check.check_start(request.app.state.prolific, db, ctx, body)
    participant, resumed = sessions.start_session(db, ctx, body, prolific_check=check)
    if resumed:
        response.status_code = status.HTTP_200_OK
    return ParticipantPublic(session_token=participant.session_token,
                             participant_id=participant.public_id, resumed=resumed)


@router.get(f"{SESSION_PATH}/state", response_description=STATE_DOC)
async def read_state(participant: ParticipantDep, ctx: ContextDep, db: SessionDep) -> Response:
    """The current phase, progress and what the phase needs; in a trial, the clicks saved
    so far (`step.draft`), so a refresh resumes where it was."""
    draft = drafts.current_draft(db, participant)
    db.commit()  # end the read transaction before the answer is built
    return state_response(ctx, participant, draft=draft)


@router.put(f"{SESSION_PATH}/draft")
async def save_draft(body: DraftSave, participant: WriterDep, ctx: ContextDep,
                     db: SessionDep) -> dict:
    """Keep the current trial's clicks so far; answers `{seq}`, the newest stored."""
    return {"seq": drafts.save_draft(db, ctx, participant, body)}


@router.post(f"{SESSION_PATH}/tab", responses={409: {"description": "another tab is the live one"}})
async def claim_tab(body: TabClaim, participant: ParticipantDep, db: SessionDep) -> dict:
    """Make this browser tab the session's live one (on load, then as a heartbeat); answers
    how often to say so again."""
    tabs.claim_tab(db, participant, body)
    return {"live": True, "heartbeat_s": tabs.HEARTBEAT_S}


@router.post(f"{SESSION_PATH}/tab/release", status_code=status.HTTP_204_NO_CONTENT)
async def release_tab(body: TabRelease, participant: ParticipantDep, db: SessionDep) -> None:
    """The live tab is closing (a beacon): another may claim the session without asking."""
    tabs.release_tab(db, participant, body)


@router.post(f"{SESSION_PATH}/consent")
async def submit_consent(body: ConsentCreate, participant: WriterDep, ctx: ContextDep,
                         db: SessionDep) -> Response:
    """Record consent, from which the session counts (409 if the study closed or filled up
    since its start, 503 while it runs its cap of sessions); answers the next state."""
    crud.record_consent(db, ctx, participant, body)
    return state_response(ctx, participant)


@router.post(f"{SESSION_PATH}/decline")
async def submit_decline(body: DeclineCreate, participant: WriterDep, ctx: ContextDep,
                         db: SessionDep) -> Response:
    """The participant does not agree: the session ends (declined_consent); answers done."""
    crud.record_decline(db, ctx, participant, body)
    return state_response(ctx, participant)


@router.post(f"{SESSION_PATH}/screen-out")
async def submit_screen_out(body: ScreenOutCreate, participant: WriterDep,
                            ctx: ContextDep, db: SessionDep) -> Response:
    """The device cannot run the study (before any trial): the session ends (screened_out)."""
    crud.record_screen_out(db, ctx, participant, body)
    return state_response(ctx, participant)


@router.post(f"{SESSION_PATH}/instructions")
async def submit_instructions(body: SubmissionBody, participant: WriterDep,
                              ctx: ContextDep, db: SessionDep) -> Response:
    """Record that the instructions were read; answers the next state."""
    crud.record_instructions(db, participant, body)
    return state_response(ctx, participant)


@router.post(f"{SESSION_PATH}/continue")
async def submit_continue(body: ContinueCreate, participant: WriterDep, ctx: ContextDep,
                          db: SessionDep) -> Response:
    """The participant read a part's screen (world_intro, practice_over); answers the next
    state."""
    crud.record_continue(db, participant, body)
    return state_response(ctx, participant)


@router.post(f"{SESSION_PATH}/predictions", status_code=status.HTTP_201_CREATED,
             responses={200: {"description": "this submission_id was already stored"}})
async def submit_predictions(body: PredictionCreate, participant: WriterDep,
                             ctx: ContextDep, db: SessionDep) -> Response:
    """Store one trial's clicked positions (start states x steps); answers the next state."""
    stored = predictions.record_predictions(db, ctx, participant, body)
    return state_response(ctx, participant, 201 if stored else 200)


@router.post(f"{SESSION_PATH}/survey")
async def submit_survey(body: SurveyCreate, participant: WriterDep, ctx: ContextDep,
                        db: SessionDep) -> Response:
    """Store the closing survey; the session is then done."""
    crud.record_survey(db, ctx, participant, body)
    return state_response(ctx, participant)


@router.post(f"{SESSION_PATH}/events", status_code=status.HTTP_202_ACCEPTED,
             responses={409: {"description": "the session has not consented yet, or is "
                                             "complete: no events are stored"}})
async def submit_events(body: EventsCreate, participant: ParticipantDep,
                        db: SessionDep) -> dict:
    """Store telemetry events (at most 100 a request, MAX_EVENTS_PER_SESSION a session);
    retried events are stored once."""
    return {"stored": telemetry.record_events(db, participant, body)}
