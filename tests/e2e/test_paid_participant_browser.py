"""Issue 21 in Debian's chromium: what a paid participant and the researcher meet.

One test per finding of the issue: a reload keeps a trial's clicks; a second tab is told
and takes over only when asked; a finished link shows its code again; every refusal is a
plain page; each world is a part with its practice, numbering and pauses; the prediction
view draws at the server's scale with labels clear of the agents; colours reach 3:1 on the
canvas; a declined session counts no trial on the dashboard.
"""

import io
import json
import shutil
import sqlite3
import time
from contextlib import closing
from pathlib import Path

import httpx
import pandas as pd
import pytest
import yaml

from app.layout import Layout
from app.prediction_view import TARGET_STEP_PX, prediction_view
from tests.conftest import (
    ADMIN_TOKEN,
    SmallStudy,
    free_port,
    freeze_bundle_of,
    patience,
    researcher_get,
    start_server,
)
from tests.e2e.conftest import BROWSER_STUDY
from tests.e2e.pages import (
    JS,
    VIEWPORT,
    answer_trial,
    bank_of,
    canvas_view,
    contrast,
    current_state,
    fresh_recruitment,
    onward,
    page_token,
    place,
    robot_outline,
    start_predicting,
    through_instructions,
    visible,
    wait_saved,
)
from tests.server.flow import Participant, new_id, prolific, served_codes

pytestmark = [pytest.mark.browser, pytest.mark.slow]

SHOTS = Path(__file__).resolve().parents[2] / "var" / "screenshots" / "issue21"
FIELD_NAMES = ("recruitment", "PROLIFIC_PID", "SESSION_ID", "STUDY_ID", "study_id", "tab:")
CLOSED, FULL = "browser_closed", "browser_full"


@pytest.fixture
def fresh(chromium):
    """A new browser context on a paused fake clock (its timers, heartbeats included, run only
    when a test moves the clock); yields a function that opens pages in it."""
    context = chromium.new_context(viewport=VIEWPORT)
    context.clock.install()
    context.clock.pause_at(int(time.time() * 1000) + 1000)
    errors = []

    def new_page():
        page = context.new_page()
        page.on("pageerror", lambda err: errors.append(str(err)))
        return page

    yield new_page
    context.close()
    assert errors == []


def study_url(base: str, recruitment: str, study: str = BROWSER_STUDY) -> str:
    return f"{base}/s/{study}?{recruitment}"


def params_of(recruitment: str) -> dict:
    return dict(pair.split("=") for pair in recruitment.split("&"))


def shoot(page, name: str) -> None:
    SHOTS.mkdir(parents=True, exist_ok=True)
    page.screenshot(path=str(SHOTS / f"{name}.png"))


def researcher_export(base: str, what: str) -> pd.DataFrame:
    """One export, as the researcher downloads it."""
    csv = researcher_get(f"{base}/api/researcher/export/{what}.csv",
                         params={"study_id": BROWSER_STUDY}).text
    return pd.read_csv(io.StringIO(csv), keep_default_na=False)


def query(db_path: Path, sql: str, *args) -> list[tuple]:
    with closing(sqlite3.connect(db_path)) as db:
        return db.execute(sql, args).fetchall()


def to_predictions(page, base: str) -> tuple[str, dict]:
    """A new participant on `page`, through to the first practice trial's predictions;
    returns their link's parameters and the trial."""
    recruitment = fresh_recruitment()
    page.goto(study_url(base, recruitment))
    through_instructions(page)
    trial = current_state(page)["step"]
    start_predicting(page)
    return recruitment, trial


# ---------------------------------------------------------------- 1. a reload keeps the clicks

