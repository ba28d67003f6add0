"""Participants arriving open-loop through the whole study at rising rates until a route's p99
passes 100 ms: p50, p99 and requests/s per route beside a bare endpoint's, and what saturates.

Each participant, from its own loopback address (127.1.x.y), does what the page does
(frontend/static/js/app.js and its modules): starts a session, reads the state, claims its tab and
then sends a tab heartbeat every `heartbeat_s` the server hands out; consents, reads the
instructions, goes on from each part's screens (world_intro, practice_over), and in every
practice and main trial watches the clips (the player's own timing), posts the clip_finished
event a second later (the page's telemetry flush), saves a draft on "Make predictions", after
every click and on every next start state (PUT .../draft, one at a time), and submits; the
survey, then done, where the tab is closed (POST .../tab/release). Writes name the tab
(X-Tab-Id) as the page's do. The phases answered are checked against app/server/flow/plan.py's
Phase before anything runs, and a participant meeting a phase the benchmark cannot answer
fails the whole run (exit code 1, the phase named).

Arrivals are a Poisson process (open loop: a participant arrives whether or not the server
has answered the ones before); each request opens its own connection (a browser idle for
seconds finds uvicorn's 5 s keep-alive closed). Beside them a probe GETs a path no route
serves (`GET bare`, --bare-per-s): the server's own cost of a request under the same load.

Think times are a person's (10-20 s over the consent, 20-40 s over the instructions, 2.5 s a
click as app/study/estimate.py's median pace, the clips as the player plays them: about 20
minutes a participant) times --think-scale, and the heartbeat interval shrinks with them, so
a participant sends the same requests in a shorter time. By Little's law the requests per
second at steady state are arrival rate x requests per participant whatever the scale; what
the scale changes is how many sessions are live at once (rate x session length), so the
server holds fewer sessions and a smaller database than people at that rate would give it.
The per-session rate limit is scaled by 1 / think-scale for the same reason (the limiter
still runs, bounding the same share of a participant's pace); the start limit is the default.

Each step (one rate, a fresh server and database, the study's session cap lifted so the
server, not the cap, is measured) warms up until its first participant is done (steady
state: as many finish as arrive), then measures --step-s. During the window it samples the
CPU of the server's processes, of PostgreSQL's and of this client (/proc/<pid>/stat; the
client shares the machine), PostgreSQL's waits (pg_stat_activity: advisory and other lock
waits, WAL and other IO waits) and its WAL writes and fsyncs (pg_stat_wal), and prints a
verdict per step. One table per deployment, then "holds N arrivals/s (M requests/s)".

    .venv/bin/python benchmarks/study_arrivals.py --database sqlite --workers 1
    .venv/bin/python benchmarks/study_arrivals.py --database postgres --workers 1 2 4
    .venv/bin/python benchmarks/study_arrivals.py --participants 5   # a short whole-flow check
"""

import argparse
import asyncio
import json
import math
import secrets
import shutil
import sys
import tempfile
import time
from collections import defaultdict
from contextlib import contextmanager, suppress
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import yaml

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from app.pilot.bots import survey_answers  # noqa: E402
from app.server.flow.plan import Phase  # noqa: E402
from app.server.flow.sessions import SESSION_HEADER, SESSION_PATH  # noqa: E402
from app.server.flow.tabs import TAB_HEADER  # noqa: E402
from app.settings import Settings  # noqa: E402
from app.study.estimate import MEDIAN_PACE, player_timing  # noqa: E402
from benchmarks._rawhttp import RawClient  # noqa: E402
from benchmarks._saturation import (  # noqa: E402
    Profile,
    Sampler,
    Usage,
    busiest_worker,
    time_wal_io,
    verdict,
)  # noqa: E402
from benchmarks.study_load import drafts, event, recruitment_params, write  # noqa: E402
from tests.conftest import (  # noqa: E402
    REPO,
    SmallStudy,
    free_port,
    fresh_database,
    start_cluster,
    start_server,
    stop_server,
)
from tests.server.flow import DEVICE, prediction_body  # noqa: E402

