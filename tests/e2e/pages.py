"""The participant page driven by clicking: the steps every browser test walks the same way."""

import json
import math
import re
import uuid
from pathlib import Path

from app.layout import Layout
from tests.conftest import ADMIN_TOKEN, REPO, SmallStudy, patience
from tests.e2e.conftest import BROWSER_STUDY

VIEWPORT = {"width": 1280, "height": 900}
SCREENSHOTS = REPO / "var" / "screenshots"  # git-ignored; for a person to look at
JS = Path(__file__).parent / "js"
ROBOT_EXTENT = (JS / "robot_extent.js").read_text()
PIXEL = """([x, y]) => Array.from(document.querySelector('#trial-canvas').getContext('2d')
    .getImageData(Math.round(x * devicePixelRatio), Math.round(y * devicePixelRatio), 1, 1).data)"""
# Distinct colours among a grid of pixels: a blank or single-colour canvas has one or two.
CANVAS_COLOUR_COUNT = """c => {
    const data = c.getContext("2d").getImageData(0, 0, c.width, c.height).data;
    const seen = new Set();
    for (let i = 0; i < data.length; i += 4 * 97) seen.add(data.slice(i, i + 4).join(","));
    return seen.size;
}"""
ROBOT_RGB = (0x00, 0x72, 0xB2)
CLIP_JUMP_MS = 2000  # fake-clock jump per poll while clips play
THINK_MS = 1500  # fake-clock time between two clicks
# an arrow key moves the keyboard cursor by this share of max_step_m (predict.js's own)
KEY_STEP_FRACTION = float(re.search(r"^const KEY_STEP_FRACTION = ([\d.]+);", (
    REPO / "frontend" / "static" / "js" / "predict.js").read_text(), re.M).group(1))


def wait_ms() -> float:
    """A screen's wait in milliseconds: 15 s on a quiet machine, scaled by patience()."""
    return patience(15) * 1000


def fresh_recruitment() -> str:
    """URL parameters of a new Prolific participant (each visit a new session)."""
    return f"PROLIFIC_PID={uuid.uuid4().hex[:24]}&STUDY_ID={'5' * 24}&SESSION_ID=s1"


def researcher_page(browser, base_url: str) -> tuple:
    """The researcher dashboard opened with the test token, and the list its page errors go
    to."""
    page = browser.new_page(viewport={"width": 1300, "height": 900})
    errors: list[str] = []
    page.on("pageerror", lambda e: errors.append(str(e)))
    log_in(page, base_url)
    return page, errors


def log_in(page, base_url: str) -> None:
    """Log into the researcher dashboard with the test token; wait until it is shown."""
    page.goto(f"{base_url}/researcher")
    page.fill("#token-input", ADMIN_TOKEN)
    page.click("#token-form button[type=submit]")
    page.wait_for_selector("#dashboard:not([hidden])")


def page_token(page, study_id: str = BROWSER_STUDY) -> str:
    """The session token the page keeps in sessionStorage."""
    key = f"tomstudy.{study_id}.session"
    return json.loads(page.evaluate(f"sessionStorage.getItem({key!r})"))["token"]


def bank_of(study: SmallStudy, study_id: str = BROWSER_STUDY) -> dict:
    """The study's bank trials by id."""
    raw = json.loads(Layout(study.data_dir).bank(study_id).read_text())
    return {t["trial_id"]: t for w in raw["worlds"].values() for t in w["trials"]}


def visible(page, screen: str) -> None:
    """Wait until the participant app shows `screen`."""
    page.wait_for_selector(f"#screen-{screen}:not([hidden])", timeout=wait_ms())


# the screens between trials that only ask to go on, and their buttons
ONWARD = {"world": "#world-done", "practice-over": "#practice-over-done", "pause": "#pause-done"}
SHOWN = "s => document.querySelector(`#screen-${s}`)?.hidden === false"


def through_instructions(page) -> None:
    """Consent, instructions and the first part's introduction, by clicking."""
    consent_and_instructions(page)
    onward(page)
    visible(page, "trial")


def consent_and_instructions(page) -> None:
    """Agree to take part and read the instructions, by clicking."""
    visible(page, "consent")
    page.check("#consent-check")
    page.click("#consent-agree")
    visible(page, "instructions")
    page.click("#instructions-done")


def open_dashboard(page, base_url: str, study_id: str = BROWSER_STUDY) -> None:
    """Log into the researcher dashboard and show a study."""
    log_in(page, base_url)
    page.fill("#study-input", study_id)
    page.click("#refresh")
    page.wait_for_selector("table.sessions")  # the dashboard has loaded


