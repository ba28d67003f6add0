"""Issue 32 items 6 and 9 in Debian's chromium: nothing recorded before consent; every screen
understood (the demo's several start positions, a relocated start, the practice's feedback,
reduced motion stepped at the clips' pace, honest save and connection states, a window shrunk
mid-study, leaving mid-trial asks first), with axe-core finding nothing.

Screenshots go to var/screenshots/ (demo.png, relocated_start.png, practice_feedback.png).
"""

import json
import math
import sqlite3
import time
from contextlib import closing
from pathlib import Path

import pytest

from tests.e2e.axe import axe_violations
from tests.e2e.conftest import BROWSER_STUDY
from tests.e2e.pages import (
    PIXEL,
    ROBOT_RGB,
    SCREENSHOTS,
    VIEWPORT,
    canvas_px,
    consent_and_instructions,
    current_state,
    fresh_recruitment,
    onward,
    page_token,
    place,
    start_predicting,
    through_feedback,
    through_instructions,
    visible,
    wait_saved,
    watch_clips,
)

pytestmark = [pytest.mark.browser, pytest.mark.slow]

SMALL = {"width": 800, "height": 500}


@pytest.fixture
def context(chromium, request):
    """A new browser context on a paused fake clock (reduced motion if the test is
    parametrized with it); fails the test on any page error."""
    motion = getattr(request, "param", "no-preference")
    # bypass_csp: axe-core is injected as an inline script, which the page's CSP refuses
    ctx = chromium.new_context(viewport=VIEWPORT, reduced_motion=motion, bypass_csp=True)
    ctx.clock.install()
    ctx.clock.pause_at(int(time.time() * 1000) + 1000)
    errors: list[str] = []
    ctx.on("page", lambda page: page.on("pageerror", lambda e: errors.append(str(e))))
    yield ctx
    ctx.close()
    assert errors == []


def open_study(ctx, base: str):
    page = ctx.new_page()
    page.goto(f"{base}/s/{BROWSER_STUDY}?{fresh_recruitment()}")
    return page


def query(db_path: Path, sql: str, *args) -> list[tuple]:
    with closing(sqlite3.connect(db_path)) as db:
        return db.execute(sql, args).fetchall()


def session_row(page, db_path: Path) -> tuple[int, dict]:
    """(row id, stored device info) of the page's session."""
    rows = query(db_path, "SELECT id, client FROM participant WHERE session_token = ?",
                 page_token(page))
    return rows[0][0], json.loads(rows[0][1])


def stored_events(db_path: Path, session: int) -> list[str]:
    return [k for (k,) in query(db_path, "SELECT kind FROM event WHERE participant_id = ? "
                                         "ORDER BY id", session)]


def shoot(page, name: str) -> None:
    SCREENSHOTS.mkdir(parents=True, exist_ok=True)
    page.screenshot(path=str(SCREENSHOTS / name))


def layout(page) -> dict:
    """What the prediction canvas last drew: whether the robot's trail is its own, its heading."""
    return page.eval_on_selector("#trial-canvas", "c => ({ownTrail: c.layoutBoxes.ownTrail, "
                                                  "heading: c.layoutBoxes.heading})")


def no_axe_violations(page) -> None:
    """axe-core finds nothing on the screen shown; the page's clock runs on from here (axe
    waits on timers, which a paused fake clock never fires)."""
    page.clock.resume()
    assert axe_violations(page) == []


# ---------------------------------------------------------------- item 6

def test_nothing_is_sent_or_stored_before_consent(context, browser_server):
    page = open_study(context, browser_server.url)
    sent = []
    page.on("request", lambda r: sent.append(r.url) if r.url.endswith("/events") else None)
    visible(page, "consent")
    page.set_viewport_size({"width": 1100, "height": 820})  # a resize at the consent page
    page.clock.run_for(3000)
    session, client = session_row(page, browser_server.db_path)
    assert sent == [] and stored_events(browser_server.db_path, session) == []
    assert client == {}  # no device information before consent
    consent_and_instructions(page)
    onward(page)
    page.set_viewport_size(VIEWPORT)
    page.clock.run_for(3000)
    assert sent  # from consent on, telemetry goes out
    assert stored_events(browser_server.db_path, session) == ["resize"]
    client = session_row(page, browser_server.db_path)[1]
    assert client["reduced_motion"] is False and client["screen_w"] == 1100


def test_the_consent_page_has_no_axe_violation(context, browser_server):
    page = open_study(context, browser_server.url)
    visible(page, "consent")
    no_axe_violations(page)