STUDY = "paper_study"
PEAK_PER_S = 22 / 120  # the paper study's target, all arriving within two minutes
BARE = "GET bare"
ROUTES = ("POST sessions", "GET state", "POST tab", "POST consent", "POST instructions",
          "POST continue", "POST events", "PUT draft", "POST predictions", "POST survey",
          "POST tab/release")
P99_LIMIT_MS = 100.0
THINK_S = {Phase.CONSENT: (10, 20), Phase.INSTRUCTIONS: (20, 40), Phase.WORLD_INTRO: (10, 20),
           Phase.PRACTICE_OVER: (5, 10), Phase.SURVEY: (30, 60)}
CLICK_S = (0.5 * MEDIAN_PACE.seconds_per_click, 1.5 * MEDIAN_PACE.seconds_per_click)
FEEDBACK_S = (1, 3)  # per start state, reading a practice trial's feedback
BARE_PER_S = 5.0
TELEMETRY_FLUSH_S = 1.0  # the page posts its events a second after the last one (telemetry.js)
PLAYER = player_timing()
SERVER_READY_S = 300  # each worker verifies the bundle on start: slow on a busy machine


class UnansweredPhase(RuntimeError):
    """The server asked for a phase this benchmark has no answer for."""

    def __init__(self, phase: str) -> None:
        super().__init__(f"phase {phase}: the benchmark cannot answer it (benchmarks/"
                         "study_arrivals.py HANDLERS); no participant would get past it")
        self.phase = phase


class RequestRefused(RuntimeError):
    """A request answered outside 2xx, or not at all: this participant stops."""


def check_phases(handlers: dict) -> None:
    """UnansweredPhase naming every phase of app/server/flow/plan.py without a handler."""
    missing = [phase.value for phase in Phase if phase is not Phase.DONE and phase not in handlers]
    if missing:
        raise UnansweredPhase(", ".join(missing))


def clip_seconds(trial: dict) -> float:
    """The trial's examples and segment played once, as the page's player times them."""
    clips = [*trial["examples"], trial["segment"]]
    return sum((len(c["positions"]) - 1) * PLAYER.step_s + PLAYER.pause_between_clips_s
               for c in clips)


def page_drafts(trial: dict, body: dict) -> list[dict]:
    """The drafts the page saves while `body` is placed: on "Make predictions", after every
    click and on every next start state (trial.js TrialScreen.changed), numbered by `seq`."""
    per_click = drafts(trial, body)
    steps, blank = trial["steps_to_predict"], [[] for _ in body["points"]]
    saved = [per_click[0] | {"points": blank, "click_times_ms": blank}]
    for i in range(len(body["points"])):
        saved += per_click[i * steps:(i + 1) * steps]
        if i + 1 < len(body["points"]):
            saved.append(saved[-1] | {"index": i + 1})
    return [draft | {"seq": seq, "replays": body["replays"]}
            for seq, draft in enumerate(saved, start=1)]


