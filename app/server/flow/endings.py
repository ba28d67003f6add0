"""How a session ends: its outcome, its completion code, and where the page sends the person.

Every ending is decided here: a session that did every trial ends `failed_checks` (too many
attention checks failed), `excluded` (the study's exclusion rules remove it) or `completed`;
one that ends before any trial ends `declined_consent` or `screened_out`. Each outcome has
its own code and message in the study config (`recruitment.endings`); the code is stored on
the session before the browser is told, and a Prolific or open study redirects to it while an
MTurk assignment is handed in by a form posted to MTurk.
"""

from sqlmodel import Session

from app.server.flow import balance
from app.server.flow.recruitment import MTURK_SUBMIT_PATH
from app.server.storage.tables import Participant
from app.study.config import StudyConfig

OUTCOMES = ("completed", "failed_checks", "excluded", "declined_consent", "screened_out")
FINISHED = ("completed", "failed_checks", "excluded")  # outcomes of a session that did every trial


def survey_ending(db: Session, config: StudyConfig, participant: Participant
                  ) -> tuple[dict, bool]:
    """The ending of a session that answered the survey, and whether the rules exclude it."""
    excluded = balance.is_excluded(db, config, participant)
    return ending_values(config, finished_outcome(config, participant, excluded)), excluded


def ending_values(config: StudyConfig, outcome: str) -> dict:
    """The Participant columns an ending sets: outcome, its completion code, completed."""
    return {"outcome": outcome, "completion_code": config.recruitment.ending(outcome)
            .completion_code, "completed": outcome in FINISHED}


def finished_outcome(config: StudyConfig, participant: Participant, excluded: bool) -> str:
    """failed_checks once `endings.min_failed` attention checks failed, else excluded when
    the study's exclusion rules remove the session, else completed."""
    if participant.attention_failed >= config.recruitment.endings.min_failed:
        return "failed_checks"
    return "excluded" if excluded else "completed"


def done_payload(cfg: StudyConfig, participant: Participant) -> dict:
    """The stored ending: its outcome, code, message, and where the page sends the person.

    An MTurk assignment is handed in by a form posted to MTurk (`mturk_submit`) instead
    of a redirect.
    """
    outcome = participant.outcome  # set by every ending; migration 0002 set the older ones
    code = participant.completion_code
    if code is None:  # completed before endings existed: the code of today's config
        code = cfg.recruitment.ending(outcome).completion_code
    return {"outcome": outcome, "completion_code": code,
            "message": cfg.recruitment.ending(outcome).message,
            "redirect_url": redirect_url(cfg, participant.recruitment, code),
            "mturk_submit": mturk_submit(participant, outcome, code)}


def mturk_submit(participant: Participant, outcome: str, code: str) -> dict | None:
    """The ExternalQuestion hand-in form: action `turkSubmitTo`/mturk/externalSubmit."""
    params = participant.recruitment_params or {}
    if participant.recruitment != "mturk" or not params.get("turkSubmitTo"):
        return None
    return {"action": f"{params['turkSubmitTo']}{MTURK_SUBMIT_PATH}",
            "fields": {"assignmentId": params["assignmentId"], "outcome": outcome,
                       "completion_code": code}}


def redirect_url(cfg: StudyConfig, recruitment: str, code: str) -> str:
    """Where the done page sends the participant ('' = show the code only)."""
    if not code:
        return ""
    template = {"prolific": cfg.recruitment.prolific_redirect_url,
                "mturk": cfg.recruitment.mturk_redirect_url}.get(
        recruitment, cfg.recruitment.open_redirect_url)
    return template.format(completion_code=code)
