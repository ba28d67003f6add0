"""Researcher API behind the bearer token: dashboard summary and the tidy CSV export."""

from fastapi import APIRouter, Request
from fastapi.responses import Response

from app.study import export
from app.study.deps import AdminDep, SessionDep, study_context

router = APIRouter(prefix="/api/researcher", tags=["researcher"])


@router.get("/summary")
def read_summary(study_id: str, request: Request, db: SessionDep, _: AdminDep) -> dict:
    """Progress, completions, exclusions and running mean alignment error per model and world."""
    return export.summary(db, study_context(request, study_id))


@router.get("/export.csv", response_class=Response,
            responses={200: {"content": {"text/csv": {}}}})
def read_export(study_id: str, request: Request, db: SessionDep, _: AdminDep) -> Response:
    """One row per (participant, trial, start state, step); columns in app/study/API.md."""
    study_context(request, study_id)
    return Response(export.export_csv(db, study_id), media_type="text/csv",
                    headers={"Content-Disposition":
                             f'attachment; filename="{study_id}_predictions.csv"'})
