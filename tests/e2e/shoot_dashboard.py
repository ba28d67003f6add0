"""Screenshots of the researcher dashboard and one replay on a copy of a pilot database.

`make screens` (after `make pilot`): serves a copy of var/pilot_coarse.db, adds three
lifecycle sessions over HTTP (one declines consent, one is screened out, one lab preview
stays in progress), then Debian's chromium saves var/screens/dashboard.png, replay.png and
replay_start.png.
"""

import os
import secrets
import shutil
import subprocess
import time
import uuid
from pathlib import Path

import httpx

from app.layout import DEFAULT_DATA_DIR, Layout
from app.server.flow.recruitment import preview_key
from tests.conftest import REPO, TOMSTUDY, patience
from tests.e2e.conftest import CHROMIUM, CHROMIUM_ARGS

STUDY = "paper_study"


def serve(db: Path, port: int, token: str) -> subprocess.Popen:
    """`tomstudy serve` of the paper study on `db`; returns once it answers."""
    env = {"DATABASE_URL": f"sqlite:///{db}", "TOMSTUDY_ADMIN_TOKEN": token}
    proc = subprocess.Popen([TOMSTUDY, "serve", "--port",
                             str(port)], env={**_env(), **env}, cwd=REPO)
    for _ in range(120):
        try:
            health = httpx.get(f"http://127.0.0.1:{port}/healthz", timeout=patience(1))
            if health.status_code == 200:
                return proc
        except httpx.TransportError:
            time.sleep(0.5)
    proc.kill()
    raise SystemExit("the server did not answer")


def _env() -> dict:
    return {k: v for k, v in os.environ.items() if not k.startswith("TOMSTUDY_")}


def add_lifecycle_sessions(url: str, token: str) -> None:
    """A declined, a screened-out and an in-progress preview session, through the real API."""
    for ending, body in (("decline", {}), ("screen-out", {"reason": "window_too_small"})):
        pid = uuid.uuid4().hex[:24]
        started = httpx.post(f"{url}/api/sessions", json={"study_id": STUDY, "recruitment": {
            "PROLIFIC_PID": pid, "STUDY_ID": "5" * 24, "SESSION_ID": "s1"}}).json()
        httpx.post(f"{url}/api/session/{ending}", json={"submission_id": str(uuid.uuid4()), **body},
                   headers={"X-Session-Token": started["session_token"]}).raise_for_status()
    lab = httpx.post(f"{url}/api/sessions", json={"study_id": STUDY,
                                                  "preview": preview_key(token, STUDY)}).json()
    httpx.post(f"{url}/api/session/consent",
               json={"submission_id": str(uuid.uuid4()), "agree": True},
               headers={"X-Session-Token": lab["session_token"]}).raise_for_status()


def shoot(url: str, token: str, out: Path) -> None:
    """The dashboard (full page), then the fourth trial of the first session replayed."""
    from playwright.sync_api import sync_playwright

    with sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=str(CHROMIUM), args=CHROMIUM_ARGS)
        page = browser.new_page(viewport={"width": 1400, "height": 1000})
        page.goto(f"{url}/researcher")
        page.fill("#token-input", token)
        page.click("#token-form button")
        page.wait_for_selector("table.sessions tbody tr")
        page.wait_for_selector("svg.error-plot")
        page.screenshot(path=str(out / "dashboard.png"), full_page=True)
        page.locator("table.sessions tbody tr").nth(0).locator("button").click()
        page.wait_for_selector(".trial-row")
        page.locator(".trial-row").nth(3).locator("button").click()
        page.wait_for_selector("#replay-view:not([hidden])")
        page.locator("#replay-card").screenshot(path=str(out / "replay.png"))
        page.select_option("#replay-start", "2")
        page.locator(".replay-stage").screenshot(path=str(out / "replay_start.png"))
        browser.close()


def main(pilot_db: Path = Layout(DEFAULT_DATA_DIR).pilot_database("coarse"),
         port: int = 8766) -> None:
    """Copy the pilot database, serve it, add the lifecycle sessions, shoot."""
    if not pilot_db.exists():
        raise SystemExit(f"{pilot_db} not found: run `make pilot` first")
    out = REPO / "var" / "screens"
    out.mkdir(parents=True, exist_ok=True)
    db = out / "dashboard.db"
    db.unlink(missing_ok=True)
    shutil.copyfile(pilot_db, db)
    token = secrets.token_urlsafe(32)
    proc = serve(db, port, token)
    try:
        url = f"http://127.0.0.1:{port}"
        add_lifecycle_sessions(url, token)
        shoot(url, token, out)
    finally:
        proc.terminate()
        proc.wait(timeout=patience(10))
    print(f"wrote {out}/dashboard.png, replay.png, replay_start.png")


if __name__ == "__main__":
    main()
