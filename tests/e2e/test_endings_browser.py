"""Each ending walked in Debian's chromium: the page shows the ending's code and where it
goes, and the server stored the receipt first. MTurk: the HIT preview starts nothing, and a
finished assignment posts its hand-in form to a local stand-in for `turkSubmitTo`.

The trials between the start and the survey are answered over HTTP with the page's own
session token (test_browser_session.py walks them by clicking); every ending screen, button
and form here is the browser's.
"""

import json
import shutil
import sqlite3
import threading
import uuid
from contextlib import closing
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path
from urllib.parse import parse_qs

import httpx
import pytest
import yaml

from tests.conftest import SmallStudy, build_bundle_of, free_port, patience, start_server
from tests.e2e.conftest import BROWSER_STUDY
from tests.e2e.pages import (
    VIEWPORT,
    answer_survey,
    bank_of,
    fresh_recruitment,
    page_token,
    through_instructions,
    visible,
)
from tests.server.flow import Participant as ApiParticipant
from tests.server.flow import fail_attention_checks, served_codes

pytestmark = [pytest.mark.browser, pytest.mark.slow]

MTURK_STUDY = "browser_mturk"


def receipt(db_path: Path, token: str) -> dict:
    """The stored ending of a session and the kinds of its stored writes and events."""
    with closing(sqlite3.connect(db_path)) as db:
        db.row_factory = sqlite3.Row
        row = dict(db.execute("SELECT * FROM participant WHERE session_token = ?",
                              (token,)).fetchone())
        kinds = [k for (k,) in db.execute("SELECT kind FROM submission WHERE participant_id = ?"
                                          " ORDER BY id", (row["id"],))]
        events = db.execute("SELECT COUNT(*) FROM event WHERE participant_id = ?",
                            (row["id"],)).fetchone()[0]
    return {"outcome": row["outcome"], "code": row["completion_code"],
            "ended": row["ended_at"] is not None, "client": json.loads(row["client"]),
            "writes": kinds, "events": events}


def done_screen(page) -> dict:
    """What the done screen shows."""
    visible(page, "done")
    return {"heading": page.inner_text("#done-heading"),
            "message": page.inner_text("#done-message"),
            "code": page.inner_text("#completion-code") if page.is_visible("#code-block") else "",
            "redirect": page.get_attribute("#redirect-link", "href")
            if page.is_visible("#redirect-block") else None}


def to_survey_failing_checks(page, base_url: str, study: SmallStudy, study_id: str) -> str:
    """Answer every trial of the page's session over HTTP, attention checks the wrong way;
    reload the page at the survey. Returns the session token."""
    token = page_token(page, study_id)
    with httpx.Client(base_url=base_url, timeout=patience(30)) as http:
        fail_attention_checks(ApiParticipant(http, study_id, token=token),
                              bank_of(study, study_id))
    page.reload()
    return token


@pytest.fixture
def page(chromium):
    """A fresh page on the fake clock (redirect timers fire only when the test says so)."""
    context = chromium.new_context(viewport=VIEWPORT)
    page = context.new_page()
    page.clock.install()
    yield page
    context.close()


def test_declining_consent_shows_its_code_and_stores_only_the_receipt(page, browser_server,
                                                                      browser_study):
    code = served_codes(browser_study)["declined_consent"]
    page.goto(f"{browser_server.url}/s/{BROWSER_STUDY}?{fresh_recruitment()}")
    visible(page, "consent")
    page.click("#consent-decline")
    shown = done_screen(page)
    assert shown["heading"] == "The study has ended" and "return" in shown["message"]
    assert shown["code"] == code
    assert shown["redirect"].endswith(f"cc={code}")
    stored = receipt(browser_server.db_path, page_token(page, BROWSER_STUDY))
    assert stored == {"outcome": "declined_consent", "code": code, "ended": True,
                      "client": {}, "writes": ["decline"], "events": 0}


def test_a_device_that_cannot_run_the_study_is_screened_out(chromium, browser_server,
                                                             browser_study):
    code = served_codes(browser_study)["screened_out"]
    context = chromium.new_context(viewport={"width": 800, "height": 560})
    page = context.new_page()
    page.clock.install()
    page.goto(f"{browser_server.url}/s/{BROWSER_STUDY}?{fresh_recruitment()}")
    visible(page, "unsupported")
    page.click("#screen-out")
    shown = done_screen(page)
    assert shown["code"] == code and shown["redirect"].endswith(f"cc={code}")
    stored = receipt(browser_server.db_path, page_token(page, BROWSER_STUDY))
    assert (stored["outcome"], stored["code"], stored["writes"]) == (
        "screened_out", code, ["screen_out"])
    context.close()