def onward(page) -> str:
    """Press on through a part's introduction, 'practice over' and pause screens; returns the
    screen that asks for more (trial, survey or done)."""
    while True:
        shown = shown_screen(page)
        if shown not in ONWARD:
            return shown
        press_on(page, shown)


def shown_screen(page) -> str:
    """Wait until one of the participant app's screens is shown; its name."""
    screens = [*ONWARD, "trial", "survey", "done"]
    page.wait_for_function(f"() => {json.dumps(screens)}.some({SHOWN})", timeout=wait_ms())
    return next(s for s in screens if page.evaluate(f"s => ({SHOWN})(s)", s))


def press_on(page, screen: str) -> None:
    """Press the button of a screen that only asks to go on, and wait until it is gone."""
    page.click(ONWARD[screen])
    page.wait_for_function(f"s => !({SHOWN})(s)", arg=screen, timeout=wait_ms())


def answer_survey(page) -> None:
    """Pick the first option of each closing question and finish."""
    visible(page, "survey")
    for name in sorted(set(page.eval_on_selector_all("#survey-form input[type=radio]",
                                                     "els => els.map(e => e.name)"))):
        page.check(f"#survey-form input[name={name}] >> nth=0")
    page.click("#survey-form button[type=submit]")


def current_state(page, study_id: str = BROWSER_STUDY) -> dict:
    """The server's state for this tab's session (token from sessionStorage, as the app does)."""
    return page.evaluate(
        """async (key) => {
            const { token } = JSON.parse(sessionStorage.getItem(key));
            const headers = { "X-Session-Token": token };
            return (await fetch("/api/session/state", { headers })).json();
        }""",
        f"tomstudy.{study_id}.session",
    )


def canvas_view(page) -> tuple[float, float, float]:
    """(px per m, x and y of the scene origin in CSS px) as the trial canvas publishes them."""
    return tuple(page.eval_on_selector(
        "#trial-canvas", "c => [c.dataset.pxPerM, c.dataset.originXPx, c.dataset.originYPx]"
                         ".map(Number)"))


def canvas_px(page, point) -> dict:
    """Position inside the trial canvas of a scene point (the canvas has no border)."""
    scale, origin_x, origin_y = canvas_view(page)
    return {"x": origin_x + point[0] * scale, "y": origin_y + point[1] * scale}


def planned_path(trial: dict, start_state: dict) -> list[list[float]]:
    """Three mid-reach moves, as straight ahead of the robot as the scene bounds allow."""
    bounds = trial["scene"]["bounds"]
    reach = (trial["min_step_m"] + trial["max_step_m"]) / 2
    margin = 0.02 * (bounds["x_max_m"] - bounds["x_min_m"])
    start = start_state["robot"]
    for offset_deg in (0, 15, -15, 30, -30, 45, -45, 60, -60, 90, -90, 120, -120, 150, -150, 180):
        angle = start_state["robot_heading"] + math.radians(offset_deg)
        path = [[start[0] + k * reach * math.cos(angle), start[1] + k * reach * math.sin(angle)]
                for k in range(1, trial["steps_to_predict"] + 1)]
        if all(bounds["x_min_m"] + margin <= x <= bounds["x_max_m"] - margin
               and bounds["y_min_m"] + margin <= y <= bounds["y_max_m"] - margin for x, y in path):
            return path
    raise AssertionError(f"no straight path fits from {start}")


def watch_clips(page) -> None:
    """Jump the page's fake clock until every clip has played and predictions may start."""
    button = page.locator("#start-predicting")
    for _ in range(500):
        if button.is_visible() and button.is_enabled():
            return
        page.clock.fast_forward(CLIP_JUMP_MS)
    raise AssertionError("the clips never finished")


def place(page, trial: dict, start: int, steps: list[int], think_ms: float = THINK_MS,
          keyboard: bool = False) -> list[list[float]]:
    """Click these steps of the planned path from start state `start`, `think_ms` of the
    page's clock apart (with `keyboard`: move the cross there with the arrow keys and press
    Enter, which lands within a key step of the point on each axis); returns the points."""
    state = trial["start_states"][start]
    path = planned_path(trial, state)
    for j in steps:
        if think_ms:
            page.clock.fast_forward(think_ms)
        if keyboard:
            page.focus("#trial-canvas")
            for key in arrow_presses(trial, state["robot"], path, j):
                page.keyboard.press(key)
            page.keyboard.press("Enter")
        else:
            page.click("#trial-canvas", position=canvas_px(page, path[j]))
    return [path[j] for j in steps]


