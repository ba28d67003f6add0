"""Screenshots of a study's instructions page with its demo, at fixed moments of the demo.

`python -m tests.e2e.shoot_instructions URL STUDY PREFIX`: opens URL/s/STUDY as a new
Prolific participant in Debian's chromium on a paused fake clock, agrees to the consent and
writes var/screens/PREFIX_{clip,own_start,moved_start}.png: the demo mid-clip, predicting
from the robot's own start, and from the last start it is moved to. Two servers of the same
study (two versions of the code) shot this way give pictures to compare pixel for pixel.
"""

import sys
import time

from tests.conftest import REPO
from tests.e2e.conftest import CHROMIUM, CHROMIUM_ARGS
from tests.e2e.pages import VIEWPORT, fresh_recruitment, visible

OUT = REPO / "var" / "screens"
# fake-clock moments of the demo (demo.js: 8 steps of 0.35 s and a 0.7 s pause, then 3 clicks
# 0.9 s apart per start, 1.4 s between starts): mid-clip, the own start's third click placed,
# the last moved start's second click placed
DEMO_MOMENTS_MS = {"clip": 1600, "own_start": 6500, "moved_start": 13600}


def shoot_instructions(page, prefix: str) -> None:
    """At the consent screen: agree, then shoot the instructions at each DEMO_MOMENTS_MS (the
    page's clock installed and paused); leaves the page on the instructions."""
    visible(page, "consent")
    page.check("#consent-check")
    page.click("#consent-agree")
    visible(page, "instructions")
    page.wait_for_timeout(100)  # the demo's first frame
    elapsed = 0
    for name, moment in DEMO_MOMENTS_MS.items():
        page.clock.run_for(moment - elapsed)
        elapsed = moment
        page.screenshot(path=str(OUT / f"{prefix}_{name}.png"), full_page=True)


def new_participant_page(browser, url: str, study_id: str):
    """A new Prolific participant's page of `study_id` on a paused fake clock (in its own
    context: close the page's context when done)."""
    context = browser.new_context(viewport=VIEWPORT)
    context.clock.install()
    context.clock.pause_at(int(time.time() * 1000) + 1000)
    page = context.new_page()
    page.goto(f"{url}/s/{study_id}?{fresh_recruitment()}")
    return page


def main(url: str, study_id: str, prefix: str) -> None:
    """Shoot the instructions of `study_id` served at `url`."""
    from playwright.sync_api import sync_playwright

    OUT.mkdir(parents=True, exist_ok=True)
    with sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=str(CHROMIUM), args=CHROMIUM_ARGS)
        shoot_instructions(new_participant_page(browser, url, study_id), prefix)
        browser.close()
    print(f"wrote {prefix}_{{{','.join(DEMO_MOMENTS_MS)}}}.png into {OUT}")


if __name__ == "__main__":
    main(*sys.argv[1:4])