class Arrival:
    """One participant: its own address and tab, think times, every request recorded."""

    def __init__(self, crowd: "Crowd", index: int) -> None:
        self.crowd = crowd
        self.source = f"127.1.{index // 250}.{index % 250 + 1}"
        self.rng = np.random.default_rng([crowd.seed, index])
        self.tab_id = f"bench-{secrets.token_hex(8)}"
        self.headers: dict[str, str] = {}
        self.phases: list[str] = []
        self.refused: list[str] = []
        self.requests = 0
        self.started_at, self.ended_at = time.perf_counter(), None
        self.clock_s = self.next_beat_s = 0.0  # the person's own time (unscaled think times)
        self.beat_every_s = math.inf
        self.beats: set[asyncio.Task] = set()

    async def call(self, route: str, path: str, body: dict | None = None,
                   write_: bool = False) -> dict:
        """One timed request on a new connection; RequestRefused outside 2xx."""
        client = RawClient(self.crowd.port, self.source)
        headers = self.headers | ({TAB_HEADER: self.tab_id} if write_ else {})
        t0 = time.perf_counter()
        try:
            status, payload = await client.request(route.split()[0], path, body, headers)
        except (ConnectionError, OSError, asyncio.IncompleteReadError) as err:
            status, payload = 0, repr(err).encode()
        finally:
            client.close()
        self.crowd.record(route, t0)
        self.requests += 1
        if not 200 <= status < 300:
            self.refused.append(f"{route}: {status} {payload[:160]!r}")
            raise RequestRefused(self.refused[-1])
        return json.loads(payload) if payload else {}

    async def think(self, seconds: tuple[float, float]) -> None:
        """A person's pause drawn from `seconds`."""
        await self.spend(self.rng.uniform(*seconds))

    async def spend(self, seconds: float) -> None:
        """`seconds` of the person's time (asleep for them times the think scale), with the
        tab's heartbeats that fall due meanwhile sent beside the flow."""
        await asyncio.sleep(seconds * self.crowd.think_scale)
        self.clock_s += seconds
        while self.clock_s >= self.next_beat_s:
            self.next_beat_s += self.beat_every_s
            beat = asyncio.create_task(self.heartbeat())
            self.beats.add(beat)
            beat.add_done_callback(self.beats.discard)

    async def run(self) -> None:
        """From session start to done, with the tab's heartbeats beside; a refusal stops it."""
        try:
            started = await self.call("POST sessions", "/api/sessions", {
                "study_id": self.crowd.study_id, "recruitment": recruitment_params("b" * 24)})
            self.headers = {SESSION_HEADER: started["session_token"]}
            state = await self.call("GET state", f"{SESSION_PATH}/state")
            claimed = await self.call("POST tab", f"{SESSION_PATH}/tab", self.claim(opened=True))
            self.beat_every_s = self.next_beat_s = claimed["heartbeat_s"]
            while state["phase"] != Phase.DONE:
                self.phases.append(state["phase"])
                state = await self.answer(state)
            self.phases.append(Phase.DONE.value)
            self.ended_at = time.perf_counter()
            await self.call("POST tab/release", f"{SESSION_PATH}/tab/release",
                            {"tab_id": self.tab_id})  # the page's goodbye when it is closed
            self.crowd.first_done.set()
        except RequestRefused:
            pass
        finally:
            for beat in self.beats:
                beat.cancel()

    async def answer(self, state: dict) -> dict:
        """Do what the phase asks after a person's time on it; returns the next state."""
        handler = self.crowd.handlers.get(state["phase"])
        if handler is None:
            raise UnansweredPhase(state["phase"])
        return await handler(self, state)

    def claim(self, opened: bool) -> dict:
        """A tab claim as the page sends it (on load with `opened`, then as a heartbeat)."""
        return {"tab_id": self.tab_id, "takeover": False, "opened": opened,
                "t_client_ms": time.time() * 1000}

    async def heartbeat(self) -> None:
        """The live tab's claim (the page's every `heartbeat_s`); a refusal is kept."""
        with suppress(RequestRefused):
            await self.call("POST tab", f"{SESSION_PATH}/tab", self.claim(opened=False))

    async def send(self, phase: Phase, body: dict, route: str = "") -> dict:
        """After the phase's think time, the write the page sends on its button."""
        await self.think(THINK_S[phase])
        what = route or phase.value
        return await self.call(f"POST {what}", f"{SESSION_PATH}/{what}", body, write_=True)

    async def consent(self, state: dict) -> dict:
        return await self.send(Phase.CONSENT, write(agree=True, client=DEVICE))

    async def instructions(self, state: dict) -> dict:
        return await self.send(Phase.INSTRUCTIONS, write())

    async def go_on(self, state: dict) -> dict:
        phase = Phase(state["phase"])
        return await self.send(phase, write(phase=phase.value), route="continue")

    async def survey(self, state: dict) -> dict:
        answers = survey_answers(state.get("step") or {}, self.rng)
        return await self.send(Phase.SURVEY, write(answers=answers))

    async def trial(self, state: dict) -> dict:
        """Watch the clips, post their event, place every click with its draft, submit."""
        trial = state["step"]
        await self.spend(clip_seconds(trial) + TELEMETRY_FLUSH_S)
        await self.call("POST events", f"{SESSION_PATH}/events", {"events": [event(
            "clip_finished", {"trial_id": trial["trial_id"], "replays": 0})]})
        body = prediction_body(trial) | {"replays": 0}
        for draft in page_drafts(trial, body):
            await self.think(CLICK_S)
            await self.call("PUT draft", f"{SESSION_PATH}/draft", draft, write_=True)
        await self.think(CLICK_S)
        answered = await self.call("POST predictions", f"{SESSION_PATH}/predictions", body,
                                   write_=True)
        if trial.get("feedback"):
            for _ in trial["start_states"]:
                await self.think(FEEDBACK_S)
        return answered


