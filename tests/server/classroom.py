"""A classroom behind one address: participants that send what the page sends, with its retries.

Each participant does what frontend/static/js/app.js does from opening the link to its first
trial answered: start (retried on 429, 5xx and network errors with the page's backoff,
api.js sendUntilAcknowledged: 0.5 s doubling to 8 s), read the state, claim its tab, consent,
read the instructions and the part's introduction (writes retried the same way), then the
practice trial as chromium measured the page's requests (the state, the clip events, the
drafts, retried as DraftSaver does, heartbeats, the answer). Every 429 it meets is counted,
retried or not; one on a request the page does not retry (the state, a tab claim, the
events) would reach the page.
"""

import asyncio
import secrets
from dataclasses import dataclass, field

import httpx

from app.server.flow.sessions import SESSION_HEADER
from app.server.flow.tabs import TAB_HEADER
from tests.conftest import patience
from tests.server.flow import DEVICE, draft_body, new_id, prediction_body

MAX_DELAY_S = 8.0  # api.js sendUntilAcknowledged's maxDelayMs
NOT_RETRIED = ("state", "tab", "events")  # what the page sends once (requestJson, fetch)


@dataclass
class Pupil:
    """One participant of the classroom and what the server answered them."""

    client: httpx.AsyncClient
    study_id: str
    click_s: float = 0.0  # time between two clicks
    token: str = ""
    tab: str = field(default_factory=lambda: secrets.token_hex(8))
    requests: int = 0
    refused: list[str] = field(default_factory=list)  # "<status> <what>" of each 429
    answered: bool = False

    async def send(self, method: str, what: str, body: dict | None = None,
                   retried: bool = True) -> httpx.Response:
        """One request as the page sends it; a write is retried until acknowledged."""
        path = "/api/sessions" if what == "start" else f"/api/session/{what}"
        headers = {SESSION_HEADER: self.token, TAB_HEADER: self.tab} if self.token else {}
        for attempt in range(100):
            self.requests += 1
            try:
                r = await self.client.request(method, path, json=body, headers=headers)
            except httpx.TransportError:
                r = None
            if r is not None and r.status_code == 429:
                self.refused.append(f"429 {what}")
            if r is not None and (r.is_success or not retried or
                                  (r.status_code < 500 and r.status_code != 429)):
                return r
            await asyncio.sleep(min(MAX_DELAY_S, 0.5 * 2 ** attempt))
        raise AssertionError(f"{what}: never acknowledged")

    async def take_part(self, recruitment: dict) -> None:
        """Open the link and answer the first (practice) trial."""
        started = await self.send("POST", "start", {"study_id": self.study_id,
                                                   "recruitment": recruitment})
        assert started.status_code == 201, started.text
        self.token = started.json()["session_token"]
        await self.send("GET", "state", retried=False)
        await self.send("POST", "tab", {"tab_id": self.tab, "opened": True}, retried=False)
        state = await self.write("consent", {"agree": True, "client": DEVICE})
        state = await self.write("instructions", {})
        while state["phase"] == "world_intro":
            state = await self.write("continue", {"phase": state["phase"]})
        await self.practice_trial(state["step"])

    async def write(self, what: str, body: dict) -> dict:
        """A step's write (a fresh submission_id, retried with it); the next state."""
        r = await self.send("POST", what, {"submission_id": new_id(), **body})
        assert r.is_success, f"{what}: {r.status_code} {r.text}"
        return r.json()

    async def practice_trial(self, trial: dict) -> None:
        """As chromium measured the page (tests/e2e/test_page_requests_browser.py: 28-29 a
        trial): the state, the clip events, a draft per click and per start position done
        (20), a heartbeat every fourth draft (every 10 s at 2.5 s a click), the answer."""
        await self.send("GET", "state", retried=False)
        clips = [{"submission_id": new_id(), "kind": "clip_finished", "t_client_ms": 1.0,
                  "data": {"trial_id": trial["trial_id"], "replays": 0}}]
        await self.send("POST", "events", {"events": clips}, retried=False)
        starts, steps = len(trial["start_states"]), trial["steps_to_predict"]
        for seq in range(1, starts * (steps + 1) + 1):
            await asyncio.sleep(self.click_s)
            body = draft_body(trial, clicks=min(steps, 1 + (seq - 1) % (steps + 1)), seq=seq)
            r = await self.send("PUT", "draft", body)
            assert r.status_code == 200, r.text
            if seq % 4 == 0:
                await self.send("POST", "tab", {"tab_id": self.tab}, retried=False)
        r = await self.send("POST", "predictions", prediction_body(trial))
        assert r.status_code == 201, r.text
        self.answered = True


async def classroom(base_url: str, study_id: str, size: int, click_s: float = 0.0,
                    recruitment=None) -> list[Pupil]:
    """`size` participants at once from this machine's one address; each answers a trial."""
    limits = httpx.Limits(max_connections=size)
    async with httpx.AsyncClient(base_url=base_url, timeout=patience(60), limits=limits) as client:
        pupils = [Pupil(client, study_id, click_s) for _ in range(size)]
        await asyncio.gather(*(p.take_part(recruitment(i) if recruitment else prolific_link())
                               for i, p in enumerate(pupils)))
    return pupils


def prolific_link() -> dict:
    """A Prolific participant's URL parameters (a new person)."""
    pid = secrets.token_hex(12)
    return {"PROLIFIC_PID": pid, "STUDY_ID": "5" * 24, "SESSION_ID": pid[:10]}
