"""Bodies the JSON parser accepts but the study must not store: lone surrogates, wrong types."""

import json

from app.server.flow.plan import Phase
from tests.server.flow import DEVICE, Participant, at_first_trial, new_id, prediction_body

SURROGATE = "\ud800"  # valid JSON ("\ud800"), but no UTF-8 encodes it
SURVEY = {"difficulty": 4, "confidence": 5, "driving": "yes"}  # the small study's required


def post_raw(p: Participant, what: str, body: dict):
    """POST `body` as ASCII JSON (lone surrogates as \\u escapes, as a browser could send)."""
    return p.post(what, None, content=json.dumps(body),
                  headers={"content-type": "application/json"})


def problem(r) -> str:
    """The refusal's `field: message` text (body validation's `message`, else `detail`)."""
    body = r.json()
    return body.get("message") or body["detail"]


def at_survey(client, study_id: str, bank: dict) -> Participant:
    """A participant who answered every trial: at the closing survey."""
    p = at_first_trial(client, study_id)
    while p.state()["phase"] != Phase.SURVEY:
        p.answer_trial(bank)
    return p


def test_lone_surrogates_get_a_422_naming_the_field(client, small_study, bank):
    p = Participant(client, small_study.study_id)
    p.start()
    r = post_raw(p, "consent", {"submission_id": new_id(), "agree": True,
                                "client": dict(DEVICE, user_agent=f"x{SURROGATE}")})
    assert r.status_code == 422 and "client.user_agent" in problem(r), r.text
    assert p.consent().status_code == 200
    event = {"submission_id": new_id(), "kind": "replay", "t_client_ms": 1.0,
             "data": {"trial_id": SURROGATE, "replays": 1}}
    r = post_raw(p, "events", {"events": [event]})
    assert r.status_code == 422 and "events.0.data.trial_id" in problem(r), r.text
    p = at_survey(client, small_study.study_id, bank)
    for answers, field in (({"strategy": f"lanes {SURROGATE}"}, "answers.strategy"),
                           ({SURROGATE: "red"}, "answers")):
        r = post_raw(p, "survey", {"submission_id": new_id(),
                                   "answers": SURVEY | answers})
        assert r.status_code == 422 and problem(r).startswith(field), r.text
    assert p.survey()["phase"] != Phase.SURVEY  # nothing was stored before


def test_json_booleans_and_strings_are_not_numbers(client, small_study, bank):
    p = at_first_trial(client, small_study.study_id)
    trial = p.state()["step"]
    r = p.post("predictions", dict(prediction_body(trial), shown_at_ms=True))
    assert r.status_code == 422 and "shown_at_ms" in problem(r), r.text
    body = prediction_body(trial)
    body["points"][0][0][0] = str(body["points"][0][0][0])
    r = p.post("predictions", body)
    assert r.status_code == 422 and "points.0.0.0" in problem(r), r.text
    body = prediction_body(trial)
    body["click_times_ms"][0][0] = True
    r = p.post("predictions", body)
    assert r.status_code == 422 and "click_times_ms.0.0" in problem(r), r.text
    r = p.post("tab", {"tab_id": "tab-12345678", "t_client_ms": True})
    assert r.status_code == 422 and "t_client_ms" in problem(r), r.text
    r = p.post("predictions", dict(prediction_body(trial), shown_at_ms=1000))  # ints are numbers
    assert r.status_code == 201, r.text
    p = at_survey(client, small_study.study_id, bank)
    r = p.post("survey", {"submission_id": new_id(),
                          "answers": SURVEY | {"difficulty": True}})
    assert r.status_code == 422 and "answers.difficulty" in problem(r), r.text
