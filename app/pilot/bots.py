"""Pilot participants: bots that take the study through the same HTTP flow as a browser.

Each bot starts a session with Prolific-style URL parameters, consents, reads the
instructions, answers the practice and every trial (clicked positions from
app/observers/inverse_planning.py, a uuid4 per write, telemetry events), fills in the survey and
reaches the completion code. Loops are bounded and every request has a timeout; a
failed request is retried with the same submission id (the server stores it once).

Presets: the inverse-planning observers of app/observers/inverse_planning.py: coarse (infers
the robot's target lane or goal and moves the way it moves), coarse_relative (the same,
reading lanes as merge left/keep/right), precise (the world's own next moves) and
random; their parameters come from study_configs/observers.yaml. The payload never holds the
true next moves, nor the bank's trial id (the browser sees a random per-session id), so a
precise bot, being a simulated participant, finds its trial in the study's trial bank on
disk by the segment it was shown and reads `policy_actions` (which build-trials computed
with the world's `robot_policy_actions`); it must therefore run where var/trials/ is.

Timing: bots run faster than people. They report a simulated participant's clock in
`click_times_ms`, `shown_at_ms` and `submitted_at_ms` (per-click think times drawn from
a log-normal with a median of THINK_MEDIAN_S), so a bot's trials look like a person's
to the too-fast exclusion rule instead of all being excluded.
"""

import asyncio
import hashlib
import json
import time
import uuid
from dataclasses import dataclass, field
from pathlib import Path

import httpx
import numpy as np

from app.core.files import read_bytes
from app.observers.inverse_planning import PRESETS, predict
from app.server.flow.plan import PART_PHASES, TRIAL_PHASES, Phase
from app.server.flow.sessions import SESSION_HEADER, SESSION_PATH

THINK_MEDIAN_S = 2.5
MAX_STEPS = 200  # no study has this many phases; a bot that gets here is stuck
RETRIES = 3


class BotError(RuntimeError):
    """A bot could not finish: the message says at which phase and why."""


@dataclass
class BotResult:
    """What one bot did."""

    index: int
    participant_id: str | None = None
    completion_code: str | None = None
    trials: int = 0
    requests: int = 0
    retries: int = 0
    error: str | None = None
    elapsed_s: float = 0.0
    phases: list[str] = field(default_factory=list)


def segment_key(segment_positions: list) -> str:
    """A trial's fingerprint from what the browser is shown: its segment's positions."""
    return hashlib.sha256(json.dumps(segment_positions).encode()).hexdigest()


def load_policy_actions(bank_path: Path) -> dict[str, np.ndarray]:
    """segment_key -> the world's own next actions [K, n, 2] from each start state."""
    bank = json.loads(read_bytes(bank_path))  # a bundle's bank is gzipped
    return {segment_key(t["segment"]["positions"]): np.asarray(t["policy_actions"],
                                                               dtype=np.float64)
            for w in bank["worlds"].values() for t in w["trials"]}


def check_preset(preset: str) -> None:
    """BotError unless `preset` is an observer preset."""
    if preset not in PRESETS:
        raise BotError(f"kind: unknown bot kind {preset!r}; choose one of {', '.join(PRESETS)}")


def choose_clicks(preset: str, payload: dict, rng: np.random.Generator,
                  policy: dict[str, np.ndarray] | None) -> np.ndarray:
    """The bot's clicked positions [K, n, 2] for one trial payload."""
    check_preset(preset)
    actions = (policy or {}).get(segment_key(payload["segment"]["positions"]))
    if preset == "precise" and actions is None:
        raise BotError(f"precise bot: no policy actions for trial {payload['trial_id']}")
    return predict(preset, payload, rng, actions)


