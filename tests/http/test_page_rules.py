"""Every rule the browser applies comes from the server's one definition, as phases do.

The pages carry the rules (app/http/routes/pages.py: `PAGE_RULES` as #page-rules on the
study page, the scene palette as #scene-palette on every page that draws a scene and as
/palette.css for the legend, the models' names and colours as #model-style on the
dashboard) and the scripts in frontend/static/js keep no copy of them.
"""

import dataclasses
import re
from typing import get_args

import pytest

from app.core.contracts import MODEL_COLORS, MODEL_LABELS
from app.data.scene import BROWSER_PALETTE
from app.prediction_view import MIN_WINDOW_PX
from app.server.flow.endings import FINISHED
from app.server.schemas import (
    ClickInput,
    ClientInfo,
    DraftSave,
    EventIn,
    EventsCreate,
    PredictionCreate,
    ScreenOutCreate,
    UrlParams,
)
from app.study.clicks import MAX_STEP_TOLERANCE
from app.study.config import SurveyQuestion
from tests.conftest import REPO
from tests.server.flow import (
    JS,
    at_first_trial,
    page_json,
    participant_scripts,
    prediction_body,
    straight_clicks,
)

CSS = REPO / "frontend" / "static" / "css" / "style.css"


def schema_of(body, field: str) -> dict:
    """The JSON schema pydantic validates `body.field` with (its enum, its size limits)."""
    return body.model_json_schema()["properties"][field]


def study_rules(client, study_id: str) -> dict:
    """The rules the study page hands its scripts (app.js and its modules)."""
    return page_json(client.get(f"/s/{study_id}").text, "page-rules")


def table_keys(source: str, name: str) -> list[str]:
    """The top-level keys of the object literal `[export] const name = {...};` in a script."""
    table = re.search(rf"^(?:export )?const {name} = \{{\n(.*?)^\}};", source, re.M | re.S)
    assert table, f"{name} table not found"
    return re.findall(r"^  (\w+): ", table.group(1), re.M)


def quoted(value: str) -> re.Pattern:
    """`value` as a string literal in a script, in any quotes."""
    return re.compile(rf"""["'`]{re.escape(value)}["'`]""")


# ---------------------------------------------------------------- the study page's rules

def test_the_study_page_carries_each_rule_as_the_server_defines_it(client, small_study):
    rules = study_rules(client, small_study.study_id)
    assert rules["recruitment_params"] == list(UrlParams.model_fields)
    assert rules["screen_out_reasons"] == schema_of(ScreenOutCreate, "reason")["enum"]
    assert rules["event_kinds"] == schema_of(EventIn, "kind")["enum"]
    assert rules["events_per_request"] == schema_of(EventsCreate, "events")["maxItems"]
    assert rules["user_agent_max_chars"] == schema_of(ClientInfo, "user_agent")["maxLength"]
    assert rules["finished_outcomes"] == list(FINISHED)
    assert rules["survey_kinds"] == schema_of(SurveyQuestion, "kind")["enum"]
    assert rules["min_window"] == MIN_WINDOW_PX
    for body in (PredictionCreate, DraftSave):
        history = schema_of(body, "history")
        assert rules["predictions"]["history_max_entries"] == history["maxItems"], body
    assert rules["predictions"]["max_step_tolerance"] == MAX_STEP_TOLERANCE


def test_the_click_tolerance_the_page_uses_is_where_the_server_refuses(client, small_study):
    tolerance = study_rules(client, small_study.study_id)["predictions"]["max_step_tolerance"]
    p = at_first_trial(client, small_study.study_id)
    trial = p.state()["step"]

    def moves_past_reach(share: float) -> list:
        reach = trial["max_step_m"] * (1 + share)
        return straight_clicks(dict(trial, min_step_m=reach, max_step_m=reach))

    over = p.post("predictions", prediction_body(trial, moves_past_reach(2 * tolerance)))
    assert over.status_code == 422 and "longer than the reachable" in over.text
    within = p.post("predictions", prediction_body(trial, moves_past_reach(tolerance / 2)))
    assert within.status_code == 201, within.text


def test_the_instructions_count_the_served_studys_clicks_and_start_positions(client, small_study):
    ctx = client.app.state.studies[small_study.study_id]
    bank = dataclasses.replace(ctx.bank, data=ctx.bank.data.model_copy(
        update={"steps_to_predict": 2}))
    config = ctx.config.model_copy(update={"start_states": 4})
    client.app.state.studies[small_study.study_id] = dataclasses.replace(
        ctx, bank=bank, config=config)
    page = " ".join(client.get(f"/s/{small_study.study_id}").text.split())
    assert "after each of the next 2 steps" in page
    assert "When all 2 positions are placed" in page and "(4 in each trial)" in page


