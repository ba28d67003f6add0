"""Screenshots of the recorded worlds as a participant and a researcher see them.

`python -m tests.e2e.shoot_recorded`: builds (or reuses) the tests' small interaction study on
GENERATED, NOT REAL recordings (tests/conftest.py `cached_interaction_study`), serves it on a
fresh SQLite file, walks it in Debian's chromium and writes var/screens/recorded_*.png: the
instructions with the study's road demo (mid-clip, an own start, a moved start), then per
world its introduction, an example clip mid-animation, the prediction screen with two clicks
made from the robot's own start and with one click from a relocated start; then the
researcher dashboard and its replay of the roundabout's first main trial (every start state,
then one).

The walk runs on the page's fake clock, seconds of server time for minutes of a person's: the
server trusts the page's clock (as pilots with bots do), so the too-fast rule keeps the session
and the dashboard draws its error plots and field panels.
"""

import shutil
import tempfile
from pathlib import Path

from tests.conftest import REPO, cached_interaction_study, free_port, patience, start_server
from tests.e2e.conftest import CHROMIUM, CHROMIUM_ARGS
from tests.e2e.pages import (
    answer_survey,
    answer_trial,
    current_state,
    open_dashboard,
    place,
    press_on,
    shown_screen,
    start_predicting,
    visible,
)
from tests.e2e.shoot_instructions import new_participant_page, shoot_instructions

OUT = REPO / "var" / "screens"
MID_CLIP_MS = 1600  # into the first example: about half of its 9 steps of 0.35 s
REPLAYED_WORLD = "roundabout"


def shoot_participant(page, study_id: str) -> None:
    """Consent to the survey, by clicking; the instructions' demo, then per world its
    introduction, a clip and two clicks."""
    shoot_instructions(page, "recorded_instructions")
    page.click("#instructions-done")
    screen = shown_screen(page)
    while screen != "survey":
        if screen == "world":
            world = current_state(page, study_id)["step"]["world"]
            page.wait_for_timeout(100)
            page.screenshot(path=str(OUT / f"recorded_{world}_intro.png"))
            press_on(page, screen)
        elif screen == "trial" and current_state(page, study_id)["step"]["is_practice"]:
            shoot_trial(page, study_id)
        elif screen == "trial":
            answer_trial(page, study_id)
        else:
            press_on(page, screen)
        screen = shown_screen(page)
    answer_survey(page)
    visible(page, "done")


def shoot_trial(page, study_id: str) -> None:
    """A practice trial: mid-clip, two clicks of the first start state (the robot's own), the
    first click of the second (a relocated start); then the rest."""
    trial = current_state(page, study_id)["step"]
    page.clock.fast_forward(MID_CLIP_MS)
    page.screenshot(path=str(OUT / f"recorded_{trial['world']}_clip.png"))
    start_predicting(page)
    place(page, trial, 0, [0, 1])
    page.mouse.move(0, 0)  # no hover preview in the picture
    page.screenshot(path=str(OUT / f"recorded_{trial['world']}_predict.png"))
    place(page, trial, 0, list(range(2, trial["steps_to_predict"])))
    page.click("#next")
    place(page, trial, 1, [0])
    page.mouse.move(0, 0)
    page.screenshot(path=str(OUT / f"recorded_{trial['world']}_predict_relocated.png"))
    answer_trial(page, study_id)


def shoot_replay(page, url: str, study_id: str) -> None:
    """The researcher dashboard, and its replay of the first main trial of REPLAYED_WORLD."""
    open_dashboard(page, url, study_id)
    page.wait_for_selector("table.sessions tbody tr")
    page.wait_for_selector(".field-canvas")
    page.screenshot(path=str(OUT / "recorded_dashboard.png"), full_page=True)
    page.locator("table.sessions tbody tr").nth(0).locator("button").click()
    page.wait_for_selector(".trial-row")
    rows = page.locator(".trial-row")
    texts = rows.all_inner_texts()
    pick = next(i for i, t in enumerate(texts)
                if REPLAYED_WORLD in t and "practice" not in t and "passed" not in t
                and "failed" not in t)
    rows.nth(pick).locator("button").click()
    page.wait_for_selector("#replay-view:not([hidden])")
    page.locator("#replay-card").screenshot(path=str(OUT / "recorded_replay.png"))
    page.select_option("#replay-start", "1")
    page.locator(".replay-stage").screenshot(path=str(OUT / "recorded_replay_start.png"))


def main() -> None:
    """Build or reuse the study, serve it, shoot."""
    from playwright.sync_api import sync_playwright

    study = cached_interaction_study()
    OUT.mkdir(parents=True, exist_ok=True)
    root = Path(tempfile.mkdtemp(prefix="tomstudy-shoot-"))
    port = free_port()
    proc = start_server(study, f"sqlite:///{root / 'study.db'}", port, log=root / "server.log",
                        TOMSTUDY_TRUST_CLIENT_CLOCK="1")
    url = f"http://127.0.0.1:{port}"
    try:
        with sync_playwright() as pw:
            browser = pw.chromium.launch(executable_path=str(CHROMIUM), args=CHROMIUM_ARGS)
            page = new_participant_page(browser, url, study.study_id)
            shoot_participant(page, study.study_id)
            page.context.close()
            page = browser.new_page(viewport={"width": 1400, "height": 1000})
            shoot_replay(page, url, study.study_id)
            browser.close()
    finally:
        proc.terminate()
        proc.wait(timeout=patience(10))
        shutil.rmtree(root, ignore_errors=True)
    print(f"wrote {', '.join(sorted(p.name for p in OUT.glob('recorded_*.png')))} into {OUT}")


if __name__ == "__main__":
    main()