def test_failing_the_attention_checks_ends_for_review(page, browser_server, browser_study):
    page.goto(f"{browser_server.url}/s/{BROWSER_STUDY}?{fresh_recruitment()}")
    through_instructions(page)
    token = to_survey_failing_checks(page, browser_server.url, browser_study, BROWSER_STUDY)
    answer_survey(page)
    shown = done_screen(page)
    assert shown["heading"] == "Thank you!" and "reviewed" in shown["message"]
    code = served_codes(browser_study)["failed_checks"]
    assert shown["code"] == code and shown["redirect"].endswith(f"cc={code}")
    stored = receipt(browser_server.db_path, token)
    assert (stored["outcome"], stored["code"], stored["writes"][-1]) == (
        "failed_checks", code, "survey")


class SubmitStandIn(BaseHTTPRequestHandler):
    """A local stand-in for MTurk's turkSubmitTo host: records each hand-in form."""

    received: list[tuple[str, dict]] = []

    def do_POST(self) -> None:  # noqa: N802 (http.server's name)
        length = int(self.headers.get("Content-Length", 0))
        form = {k: v[0] for k, v in parse_qs(self.rfile.read(length).decode()).items()}
        self.received.append((self.path, form))
        self.send_response(200)
        self.send_header("Content-Type", "text/html")
        self.end_headers()
        self.wfile.write(b"<p>HIT submitted</p>")

    def log_message(self, *args) -> None:
        return


@pytest.fixture(scope="module")
def turk_submit_to():
    """The stand-in's origin, running in a thread."""
    server = ThreadingHTTPServer(("127.0.0.1", free_port()), SubmitStandIn)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    yield f"http://127.0.0.1:{server.server_address[1]}"
    server.shutdown()


@pytest.fixture(scope="module")
def mturk_server(browser_study, turk_submit_to, tmp_path_factory):
    """The browser study as an MTurk HIT whose hand-in goes to the stand-in."""
    root = tmp_path_factory.mktemp("mturk")
    shutil.copytree(browser_study.configs_dir, root / "configs")
    shutil.copytree(browser_study.data_dir, root / "var")
    config = yaml.safe_load((root / "configs" / f"{BROWSER_STUDY}.yaml").read_text())
    config["recruitment"] |= {"platform": "mturk", "mturk_submit_hosts": [turk_submit_to]}
    (root / "configs" / f"{MTURK_STUDY}.yaml").write_text(yaml.safe_dump(config))
    study = SmallStudy(root / "var", root / "configs", MTURK_STUDY)
    build_bundle_of(study)
    port, db_path = free_port(), root / "study.db"
    proc = start_server(study, f"sqlite:///{db_path}", port, log=root / "server.log")
    yield study, f"http://127.0.0.1:{port}", db_path
    proc.terminate()
    proc.wait(timeout=patience(10))


def participants(db_path: Path) -> int:
    with closing(sqlite3.connect(db_path)) as db:
        return db.execute("SELECT COUNT(*) FROM participant").fetchone()[0]


def test_mturk_preview_starts_nothing_and_the_hit_is_handed_in(page, mturk_server,
                                                               turk_submit_to):
    study, url, db_path = mturk_server
    hit = f"hitId=H1&turkSubmitTo={turk_submit_to}"
    page.goto(f"{url}/s/{MTURK_STUDY}?assignmentId=ASSIGNMENT_ID_NOT_AVAILABLE&{hit}")
    assert "Accept the HIT" in page.inner_text("#mturk-preview")
    page.clock.fast_forward(5000)
    assert participants(db_path) == 0
    assignment = f"A{uuid.uuid4().hex[:12]}"
    page.goto(f"{url}/s/{MTURK_STUDY}?workerId=W{uuid.uuid4().hex[:10]}"
              f"&assignmentId={assignment}&{hit}")
    through_instructions(page)
    token = to_survey_failing_checks(page, url, study, MTURK_STUDY)
    answer_survey(page)
    visible(page, "done")
    assert receipt(db_path, token)["outcome"] == "failed_checks"  # stored before the hand-in
    with page.expect_navigation():
        page.click("#mturk-form button[type=submit]")
    assert "HIT submitted" in page.content()
    assert SubmitStandIn.received == [("/mturk/externalSubmit", {
        "assignmentId": assignment, "outcome": "failed_checks",
        "completion_code": served_codes(study)["failed_checks"]})]