# ---------------------------------------------------------------- the demo

def test_the_demo_predicts_from_several_start_positions(context, browser_server):
    page = open_study(context, browser_server.url)
    visible(page, "consent")
    page.check("#consent-check")
    page.click("#consent-agree")
    visible(page, "instructions")
    shot = False
    for _ in range(100):
        if page.get_attribute("#demo-canvas", "data-demo-starts"):
            break
        page.clock.run_for(300)
        clicks = page.eval_on_selector("#demo-canvas", "c => c.layoutBoxes?.rings.length")
        if "Start position 2 of 3" in page.inner_text("#demo-caption") and clicks == 3:
            if not shot:  # the first moved start, its three clicks placed
                page.locator("#demo-block").scroll_into_view_if_needed()
                shoot(page, "demo.png")
            shot = True
    assert shot
    assert page.get_attribute("#demo-canvas", "data-demo-starts") == "3"
    relocated = page.eval_on_selector("#demo-canvas", "c => c.layoutBoxes")
    assert relocated["ownTrail"] is False and relocated["heading"] is None  # a disc moved
    assert len(relocated["rings"]) == 3
    no_axe_violations(page)


# ---------------------------------------------------------------- a relocated start

def test_a_relocated_start_has_no_trail_of_its_own_and_its_own_heading(context, browser_server):
    page = open_study(context, browser_server.url)
    through_instructions(page)
    trial = current_state(page)["step"]
    start_predicting(page)
    own = layout(page)
    assert own == {"ownTrail": True, "heading": trial["start_states"][0]["robot_heading"]}
    place(page, trial, 0, [0, 1, 2])
    page.click("#next")
    moved = layout(page)
    assert moved["ownTrail"] is False
    assert "placed somewhere else" in page.inner_text("#trial-message")
    segment_heading = trial["start_states"][1]["robot_heading"]
    if trial["scene"]["lanes"]:  # a car: the road's direction of travel
        assert moved["heading"] == (0 if math.cos(segment_heading) >= 0 else pytest.approx(math.pi))
    else:  # a disc: no heading of its own is known, none is drawn
        assert moved["heading"] is None
    place(page, trial, 1, [0])
    shoot(page, "relocated_start.png")
    no_axe_violations(page)


# ---------------------------------------------------------------- the practice's feedback

def test_the_practice_ends_with_where_the_robot_went(context, browser_server):
    page = open_study(context, browser_server.url)
    through_instructions(page)
    trial = current_state(page)["step"]
    assert trial["is_practice"] and len(trial["feedback"]["robot"]) == len(trial["start_states"])
    start_predicting(page)
    for k in range(len(trial["start_states"])):
        place(page, trial, k, [0, 1, 2])
        page.click("#next")
    page.wait_for_selector("#feedback-legend:not([hidden])")
    assert page.inner_text("#trial-caption") == "Practice feedback, start position 1 of 5"
    robot_dots = [page.evaluate(PIXEL, [p["x"], p["y"]]) for p in
                  (canvas_px(page, point) for point in trial["feedback"]["robot"][0])]
    assert any(tuple(rgba[:3]) == ROBOT_RGB for rgba in robot_dots), robot_dots
    assert layout(page)["ownTrail"] is False  # the clip's path is grey beside the answers
    shoot(page, "practice_feedback.png")
    no_axe_violations(page)
    assert through_feedback(page) == len(trial["start_states"])
    assert onward(page) == "trial"  # practice over, then the first scored trial
    assert "feedback" not in current_state(page)["step"]


# ---------------------------------------------------------------- reduced motion

def clip_timeline(page) -> tuple[list[str], int]:
    """The practice trial's canvas every 100 ms over its first clip's first second, and the
    ms until every clip has played."""
    through_instructions(page)
    frames = []
    for _ in range(10):
        page.clock.run_for(100)
        frames.append(page.eval_on_selector("#trial-canvas", "c => c.toDataURL()"))
    waited = 1000
    while not page.is_enabled("#start-predicting"):
        page.clock.run_for(250)
        waited += 250
        assert waited < 600_000, "the clips never finished"
    return frames, waited