def participant_source() -> str:
    """The study page's scripts (app.js and every module it imports) as one text."""
    return "\n".join(participant_scripts().values())


def test_the_study_page_has_one_device_check_per_screen_out_reason():
    keys = table_keys(participant_source(), "DEVICE_CHECKS")
    assert keys == schema_of(ScreenOutCreate, "reason")["enum"]


def test_the_study_page_has_one_input_per_survey_question_kind():
    keys = table_keys(participant_source(), "QUESTION_INPUTS")
    assert keys == schema_of(SurveyQuestion, "kind")["enum"]


def test_predict_js_records_exactly_the_click_inputs_the_server_takes():
    source = (JS / "predict.js").read_text()
    pointers = re.search(r"^const POINTER_INPUTS = \{\n(.*?)^\};", source, re.M | re.S)
    keyboard = re.search(r'^const KEYBOARD_INPUT = "(\w+)";', source, re.M)
    assert pointers and keyboard, "predict.js names its click inputs in these two constants"
    recorded = set(re.findall(r': "(\w+)",', pointers.group(1))) | {keyboard.group(1)}
    assert recorded == set(get_args(ClickInput))


def test_the_study_page_logs_exactly_the_event_kinds_the_server_takes():
    calls = re.findall(r"telemetry\.log\(([^,)]*)", participant_source())
    logged = {kind for call in calls for kind in re.findall(r'"(\w+)"', call)}
    assert logged == set(schema_of(EventIn, "kind")["enum"])


# ---------------------------------------------------------------- the scene palette

@pytest.mark.parametrize("path", ["/", "/s/{study}", "/researcher"])
def test_every_page_that_draws_a_scene_carries_the_palette(client, small_study, path):
    page = client.get(path.format(study=small_study.study_id)).text
    assert page_json(page, "scene-palette") == BROWSER_PALETTE
    assert '<link rel="stylesheet" href="/palette.css">' in page


def test_the_legend_css_takes_the_agents_colours_from_the_palette(client):
    css = client.get("/palette.css")
    assert css.headers["content-type"].startswith("text/css")
    declared = dict(re.findall(r"--(\w+): ([^;]+);", css.text))
    assert declared == {"robot": BROWSER_PALETTE["robot"], "human": BROWSER_PALETTE["human"]}
    assert not re.search(r"--(robot|human)\s*:", CSS.read_text())


# ---------------------------------------------------------------- the dashboard's models

def test_the_dashboard_names_and_colours_models_as_the_figures_do(client):
    style = page_json(client.get("/researcher").text, "model-style")
    assert style == {"colors": MODEL_COLORS, "labels": MODEL_LABELS}
    assert not re.search(r"\.swatch-\w+\s*\{", CSS.read_text())  # the legend takes them too


# ---------------------------------------------------------------- no second copy in the scripts

def colours_in(value) -> list[str]:
    """Every string in a palette entry, however deep (groups, lists)."""
    if isinstance(value, str):
        return [value]
    items = value.values() if isinstance(value, dict) else value
    return [colour for item in items for colour in colours_in(item)]


def defined_colours() -> list[str]:
    """Every colour of the scene palette and of the models but black (which any script may
    draw with)."""
    scene = colours_in(BROWSER_PALETTE)
    return scene + [colour for colour in MODEL_COLORS.values() if colour != "#000000"]


SERVER_NAMES = [*UrlParams.model_fields, *FINISHED]  # each only ever read from the rules
MODEL_NAMES = [label for model, label in MODEL_LABELS.items() if label.lower() != model]  # not keys


@pytest.mark.parametrize("script", sorted(p.name for p in JS.glob("*.js")))
def test_no_script_writes_a_copy_of_a_server_rule(script):
    source = (JS / script).read_text()
    copies = [name for name in SERVER_NAMES + MODEL_NAMES if quoted(name).search(source)]
    copies += [colour for colour in defined_colours() if colour.lower() in source.lower()]
    copies += [old for old in ("RECRUITMENT_PARAMS", "max_chars ??", "slice(-500)",
                               "splice(0, 100)", "0, 114, 178") if old in source]
    assert copies == [], f"{script}: take these from what the page carries"
