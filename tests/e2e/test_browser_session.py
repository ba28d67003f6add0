"""A whole participant session in Debian's chromium, clicking on the canvas, then the export.

The page runs on Playwright's fake clock: clips are fast-forwarded instead of watched, and
the clock moves on between clicks like a person's would, so timings look human.
"""

import csv
import io
import json
import math
import sqlite3
from contextlib import closing
from pathlib import Path

import pytest
import yaml

from app.http.routes.pages import PAGE_RULES
from tests.conftest import researcher_get
from tests.e2e.conftest import BROWSER_STUDY
from tests.e2e.pages import (
    SCREENSHOTS,
    THINK_MS,
    VIEWPORT,
    answer_survey,
    answer_trial,
    canvas_px,
    canvas_view,
    current_state,
    fresh_recruitment,
    onward,
    open_dashboard,
    place,
    planned_path,
    start_predicting,
    through_feedback,
    through_instructions,
    visible,
    wait_saved,
    watch_clips,
)
from tests.server.flow import served_codes

pytestmark = [pytest.mark.browser, pytest.mark.slow]

RESIZED = {"width": 1300, "height": 880}
PID = "e2e0000000000000000000a1"  # 24 hex characters, as Prolific sends
RECRUITMENT = f"PROLIFIC_PID={PID}&STUDY_ID={'5' * 24}&SESSION_ID=e2e-session"


def drop_first_answer(page) -> dict:
    """Let the next predictions POST reach the server, but cut the connection before the answer."""
    seen = {"dropped": 0}

    def handle(route):
        if route.request.method == "POST" and not seen["dropped"]:
            seen["dropped"] = route.fetch().status  # the server stores it...
            route.abort("connectionreset")  # ...and the browser never hears back
        else:
            route.continue_()

    page.route("**/predictions", handle)
    return seen


def predict_trial(page, screenshot: Path | None = None, replay: bool = False,
                  lose_answer: bool = False, undo_once: bool = False) -> tuple[dict, dict]:
    """Watch one trial, click every point on the canvas, submit; return (trial, clicks).

    With `undo_once`, the first click of the second start state is undone and placed again.
    """
    trial = current_state(page)["step"]
    if page.is_visible("#start-predicting"):  # else a draft resumed it in predictions
        watch_clips(page)
        if replay:
            page.click("#replay")
            watch_clips(page)
        page.click("#start-predicting")
    clicks = {}
    for k, start_state in enumerate(trial["start_states"]):
        for j, point in enumerate(planned_path(trial, start_state)):
            page.clock.fast_forward(THINK_MS)
            page.click("#trial-canvas", position=canvas_px(page, point))
            if undo_once and (k, j) == (1, 0):
                page.clock.fast_forward(THINK_MS)
                page.click("#undo")
                page.click("#trial-canvas", position=canvas_px(page, point))
            clicks[(k, j)] = (point, canvas_view(page)[0])
            if screenshot and k == 2 and j == 1:
                page.screenshot(path=str(screenshot))
        assert page.is_enabled("#next")
        heading = page.inner_text("#trial-heading")
        if lose_answer and k == len(trial["start_states"]) - 1:
            seen = drop_first_answer(page)
        page.click("#next")
    if lose_answer:
        page.wait_for_function("() => document.querySelector('#trial-message').textContent"
                               ".includes('retrying')")
        assert seen["dropped"] == 201
        page.clock.fast_forward(1000)  # the app's back-off before the retry
    if trial["is_practice"]:
        assert through_feedback(page) == len(trial["start_states"])
    page.wait_for_function(
        "h => document.querySelector('#screen-trial').hidden"
        " || document.querySelector('#trial-heading').textContent !== h", arg=heading)
    if lose_answer:
        page.unroute("**/predictions")
    return trial, clicks


