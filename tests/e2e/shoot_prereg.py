"""Screenshots of a preregistration page as a reader sees it in Debian's chromium.

`python -m tests.e2e.shoot_prereg HTML PREFIX`: opens the file HTML (`tomstudy prereg`'s
preregistration.html) with the network blocked, so anything the page fetched would be missing,
and writes var/screenshots/PREFIX_top.png (the first screen) and PREFIX_full.png (the page).
"""

import sys
from pathlib import Path

from playwright.sync_api import sync_playwright

from tests.conftest import REPO
from tests.e2e.conftest import CHROMIUM, CHROMIUM_ARGS

OUT = REPO / "var" / "screenshots"


def shoot_prereg(html: Path, prefix: str) -> list[str]:
    """Shoot the page; the URLs it tried to fetch (none for a self-contained page)."""
    OUT.mkdir(parents=True, exist_ok=True)
    fetched: list[str] = []
    with sync_playwright() as playwright:
        browser = playwright.chromium.launch(executable_path=str(CHROMIUM), args=CHROMIUM_ARGS)
        page = browser.new_page(viewport={"width": 1280, "height": 900})
        page.route("**/*", lambda route: route.continue_() if route.request.url.startswith(
            "file:") else (fetched.append(route.request.url), route.abort()))
        page.goto(Path(html).resolve().as_uri())
        page.screenshot(path=str(OUT / f"{prefix}_top.png"))
        page.screenshot(path=str(OUT / f"{prefix}_full.png"), full_page=True)
        browser.close()
    return fetched


if __name__ == "__main__":
    tried = shoot_prereg(Path(sys.argv[1]), sys.argv[2])
    print(f"wrote {OUT / (sys.argv[2] + '_top.png')} and _full.png; fetched: {tried or 'nothing'}")