def arrow_presses(trial: dict, start: list[float], path: list, j: int) -> list[str]:
    """The arrow keys that move the keyboard cursor, which starts at the last click, from
    `path[j - 1]` (or `start`) to `path[j]`, both rounded to whole key steps from `start`."""
    key_step = trial["max_step_m"] * KEY_STEP_FRACTION

    def steps_to(point) -> list[int]:
        return [round((point[axis] - start[axis]) / key_step) for axis in (0, 1)]

    before = steps_to(path[j - 1]) if j else [0, 0]
    dx, dy = (after - at for at, after in zip(before, steps_to(path[j]), strict=True))
    return (["ArrowRight" if dx > 0 else "ArrowLeft"] * abs(dx)
            + ["ArrowDown" if dy > 0 else "ArrowUp"] * abs(dy))  # +y is down the canvas


def start_predicting(page) -> None:
    """Watch the clips to the end and press Make predictions."""
    watch_clips(page)
    page.click("#start-predicting")


def answer_trial(page, study_id: str = BROWSER_STUDY) -> dict:
    """Answer the trial on screen (from wherever its input stands) by clicking the rest of
    every planned path, then submit; returns its payload."""
    trial = current_state(page, study_id)["step"]
    if page.is_visible("#start-predicting"):
        start_predicting(page)
    while page.is_visible("#screen-trial"):
        # "Start position k of K: p of n positions placed."
        where, placed = page.inner_text("#trial-caption").split(": ")
        start = int(where.split()[2]) - 1
        done = int(placed.split(" of")[0])
        place(page, trial, start, list(range(done, trial["steps_to_predict"])))
        last = page.inner_text("#next").startswith("Submit")
        page.click("#next")
        if last:
            through_feedback(page)
            page.wait_for_function("() => document.querySelector('#screen-trial').hidden")
    return trial


FEEDBACK_OR_GONE = """() => document.querySelector('#screen-trial').hidden
    || !document.querySelector('#feedback-legend').hidden"""


def through_feedback(page) -> int:
    """After submitting a trial: press on through a practice trial's feedback (a screen per
    start position); how many screens it showed (0 after a scored trial)."""
    page.wait_for_function(FEEDBACK_OR_GONE, timeout=wait_ms())
    shown = 0
    while page.is_visible("#screen-trial") and page.is_visible("#feedback-legend"):
        shown += 1
        page.click("#next")
    return shown


def wait_saved(page) -> None:
    """Wait until the page says every click so far is on the server."""
    page.wait_for_function(
        "() => document.querySelector('#save-status').textContent.includes('are saved')")


def contrast(a, b) -> float:
    """WCAG 2.1 contrast ratio of two sRGB colours (0-255 each)."""
    def luminance(rgb):
        linear = [c / 12.92 if c <= 0.04045 else ((c + 0.055) / 1.055) ** 2.4
                  for c in (v / 255 for v in rgb[:3])]
        return 0.2126 * linear[0] + 0.7152 * linear[1] + 0.0722 * linear[2]
    high, low = sorted((luminance(a), luminance(b)), reverse=True)
    return (high + 0.05) / (low + 0.05)


def robot_outline(page, trial: dict) -> dict:
    """Across the robot at the first start state of the prediction screen (its sides: a car's
    nose wedge is not there): its drawn width (CSS px), its outline's colour and the colour
    just outside it (the reach disc's tint over the ground)."""
    scale, origin_x, origin_y = canvas_view(page)
    start = trial["start_states"][0]
    agent = trial["scene"]["agents"][0]
    width_m = trial["segment"].get("sizes", [[0, agent["width_m"]]])[0][1]  # as recorded
    centre = [origin_x + start["robot"][0] * scale, origin_y + start["robot"][1] * scale]
    heading = start["robot_heading"] if agent["kind"] == "car" else 0.0
    across = [-math.sin(heading), math.cos(heading)]
    extent = page.evaluate(ROBOT_EXTENT, [*centre, *across, width_m * scale / 2 + 4,
                                          list(ROBOT_RGB)])
    at = lambda d: [centre[0] + d * across[0], centre[1] + d * across[1]]  # noqa: E731
    return {"width": extent[1] - extent[0], "outline": page.evaluate(PIXEL, at(extent[1] - 1)),
            "ground": page.evaluate(PIXEL, at(extent[1] + 6))}