def check_input_rules(page) -> None:
    """On the practice trial: a too-short click is refused; keyboard, undo and reset work."""
    trial = current_state(page)["step"]
    watch_clips(page)
    page.click("#start-predicting")
    start = trial["start_states"][0]["robot"]
    page.click("#trial-canvas", position=canvas_px(page, [start[0] + trial["min_step_m"] * 0.3,
                                                          start[1]]))
    assert "Too short" in page.inner_text("#trial-message")
    assert "0 of 3 positions placed" in page.inner_text("#trial-caption")
    page.focus("#trial-canvas")
    page.keyboard.press("Enter")  # the keyboard cursor starts at the robot: nothing to place
    assert "arrow keys first" in page.inner_text("#trial-message")
    assert "0 of 3 positions placed" in page.inner_text("#trial-caption")
    place(page, trial, 0, [0, 1, 2], think_ms=0, keyboard=True)
    assert "3 of 3 positions placed" in page.inner_text("#trial-caption")
    assert page.is_enabled("#next")
    page.keyboard.press("Backspace")
    assert "2 of 3 positions placed" in page.inner_text("#trial-caption")
    page.click("#reset")
    assert "0 of 3 positions placed" in page.inner_text("#trial-caption")


def complete_session(page, base_url: str) -> dict:
    """Consent, instructions, practice, every trial, survey; returns what the test checks."""
    SCREENSHOTS.mkdir(parents=True, exist_ok=True)
    page.clock.install()
    page.goto(f"{base_url}/s/{BROWSER_STUDY}?{RECRUITMENT}")
    visible(page, "consent")
    assert page.is_disabled("#consent-agree")
    through_instructions(page)
    assert "Practice" in page.inner_text("#trial-heading")
    page.clock.fast_forward(1200)
    page.screenshot(path=str(SCREENSHOTS / "clip.png"))
    check_input_rules(page)
    page.set_viewport_size(RESIZED)  # logged as a resize event once the size settles
    page.wait_for_function("w => innerWidth === w", arg=RESIZED["width"])
    page.clock.fast_forward(500)
    with page.expect_request(lambda r: r.url.endswith("/events") and "resize" in r.post_data):
        page.clock.fast_forward(1500)  # the telemetry batch goes out
    page.reload()  # a refresh resumes the same trial through the token in sessionStorage
    visible(page, "trial")
    assert "Practice" in page.inner_text("#trial-heading")
    clicks = {}
    trial, trial_clicks = predict_trial(page)
    clicks[trial["trial_id"]] = trial_clicks
    while onward(page) == "trial":
        n = len(clicks)  # 1 = the first main trial
        trial, trial_clicks = predict_trial(page, SCREENSHOTS / "predict.png" if n == 1 else None,
                                            replay=n == 2, lose_answer=n == 3,
                                            undo_once=n == 1)
        clicks[trial["trial_id"]] = trial_clicks
    answer_survey(page)
    visible(page, "done")
    return {"clicks": clicks, "code": page.inner_text("#completion-code"),
            "redirect": page.get_attribute("#redirect-link", "href")}


def download_export(page, what: str = "predictions") -> list[dict]:
    """Download one export through the open dashboard's button."""
    page.select_option("#export-what", what)
    with page.expect_download() as download:
        page.click("#download")
    return list(csv.DictReader(io.StringIO(Path(download.value.path()).read_text())))


def truthy(value: str) -> bool:
    return value.strip().lower() in ("true", "1")


