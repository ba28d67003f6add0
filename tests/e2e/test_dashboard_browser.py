"""The researcher dashboard in Debian's chromium: bot sessions in the table, one replay drawn."""

import asyncio
import re

import httpx
import pytest

from app.pilot.bots import run_bots
from tests.conftest import ADMIN_TOKEN, REPO
from tests.e2e.conftest import BROWSER_STUDY
from tests.e2e.pages import researcher_page

pytestmark = [pytest.mark.browser, pytest.mark.slow]

BOTS = 3
SCREENSHOTS = REPO / "var" / "screenshots"

# Distinct colours among a grid of pixels: a blank or single-colour canvas has one or two.
CANVAS_COLOURS = """c => {
    const data = c.getContext("2d").getImageData(0, 0, c.width, c.height).data;
    const seen = new Set();
    for (let i = 0; i < data.length; i += 4 * 97) seen.add(data.slice(i, i + 4).join(","));
    return seen.size;
}"""


@pytest.fixture(scope="module")
def bot_sessions(browser_server) -> list:
    """A few coarse bots take the study through HTTP (before Playwright opens its loop)."""
    results = asyncio.run(run_bots(browser_server.url, BROWSER_STUDY, "coarse", BOTS,
                                   concurrency=BOTS, seed=3))
    assert [r.error for r in results if r.error] == []
    return results


def test_dashboard_lists_sessions_and_replays_a_trial(browser_server, bot_sessions, chromium):
    page, errors = researcher_page(chromium, browser_server.url)
    page.wait_for_selector("table.sessions tbody tr")
    rows = page.locator("table.sessions tbody tr")
    assert rows.count() >= BOTS
    assert page.locator("table.sessions th", has_text="external id").count() == 0
    shown_verdicts(page, browser_server.url)
    # bots answer faster than people: by the server's clock most end `excluded` (too fast)
    finished = re.compile("completed|excluded")
    done = [row for row in rows.all_inner_texts() if finished.search(row)]
    assert len(done) >= BOTS
    bot_row = page.locator("table.sessions tbody tr", has_text=finished).first
    public_id = bot_row.get_attribute("data-public-id")
    bot_row.locator("button").click()
    page.wait_for_selector(".trial-row")
    assert public_id in page.text_content("#replay-heading")
    trials = page.locator(".trial-row")
    assert trials.count() == 24  # 2 worlds x (1 practice + 10 trials + 1 attention check)
    trials.nth(2).locator("button").click()
    page.wait_for_selector("#replay-view:not([hidden])")
    assert page.get_attribute("#replay-clicks-count", "data-clicks") == "15"
    assert page.text_content("#replay-clicks-count").startswith("15 clicks")
    assert page.locator("#replay-click-table tbody tr").count() == 15
    canvas = page.locator("#replay-canvas")
    assert canvas.get_attribute("data-clicks-drawn") == "15"
    assert canvas.evaluate(CANVAS_COLOURS) > 10
    page.select_option("#replay-start", "0")
    assert canvas.get_attribute("data-clicks-drawn") == "3"
    page.fill("#replay-time", "0")
    page.dispatch_event("#replay-time", "input")
    assert canvas.get_attribute("data-clicks-drawn") == "0"
    page.click("#replay-play")  # the participant page's own clip player
    page.wait_for_function("document.getElementById('replay-caption').textContent"
                           ".startsWith('Example 1 of')")
    SCREENSHOTS.mkdir(parents=True, exist_ok=True)
    page.screenshot(path=str(SCREENSHOTS / "dashboard_replay_e2e.png"), full_page=True)
    assert errors == []
    page.close()


def shown_verdicts(page, url: str) -> None:
    """The page lists, per world, the primary test's sentence the dashboard API gives (the
    report's, analysis/verdicts.py), or says there is none yet."""
    board = httpx.get(f"{url}/api/researcher/dashboard", params={"study_id": BROWSER_STUDY},
                      headers={"Authorization": f"Bearer {ADMIN_TOKEN}"}, timeout=30).json()
    verdicts = board["alignment"]["verdicts"]
    page.wait_for_selector("#verdicts li")
    items = page.locator("#verdicts li")
    if verdicts:
        assert items.all_inner_texts() == list(verdicts.values())
        assert [items.nth(i).get_attribute("data-world") for i in range(items.count())] == list(
            verdicts)
    else:
        assert items.all_inner_texts() == ["Not yet: the test needs kept participants whose "
                                           "answers ran the loaded trial bank."]
    assert page.text_content("#verdicts-heading").startswith("The answer so far")
    progress = board["progress"]
    excluded = progress["completed"] - progress["usable"]
    headline = " ".join(page.text_content("#progress-line").split())
    assert headline.startswith(f"{progress['usable']} usable of {progress['target_sample_size']}")
    assert f"{progress['completed']} finished" in headline
    assert (f"{excluded} excluded" in headline) == (excluded > 0)