def test_a_reload_mid_trial_keeps_the_clicks(fresh, browser_server):
    page = fresh()
    recruitment, trial = to_predictions(page, browser_server.url)
    before = place(page, trial, 0, [0, 1, 2])
    page.click("#next")
    before += place(page, trial, 1, [0, 1])
    wait_saved(page)

    page.reload()

    visible(page, "trial")
    assert page.is_visible("#predict-controls") and page.is_hidden("#start-predicting")
    assert page.inner_text("#trial-caption") == "Start position 2 of 5: 2 of 3 positions placed."
    assert "your 5 clicks so far are restored" in page.inner_text("#trial-message")
    answer_trial(page)
    pid = params_of(recruitment)["PROLIFIC_PID"]
    stored = query(browser_server.db_path,
                   "SELECT click_x, click_y FROM predictionrow JOIN participant ON participant.id "
                   "= predictionrow.participant_id WHERE external_id = ? ORDER BY start_index, "
                   "step", pid)[:5]
    scale = canvas_view(page)[0]
    assert all(abs(x - p[0]) * scale <= 1.01 and abs(y - p[1]) * scale <= 1.01
               for (x, y), p in zip(stored, before, strict=True))
    events = researcher_export(browser_server.url, "events")
    public_id = query(browser_server.db_path, "SELECT public_id FROM participant WHERE "
                      "external_id = ?", pid)[0][0]
    opened = events[(events.participant_id == public_id) & (events.kind == "page_opened")]
    # the first visit opened the link before consent, which stores nothing; then the reload
    assert list(zip(opened.source, opened.clicks, opened.start_index, strict=True)) == [
        ("server", 5, 1)]
    assert "practice" in opened.trial_id.iloc[0]  # the bank's trial id


# ---------------------------------------------------------------- 2. two tabs

def test_a_second_tab_is_told_and_takes_over_only_when_asked(fresh, browser_server):
    first = fresh()
    recruitment, trial = to_predictions(first, browser_server.url)
    place(first, trial, 0, [0])
    wait_saved(first)

    second = fresh()
    second.goto(study_url(browser_server.url, recruitment))
    visible(second, "notice")
    assert second.inner_text("#notice-title") == "The study is open in another tab"
    assert second.inner_text("#notice-action") == "Continue here instead"
    assert not any(name in second.inner_text("#screen-notice") for name in FIELD_NAMES)
    shoot(second, "second-tab")
    place(first, trial, 0, [1])  # the first tab goes on, untouched
    wait_saved(first)
    assert first.is_visible("#screen-trial")

    second.click("#notice-action")
    visible(second, "trial")
    assert "2 of 3 positions placed" in second.inner_text("#trial-caption")

    # its draft is refused: the session moved to the other tab (no clock time passes, so no
    # heartbeat tells it first)
    place(first, trial, 0, [2], think_ms=0)
    visible(first, "notice")
    assert "another tab" in first.inner_text("#notice-title")
    assert first.inner_text("#notice-extra").startswith("Your last click in this tab was not "
                                                        "saved")
    assert first.is_visible("#notice-action")
    shoot(first, "tab-left-behind")
    answer_trial(second)
    assert onward(second) == "trial"
    kinds = query(browser_server.db_path,
                  "SELECT kind, json_extract(data, '$.clicks') FROM event JOIN participant ON "
                  "participant.id = event.participant_id WHERE external_id = ? ORDER BY "
                  "event.id", params_of(recruitment)["PROLIFIC_PID"])
    assert ("tab_takeover", 2) in kinds


# ---------------------------------------------------------------- 3. a finished link

def test_reopening_a_finished_link_shows_its_code_again(fresh, browser_server, browser_study):
    recruitment = prolific("finished-" + new_id())
    with httpx.Client(base_url=browser_server.url, timeout=patience(30)) as http:
        p = Participant(http, BROWSER_STUDY)
        p.start(**recruitment)
        p.pass_intro()
        ended = p.finish(bank_of(browser_study))
    # an HTTP walk answers faster than the server's clock allows a person, so its ending may
    # be the review code (issue 22): the link must show whichever code the session got
    code = ended["step"]["completion_code"]
    codes = served_codes(browser_study)
    assert code in (codes["completed"], codes["excluded"])
    page = fresh()
    redirected = []
    page.route("https://app.prolific.com/**", lambda route: (
        redirected.append(route.request.url), route.fulfill(body="Prolific")))
    page.goto(study_url(browser_server.url, "&".join(f"{k}={v}" for k, v in recruitment.items())))
    visible(page, "done")
    assert page.inner_text("#done-heading") == "Thank you!"
    assert page.inner_text("#completion-code") == code
    shoot(page, "finished-link")
    page.clock.fast_forward(6000)  # the redirect to Prolific, again
    page.wait_for_function("() => location.host === 'app.prolific.com'")
    assert redirected == [f"https://app.prolific.com/submissions/complete?cc={code}"]


# ---------------------------------------------------------------- 4. refusals