def test_participant_completes_the_study_by_clicking(chromium, browser_server, browser_study):
    config = yaml.safe_load((browser_study.configs_dir / f"{BROWSER_STUDY}.yaml").read_text())
    context = chromium.new_context(viewport=VIEWPORT, accept_downloads=True)
    page = context.new_page()
    errors = []
    page.on("pageerror", lambda err: errors.append(str(err)))

    done = complete_session(page, browser_server.url)

    code = done["code"]
    assert done["redirect"].endswith(f"cc={code}")
    open_dashboard(page, browser_server.url)
    rows = download_export(page)
    sheet = {r["external_id"]: r for r in download_export(page, "participants")}
    assert errors == []
    context.close()
    # the fake clock answers trials in seconds of server time: the too-fast rule (on the
    # smaller of both clocks) may exclude the session, which then gets the review code
    outcome = sheet[PID]["outcome"]
    assert outcome in ("completed", "excluded")
    assert sheet[PID]["completion_code"] == code == served_codes(browser_study)[outcome]

    mine = [r for r in rows if r["participant_id"] == public_id_of(browser_server.db_path, PID)]
    bank_ids = bank_ids_of_refs(browser_server.db_path, PID)  # the browser saw opaque ids
    done["clicks"] = {bank_ids[ref]: clicks for ref, clicks in done["clicks"].items()}
    main = [r for r in mine if not truthy(r["is_practice"]) and not truthy(r["attention_check"])]
    practice = [r for r in mine if truthy(r["is_practice"])]
    checks = [r for r in mine if truthy(r["attention_check"])]
    n_worlds = len(config["worlds"])
    per_trial = config["start_states"] * config["steps_to_predict"]
    assert len(main) == n_worlds * config["trials_per_world"] * per_trial == 300
    assert len(practice) == n_worlds * config["practice_trials"] * per_trial
    assert len(checks) == n_worlds * config["attention_checks"]["per_world"] * per_trial
    assert all(truthy(r["completed"]) for r in mine)
    assert len({r["trial_id"] for r in mine}) == len(done["clicks"])
    # Every stored click is where the browser clicked: mouse events carry whole CSS pixels,
    # so each axis may round by up to a pixel.
    for row in mine:
        point, px_per_m = done["clicks"][row["trial_id"]][(int(row["start_index"]),
                                                           int(row["step"]))]
        clicked = (float(row["participant_click_x"]), float(row["participant_click_y"]))
        error_px = math.dist(point, clicked) * px_per_m
        assert error_px <= math.sqrt(2) + 1e-3, (row["trial_id"], error_px)
    for client_ms, server_ms, used_ms in trial_durations(browser_server.db_path, PID):
        assert client_ms >= per_trial * THINK_MS  # the page's (fake) clock, like a person's
        assert used_ms == min(client_ms, server_ms)  # the too-fast rule trusts neither alone
    trial_ids = list(done["clicks"])
    replays = {r["trial_id"]: int(r["replays"]) for r in mine}
    assert replays[trial_ids[2]] == 1 and sum(replays.values()) == 1
    assert sum(r["trial_id"] == trial_ids[3] for r in mine) == per_trial  # retried, stored once
    events = stored_events(browser_server.db_path, PID)
    assert sum(kind == "clip_finished" for kind, _ in events) >= len(trial_ids)
    assert [bank_ids[data["trial_id"]] for kind, data in events
            if kind == "replay"] == [trial_ids[2]]
    resized = {"w": RESIZED["width"], "h": RESIZED["height"]}
    assert resized in [data for kind, data in events if kind == "resize"]
    histories = stored_histories(browser_server.db_path, PID)
    # the practice's undo and reset (check_input_rules) survived the reload with its draft
    assert [[(h["action"], h["start_index"]) for h in histories[t]] for t in trial_ids] == [
        [("undo", 0), ("reset", 0)], [("undo", 1)], *[[]] * (len(trial_ids) - 2)]
    assert stored_ending(browser_server.db_path, PID) == (outcome, code)


