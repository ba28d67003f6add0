"""Issue 21 over HTTP: drafts resume a trial, one live tab, a finished link shows its code,
plain notices for refusals, a part per world, counts of sessions that ended early."""

import io

import numpy as np
import pandas as pd
import pytest

from app.prediction_view import TARGET_STEP_PX, click_resolution_deg, prediction_view
from app.server.flow.plan import TRIAL_PHASES, Phase
from tests.server.flow import (
    ADMIN,
    Participant,
    at_first_trial,
    bank_trial,
    draft_body,
    new_id,
    prediction_body,
    prolific,
    with_recruitment,
)

TAB_A, TAB_B = "tab-aaaaaaaa", "tab-bbbbbbbb"


def export(client, study_id: str, what: str) -> pd.DataFrame:
    """One researcher export as a frame."""
    r = client.get(f"/api/researcher/export/{what}.csv?study_id={study_id}", headers=ADMIN)
    assert r.status_code == 200, r.text
    return pd.read_csv(io.StringIO(r.text), keep_default_na=False)


def claim(p: Participant, tab: str, **flags):
    """POST .../tab for `tab`."""
    return p.post("tab", {"tab_id": tab, "t_client_ms": 1.0, **flags})


# ---------------------------------------------------------------- drafts

def test_a_draft_comes_back_with_its_trial_until_the_trial_is_stored(client, small_study):
    p = at_first_trial(client, small_study.study_id)
    trial = p.state()["step"]
    assert trial["draft"] is None
    assert p.save_draft(clicks=2, seq=3).json() == {"seq": 3}
    late = draft_body(trial, clicks=1, seq=2)  # an older save arriving late changes nothing
    assert p.put("draft", late).json() == {"seq": 3}
    draft = p.state()["step"]["draft"]
    assert draft["seq"] == 3 and [len(points) for points in draft["points"]] == [2, 0, 0, 0, 0]
    assert draft["shown_at_ms"] == 1000.0 and draft["index"] == 0
    assert draft["click_inputs"] == [["mouse", "mouse"], [], [], [], []]
    p.answer_trial()
    assert p.pass_screens()["step"]["draft"] is None  # the next trial starts clean


def test_a_draft_must_fit_the_current_trial(client, small_study):
    p = at_first_trial(client, small_study.study_id)
    trial = p.state()["step"]
    wrong = draft_body(trial) | {"points": [[]]}
    r = p.put("draft", wrong)
    assert r.status_code == 422 and r.json()["detail"].startswith("points:")
    four = draft_body(trial, clicks=3)
    four["points"][0].append(four["points"][0][-1])
    four["click_times_ms"][0].append(9000.0)
    assert p.put("draft", four).json()["detail"].startswith("points.0:")
    others = [[] for _ in trial["start_states"][1:]]
    unmatched = draft_body(trial, clicks=2) | {"click_inputs": [["mouse"], *others]}
    assert p.put("draft", unmatched).json()["detail"].startswith("click_inputs.0:")
    pen = draft_body(trial, clicks=2) | {"click_inputs": [["mouse", "pen"], *others]}
    r = p.put("draft", pen)
    assert r.status_code == 422 and r.json()["message"].startswith("click_inputs.0.1:")
    p.answer_trial()
    p.pass_screens()
    r = p.put("draft", draft_body(trial))  # the practice, already stored
    assert r.status_code == 409 and r.json()["detail"].startswith("trial_id:")


# ---------------------------------------------------------------- one live tab

def test_a_second_tab_is_refused_until_it_takes_over(client, small_study):
    p = at_first_trial(client, small_study.study_id)
    assert claim(p, TAB_A, opened=True).status_code == 200
    p.save_draft(clicks=2)
    refused = claim(p, TAB_B, opened=True)
    assert refused.status_code == 409 and refused.json()["detail"].startswith("tab:")
    notice = refused.json()["notice"]
    assert notice["action"] == "takeover" and "another tab" in notice["title"]
    assert "tab_id" not in notice["text"]
    assert claim(p, TAB_A).status_code == 200  # the live tab's heartbeat
    assert claim(p, TAB_B, opened=True, takeover=True).status_code == 200
    trial = p.state()["step"]
    stale = p.put("draft", draft_body(trial, 3, seq=9), headers={"X-Tab-Id": TAB_A})
    assert stale.status_code == 409 and stale.json()["notice"]["action"] == "takeover"
    body = {"submission_id": new_id()}
    assert p.post("consent", body | {"agree": True},
                  headers={"X-Tab-Id": TAB_A}).status_code == 409
    assert claim(p, TAB_A).status_code == 409  # the old tab's heartbeat learns it
    events = export(client, small_study.study_id, "events")
    opened = events[events.kind.isin(["page_opened", "tab_takeover"])]
    assert list(opened.kind) == ["page_opened", "tab_takeover"]
    assert list(opened.clicks) == [0, 2]  # the takeover restored the 2 clicks of the draft
    assert (opened.trial_id.str.contains("practice")).all()  # the bank's id, not the ref