@pytest.fixture(scope="module")
def refusing_server(browser_study, tmp_path_factory):
    """The browser study served twice more: once closed, once full after one session."""
    root = tmp_path_factory.mktemp("refusing")
    shutil.copytree(browser_study.configs_dir, root / "configs")
    shutil.copytree(browser_study.data_dir, root / "var")
    layout = Layout(root / "var")
    config = yaml.safe_load((root / "configs" / f"{BROWSER_STUDY}.yaml").read_text())
    for study, change in ((CLOSED, {"closed": True}), (FULL, {"max_counted_sessions": 1})):
        shutil.copytree(layout.bank_dir(BROWSER_STUDY), layout.bank_dir(study))
        variant = config | {"recruitment": config["recruitment"] | change}
        (root / "configs" / f"{study}.yaml").write_text(yaml.safe_dump(variant))
        freeze_bundle_of(SmallStudy(root / "var", root / "configs", study))
    study = SmallStudy(root / "var", root / "configs", CLOSED)
    port = free_port()
    proc = start_server(study, f"sqlite:///{root / 'study.db'}", port, log=root / "server.log",
                        args=("--study", f"{CLOSED},{FULL}"))
    url = f"http://127.0.0.1:{port}"
    # the one counted session the full study holds
    with httpx.Client(base_url=url, timeout=patience(30)) as http:
        first = Participant(http, FULL)
        assert first.start(**prolific("first-in"))["resumed"] is False
        assert first.consent().status_code == 200  # a session counts from its consent
    yield url
    proc.terminate()
    proc.wait(timeout=patience(10))


def _started_elsewhere(base: str) -> str:
    """A link whose person has another attempt running."""
    params = prolific("running-" + new_id())
    with httpx.Client(base_url=base, timeout=patience(30)) as http:
        Participant(http, BROWSER_STUDY).start(**params)
    return "&".join(f"{k}={v}" for k, v in (params | {"SESSION_ID": "another"}).items())


def _taken_part(base: str) -> str:
    """A link whose person ended the study (declined) under another attempt."""
    params = prolific("declined-" + new_id())
    with httpx.Client(base_url=base, timeout=patience(30)) as http:
        p = Participant(http, BROWSER_STUDY)
        p.start(**params)
        p.post("decline", {"submission_id": new_id()})
    return "&".join(f"{k}={v}" for k, v in (params | {"SESSION_ID": "another"}).items())


REFUSALS = {  # case -> (the link, the heading the person reads)
    "missing": (lambda base, _: f"{base}/s/{BROWSER_STUDY}", "This link is incomplete"),
    "malformed": (lambda base, _: study_url(base, "PROLIFIC_PID=not-an-id&STUDY_ID=x"
                                                  "&SESSION_ID=s"), "This link is incomplete"),
    "running": (lambda base, _: study_url(base, _started_elsewhere(base)),
                "The study is already running for you"),
    "taken_part": (lambda base, _: study_url(base, _taken_part(base)),
                   "You have already taken part"),
    "closed": (lambda _, refusing: study_url(refusing(), fresh_recruitment(), CLOSED),
               "This study is closed"),
    "full": (lambda _, refusing: study_url(refusing(), fresh_recruitment(), FULL),
             "This study is full"),
    "unknown_study": (lambda base, _: f"{base}/s/no_such_study", "This study is not available"),
}


@pytest.mark.parametrize("case", list(REFUSALS))
def test_every_refusal_is_a_plain_page(fresh, browser_server, request, case):
    link, title = REFUSALS[case]
    page = fresh()
    page.goto(link(browser_server.url, lambda: request.getfixturevalue("refusing_server")))
    page.wait_for_selector("#screen-notice:not([hidden]), #refusal")
    card = page.locator("#screen-notice:not([hidden]), #refusal")
    text = card.inner_text()
    assert card.locator("h2").inner_text() == title
    assert not any(name in text for name in FIELD_NAMES), text
    assert "Prolific" in text and not page.is_visible("#notice-action")
    shoot(page, f"refusal-{case}")


# ---------------------------------------------------------------- 5. a clear path

def answer_part_over_http(base: str, token: str, part: int, bank: dict) -> None:
    """Answer what is left of `part` over HTTP (the page's session), as the page would."""
    with httpx.Client(base_url=base, timeout=patience(30)) as http:
        p = Participant(http, BROWSER_STUDY, token=token)
        state = p.state()
        while state["phase"] != "world_intro" or state["step"]["part"] == part:
            if state["phase"] in ("world_intro", "practice_over"):
                p.post("continue", {"submission_id": new_id(), "phase": state["phase"]})
            else:
                p.answer_trial(bank)
            state = p.state()