HANDLERS = {Phase.CONSENT: Arrival.consent, Phase.INSTRUCTIONS: Arrival.instructions,
            Phase.WORLD_INTRO: Arrival.go_on, Phase.PRACTICE: Arrival.trial,
            Phase.PRACTICE_OVER: Arrival.go_on, Phase.TRIAL: Arrival.trial,
            Phase.SURVEY: Arrival.survey}


class Crowd:
    """Poisson arrivals against one server: each request's start and latency by route; the
    first failure that is the benchmark's (an unanswered phase, a bug) ends the run."""

    def __init__(self, port: int, study_id: str, rate: float, think_scale: float, seed: int,
                 handlers: dict | None = None) -> None:
        self.port, self.study_id, self.rate = port, study_id, rate
        self.think_scale, self.seed = think_scale, seed
        self.handlers = HANDLERS if handlers is None else handlers
        self.latencies: dict[str, list[tuple[float, float]]] = defaultdict(list)
        self.people: list[Arrival] = []
        self.tasks: list[asyncio.Task] = []
        self.first_done = asyncio.Event()
        self.failed = asyncio.Event()
        self.failure: BaseException | None = None

    def record(self, route: str, t0: float) -> None:
        """Keep one request's start and latency (seconds)."""
        self.latencies[route].append((t0, time.perf_counter() - t0))

    async def arrive(self, count: int | None = None) -> None:
        """Arrivals at `rate` (`count` of them, or until cancelled)."""
        gaps = np.random.default_rng(self.seed)
        while count is None or len(self.people) < count:
            person = Arrival(self, len(self.people))
            self.people.append(person)
            self.watch(asyncio.create_task(person.run()))
            await asyncio.sleep(gaps.exponential(1 / self.rate))

    def watch(self, task: asyncio.Task) -> None:
        """Keep `task`; its exception, if any, fails the run."""
        self.tasks.append(task)
        task.add_done_callback(self.check)

    def check(self, task: asyncio.Task) -> None:
        if task.cancelled() or task.exception() is None or self.failure is not None:
            return
        self.failure = task.exception()
        self.failed.set()

    async def until(self, awaitable, timeout_s: float | None = None) -> bool:
        """Wait for `awaitable` (False after `timeout_s`); raise the run's failure if one
        comes first."""
        waiting = asyncio.ensure_future(awaitable)
        failed = asyncio.create_task(self.failed.wait())
        done, _ = await asyncio.wait({waiting, failed}, timeout=timeout_s,
                                     return_when=asyncio.FIRST_COMPLETED)
        for task in (waiting, failed):
            task.cancel()
        await asyncio.gather(waiting, failed, return_exceptions=True)
        if self.failure is not None:
            raise self.failure
        return waiting in done

    async def probe(self, per_s: float) -> None:
        """GET a path no route serves, `per_s` times a second, until cancelled."""
        while True:
            client = RawClient(self.port, "127.2.0.1")
            t0 = time.perf_counter()
            try:
                await client.request("GET", "/no-such-route")
                self.record(BARE, t0)
            except (ConnectionError, OSError, asyncio.IncompleteReadError):
                pass
            finally:
                client.close()
            await asyncio.sleep(1 / per_s)

    async def close(self) -> None:
        """Stop every participant and the probe."""
        for task in self.tasks:
            task.cancel()
        await asyncio.gather(*self.tasks, return_exceptions=True)

    def live_at(self, t: float) -> int:
        """Sessions started and not yet done at `t`."""
        return sum(p.started_at <= t and (p.ended_at is None or p.ended_at > t)
                   for p in self.people)


