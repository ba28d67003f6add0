"""A local stand-in for Prolific's researcher API: the endpoints app/server/prolific.py calls.

Prolific cannot be reached from the test machines, so the client is tested against this: the
same paths under /api/v1/, the same `Authorization: Token <token>` check (401 otherwise), the
same bodies as Prolific documents them (docs.prolific.com, API reference, Submissions):

- GET  /api/v1/submissions/{id}/                 the submission, or 404
- POST /api/v1/submissions/{id}/transition/      {"action": "APPROVE"}: AWAITING_REVIEW only
- POST /api/v1/submissions/{id}/request-return/  {"request_return_reasons": [...]}

Tests add submissions with `ProlificStandIn.add` and run it on 127.0.0.1 (`serve`); every
request is kept in `requests`, so a test sees what the server asked.
"""

import threading
import time
from contextlib import contextmanager
from dataclasses import dataclass, field
from datetime import UTC, datetime

import uvicorn
from fastapi import FastAPI, Header, HTTPException, Request

from tests.conftest import patience

API = "/api/v1"


@dataclass
class ProlificStandIn:
    """Submissions by id, the API token Prolific would accept, and the requests received."""

    token: str = "standin-token"
    submissions: dict[str, dict] = field(default_factory=dict)
    requests: list[tuple[str, str]] = field(default_factory=list)

    def add(self, session_id: str, study_id: str, participant_id: str,
            status: str = "ACTIVE") -> dict:
        """A submission as Prolific stores it once a participant opens the study."""
        self.submissions[session_id] = {
            "id": session_id, "study_id": study_id, "participant": participant_id,
            "status": status, "started_at": datetime.now(UTC).isoformat(),
            "completed_at": None, "entered_code": None, "return_requested": None}
        return self.submissions[session_id]

    def app(self) -> FastAPI:
        """The stand-in's endpoints as an ASGI app."""
        api = FastAPI()

        def authorised(request: Request, authorization: str | None) -> None:
            self.requests.append((request.method, request.url.path))
            if authorization != f"Token {self.token}":
                raise HTTPException(401, {"error": {"detail": "Invalid token."}})

        def found(submission_id: str) -> dict:
            if submission_id not in self.submissions:
                raise HTTPException(404, {"error": {"detail": "Not found."}})
            return self.submissions[submission_id]

        @api.get(API + "/submissions/{submission_id}/")
        def get_submission(submission_id: str, request: Request,
                           authorization: str | None = Header(None)) -> dict:
            authorised(request, authorization)
            return found(submission_id)

        @api.post(API + "/submissions/{submission_id}/transition/")
        def transition(submission_id: str, body: dict, request: Request,
                       authorization: str | None = Header(None)) -> dict:
            authorised(request, authorization)
            submission = found(submission_id)
            if body.get("action") != "APPROVE":
                raise HTTPException(400, {"error": {"detail": "action: only APPROVE here"}})
            if submission["status"] != "AWAITING_REVIEW":
                raise HTTPException(400, {"error": {
                    "detail": f"Cannot approve a submission in status {submission['status']}"}})
            submission["status"] = "APPROVED"
            return submission

        @api.post(API + "/submissions/{submission_id}/request-return/")
        def request_return(submission_id: str, body: dict, request: Request,
                           authorization: str | None = Header(None)) -> dict:
            authorised(request, authorization)
            submission = found(submission_id)
            reasons = body.get("request_return_reasons")
            if not reasons or not isinstance(reasons, list):
                raise HTTPException(400, {"error": {
                    "detail": "request_return_reasons: a non-empty list is required"}})
            submission["return_requested"] = datetime.now(UTC).isoformat()
            return {"id": submission_id, "status": submission["status"],
                    "participant": submission["participant"],
                    "return_requested": submission["return_requested"]}

        return api


@contextmanager
def serve(standin: ProlificStandIn, port: int):
    """Run the stand-in on 127.0.0.1:`port` for the block; yields its API base URL."""
    server = uvicorn.Server(uvicorn.Config(standin.app(), host="127.0.0.1", port=port,
                                           log_level="warning", lifespan="off"))
    thread = threading.Thread(target=server.run, daemon=True)
    thread.start()
    deadline = time.monotonic() + patience(10)
    while not server.started:
        if time.monotonic() > deadline or not thread.is_alive():
            raise RuntimeError("the Prolific stand-in did not start")
        time.sleep(0.02)
    try:
        yield f"http://127.0.0.1:{port}{API}/"
    finally:
        server.should_exit = True
        thread.join(timeout=patience(10))
