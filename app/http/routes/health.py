"""GET /healthz for load balancers and uptime checks: is the database answering?"""

import logging
from typing import Literal

from fastapi import APIRouter, Request, Response
from pydantic import BaseModel
from sqlalchemy import text
from sqlalchemy.engine import Engine

router = APIRouter(tags=["operations"])
logger = logging.getLogger(__name__)


class Health(BaseModel):
    """The server's health: `database` is "ok" or a short reason (never a stack trace)."""

    status: Literal["ok", "error"]
    database: str


def database_problem(engine: Engine) -> str | None:
    """None if the database runs `SELECT 1`, else a short reason without hosts or passwords."""
    try:
        with engine.connect() as conn:
            conn.execute(text("SELECT 1"))
    except Exception as err:  # any failure is a 503 here, never a 500
        logger.warning("healthz: database check failed: %s", err)
        cause = getattr(err, "orig", None) or err  # the driver's error names the kind
        return f"unavailable ({type(cause).__name__})"
    return None


# sync: FastAPI runs it in the thread pool, so a database that is slow to refuse (up to
# the connect timeout) holds one thread, not the event loop
@router.get("/healthz", response_model=Health,
            responses={503: {"model": Health, "description": "the database does not answer"}})
def read_health(request: Request, response: Response) -> Health:
    """200 if the database answers `SELECT 1`, else 503 with a short reason."""
    response.headers["Cache-Control"] = "no-store"
    problem = database_problem(request.app.state.engine)
    if problem:
        response.status_code = 503
        return Health(status="error", database=problem)
    return Health(status="ok", database="ok")