@dataclass
class StepResult:
    """One rate's window: the crowd, the window's bounds and what was sampled in it."""

    rate: float
    crowd: Crowd
    start: float
    end: float
    usage: Usage | None = None
    warm: bool | None = True  # a participant finished before the window (None: a cohort)
    profile: str = ""  # where one worker's time went (--profile)
    stats: dict = field(default_factory=dict)  # route -> (n, per s, p50 ms, p99 ms)

    def summarise(self) -> None:
        """Per route: requests started inside the window, their rate and percentiles."""
        seconds = self.end - self.start
        for route, rows in self.crowd.latencies.items():
            ms = np.asarray([dt for t0, dt in rows if self.start <= t0 < self.end]) * 1000
            if len(ms):
                p50, p99 = np.percentile(ms, [50, 99])
                self.stats[route] = (len(ms), len(ms) / seconds, p50, p99)

    def worst_p99(self) -> float:
        """The largest participant route's p99 (ms)."""
        return max((s[3] for r, s in self.stats.items() if r != BARE), default=math.inf)

    def requests_per_s(self) -> float:
        """Every participant request a second (the bare probe left out)."""
        return sum(s[1] for r, s in self.stats.items() if r != BARE)


async def measure_step(port: int, rate: float, args: argparse.Namespace, sampler: Sampler,
                       profile_to: Path | None = None) -> StepResult:
    """Arrivals at `rate`: warm up until one is done, then the --step-s window, sampled (and
    one worker profiled into `profile_to`)."""
    crowd = Crowd(port, STUDY, rate, args.think_scale, args.seed)
    crowd.watch(asyncio.create_task(crowd.probe(args.bare_per_s)))
    arriving = asyncio.create_task(crowd.arrive())
    try:
        warm = await crowd.until(crowd.first_done.wait(), args.warmup_max_s)
        start = time.perf_counter()
        sampler.start()
        profile = (Profile(busiest_worker(sampler.server_pid), args.step_s, profile_to)
                   if profile_to else None)
        await crowd.until(asyncio.sleep(args.step_s))
        end = time.perf_counter()
        usage = sampler.stop()
    finally:
        arriving.cancel()
        await crowd.close()
    step = StepResult(rate, crowd, start, end, usage, warm)
    if profile is not None:
        step.profile = await asyncio.to_thread(profile.top)
    step.summarise()
    return step


async def run_cohort(port: int, count: int, rate: float, think_scale: float, timeout_s: float,
                     seed: int = 0, handlers: dict | None = None) -> StepResult:
    """`count` participants arriving at `rate`, waited for until every one stops."""
    crowd = Crowd(port, STUDY, rate, think_scale, seed, handlers)
    probe = asyncio.create_task(crowd.probe(BARE_PER_S))
    start = time.perf_counter()
    try:
        await crowd.until(crowd.arrive(count), timeout_s)
        people = asyncio.gather(*crowd.tasks, return_exceptions=True)
        if not await crowd.until(people, timeout_s):
            raise TimeoutError(f"participants not done within {timeout_s:.0f} s")
    finally:
        probe.cancel()
        await crowd.close()
    step = StepResult(rate, crowd, start, time.perf_counter(), warm=None)
    step.summarise()
    return step


def study_without_cap(root: Path) -> SmallStudy:
    """The paper study with its live-session cap lifted, in a copy of study_configs (its
    shipped bundle served as `tomstudy serve` serves it) and an empty data dir."""
    configs = root / "configs"
    shutil.copytree(REPO / "study_configs", configs, dirs_exist_ok=True)
    path = configs / f"{STUDY}.yaml"
    config = yaml.safe_load(path.read_text())
    config["max_live_sessions_per_target"] = 1e6
    path.write_text(yaml.safe_dump(config))
    (root / "var").mkdir(exist_ok=True)
    return SmallStudy(root / "var", configs, STUDY)


def scaled_limit(limit: str, think_scale: float) -> str:
    """A rate limit ("120/minute") with its count divided by `think_scale`."""
    count, _, per = limit.partition("/")
    return f"{math.ceil(int(count) / think_scale)}/{per}" if count else limit


