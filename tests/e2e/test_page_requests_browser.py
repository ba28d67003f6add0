"""What one participant's page sends, counted in chromium: the requests a trial costs and a
minute of the page's clock, against the per-session rate limit (issue 32 item 4).

The page runs on Playwright's fake clock, clips fast-forwarded at their own length and
THINK_MS between clicks (faster than the 2-3 s people take), so the rate is an upper bound.
Run with `-s` to see the figures docs/run/hosting.md quotes.
"""

from collections import Counter
from urllib.parse import urlparse

import pytest
from limits import parse

from app.settings import Settings
from tests.e2e.conftest import BROWSER_STUDY
from tests.e2e.pages import (
    VIEWPORT,
    answer_trial,
    fresh_recruitment,
    onward,
    through_instructions,
)

pytestmark = [pytest.mark.browser, pytest.mark.slow]
TRIALS = 4  # the practice trial and three main trials


def test_a_participants_page_stays_well_inside_its_session_budget(chromium, browser_server):
    context = chromium.new_context(viewport=VIEWPORT)
    page = context.new_page()
    sent: list[str] = []
    page.on("request", lambda r: sent.append(f"{r.method} {urlparse(r.url).path}")
            if urlparse(r.url).path.startswith("/api/session") else None)
    page.clock.install()
    page.goto(f"{browser_server.url}/s/{BROWSER_STUDY}?{fresh_recruitment()}")
    through_instructions(page)
    per_trial, minutes = [], []
    for n in range(TRIALS):
        if n:
            assert onward(page) == "trial"
        before, began_ms = len(sent), page.evaluate("Date.now()")
        answer_trial(page)
        page.wait_for_function("() => !document.querySelector('#screen-trial:not([hidden])')")
        per_trial.append(sent[before:])
        minutes.append((page.evaluate("Date.now()") - began_ms) / 60000)
    context.close()
    counts = [len(requests) for requests in per_trial]
    rate = sum(counts) / sum(minutes)
    kinds = Counter(r for requests in per_trial for r in requests)
    print(f"\nrequests per trial {counts}, {sum(minutes) / TRIALS:.2f} page-clock minutes a "
          f"trial, {rate:.1f} a minute; by route {dict(kinds)}")
    budget = parse(Settings().rate_limit_requests)
    per_minute = budget.amount * 60 / budget.get_expiry()
    assert "POST /api/session/predictions" in kinds and "PUT /api/session/draft" in kinds
    assert rate * 2 <= per_minute  # the default leaves room for the page's retries
