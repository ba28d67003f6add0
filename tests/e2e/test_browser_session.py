"""A whole participant session in Debian's chromium, clicking on the canvas, then the export."""

import csv
import io
import json
import math
from pathlib import Path

import pytest

pytestmark = [pytest.mark.browser, pytest.mark.slow]

CHROMIUM = Path("/usr/bin/chromium")
CHROMIUM_ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
                 "--disable-component-update", "--disable-sync", "--no-first-run"]
CLIP_STEP_MS = 2000  # fake-clock time advanced per poll while clips play


def visible(page, screen: str) -> None:
    """Wait until the participant app shows `screen`."""
    page.wait_for_selector(f"#screen-{screen}:not([hidden])", timeout=15000)


def current_state(page, study_id: str) -> dict:
    """The server's state for this tab's session (token from sessionStorage, as the app keeps it)."""
    return page.evaluate(
        """async (key) => {
            const { token } = JSON.parse(sessionStorage.getItem(key));
            const response = await fetch(`/api/sessions/${token}/state`);
            return response.json();
        }""",
        f"tomstudy.{study_id}.session",
    )


def canvas_px(page, point) -> dict:
    """CSS-pixel position inside the trial canvas of a scene point (the canvas has no border)."""
    data = page.eval_on_selector(
        "#trial-canvas", "c => [Number(c.dataset.pxPerM), Number(c.dataset.originXPx), "
                         "Number(c.dataset.originYPx)]")
    scale, origin_x, origin_y = data
    return {"x": origin_x + point[0] * scale, "y": origin_y + point[1] * scale}


def planned_path(trial: dict, start: list[float]) -> list[list[float]]:
    """Three moves of mid reach in the first direction that keeps every point inside the scene."""
    bounds = trial["scene"]["bounds"]
    reach = (trial["min_step_m"] + trial["max_step_m"]) / 2
    margin = 0.02 * (bounds["x_max_m"] - bounds["x_min_m"])
    steps = trial["steps_to_predict"]
    for angle_deg in range(0, 360, 15):
        dx, dy = reach * math.cos(math.radians(angle_deg)), reach * math.sin(math.radians(angle_deg))
        path = [[start[0] + dx * k, start[1] + dy * k] for k in range(1, steps + 1)]
        if all(bounds["x_min_m"] + margin <= x <= bounds["x_max_m"] - margin
               and bounds["y_min_m"] + margin <= y <= bounds["y_max_m"] - margin for x, y in path):
            return path
    raise AssertionError(f"no straight path fits from {start}")


def watch_clips(page) -> None:
    """Advance the page's fake clock until every clip has played and predictions may start."""
    button = page.locator("#start-predicting")
    for _ in range(400):
        if button.is_enabled():
            return
        page.clock.run_for(CLIP_STEP_MS)
    raise AssertionError("the clips never finished")


def predict_trial(page, study_id: str, screenshot_dir: Path | None = None) -> dict:
    """Watch one trial, place every point by clicking on the canvas, submit; return the trial."""
    trial = current_state(page, study_id)["step"]
    watch_clips(page)
    page.click("#start-predicting")
    for k, start_state in enumerate(trial["start_states"]):
        for j, point in enumerate(planned_path(trial, start_state["robot"])):
            page.click("#trial-canvas", position=canvas_px(page, point))
            if screenshot_dir and k == 2 and j == 1:
                page.screenshot(path=str(screenshot_dir / "predict.png"))
        heading = page.inner_text("#trial-heading")
        page.click("#next")
    page.wait_for_function(
        "h => !document.querySelector('#screen-survey').hidden"
        " || document.querySelector('#trial-heading').textContent !== h", arg=heading)
    return trial


def check_refusals(page, study_id: str) -> None:
    """On the practice trial: a too-short click is refused; keyboard, undo and reset work."""
    trial = current_state(page, study_id)["step"]
    watch_clips(page)
    page.click("#start-predicting")
    start = trial["start_states"][0]["robot"]
    too_short = [start[0] + trial["min_step_m"] * 0.3, start[1]]
    page.click("#trial-canvas", position=canvas_px(page, too_short))
    assert "Too short" in page.inner_text("#trial-message")
    assert page.is_disabled("#next")
    page.focus("#trial-canvas")
    for _ in range(3):
        page.keyboard.press("Enter")
    assert "3 of 3 positions placed" in page.inner_text("#trial-caption")
    page.keyboard.press("Backspace")
    assert "2 of 3 positions placed" in page.inner_text("#trial-caption")
    page.click("#reset")
    assert "0 of 3 positions placed" in page.inner_text("#trial-caption")


def complete_session(page, base_url: str, study_id: str, screenshot_dir: Path) -> dict:
    """Consent, instructions, practice, every trial, survey; return the done state."""
    page.clock.install()
    page.goto(f"{base_url}/s/{study_id}?PROLIFIC_PID=e2e-pid-1&STUDY_ID=e2e&SESSION_ID=e2e-s1")
    visible(page, "consent")
    assert page.is_disabled("#consent-agree")
    page.check("#consent-check")
    page.click("#consent-agree")
    visible(page, "instructions")
    page.click("#instructions-done")
    visible(page, "trial")
    assert "Practice" in page.inner_text("#trial-heading")
    page.clock.run_for(1200)
    page.screenshot(path=str(screenshot_dir / "clip.png"))
    check_refusals(page, study_id)
    page.reload()  # a refresh resumes the same (practice) trial through sessionStorage
    visible(page, "trial")
    assert "Practice" in page.inner_text("#trial-heading")
    predict_trial(page, study_id)
    n_trials = 0
    while current_state(page, study_id)["phase"] == "trial":
        predict_trial(page, study_id, screenshot_dir if n_trials == 0 else None)
        n_trials += 1
    visible(page, "survey")
    for name in set(page.eval_on_selector_all("#survey-form input[type=radio]",
                                              "els => els.map(e => e.name)")):
        page.check(f"#survey-form input[name={name}] >> nth=0")
    page.click("#survey-form button[type=submit]")
    visible(page, "done")
    return {"n_trials": n_trials, "code": page.inner_text("#completion-code")}