class Deployment:
    """A database and worker count: a fresh server (and database) per step."""

    def __init__(self, args: argparse.Namespace, root: Path, workers: int) -> None:
        self.args, self.root, self.workers = args, root, workers
        self.study = study_without_cap(root)
        self.name = f"{args.database}, {workers} worker(s)"

    def serve(self, tag: str):
        """Start the server on a fresh database; (process, port, database URL)."""
        port, defaults = free_port(), Settings()
        url = (fresh_database(self.args.postgres_url, f"w{self.workers}_{tag}")
               if self.args.database == "postgres" else f"sqlite:///{self.root}/{tag}.db")
        proc = start_server(
            self.study, url, port, workers=self.workers, log=self.root / f"{tag}.log",
            ready_s=SERVER_READY_S,
            TOMSTUDY_RATE_LIMIT_STARTS=defaults.rate_limit_starts,
            TOMSTUDY_RATE_LIMIT_REQUESTS=scaled_limit(defaults.rate_limit_requests,
                                                      self.args.think_scale))
        return proc, port, url

    def step(self, rate: float) -> StepResult:
        """One rate on a fresh server, sampled."""
        proc, port, url = self.serve(f"r{rate:g}".replace(".", "_"))
        sampler = Sampler(proc.pid, url if self.args.database == "postgres" else None)
        profile_to = self.root / f"profile_r{rate:g}.txt" if self.args.profile else None
        try:
            return asyncio.run(measure_step(port, rate, self.args, sampler, profile_to))
        finally:
            sampler.close()
            stop_server(proc)

    def sweep(self) -> list[StepResult]:
        """Rising rates until a route's p99 passes the limit."""
        steps = []
        for rate in self.args.rates:
            steps.append(self.step(rate))
            print(f"  {self.name}, {rate:g} arrivals/s: worst route p99 "
                  f"{steps[-1].worst_p99():.1f} ms", file=sys.stderr, flush=True)
            if steps[-1].worst_p99() >= P99_LIMIT_MS:
                break
        return steps


def print_table(title: str, steps: list[StepResult], think_scale: float, workers: int) -> None:
    """One table of every step's routes, then each step's load and saturation verdict."""
    print(f"\n{title} (think times x{think_scale:g})")
    print("| arrivals/s | live sessions | route | n | req/s | p50 ms | p99 ms | p99 / bare |")
    print("|---|---|---|---|---|---|---|---|")
    for step in steps:
        live = step.crowd.live_at((step.start + step.end) / 2)
        bare_p99 = step.stats.get(BARE, (0, 0, 0, math.nan))[3]
        for route in (*ROUTES, BARE):
            if route in step.stats:
                n, per_s, p50, p99 = step.stats[route]
                print(f"| {step.rate:g} | {live} | {route} | {n} | {per_s:.1f} | {p50:.1f} | "
                      f"{p99:.1f} | {p99 / bare_p99:.2f} |")
    for step in steps:
        print(step_line(step))
        if step.usage is not None:
            print(f"  what saturates: {verdict(step.usage, workers)}")
        if step.profile:
            print(f"  one worker's busy samples (py-spy): {step.profile}")


def step_line(step: StepResult) -> str:
    """Arrivals, completions and refusals, and Little's law's check of the request rate."""
    people = step.crowd.people
    done = [p for p in people if p.ended_at is not None]
    refused = [r for p in people for r in p.refused]
    line = (f"{step.rate:g} arrivals/s: {len(people)} arrived, {len(done)} done, "
            f"{len(refused)} refused requests; {step.requests_per_s():.1f} requests/s")
    if done and step.warm:
        per_person = np.mean([p.requests for p in done])
        line += (f" (Little's law: {step.rate:g} x {per_person:.0f} requests a participant = "
                 f"{step.rate * per_person:.1f})")
    if step.warm is False:
        line += "; not at steady state (no participant had finished when the window began)"
    return line + "".join(f"\n  refused: {r}" for r in refused[:3])


