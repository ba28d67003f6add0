"""HTML pages: landing, the participant app and the researcher dashboard (jinja2)."""

from typing import get_args

from fastapi import APIRouter, Request
from fastapi.responses import HTMLResponse, Response

from app.core.contracts import MODEL_COLORS, MODEL_LABELS
from app.data.scene import BROWSER_PALETTE
from app.http.deps import study_context
from app.prediction_view import MIN_WINDOW_PX
from app.server.flow import notices
from app.server.flow.endings import FINISHED
from app.server.flow.plan import BEFORE_TRIALS, Phase
from app.server.flow.recruitment import MTURK_PREVIEW
from app.server.schemas import (
    EVENTS_PER_REQUEST,
    HISTORY_MAX_ENTRIES,
    USER_AGENT_MAX_CHARS,
    EventKind,
    ScreenOutReason,
    UrlParams,
)
from app.study.clicks import MAX_STEP_TOLERANCE
from app.study.config import SurveyQuestion
from app.study.consent import render
from app.study.errors import Notice
from app.study.words import page_words

router = APIRouter(tags=["pages"], include_in_schema=False)
# Every rule the participant page applies, from the server's one definition of it (study.html
# hands it to app.js as #page-rules). app.js keeps one handler per phase, device.js one check
# per screen-out reason and survey.js one input per survey question kind; a trial's own limits
# (steps, reach, scene) come with the trial.
PAGE_RULES = {
    "phases": [phase.value for phase in Phase],
    "screen_out_phases": [phase.value for phase in BEFORE_TRIALS],
    "screen_out_reasons": list(get_args(ScreenOutReason)),
    "min_window": MIN_WINDOW_PX,
    "recruitment_params": list(UrlParams.model_fields),
    "event_kinds": list(get_args(EventKind)),
    "events_per_request": EVENTS_PER_REQUEST,
    "user_agent_max_chars": USER_AGENT_MAX_CHARS,
    "finished_outcomes": list(FINISHED),
    "survey_kinds": list(get_args(SurveyQuestion.model_fields["kind"].annotation)),
    "predictions": {"max_step_tolerance": MAX_STEP_TOLERANCE,
                    "history_max_entries": HISTORY_MAX_ENTRIES},
}
# how the dashboard names and colours each model: as the analysis' figures do
MODEL_STYLE = {"colors": MODEL_COLORS, "labels": MODEL_LABELS}


def _render(request: Request, name: str, study_id: str, **extra) -> HTMLResponse:
    ctx = study_context(request, study_id)
    config = ctx.config  # its words name the agents in the page and in its scripts' texts
    return request.app.state.templates.TemplateResponse(
        request, name, {"study_id": study_id, "title": config.title,
                        "description": render(config.description, ctx.estimate().advert),
                        "static_url": "/static", "studies": sorted(request.app.state.studies),
                        "scene_palette": BROWSER_PALETTE, "words": config.words,
                        "study_words": page_words(config.words, config.demo), **extra})


@router.get("/palette.css")
def palette_css() -> Response:
    """The scene palette's agent colours as CSS variables: the legend keys match the canvas."""
    css = f":root {{ --robot: {BROWSER_PALETTE['robot']}; --human: {BROWSER_PALETTE['human']}; }}\n"
    return Response(css, media_type="text/css")


@router.get("/", response_class=HTMLResponse)
def show_index(request: Request) -> HTMLResponse:
    """Landing page: the served studies and a link to the default one."""
    return _render(request, "index.html", request.app.state.default_study)


@router.get("/s/{study_id}", response_class=HTMLResponse)
def show_study(study_id: str, request: Request) -> HTMLResponse:
    """The participant app (one page; recruitment parameters stay in the URL).

    MTurk's HIT preview (assignmentId=ASSIGNMENT_ID_NOT_AVAILABLE) gets a page that
    describes the study and loads no script, so no session can start from it.
    """
    if study_id not in request.app.state.studies:
        return notice_page(request, notices.unknown_study(), status_code=404)
    if request.query_params.get("assignmentId") == MTURK_PREVIEW:
        return _render(request, "mturk_preview.html", study_id, scene_palette=None)
    ctx = study_context(request, study_id)  # the instructions say how many clicks, from where
    return _render(request, "study.html", study_id, page_rules=PAGE_RULES,
                   steps_to_predict=ctx.bank.data.steps_to_predict,
                   start_states=ctx.config.start_states)


def notice_page(request: Request, notice: Notice, status_code: int) -> HTMLResponse:
    """A plain-language page that turns a participant away (no script, nothing starts)."""
    return request.app.state.templates.TemplateResponse(
        request, "notice.html", {"title": "Online study", "notice": notice,
                                 "static_url": "/static"}, status_code=status_code)


@router.get("/researcher", response_class=HTMLResponse)
def show_researcher(request: Request) -> HTMLResponse:
    """The researcher dashboard (asks for the token, then calls the JSON routes)."""
    return _render(request, "researcher.html", request.app.state.default_study,
                   model_style=MODEL_STYLE)