def test_each_world_is_a_part_with_its_practice_numbering_and_pauses(fresh, browser_server,
                                                                      browser_study):
    config = yaml.safe_load((browser_study.configs_dir / f"{BROWSER_STUDY}.yaml").read_text())
    page = fresh()
    page.goto(study_url(browser_server.url, fresh_recruitment()))
    visible(page, "consent")
    page.check("#consent-check")
    page.click("#consent-agree")
    visible(page, "instructions")
    page.click("#instructions-done")
    visible(page, "world")
    first = current_state(page)["step"]
    assert page.inner_text("#world-part").lower() == "part 1 of 2"
    assert page.inner_text("#world-title") == config["world_intros"][first["world"]]["title"]
    assert page.inner_text("#world-text").startswith("The robot is a blue")
    assert "a practice trial, which does not count, then 11 trials" in page.inner_text(
        "#world-plan")
    page.click("#world-done")
    visible(page, "trial")
    assert page.inner_text("#trial-heading") == "Part 1 of 2 · Practice trial 1 of 1 (not counted)"
    answer_trial(page)
    visible(page, "practice-over")
    assert "The next 11 trials count; they are numbered 1 to 11" in page.inner_text(
        "#practice-over-text")
    page.click("#practice-over-done")
    visible(page, "trial")
    assert page.inner_text("#trial-heading") == "Part 1 of 2 · Trial 1 of 11"
    answer_trial(page)
    visible(page, "pause")
    assert page.inner_text("#pause-heading") == "Part 1 of 2 · Trial 1 of 11 saved"
    assert page.inner_text("#pause-done") == "Continue to trial 2"
    page.click("#pause-done")
    visible(page, "trial")
    assert page.inner_text("#trial-heading") == "Part 1 of 2 · Trial 2 of 11"
    answer_part_over_http(browser_server.url, page_token(page), 1, bank_of(browser_study))
    page.reload()
    visible(page, "world")
    assert page.inner_text("#world-part").lower() == "part 2 of 2: a new world"
    second = current_state(page)["step"]["world"]
    assert second != first["world"]
    assert page.inner_text("#world-title") == config["world_intros"][second]["title"]


# ---------------------------------------------------------------- 6, 7. the prediction view

def check_view(page, browser_study) -> dict:
    """At the first start state of the trial on screen: the scale is the server's rule, the
    robot is drawn that large, and its outline stands out from the ground."""
    trial = current_state(page)["step"]
    raw = json.loads(Layout(browser_study.data_dir).bank(BROWSER_STUDY).read_text())
    rule = prediction_view(raw["worlds"][trial["world"]])
    scale = canvas_view(page)[0]
    assert trial["view"]["px_per_m"] == rule.px_per_m and scale == pytest.approx(rule.px_per_m)
    assert rule.median_step_m * scale == pytest.approx(TARGET_STEP_PX, abs=0.1)
    drawn = robot_outline(page, trial)
    assert drawn["width"] == pytest.approx(trial["scene"]["agents"][0]["width_m"] * scale + 3,
                                           abs=2)  # a 3 px outline
    box = page.eval_on_selector("#trial-canvas", "c => c.getBoundingClientRect().toJSON()")
    fits = page.evaluate("() => innerHeight") - box["bottom"]
    scene_px = (trial["scene"]["bounds"]["y_max_m"] - trial["scene"]["bounds"]["y_min_m"]) * scale
    assert fits >= 0 and (fits <= 80 or box["height"] >= scene_px)  # the height is used
    return drawn


def labels_clear(page) -> None:
    """No label overlaps an agent, a click ring or another label."""
    boxes = page.eval_on_selector("#trial-canvas", "c => c.layoutBoxes")
    labels = boxes["labels"]
    assert len(boxes["rings"]) == 3
    for i, label in enumerate(labels):
        others = boxes["agents"] + boxes["rings"] + labels[i + 1:]
        assert not any(overlap(label, other) for other in others), json.dumps([label, boxes])


def overlap(a: dict, b: dict) -> bool:
    """Two boxes {x0, y0, x1, y1} share some area."""
    return a["x0"] < b["x1"] and b["x0"] < a["x1"] and a["y0"] < b["y1"] and b["y0"] < a["y1"]


