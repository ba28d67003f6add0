"""Researcher API behind the bearer token: dashboard summary, exports, withdrawals and Prolific
approvals and return requests."""

from typing import Literal

from fastapi import APIRouter, Request
from fastapi.responses import Response

from app.researcher import exports, payments, progress, withdrawal
from app.researcher.archive_registry import RegistryError, read_registry
from app.server.deps import AdminDep, SessionDep, study_context
from app.server.schemas import PaymentActionCreate, WithdrawalCreate
from app.study.errors import Refused

router = APIRouter(prefix="/api/researcher", tags=["researcher"])

CSV = {200: {"content": {"text/csv": {}}}}


@router.get("/summary")
def read_summary(study_id: str, request: Request, db: SessionDep, _: AdminDep) -> dict:
    """Progress, completions, exclusions and running mean alignment error per model and world."""
    return progress.summary(db, study_context(request, study_id))


@router.get("/export/{what}.csv", response_class=Response, responses=CSV)
def read_export(what: Literal[exports.WHAT], study_id: str, request: Request, db: SessionDep,
                _: AdminDep) -> Response:
    """One export (predictions, survey, events, participants); columns in app/server/API.md."""
    return _csv(request, db, study_id, what)


@router.get("/export.csv", response_class=Response, responses=CSV)
def read_predictions_export(study_id: str, request: Request, db: SessionDep,
                            _: AdminDep) -> Response:
    """The predictions export (the same as /export/predictions.csv)."""
    return _csv(request, db, study_id, "predictions")


def _csv(request: Request, db: SessionDep, study_id: str, what: str) -> Response:
    config = study_context(request, study_id).config
    return Response(exports.export_csv(db, config, study_id, what), media_type="text/csv",
                    headers={"Content-Disposition":
                             f'attachment; filename="{study_id}_{what}.csv"'})


@router.post("/withdrawals", status_code=201)
def create_withdrawal(body: WithdrawalCreate, request: Request, db: SessionDep,
                      _: AdminDep) -> dict:
    """Delete every row of one participant (by external_id, or participant_id for open and
    pilot sessions); answers the audit line (no id in it), the archives that hold the
    participant (to re-issue) and what became of the files."""
    ctx = study_context(request, body.study_id)
    try:  # read before anything is deleted: an archive holding the person must be named
        archives = read_registry(request.app.state.settings.layout)
    except RegistryError as err:
        raise Refused(503, f"archives: {err}") from None
    done = withdrawal.withdraw(db, body.study_id, body, ctx.config.recruitment.platform,
                               via="api")
    return withdrawal.answer_line(done, archives) | {
        "storage": withdrawal.erase_from_files(request.app.state.engine)}


@router.get("/withdrawals/audit")
def read_withdrawals(study_id: str, request: Request, db: SessionDep, _: AdminDep) -> list[dict]:
    """Every withdrawal of the study, oldest first."""
    study_context(request, study_id)
    return withdrawal.audit_lines(db, study_id)


@router.post("/prolific/approve", status_code=201)
async def create_approvals(body: PaymentActionCreate, request: Request,
                           _: AdminDep) -> list[dict]:
    """Approve (pay) these completed sessions' Prolific submissions; answers one audit line
    per session, saying whether Prolific accepted it."""
    return await _payment_action(request, "approve", body)


@router.post("/prolific/return", status_code=201)
async def create_return_requests(body: PaymentActionCreate, request: Request,
                                 _: AdminDep) -> list[dict]:
    """Ask these sessions' participants to return their Prolific submissions, giving `reason`;
    answers one audit line per session, saying whether Prolific accepted it."""
    return await _payment_action(request, "return", body)


async def _payment_action(request: Request, action: str, body: PaymentActionCreate
                          ) -> list[dict]:
    study_context(request, body.study_id)
    return await payments.send_actions(request.app.state.engine, request.app.state.prolific,
                                       body.study_id, action, body.participant_ids,
                                       body.reason, via="api")


@router.get("/prolific/audit")
def read_payment_actions(study_id: str, request: Request, db: SessionDep,
                         _: AdminDep) -> list[dict]:
    """Every approval and return request sent to Prolific for the study, oldest first."""
    study_context(request, study_id)
    return payments.audit_lines(db, study_id)
