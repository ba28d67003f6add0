"""Who may start a session: the study's platform rules and the researcher preview key.

Only the study's own traffic gets a session. A Prolific study needs Prolific's three
URL parameters, an MTurk study MTurk's three; an `open` study (a lab) takes anonymous
visitors. Lab members who try the live link use the preview key instead: their sessions
are pilots and never count for balance, progress or analysis.
"""

import hashlib
import hmac
import re
from dataclasses import dataclass, field

from app.server.flow import notices
from app.server.schemas import SessionCreate, UrlParams
from app.study.config import StudyConfig
from app.study.errors import Refused

PROLIFIC_ID = re.compile(r"[0-9a-fA-F]{24}")  # Prolific participant and study ids
PLATFORM_ID = re.compile(r"[A-Za-z0-9_-]{1,64}")
MTURK_PREVIEW = "ASSIGNMENT_ID_NOT_AVAILABLE"
MTURK_SUBMIT_PATH = "/mturk/externalSubmit"
ATTEMPT_KEYS = {"prolific": "SESSION_ID", "mturk": "assignmentId"}
_HOW = {"prolific": "open the study from your Prolific study page",
        "mturk": "open the study from the HIT on MTurk"}


@dataclass(frozen=True)
class Identity:
    """Where a session comes from: platform (or `open`/`pilot`), external id, attempt."""

    recruitment: str
    external_id: str | None = None
    attempt_key: str | None = None
    params: dict = field(default_factory=dict)

    @property
    def pilot(self) -> bool:
        """A researcher's preview session."""
        return self.recruitment == "pilot"


def preview_key(admin_token: str, study_id: str) -> str:
    """The key of a study's preview link: derived from the researcher token, not equal to it."""
    message = f"tomstudy-preview:{study_id}".encode()
    return hmac.new(admin_token.encode(), message, hashlib.sha256).hexdigest()[:32]


def preview_path(study_id: str, key: str) -> str:
    """The path of a study's preview link (for lab members trying the live study)."""
    return f"/s/{study_id}?preview={key}"


def identify(config: StudyConfig, body: SessionCreate, key: str) -> Identity:
    """The identity a session start claims, checked against the study's platform (403)."""
    if body.preview is not None:
        if not key or not hmac.compare_digest(body.preview.encode(), key.encode()):
            raise Refused(403, "preview: not this study's preview key; copy the current "
                               "preview link from the researcher dashboard",
                          notices.preview_link_outdated())
        return Identity("pilot")
    platform = config.recruitment.platform
    if platform == "open":
        return Identity("open")
    params = body.recruitment
    if platform == "prolific":
        return _prolific(config, params)
    return _mturk(config, params)


def _prolific(config: StudyConfig, params: UrlParams) -> Identity:
    _require("prolific", params, "PROLIFIC_PID", PROLIFIC_ID, "24 hexadecimal characters")
    _require("prolific", params, "STUDY_ID", PROLIFIC_ID, "24 hexadecimal characters")
    _require("prolific", params, "SESSION_ID", PLATFORM_ID, "1-64 letters, digits, - or _")
    expected = config.recruitment.prolific_study_id
    if expected and params.STUDY_ID.lower() != expected.lower():
        raise Refused(403, "recruitment.STUDY_ID: this link belongs to another Prolific study; "
                           f"{_HOW['prolific']}", notices.other_study("prolific"))
    kept = params.model_dump(include={"PROLIFIC_PID", "STUDY_ID", "SESSION_ID"})
    pid = normalise_external_id("prolific", params.PROLIFIC_PID)
    return Identity("prolific", pid, params.SESSION_ID, kept | {"PROLIFIC_PID": pid})


def _mturk(config: StudyConfig, params: UrlParams) -> Identity:
    if params.assignmentId == MTURK_PREVIEW:
        raise Refused(403, "recruitment.assignmentId: this is the HIT preview; accept the HIT "
                           "to start the study", notices.hit_preview())
    for name in ("workerId", "assignmentId", "hitId"):
        _require("mturk", params, name, PLATFORM_ID, "1-64 letters, digits, - or _")
    worker = normalise_external_id("mturk", params.workerId)
    kept = params.model_dump(include={"workerId", "assignmentId", "hitId"}) | {"workerId": worker}
    if params.turkSubmitTo is not None:
        kept["turkSubmitTo"] = _submit_host(config, params.turkSubmitTo)
    return Identity("mturk", worker, params.assignmentId, kept)


def normalise_external_id(platform: str, external_id: str) -> str:
    """One spelling per person: Prolific ids are hex (lower case), MTurk worker ids upper
    case; `ABC` and `abc` are the same participant on either platform."""
    if platform == "prolific":
        return external_id.lower()
    if platform == "mturk":
        return external_id.upper()
    return external_id


def _submit_host(config: StudyConfig, submit_to: str) -> str:
    """turkSubmitTo if it is one of the study's MTurk hosts (the hand-in form posts there)."""
    host = submit_to.rstrip("/")
    if host not in config.recruitment.mturk_submit_hosts:
        raise Refused(403, "recruitment.turkSubmitTo: not an MTurk submit host of this study; "
                           f"{_HOW['mturk']}", notices.link_incomplete("mturk"))
    return host


def _require(platform: str, params: UrlParams, name: str, pattern: re.Pattern,
             shape: str) -> None:
    value = getattr(params, name)
    if not value:
        raise Refused(403, f"recruitment.{name}: missing; this study takes part through "
                           f"{platform}: {_HOW[platform]}", notices.link_incomplete(platform))
    if not pattern.fullmatch(value):
        raise Refused(403, f"recruitment.{name}: must be {shape}; {_HOW[platform]}",
                      notices.link_incomplete(platform))