def survey_answers(step: dict, rng: np.random.Generator) -> dict:
    """A plausible answer to every survey question in the state's step."""
    questions = step.get("questions") or step.get("survey") or []
    answers: dict = {}
    for q in questions:
        if q.get("kind") == "likert":
            answers[q["key"]] = int(rng.integers(q.get("scale_min", 1), q.get("scale_max", 7) + 1))
        elif q.get("kind") == "choice" and q.get("options"):
            answers[q["key"]] = q["options"][int(rng.integers(len(q["options"])))]
        else:
            answers[q["key"]] = "I watched where the robot was heading."
    return answers


class Bot:
    """One simulated participant talking to the server over HTTP."""

    def __init__(self, client: httpx.AsyncClient, study_id: str, preset: str, index: int,
                 seed: int, policy: dict[str, np.ndarray] | None) -> None:
        self.client = client
        self.study_id = study_id
        self.preset = preset
        self.rng = np.random.default_rng([seed, index])
        self.policy = policy
        self.result = BotResult(index=index)
        self.clock_ms = 0.0  # the simulated participant's clock
        # a Prolific-shaped study id; a study config that pins its real one refuses bots
        self.prolific_study_id = hashlib.sha256(f"pilot:{study_id}".encode()).hexdigest()[:24]
        self.token = ""

    async def request(self, method: str, path: str, body: dict | None = None) -> dict:
        """One request, retried on transport errors and 5xx with the same body."""
        for attempt in range(RETRIES + 1):
            self.result.requests += 1
            try:
                headers = {SESSION_HEADER: self.token} if self.token else None
                response = await self.client.request(method, path, json=body, headers=headers)
            except httpx.TransportError as err:
                if attempt == RETRIES:
                    raise BotError(f"{method} {path}: {type(err).__name__}: {err}") from err
            else:
                if response.status_code < 400:
                    return response.json()
                if response.status_code < 500 or attempt == RETRIES:
                    raise BotError(f"{method} {path}: {response.status_code} {response.text[:300]}")
            self.result.retries += 1
            await asyncio.sleep(0.2 * (attempt + 1))
        raise BotError(f"{method} {path}: gave up")

    async def run(self) -> BotResult:
        """Take part from session start to completion code."""
        started = time.perf_counter()
        try:
            state = await self.start()
            for _ in range(MAX_STEPS):
                self.result.phases.append(state["phase"])
                if state["phase"] == Phase.DONE:
                    self.result.completion_code = (state.get("step") or {}).get("completion_code")
                    break
                state = await self.answer(state)
            else:
                raise BotError(f"did not finish within {MAX_STEPS} steps")
        except BotError as err:
            self.result.error = str(err)
        self.result.elapsed_s = time.perf_counter() - started
        return self.result

    async def start(self) -> dict:
        """POST /api/sessions with Prolific-style parameters, then read the state."""
        body = {"study_id": self.study_id,
                "recruitment": {"PROLIFIC_PID": uuid.uuid4().hex[:24],
                                "STUDY_ID": self.prolific_study_id,
                                "SESSION_ID": uuid.uuid4().hex}}
        session = await self.request("POST", "/api/sessions", body)
        self.token = session["session_token"]
        self.result.participant_id = session["participant_id"]
        return await self.request("GET", f"{SESSION_PATH}/state")

    async def answer(self, state: dict) -> dict:
        """Do what the current phase asks; returns the next state."""
        phase, base = state["phase"], SESSION_PATH
        if phase == Phase.CONSENT:
            client = {"screen_w": 1600, "screen_h": 900, "touch_only": False,
                      "user_agent": f"tomstudy-bot/{self.preset}"}
            return await self.request("POST", f"{base}/consent",
                                      self.write(agree=True, client=client))
        if phase == Phase.INSTRUCTIONS:
            return await self.request("POST", f"{base}/instructions", self.write())
        if phase in PART_PHASES:
            return await self.request("POST", f"{base}/continue", self.write(phase=phase))
        if phase in TRIAL_PHASES:
            return await self.predict(state["step"])
        if phase == Phase.SURVEY:
            answers = survey_answers(state.get("step") or {}, self.rng)
            return await self.request("POST", f"{base}/survey", self.write(answers=answers))
        raise BotError(f"unknown phase {phase!r}")

    def write(self, **fields) -> dict:
        """A write body with a fresh client-made UUID."""
        return {"submission_id": str(uuid.uuid4()), **fields}

    async def predict(self, payload: dict) -> dict:
        """Watch the clip (telemetry), click 3 moves from each start state and submit."""
        base = SESSION_PATH
        shown_at = self.clock_ms
        clip_s = len(payload["examples"]) * 4.0 + 3.0
        self.clock_ms += clip_s * 1000
        await self.request("POST", f"{base}/events", {"events": [
            self.event("clip_finished", {"trial_id": payload["trial_id"], "replays": 0}),
            self.event("resize", {"w": 1600, "h": 900}),
        ]})
        clicks = choose_clicks(self.preset, payload, self.rng, self.policy)
        think = self.rng.lognormal(np.log(THINK_MEDIAN_S), 0.4, size=clicks.shape[:2]) * 1000
        click_times = self.clock_ms - shown_at + np.cumsum(think.ravel()).reshape(think.shape)
        self.clock_ms = shown_at + float(click_times[-1, -1]) + 800.0
        body = self.write(trial_id=payload["trial_id"], points=np.round(clicks, 4).tolist(),
                          click_times_ms=np.round(click_times, 1).tolist(),
                          shown_at_ms=round(shown_at, 1), submitted_at_ms=round(self.clock_ms, 1),
                          replays=0)
        self.result.trials += 1
        return await self.request("POST", f"{base}/predictions", body)

    def event(self, kind: str, data: dict) -> dict:
        """One telemetry event at the simulated clock."""
        return {"submission_id": str(uuid.uuid4()), "kind": kind,
                "t_client_ms": round(self.clock_ms, 1), "data": data}


