"""The OpenAPI schema declares every error status each route can answer, in one place.

Routes raise `Refused(status, "field: message")` deep in plan, validation, crud and deps, so their
decorators cannot see what they may answer; `error_statuses` names it by route instead,
and `declare_error_responses` adds it to the generated schema with the error bodies the
handlers in main.py write.
"""

from fastapi import FastAPI
from pydantic import BaseModel
from pydantic.json_schema import models_json_schema

REF = "#/components/schemas/{model}"


class PlainNotice(BaseModel):
    """The refusal in plain language for a participant (app/server/flow/notices.py)."""

    title: str
    text: str
    action: str = ""


class ErrorDetail(BaseModel):
    """A refused request: `detail` is `field: message`; `notice` what a participant reads."""

    detail: str
    notice: PlainNotice | None = None


class ValidationItem(BaseModel):
    """One field that failed validation (the input itself is never echoed)."""

    loc: list[str | int]
    msg: str
    type: str


class ValidationProblem(BaseModel):
    """422: a list of failed fields plus `message`, or one `field: message` (a study rule)."""

    detail: str | list[ValidationItem]
    message: str | None = None


UNREADABLE = "body: not readable as JSON (e.g. not UTF-8); JSON that fails to parse is a 422"
TOO_LARGE = "body: larger than 64 KiB"
INVALID = "a body or parameter fails validation; `detail` names the field"
RATE_LIMITED = ("rate: too many session starts from this address, or requests of this session; "
                "`Retry-After` says when to retry")
DB_DOWN = "database: unavailable, try again shortly; `Retry-After` says when to retry"
UNKNOWN_SESSION = "X-Session-Token: unknown session"
GONE = ("X-Session-Token: the session cannot continue: a newer attempt of the same "
        "participant replaced it, or the study's trial bank changed under it")
SESSION_STATUSES = {404: UNKNOWN_SESSION, 410: GONE, 422: INVALID, 429: RATE_LIMITED,
                    503: DB_DOWN}
SESSION_WRITE_STATUSES = {
    400: UNREADABLE,
    404: f"{UNKNOWN_SESSION}; trial_id: not a trial of this session",
    409: "phase: the session is at another step or trial, moved on in another request, or "
         "done or not yet consented (telemetry); submission_id: used by another session; tab: "
         "another tab of this session is the live one; study_id: (consent) the study closed "
         "or became full since this session started",
    410: GONE,
    413: TOO_LARGE,
    422: f"{INVALID}, or breaks a study rule: clicks outside the scene or reach, survey "
         "answers, telemetry past its cap, a submission_id reused for a different request",
    429: RATE_LIMITED,
    503: "study: (consent) as many sessions are running as the study takes at once; or "
         + DB_DOWN,
}
START_STATUSES = {
    400: UNREADABLE,
    403: "recruitment: missing or malformed parameters of the study's platform, or another "
         "Prolific study, or a SESSION_ID Prolific does not know (with a Prolific API token); "
         "preview: a wrong preview key",
    404: "study_id: unknown study",
    409: "recruitment: this participant already took part under another attempt, started at "
         "the same moment, or has another attempt (SESSION_ID / assignmentId) in progress; "
         "study_id: the study is closed or full",
    413: TOO_LARGE,
    422: INVALID,
    429: RATE_LIMITED,
    503: "study: as many sessions are running as the study takes at once "
         "(max_live_sessions_per_target x target_sample_size); or " + DB_DOWN,
}
RESEARCHER_STATUSES = {
    401: "authorization: missing bearer token",
    403: "authorization: wrong researcher token",
    404: "study_id: unknown study",
    422: INVALID,
    429: "authorization: too many wrong researcher tokens from this address (TOMSTUDY_"
         "RESEARCHER_LOCKOUT, 10 per 10 minutes); `Retry-After` says when to retry",
    503: DB_DOWN,
}
WITHDRAWAL_STATUSES = RESEARCHER_STATUSES | {
    400: UNREADABLE,
    404: "study_id: unknown study; external_id / participant_id: no session of this id in "
         "the study",
    413: TOO_LARGE,
    503: f"{DB_DOWN}; archives: the data dir's archive registry is unreadable (nothing was "
         "deleted)",
}
PAYMENT_STATUSES = RESEARCHER_STATUSES | {
    400: UNREADABLE,
    404: "study_id: unknown study; participant_ids: no session of this id in the study",
    409: "prolific: no Prolific API token; participant_ids: a session not from Prolific, or "
         "an approval of a session that did not complete",
    413: TOO_LARGE,
    422: f"{INVALID}; reason: a return request without one",
}


def error_statuses(method: str, path: str) -> dict[int, str]:
    """The error statuses the route `method path` can answer, each with why."""
    if path == "/api/researcher/withdrawals" and method == "POST":
        return WITHDRAWAL_STATUSES
    if path in ("/api/researcher/prolific/approve", "/api/researcher/prolific/return"):
        return PAYMENT_STATUSES
    if path.startswith("/api/researcher/"):
        return RESEARCHER_STATUSES
    if path == "/api/sessions" and method == "POST":
        return START_STATUSES
    if path.startswith("/api/session/"):
        return SESSION_WRITE_STATUSES if method in ("POST", "PUT") else SESSION_STATUSES
    return {}


def declare_error_responses(app: FastAPI) -> None:
    """Make `app.openapi()` declare each route's `error_statuses` with its error body."""
    generate = app.openapi

    def openapi() -> dict:
        if app.openapi_schema is None:
            add_error_responses(generate())  # FastAPI caches this dict in app.openapi_schema
        return app.openapi_schema

    app.openapi = openapi


def add_error_responses(schema: dict) -> None:
    """Add the error responses and their body schemas to a generated OpenAPI dict, in place."""
    for path, operations in schema.get("paths", {}).items():
        for method, operation in operations.items():
            responses = operation.setdefault("responses", {})
            statuses = error_statuses(method.upper(), path)
            if "422" in responses:  # FastAPI's, in a shape our handler does not write
                statuses = {422: INVALID} | statuses
            for status, why in statuses.items():
                declared = responses.get(str(status), {})
                if status == 422 or "content" not in declared:  # else a route's own body wins
                    responses[str(status)] = error_response(status, why)
    components = schema.setdefault("components", {}).setdefault("schemas", {})
    components.update(error_schemas())
    drop_unreferenced(schema, components, ("HTTPValidationError", "ValidationError"))


def error_response(status: int, why: str) -> dict:
    """One OpenAPI response: `why` and the JSON body the error handlers write."""
    model = ValidationProblem if status == 422 else ErrorDetail
    return {"description": why,
            "content": {"application/json": {"schema": {"$ref": REF.format(model=model.__name__)}}}}


def error_schemas() -> dict:
    """JSON schemas of the error bodies, named as `error_response` refers to them."""
    _, top = models_json_schema([(ErrorDetail, "serialization"), (PlainNotice, "serialization"),
                                 (ValidationProblem, "serialization")], ref_template=REF)
    return top["$defs"]


def drop_unreferenced(schema: dict, components: dict, names: tuple[str, ...]) -> None:
    """Remove the named component schemas that nothing refers to any more."""
    for name in names:
        definition = components.pop(name, None)
        if definition is not None and REF.format(model=name) in repr(schema):
            components[name] = definition