def test_enter_alone_answers_nothing_and_keyboard_clicks_are_recorded(chromium, browser_server):
    context = chromium.new_context(viewport=VIEWPORT)
    page = context.new_page()
    errors = []
    page.on("pageerror", lambda err: errors.append(str(err)))
    page.clock.install()
    recruitment = fresh_recruitment()
    page.goto(f"{browser_server.url}/s/{BROWSER_STUDY}?{recruitment}")
    through_instructions(page)
    trial = current_state(page)["step"]
    start_predicting(page)
    k, n = len(trial["start_states"]), trial["steps_to_predict"]

    page.focus("#trial-canvas")
    for key in ["Enter", " "] * (k * n):  # more presses than the trial has clicks
        page.keyboard.press(key)

    message = page.locator("#trial-message")  # the trial's live region, read out politely
    assert (message.get_attribute("role"), message.get_attribute("aria-live")) == (
        "status", "polite")
    assert message.inner_text().startswith("Move the cross with the arrow keys first")
    assert page.inner_text("#trial-caption").endswith("0 of 3 positions placed.")
    assert page.is_disabled("#next")

    place(page, trial, 0, list(range(n)), keyboard=True)  # the first start state by keyboard
    page.click("#next")
    place(page, trial, 1, [0])  # then one mouse click, and a reload: the draft keeps both
    wait_saved(page)
    page.reload()
    visible(page, "trial")
    answer_trial(page)  # the rest by mouse
    context.close()
    assert errors == []

    pid = dict(pair.split("=") for pair in recruitment.split("&"))["PROLIFIC_PID"]
    with closing(sqlite3.connect(browser_server.db_path)) as db:
        stored = db.execute(
            "SELECT start_index, step, click_input FROM predictionrow JOIN participant ON "
            "participant.id = predictionrow.participant_id WHERE external_id = ?",
            (pid,)).fetchall()
    expected = {(i, j): "keyboard" if i == 0 else "mouse" for i in range(k) for j in range(n)}
    assert {(i, j): device for i, j, device in stored} == expected
    export = researcher_get(f"{browser_server.url}/api/researcher/export/predictions.csv",
                            params={"study_id": BROWSER_STUDY}).text
    mine = public_id_of(browser_server.db_path, pid)
    rows = [r for r in csv.DictReader(io.StringIO(export)) if r["participant_id"] == mine]
    assert {(int(r["start_index"]), int(r["step"])): r["click_input"] for r in rows} == expected


def stored_histories(db_path: Path, external_id: str) -> dict[str, list]:
    """Bank trial id -> the undo/reset history stored with that trial."""
    with closing(sqlite3.connect(db_path)) as db:
        rows = db.execute(
            "SELECT trial_id, history FROM trialresponse JOIN participant ON participant.id = "
            "trialresponse.participant_id WHERE external_id = ?", (external_id,)).fetchall()
    return {trial_id: json.loads(history) for trial_id, history in rows}


def stored_ending(db_path: Path, external_id: str) -> tuple[str, str]:
    """(outcome, completion code) stored for a participant."""
    with closing(sqlite3.connect(db_path)) as db:
        return db.execute("SELECT outcome, completion_code FROM participant "
                          "WHERE external_id = ?", (external_id,)).fetchone()


def public_id_of(db_path: Path, external_id: str) -> str:
    """The pseudonymous id the exports carry for this platform id."""
    with closing(sqlite3.connect(db_path)) as db:
        (public_id,) = db.execute("SELECT public_id FROM participant WHERE external_id = ?",
                                  (external_id,)).fetchone()
    return public_id


def bank_ids_of_refs(db_path: Path, external_id: str) -> dict[str, str]:
    """The opaque per-session trial ids the browser saw -> the bank's trial ids."""
    with closing(sqlite3.connect(db_path)) as db:
        (plan,) = db.execute("SELECT plan FROM participant WHERE external_id = ?",
                             (external_id,)).fetchone()
    return {s["ref"]: s["trial_id"] for s in json.loads(plan) if "ref" in s}


def trial_durations(db_path: Path, external_id: str) -> list[tuple[float, float, float]]:
    """(client, server, used) duration of every answered trial of one participant."""
    with closing(sqlite3.connect(db_path)) as db:
        return db.execute(
            "SELECT client_duration_ms, server_duration_ms, duration_ms FROM trialresponse "
            "JOIN participant ON participant.id = trialresponse.participant_id "
            "WHERE external_id = ?", (external_id,)).fetchall()


def stored_events(db_path: Path, external_id: str) -> list[tuple[str, dict]]:
    """(kind, data) of every telemetry event the server stored of one participant (the
    server is shared with other tests, which may run first)."""
    with closing(sqlite3.connect(db_path)) as db:
        rows = db.execute("SELECT kind, data FROM event JOIN participant "
                          "ON participant.id = event.participant_id WHERE external_id = ?",
                          (external_id,)).fetchall()
    return [(kind, json.loads(data)) for kind, data in rows]