async def run_bots(url: str, study_id: str, preset: str, n: int, concurrency: int = 8,
                   seed: int = 0, bank_path: Path | None = None, timeout_s: float = 30.0,
                   progress=None, transport: httpx.AsyncBaseTransport | None = None
                   ) -> list[BotResult]:
    """Run `n` bots of one preset against the server at `url`, at most `concurrency` at once."""
    check_preset(preset)
    policy = load_policy_actions(bank_path) if preset == "precise" else None
    limits = httpx.Limits(max_connections=concurrency, max_keepalive_connections=concurrency)
    gate = asyncio.Semaphore(concurrency)
    async with httpx.AsyncClient(base_url=url, timeout=timeout_s, limits=limits,
                                 transport=transport) as client:

        async def one(index: int) -> BotResult:
            async with gate:
                result = await Bot(client, study_id, preset, index, seed, policy).run()
            if progress is not None:
                progress.update(1)
            return result

        return list(await asyncio.gather(*(one(i) for i in range(n))))


def run_pilot(url: str, study_id: str, preset: str, n: int, concurrency: int, seed: int,
              bank_path: Path | None) -> list[BotResult]:
    """Run the bots with a progress bar, print a summary; returns the bots that failed."""
    from tqdm import tqdm

    started = time.perf_counter()
    with tqdm(total=n, desc=f"{preset} bots", unit="bot") as bar:
        results = asyncio.run(run_bots(url, study_id, preset, n, concurrency, seed, bank_path,
                                       progress=bar))
    failed = [r for r in results if r.error]
    wall = time.perf_counter() - started
    done = sum(1 for r in results if r.completion_code)
    print(f"{done}/{n} bots completed in {wall:.1f} s; {sum(r.trials for r in results)} trials, "
          f"{sum(r.requests for r in results)} requests, {sum(r.retries for r in results)} "
          f"retries, {len(failed)} failed")
    for r in failed[:10]:
        print(f"  bot {r.index}: {r.error}")
    return failed
