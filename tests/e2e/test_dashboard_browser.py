"""The researcher dashboard in Debian's chromium: bot sessions in the table, one replay drawn."""

import asyncio
import json
import re

import frictionless
import httpx
import pytest
from playwright.sync_api import expect

from app.pilot.bots import run_bots
from tests.conftest import patience, researcher_get
from tests.e2e.axe import axe_violations
from tests.e2e.conftest import BROWSER_STUDY
from tests.e2e.pages import CANVAS_COLOUR_COUNT, SCREENSHOTS, log_in, researcher_page
from tests.server.flow import Participant, hex24, prolific, served_codes

pytestmark = [pytest.mark.browser, pytest.mark.slow]

BOTS = 3


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
    assert canvas.evaluate(CANVAS_COLOUR_COUNT) > 10
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


def test_withdrawal_from_the_dashboard_asks_first_and_shows_the_audit_line(
        browser_server, browser_study, bot_sessions, chromium):
    with httpx.Client(base_url=browser_server.url, timeout=patience(30)) as http:
        Participant(http, BROWSER_STUDY).start(**prolific("withdraws-later"))
    # bypass_csp: axe-core is injected as an inline script, which the page's CSP refuses
    page = chromium.new_page(viewport={"width": 1300, "height": 900}, bypass_csp=True)
    errors: list[str] = []
    page.on("pageerror", lambda e: errors.append(str(e)))
    log_in(page, browser_server.url)
    session = public_id("withdraws-later", browser_server.url)
    row = f'table.sessions tbody tr[data-public-id="{session}"]'
    page.wait_for_selector(row)
    codes = served_codes(browser_study)
    shown_codes = page.locator("#completion-codes tbody tr").all_inner_texts()
    assert [line.split("\t")[1] for line in shown_codes] == list(codes.values())
    assert axe_violations(page) == []
    page.select_option("#withdraw-kind", "external_id")
    page.fill("#withdraw-id", hex24("withdraws-later").upper())  # any case matches
    page.click("#withdraw-form button[type=submit]")
    assert page.locator("#withdraw-dialog").evaluate("d => d.open")
    assert "cannot be restored" in page.text_content("#withdraw-dialog-text")
    assert axe_violations(page) == []  # the open dialog too
    page.evaluate("window.scrollTo(0, 0)")
    SCREENSHOTS.mkdir(parents=True, exist_ok=True)
    page.screenshot(path=str(SCREENSHOTS / "dashboard_withdrawal.png"))
    page.click("#withdraw-cancel")  # nothing happens without the confirmation
    assert not page.locator("#withdraw-dialog").evaluate("d => d.open")
    assert audit(browser_server.url) == [] and page.locator(row).count() == 1
    page.click("#withdraw-form button[type=submit]")
    page.click("#withdraw-confirm")
    page.wait_for_function("document.getElementById('withdraw-message').textContent"
                           ".startsWith('Withdrawn: 1 session(s)')")
    [line] = audit(browser_server.url)
    assert (line["via"], line["id_kind"], line["row_counts"]["participant"]) == (
        "api", "external_id", 1)
    assert f"audit line {line['id']}" in page.text_content("#withdraw-message")
    page.wait_for_selector(row, state="detached")  # the table was refreshed
    # the audit table is re-read after the sessions table: wait for it, do not count at once
    expect(page.locator("#withdraw-audit tbody tr")).to_have_count(1)
    assert errors == []
    page.close()


def test_the_dashboard_downloads_each_export_with_its_codebook(browser_server, bot_sessions,
                                                               chromium, tmp_path):
    """The CSV and its datapackage.json land side by side under the names the package
    expects, and `frictionless` validates the one against the other."""
    page = chromium.new_page(viewport={"width": 1300, "height": 900}, bypass_csp=True,
                             accept_downloads=True)
    errors: list[str] = []
    page.on("pageerror", lambda e: errors.append(str(e)))
    log_in(page, browser_server.url)
    page.wait_for_selector("table.sessions tbody tr")
    assert axe_violations(page) == []
    for what in ("survey", "predictions"):
        page.select_option("#export-what", what)
        for button in ("#download-codebook", "#download"):
            with page.expect_download() as download:
                page.click(button)
            download.value.save_as(tmp_path / download.value.suggested_filename)
        expect(page.locator("#dashboard-message")).to_have_text(re.compile("^Downloaded"))
        package = tmp_path / f"{BROWSER_STUDY}_{what}.datapackage.json"
        assert json.loads(package.read_text())["resources"][0]["path"] == (
            f"{BROWSER_STUDY}_{what}.csv")
        report = frictionless.validate(package)
        assert report.valid, report.flatten(["type", "fieldName", "note"])
    expect(page.locator("#download-codebook")).to_have_accessible_description(
        re.compile("^The codebook"))
    SCREENSHOTS.mkdir(parents=True, exist_ok=True)
    page.locator("#dashboard section.card").first.screenshot(
        path=str(SCREENSHOTS / "dashboard_codebook.png"))
    assert errors == []
    page.close()


def public_id(name: str, url: str) -> str:
    """The public id of the session of Prolific participant `name` (from the dashboard API)."""
    board = researcher_get(f"{url}/api/researcher/dashboard", params={
        "study_id": BROWSER_STUDY, "external_ids": True}).json()
    [found] = [r["public_id"] for r in board["participants"] if r.get("external_id") == hex24(name)]
    return found


def audit(url: str) -> list[dict]:
    """The study's withdrawal audit lines."""
    return researcher_get(f"{url}/api/researcher/withdrawals/audit",
                          params={"study_id": BROWSER_STUDY}).json()


def shown_verdicts(page, url: str) -> None:
    """The page lists, per world, the primary test's sentence the dashboard API gives (the
    report's, analysis/verdicts.py), or says there is none yet."""
    board = researcher_get(f"{url}/api/researcher/dashboard",
                           params={"study_id": BROWSER_STUDY}).json()
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