def test_small_window_and_touch_only_devices_get_a_message(chromium, browser_server):
    context = chromium.new_context(viewport={"width": 800, "height": 600})
    page = context.new_page()
    page.goto(f"{browser_server.url}/s/{BROWSER_STUDY}?{fresh_recruitment()}")
    visible(page, "unsupported")
    assert "800 × 600" in page.inner_text("#unsupported-reason")
    page.set_viewport_size({"width": 1000, "height": 700})  # enlarging the window starts it
    visible(page, "consent")
    context.close()
    context = chromium.new_context(viewport=VIEWPORT, has_touch=True, is_mobile=True)
    page = context.new_page()
    page.goto(f"{browser_server.url}/s/{BROWSER_STUDY}?{fresh_recruitment()}")
    visible(page, "unsupported")
    assert "touch" in page.inner_text("#unsupported-reason")
    context.close()


MODULE_CHECKS = """async () => {
    const { fitView } = await import("/static/js/scene.js");
    const { poseAt } = await import("/static/js/player.js");
    const { PredictionInput } = await import("/static/js/predict.js");
    const bounds = { x_min_m: -50, x_max_m: 50, y_min_m: -3, y_max_m: 11 };
    const view = fitView(bounds, 1000, 300, 24);
    const corner = view.toPx([bounds.x_max_m, bounds.y_max_m]);
    const back = view.toM(view.toPx([12.5, 4.25]));
    const clip = { positions: [[[0, 0], [5, 5]], [[2, 4], [5, 5]]],
                   headings: [[3.1, 0], [-3.1, 0]] };
    const mid = poseAt(clip, 0.5);
    const wrap = document.createElement("div");
    wrap.style.width = "1000px";
    const canvas = document.createElement("canvas");
    wrap.append(canvas);
    document.body.append(wrap);
    const start = { robot: [0, 4], human: [10, 8], robot_heading: 0, human_heading: 0 };
    const trial = { trial_id: "t", scene: { bounds, lanes: [], obstacles: [], goals: [],
                    agents: [] }, segment: clip, start_states: [start, start],
                    steps_to_predict: 3, max_step_m: 4, min_step_m: 0.4 };
    const input = new PredictionInput(canvas, trial, { rules: PREDICTION_RULES });
    input.shownAtPerf = performance.now();
    const refusals = [[0.1, 4], [5, 4], [2, 6], [0, 11.5]].map((p) => input.refusal(p));
    const placed = [[3, 4], [6, 4], [9, 4], [12, 4]].map((p) => input.place(p, "mouse"));
    input.undo();
    const metreY = view.toPx([0, 1])[1] - view.toPx([0, 0])[1];
    const metreX = view.toPx([1, 0])[0] - view.toPx([0, 0])[0];
    return { scale: view.scale, metreX, metreY, corner, back, mid, refusals, placed,
             done: input.stateDone(), next: input.next(), index: input.index };
}""".replace("PREDICTION_RULES", json.dumps(PAGE_RULES["predictions"]))


def test_frontend_modules_scale_interpolate_and_refuse(chromium, browser_server):
    page = chromium.new_page()
    page.goto(f"{browser_server.url}/")
    out = page.evaluate(MODULE_CHECKS)
    page.close()
    # the same px per metre in x and y, limited here by the width: (1000 - 2 * 24) / 100
    assert out["scale"] == pytest.approx(9.52)
    assert out["metreX"] == pytest.approx(9.52) and out["metreY"] == pytest.approx(9.52)
    assert out["corner"] == pytest.approx([1000 - 24, (300 + 9.52 * 14) / 2])  # centred in y
    assert out["back"] == pytest.approx([12.5, 4.25])
    assert out["mid"][0]["position"] == pytest.approx([1, 2])
    assert abs(math.cos(out["mid"][0]["heading"]) + 1) < 1e-3  # turns through pi, not 0
    too_short, too_far, ok, outside = out["refusals"]
    assert too_short.startswith("Too short") and too_far.startswith("Too far")
    assert ok is None and "outside" in outside
    assert out["placed"] == [True, True, True, False]  # a 4th point is refused
    assert out["done"] is False and out["next"] is False and out["index"] == 0  # after undo