def test_a_released_tab_frees_the_session_and_a_write_without_a_tab_is_not_checked(
        client, small_study):
    p = at_first_trial(client, small_study.study_id)
    assert claim(p, TAB_A, opened=True).status_code == 200
    assert p.post("tab/release", {"tab_id": TAB_A}).status_code == 204
    assert claim(p, TAB_B, opened=True).status_code == 200  # nobody is asked
    p.answer_trial()  # bots and API clients name no tab


# ---------------------------------------------------------------- endings and refusals

def test_a_finished_link_resumes_its_ending_and_another_attempt_is_told(codes, client, small_study,
                                                                       bank):
    me = prolific("finisher")
    p = at_first_trial(client, small_study.study_id, **me)
    p.finish(bank)  # passes the attention checks, so the session is kept: the approve code
    again = Participant(client, small_study.study_id)
    assert again.start(**me)["resumed"] is True and again.status == 200
    done = again.state()
    assert done["phase"] == Phase.DONE and done["step"]["completion_code"] == codes["completed"]
    assert done["step"]["redirect_url"].endswith(f"cc={codes['completed']}")
    other = Participant(client, small_study.study_id)
    body = other.start(**(me | {"SESSION_ID": "another-attempt"}))
    assert other.status == 409 and body["detail"].startswith("recruitment:")
    assert body["notice"]["title"] == "You have already taken part"
    assert "Prolific" in body["notice"]["text"] and "SESSION_ID" not in body["notice"]["text"]


@pytest.mark.parametrize(("params", "title"), [
    ({}, "This link is incomplete"),
    ({"PROLIFIC_PID": "not-an-id", "STUDY_ID": "5" * 24, "SESSION_ID": "s"},
     "This link is incomplete"),
])
def test_a_link_refusal_carries_a_plain_notice(client, small_study, params, title):
    p = Participant(client, small_study.study_id)
    body = p.start(**params) if params else client.post(
        "/api/sessions", json={"study_id": small_study.study_id}).json()
    assert body["detail"].startswith("recruitment.PROLIFIC_PID:")  # the field, for the logs
    assert body["notice"]["title"] == title
    assert "recruitment" not in body["notice"]["text"] and "Prolific" in body["notice"]["text"]


def test_a_closed_or_full_study_turns_new_people_away_but_not_those_who_started(
        client, small_study):
    sid = small_study.study_id
    started = at_first_trial(client, sid, **prolific("early"))
    with_recruitment(client, sid, closed=True)
    late = Participant(client, sid)
    body = late.start(**prolific("late"))
    assert late.status == 409 and body["notice"]["title"] == "This study is closed"
    assert Participant(client, sid).start(**prolific("early"))["resumed"] is True
    preview = client.app.state.studies[sid].preview_key
    assert Participant(client, sid).start(preview=preview)["resumed"] is False  # the lab
    with_recruitment(client, sid, closed=False, max_counted_sessions=1)
    body = late.start(**prolific("late"))
    assert late.status == 409 and body["notice"]["title"] == "This study is full"
    assert body["detail"].startswith("study_id: the study is full (1 counted")
    started.finish()


def test_an_unknown_study_is_a_plain_page(client):
    page = client.get("/s/no_such_study")
    assert page.status_code == 404 and "This study is not available" in page.text
    assert "<script" not in page.text and "study_id" not in page.text
    api = client.post("/api/sessions", json={"study_id": "no_such_study"})
    assert api.status_code == 404 and api.json()["notice"]["title"] == page_title(page.text)


def page_title(html: str) -> str:
    return html.split("<title>")[1].split("</title>")[0]


# ---------------------------------------------------------------- parts and counts

