"""Researcher API behind the bearer token: dashboard summary, exports, withdrawals and Prolific
approvals and return requests."""

from pathlib import Path
from typing import Literal

from fastapi import APIRouter, Request
from fastapi.responses import JSONResponse, Response

from app.core.contracts import WHAT
from app.http.deps import AdminDep, SessionDep, study_context
from app.researcher import payments, withdrawal
from app.researcher.archive_registry import RegistryError, read_registry
from app.server.schemas import PaymentActionCreate, WithdrawalCreate
from app.study.errors import Refused

router = APIRouter(prefix="/api/researcher", tags=["researcher"])
# progress and exports (pandas and the analysis code, ~1 s of imports) load on the first
# researcher request, not in every worker's start: participants never need them

CSV = {200: {"content": {"text/csv": {}}}}


@router.get("/summary")
def read_summary(study_id: str, request: Request, db: SessionDep, _: AdminDep) -> dict:
    """Progress, completions, exclusions and running mean alignment error per model and world."""
    from app.researcher import progress

    return progress.summary(db, study_context(request, study_id))


@router.get("/export/{what}.csv", response_class=Response, responses=CSV)
def read_export(what: Literal[WHAT], study_id: str, request: Request, db: SessionDep,
                _: AdminDep) -> Response:
    """One export (predictions, survey, events, participants); columns in app/http/API.md."""
    return _csv(request, db, study_id, what)


@router.get("/export.csv", response_class=Response, responses=CSV)
def read_predictions_export(study_id: str, request: Request, db: SessionDep,
                            _: AdminDep) -> Response:
    """The predictions export (the same as /export/predictions.csv)."""
    return _csv(request, db, study_id, "predictions")


@router.get("/export/{what}.datapackage.json")
def read_export_package(what: Literal[WHAT], study_id: str, request: Request,
                        db: SessionDep, _: AdminDep) -> JSONResponse:
    """The codebook of one export: a Frictionless Data Package describing the CSV the sibling
    route serves now (its columns, units, allowed values, sha256 and rows)."""
    return _package(request, db, study_id, what)


@router.get("/export.datapackage.json")
def read_predictions_package(study_id: str, request: Request, db: SessionDep,
                             _: AdminDep) -> JSONResponse:
    """The predictions export's codebook (the same as /export/predictions.datapackage.json)."""
    return _package(request, db, study_id, "predictions")


def _csv(request: Request, db: SessionDep, study_id: str, what: str) -> Response:
    from app.researcher import exports

    config = study_context(request, study_id).config
    return Response(exports.export_csv(db, config, study_id, what), media_type="text/csv",
                    headers=_attachment(exports.export_filename(study_id, what)))


def _package(request: Request, db: SessionDep, study_id: str, what: str) -> JSONResponse:
    from app.researcher import exports

    config = study_context(request, study_id).config
    frame = exports.export_table(db, config, study_id, what)
    csv_name = exports.export_filename(study_id, what)
    package = exports.export_package(frame, config, study_id, what,
                                     exports.csv_text(frame).encode(), csv_name)
    name = exports.package_path(Path(csv_name)).name
    return JSONResponse(package, headers=_attachment(name))


def _attachment(name: str) -> dict[str, str]:
    return {"Content-Disposition": f'attachment; filename="{name}"'}


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