def test_the_prediction_view_draws_at_the_servers_scale_with_labels_clear(
        fresh, browser_server, browser_study):
    page = fresh()
    page.goto(study_url(browser_server.url, fresh_recruitment()))
    through_instructions(page)
    for part in (1, 2):
        trial = current_state(page)["step"]
        start_predicting(page)
        colours = check_view(page, browser_study)
        assert contrast(colours["outline"], colours["ground"]) >= 3
        place(page, trial, 0, [0, 1, 2])
        labels_clear(page)
        shoot(page, f"predict-{trial['world']}")
        if part == 1:
            answer_part_over_http(browser_server.url, page_token(page), 1,
                                  bank_of(browser_study))
            page.reload()
            assert onward(page) == "trial"


CANVAS_COLOURS = (JS / "canvas_colours.js").read_text()


def test_agents_traces_markers_and_goals_reach_3_to_1_on_the_canvas(fresh, browser_server):
    page = fresh()
    page.goto(f"{browser_server.url}/")
    colours = page.evaluate(CANVAS_COLOURS)
    grounds = ("field", "road", "shoulder", "recorded road", "recorded field")
    assert set(colours) == {*grounds, "goals", "goal_ground"}
    ratios = {}
    for ground in grounds:
        drawn = colours[ground]
        for thing in ("robot", "person", "robot_trace", "person_trace", "ring", "robot_outline"):
            ratios[f"{thing} on {ground}"] = contrast(drawn[thing], drawn["ground"])
    for k, goal in enumerate(colours["goals"]):
        ratios[f"goal {k + 1} on field"] = contrast(goal, colours["goal_ground"])
    low = {name: round(r, 2) for name, r in ratios.items() if r < 3}
    assert low == {}, low
    print(json.dumps({name: round(r, 2) for name, r in ratios.items()}))


# ---------------------------------------------------------------- 8. the researcher

def test_the_dashboard_counts_a_declined_session_fits_and_explains_its_timings(
        fresh, browser_server):
    page = fresh()
    page.goto(study_url(browser_server.url, fresh_recruitment()))
    visible(page, "consent")
    page.click("#consent-decline")
    visible(page, "done")
    declined = page_public_id(page, browser_server)
    with httpx.Client(base_url=browser_server.url, timeout=patience(30)) as http:
        answered = Participant(http, BROWSER_STUDY)
        answered.start()
        answered.pass_intro()
        answered.answer_trial()
    public = researcher_get(f"{browser_server.url}/api/researcher/dashboard",
                            params={"study_id": BROWSER_STUDY}).json()
    sheet = researcher_export(browser_server.url, "participants").set_index("participant_id")
    assert (sheet.loc[declined, "outcome"], sheet.loc[declined, "steps_done"]) == (
        "declined_consent", 0)
    mine = next(r for r in public["participants"] if r["public_id"] == declined)
    assert mine["progress"]["done"] == 0

    page = fresh()  # the done page redirects to Prolific on its own
    page.goto(f"{browser_server.url}/researcher")
    page.fill("#token-input", ADMIN_TOKEN)
    page.click("#token-form button[type=submit]")
    page.fill("#study-input", BROWSER_STUDY)
    page.click("#refresh")
    row = page.locator(f"table.sessions tr[data-public-id='{declined}']")
    row.wait_for()
    assert row.locator("td").nth(10).inner_text() == f"0 / {mine['progress']['total']}"
    fit = page.eval_on_selector("table.sessions",
                                "t => [t.scrollWidth, t.parentElement.clientWidth]")
    assert fit[0] <= fit[1]  # no horizontal scrolling at 1280 px
    shoot(page, "dashboard")
    others = [r["public_id"] for r in public["participants"] if r["progress"]["done"]]
    page.locator(f"table.sessions tr[data-public-id='{others[-1]}'] button").click()
    page.locator(".trial-row button").first.click()
    page.wait_for_selector("#replay-view:not([hidden])")
    timing = page.inner_text("#replay-timing")
    assert "browser" in timing and "server" in timing and "smaller of the two" in timing


def page_public_id(page, server) -> str:
    """The public id of the page's session (from its token, through the database)."""
    token = page_token(page)
    return query(server.db_path, "SELECT public_id FROM participant WHERE session_token = ?",
                 token)[0][0]