def test_each_world_is_a_part_with_its_introduction_practice_and_numbered_trials(
        client, small_study):
    p = Participant(client, small_study.study_id)
    p.start()
    p.post("consent", {"submission_id": new_id(), "agree": True})
    intro = p.post("instructions", {"submission_id": new_id()}).json()
    config = client.app.state.studies[small_study.study_id].config
    for part in (1, 2):
        assert intro["phase"] == Phase.WORLD_INTRO
        step = intro["step"]
        assert (step["part"], step["parts"]) == (part, 2)
        assert step["title"] == config.world_intros[step["world"]].title
        assert (step["practice_trials"], step["trials"]) == (1, 3 + 1)
        wrong = p.post("continue", {"submission_id": new_id(), "phase": "practice_over"})
        assert wrong.status_code == 409 and wrong.json()["detail"].startswith("phase:")
        practice = p.post("continue", {"submission_id": new_id(), "phase": "world_intro"}).json()
        assert practice["phase"] == Phase.PRACTICE and practice["step"]["world"] == step["world"]
        assert (practice["step"]["number"], practice["step"]["of"]) == (1, 1)
        over = p.post("predictions", prediction_body(practice["step"])).json()
        assert over["phase"] == Phase.PRACTICE_OVER and over["step"]["trials"] == 4
        first = p.post("continue", {"submission_id": new_id(), "phase": "practice_over"}).json()
        numbers = []
        state = first
        while state["phase"] == Phase.TRIAL:
            numbers.append((state["step"]["part"], state["step"]["number"], state["step"]["of"]))
            state = p.post("predictions", prediction_body(state["step"])).json()
        assert numbers == [(part, n, 4) for n in range(1, 5)]
        intro = state
    assert intro["phase"] == Phase.SURVEY


def test_sessions_that_end_early_count_only_the_steps_they_took(client, small_study):
    sid = small_study.study_id
    declined = Participant(client, sid)
    declined.start(**prolific("no"))
    assert declined.post("decline", {"submission_id": new_id()}).json()["progress"]["done"] == 0
    screened = Participant(client, sid)
    screened.start(**prolific("small-window"))
    screened.post("consent", {"submission_id": new_id(), "agree": True})
    done = screened.post("screen-out", {"submission_id": new_id(), "reason": "window_too_small"})
    assert done.json()["phase"] == Phase.DONE and done.json()["progress"]["done"] == 0
    sheet = export(client, sid, "participants").set_index("outcome")
    assert sheet.loc["declined_consent", "steps_done"] == 0
    assert sheet.loc["screened_out", "steps_done"] == 1  # consent was given
    rows = client.get(f"/api/researcher/dashboard?study_id={sid}", headers=ADMIN).json()
    trials = {r["outcome"]: r["progress"]["done"] for r in rows["participants"]}
    assert trials == {"declined_consent": 0, "screened_out": 0}


# ---------------------------------------------------------------- the prediction view

def _world(step_m: list[float], kinds: list[str]) -> dict:
    """A bank world whose policy's first moves have these lengths (dt 0.5 s)."""
    trials = [{"kind": kind, "policy_actions": [[[2 * s, 0.0]] * 3]}
              for s, kind in zip(step_m, kinds, strict=True)]
    return {"dt_s": 0.5, "trials": trials}


def test_the_view_makes_the_median_main_step_span_the_target():
    world = _world([0.2, 0.4, 0.5, 9.0], ["main", "main", "main", "practice"])
    view = prediction_view(world)
    assert view.median_step_m == pytest.approx(0.4)
    assert view.median_step_px == pytest.approx(TARGET_STEP_PX)
    assert click_resolution_deg(world) == pytest.approx(np.degrees(np.arctan2(1, 60)))
    with pytest.raises(ValueError, match="main trial"):
        prediction_view(_world([0.4], ["practice"]))


def test_every_trial_payload_carries_its_worlds_view(client, small_study, bank):
    p = at_first_trial(client, small_study.study_id)
    trial = p.state()["step"]
    world = {"dt_s": trial["dt_s"], "trials": [t for t in bank.values()
                                              if t["world"] == trial["world"]]}
    assert trial["view"] == prediction_view(world).payload()


def test_only_practice_trials_carry_where_the_robot_goes(client, small_study, bank):
    p = at_first_trial(client, small_study.study_id)
    kinds = []
    while (state := p.pass_screens())["phase"] in TRIAL_PHASES:
        trial = state["step"]
        record = bank_trial(bank, trial)
        kinds.append(record["kind"])
        if record["kind"] != "practice":
            assert "feedback" not in trial  # a scored trial's answer never leaves the server
        else:
            starts = np.array([s["robot"] for s in record["start_states"]])[:, None]
            moves = np.cumsum(np.array(record["policy_actions"]) * trial["dt_s"], axis=1)
            assert np.allclose(trial["feedback"]["robot"], starts + moves, atol=1e-3)
        p.answer_trial(bank)
    assert {"practice", "main", "attention"} <= set(kinds)
