"""The dashboard's time and pay line in chromium: the advertised time and pay, the finished
sessions' median by the server's clock, and the red flag once that median is more than 10% over
the advertised time."""

import asyncio
import sqlite3
from datetime import datetime, timedelta

import pytest

from app.pilot.bots import run_bots
from tests.e2e.conftest import BROWSER_STUDY, serve_study
from tests.e2e.pages import SCREENSHOTS, researcher_page

pytestmark = [pytest.mark.browser, pytest.mark.slow]

BOTS = 3


@pytest.fixture(scope="module")
def own_server(browser_study, tmp_path_factory):
    """A server of the browser study of this module's own (its sessions are made longer)."""
    yield from serve_study(browser_study, tmp_path_factory.mktemp("time-pay"))


@pytest.fixture(scope="module")
def long_sessions(own_server) -> float:
    """Bots finish the study, then each session is made to have lasted 60 minutes by moving
    its start back in the database; returns those minutes."""
    results = asyncio.run(run_bots(own_server.url, BROWSER_STUDY, "coarse", BOTS,
                                   concurrency=BOTS, seed=5))
    assert [r.error for r in results if r.error] == []
    minutes = 60.0
    with sqlite3.connect(own_server.db_path) as db:
        for row_id, ended in db.execute("SELECT id, ended_at FROM participant "
                                        "WHERE ended_at IS NOT NULL").fetchall():
            start = datetime.fromisoformat(ended) - timedelta(minutes=minutes)
            db.execute("UPDATE participant SET created_at = ? WHERE id = ?",
                       (start.isoformat(sep=" "), row_id))
    return minutes


def test_the_dashboard_flags_a_median_over_the_advertised_time(own_server, long_sessions,
                                                              chromium):
    page, errors = researcher_page(chromium, own_server.url)
    page.wait_for_selector("#time-and-pay")
    line = page.inner_text("#time-and-pay")
    assert line.startswith("Advertised ") and "(GBP 9.00 per hour)" in line
    assert f"median of {BOTS} finished participants: {long_sessions:g} min" in line
    assert "effectively GBP " in line  # the advertised pay over 60 minutes
    flag = page.inner_text("#time-overrun")
    assert "over the advertised" in flag and "underpaid" in flag
    SCREENSHOTS.mkdir(parents=True, exist_ok=True)
    page.screenshot(path=str(SCREENSHOTS / "dashboard_time_and_pay.png"), full_page=False)
    assert errors == []
    page.close()
