"""Researcher dashboard API behind the bearer token: sessions, live numbers and replays."""

from typing import Literal

from fastapi import APIRouter, Request

from app.http.deps import AdminDep, SessionDep, study_context
from app.http.openapi import ErrorDetail
from app.researcher import replay

router = APIRouter(prefix="/api/researcher", tags=["researcher"])
NOT_IN_BANK = {409: {"model": ErrorDetail, "description": "clip_sha256: the trial bank this "
                     "server loaded does not hold the clip the participant saw"}}


@router.get("/dashboard")
def read_dashboard(study_id: str, request: Request, db: SessionDep, _: AdminDep,
                   rules: Literal["kept", "live"] = "kept", external_ids: bool = False) -> dict:
    """Every session, sessions per config/bank hash, and alignment error CIs and fields
    under the study's exclusion rules (`live`: incomplete sessions kept)."""
    from app.researcher import dashboard  # pandas: on the first request, not at every start

    return dashboard.dashboard(db, study_context(request, study_id), rules, external_ids)


@router.get("/participants/{public_id}/trials")
def read_participant_trials(public_id: str, study_id: str, request: Request, db: SessionDep,
                            _: AdminDep) -> dict:
    """A session's answered trials in the order answered."""
    return replay.trial_rows(db, study_context(request, study_id), public_id)


@router.get("/participants/{public_id}/trials/{trial_id}", responses=NOT_IN_BANK)
def read_trial_replay(public_id: str, trial_id: str, study_id: str, request: Request,
                      db: SessionDep, _: AdminDep) -> dict:
    """One answered trial to replay: the clip as shown, clicks with times, undo history,
    and Ours', the VAE's, the policy's and constant velocity's moves from each start."""
    return replay.trial_replay(db, study_context(request, study_id), public_id, trial_id)