@pytest.mark.parametrize("context", ["reduce", "no-preference"], indirect=True)
def test_reduced_motion_steps_the_clips_at_their_pace_and_is_recorded(context, browser_server):
    page = open_study(context, browser_server.url)
    reduced = page.evaluate("matchMedia('(prefers-reduced-motion: reduce)').matches")
    frames, waited = clip_timeline(page)
    changes = sum(a != b for a, b in zip(frames[:-1], frames[1:], strict=True))
    if reduced:  # a step every 0.35 s over 1 s: two or three changes, not every frame
        assert 2 <= changes <= 3
    else:
        assert changes == len(frames) - 1
    trial = current_state(page)["step"]
    steps = sum(len(c["positions"]) - 1 for c in [*trial["examples"], trial["segment"]])
    pauses = len(trial["examples"]) + 1
    assert waited == pytest.approx(steps * 350 + pauses * 700, abs=1000)  # the same pace
    page.click("#start-predicting")
    for k in range(len(trial["start_states"])):
        place(page, trial, k, [0, 1, 2])
        page.click("#next")
    through_feedback(page)
    session = session_row(page, browser_server.db_path)[0]
    assert query(browser_server.db_path, "SELECT reduced_motion FROM trialresponse WHERE "
                 "participant_id = ?", session) == [(int(reduced),)]
    assert session_row(page, browser_server.db_path)[1]["reduced_motion"] is reduced


# ---------------------------------------------------------------- save, offline, window, leave

def test_the_save_status_says_saving_until_the_server_answers(context, browser_server):
    page = open_study(context, browser_server.url)
    through_instructions(page)
    trial = current_state(page)["step"]
    start_predicting(page)
    held = []
    page.route("**/api/session/draft", lambda route: held.append(route))
    place(page, trial, 0, [0])
    page.wait_for_function("() => document.querySelector('#save-status').textContent"
                           ".includes('Saving')")
    page.clock.run_for(2000)
    assert "Saving" in page.inner_text("#save-status")  # no answer yet: not "saved"
    held[0].continue_()  # the server answers now
    page.unroute("**/api/session/draft")
    wait_saved(page)


def test_watching_again_can_be_stopped_at_any_time(context, browser_server):
    page = open_study(context, browser_server.url)
    through_instructions(page)
    trial = current_state(page)["step"]
    start_predicting(page)  # the first viewing plays to its end
    place(page, trial, 0, [0])
    page.click("#replay")
    stop = page.locator("#start-predicting")
    assert stop.is_enabled() and "Stop" in stop.inner_text()
    assert page.inner_text("#trial-caption").startswith("Example 1 of")
    stop.click()
    assert page.is_visible("#predict-controls")
    page.clock.run_for(60_000)  # the stopped clips do not come back
    caption = page.inner_text("#trial-caption")
    assert caption.startswith("Start position 1 of") and "1 of 3 positions placed" in caption


def test_an_offline_press_says_so_and_goes_on_when_back(context, browser_server):
    page = open_study(context, browser_server.url)
    consent_and_instructions(page)
    visible(page, "world")
    context.set_offline(True)
    page.click("#world-done")
    page.wait_for_function("() => document.querySelector('#world-status').textContent"
                           ".includes('offline')")
    assert page.is_visible("#screen-world")
    context.set_offline(False)
    page.clock.run_for(10_000)  # the page's retry
    visible(page, "trial")


def test_a_window_shrunk_mid_study_is_checked_again(context, browser_server):
    page = open_study(context, browser_server.url)
    through_instructions(page)
    trial = current_state(page)["step"]
    start_predicting(page)
    place(page, trial, 0, [0])
    page.set_viewport_size(SMALL)
    visible(page, "unsupported")
    assert page.inner_text("#unsupported-title") == "Please make the window larger"
    assert "800 × 500" in page.inner_text("#unsupported-reason")
    assert page.is_hidden("#screen-out-block")
    no_axe_violations(page)
    page.set_viewport_size(VIEWPORT)
    visible(page, "trial")
    assert "1 of 3 positions placed" in page.inner_text("#trial-caption")
    width = page.eval_on_selector("#trial-canvas", "c => c.clientWidth")
    assert width > SMALL["width"]  # redrawn at the window's size


def test_leaving_mid_trial_asks_first(context, browser_server):
    page = open_study(context, browser_server.url)
    through_instructions(page)
    trial = current_state(page)["step"]
    watch_clips(page)
    page.click("#start-predicting")
    place(page, trial, 0, [0])
    with page.expect_event("dialog") as asked:
        page.close(run_before_unload=True)
    assert asked.value.type == "beforeunload"
    asked.value.dismiss()  # the person stays
    assert not page.is_closed() and page.is_visible("#screen-trial")