def summary(name: str, steps: list[StepResult]) -> str:
    """The largest rate held with every route's p99 under the limit."""
    held = [s for s in steps if s.worst_p99() < P99_LIMIT_MS]
    if not held:
        return f"{name}: holds no tested rate ({steps[0].rate:g} arrivals/s already broke)"
    best = held[-1]
    more = "" if len(held) < len(steps) else " (every tested rate: add higher --rates)"
    if best.warm is False:
        more += " (not at steady state: raise --warmup-max-s)"
    return (f"{name}: holds {best.rate:g} arrivals/s ({best.requests_per_s():.0f} requests/s) "
            f"with every route's p99 under {P99_LIMIT_MS:.0f} ms, "
            f"{best.rate / PEAK_PER_S:.2g}x the paper study's expected peak{more}")


def cohort(args: argparse.Namespace, root: Path) -> bool:
    """--participants: that many through the whole flow on one server; True if all done."""
    deployment = Deployment(args, root, args.workers[0])
    proc, port, _ = deployment.serve("cohort")
    try:
        step = asyncio.run(run_cohort(port, args.participants, args.rates[0], args.think_scale,
                                      args.timeout_s, args.seed))
    finally:
        stop_server(proc)
    print_table(f"{args.participants} participant(s) at {args.rates[0]:g} arrivals/s, "
                f"{deployment.name}", [step], args.think_scale, deployment.workers)
    return all(p.phases[-1:] == [Phase.DONE.value] for p in step.crowd.people)


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--database", choices=("sqlite", "postgres"), default="sqlite")
    parser.add_argument("--workers", type=int, nargs="+", default=[1],
                        help="one deployment per count, e.g. 1 2 4")
    parser.add_argument("--rates", type=float, nargs="+", default=[0.05, 0.1, 0.2, 0.4, 0.8, 1.6],
                        help="arrivals per second, one step each, rising")
    parser.add_argument("--think-scale", type=float, default=0.02,
                        help="every think time (and the heartbeat interval) times this")
    parser.add_argument("--step-s", type=float, default=30.0, help="each step's window")
    parser.add_argument("--warmup-max-s", type=float, default=90.0,
                        help="at most this long waiting for a step's first participant")
    parser.add_argument("--bare-per-s", type=float, default=BARE_PER_S)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--profile", action="store_true",
                        help="py-spy one worker during each window (it costs some CPU)")
    parser.add_argument("--participants", type=int, default=0,
                        help="instead of the sweep: this many through the whole flow at the "
                        "first rate; exit 1 unless every one is done")
    parser.add_argument("--timeout-s", type=float, default=600.0, help="for --participants")
    parser.add_argument("--postgres-url", default="", help="a PostgreSQL server (default: a "
                        "throwaway cluster from Debian's binaries, fsync on)")
    args = parser.parse_args(argv)
    if args.think_scale <= 0 or any(r <= 0 for r in args.rates):
        parser.error("--think-scale and --rates must be positive")
    return args


def main(argv: list[str] | None = None) -> None:
    args = parse_args(argv)
    try:
        check_phases(HANDLERS)
        with tempfile.TemporaryDirectory() as tmp, postgres_server(args):
            if args.participants:
                if not cohort(args, Path(tmp)):
                    sys.exit("study_arrivals: not every participant reached done")
                return
            results = {}
            for workers in args.workers:
                deployment = Deployment(args, Path(tmp) / f"w{workers}", workers)
                results[deployment.name] = deployment.sweep()
                print_table(deployment.name, results[deployment.name], args.think_scale,
                            workers)
            print()
            for name, steps in results.items():
                print(summary(name, steps))
    except UnansweredPhase as err:
        sys.exit(f"study_arrivals: {err}")


@contextmanager
def postgres_server(args: argparse.Namespace):
    """A throwaway PostgreSQL cluster (fsync on) into `args.postgres_url` for --database
    postgres without one; stopped and removed on exit."""
    if args.database != "postgres" or args.postgres_url:
        yield
        return
    # its own folder under /tmp: the private temp dir is not the postgres user's to enter
    root = Path(tempfile.mkdtemp(prefix="tomstudy-bench-pg-"))
    args.postgres_url, stop = start_cluster(root, fsync=True)
    try:
        time_wal_io(args.postgres_url)
        yield
    finally:
        stop()
        shutil.rmtree(root, ignore_errors=True)


if __name__ == "__main__":
    main()
