"""Participant routes under load: p50/p99 of each route beside a bare endpoint's, same run.

Starts a real `tomstudy serve` on 127.0.0.1 (SQLite WAL, 1 worker, unless told) with the
paper's study (its bundle ships with the code), else the small test study. Then N
simulated participants (200) run the whole flow at once, as app/pilot/bots.py does: start
a session with Prolific-style parameters, read the state, consent, instructions, per trial
post telemetry and predictions, then the survey. Before each step every participant also
GETs the bare endpoint, so both see the same load: by default a path no route serves, i.e.
the server's own cost of a request (HTTP, middleware, routing, a small JSON 404) and
nothing else. (A static file is no baseline: StaticFiles reads it in the thread pool,
which under this load was slower than any participant route.)
Each participant holds one keep-alive connection of a raw asyncio HTTP/1.1 client (httpx
would saturate a core before the server does). Prints each route's p50 and p99 and their
ratios to the bare endpoint's; it stops when every participant is done or after
--timeout-s (exit 1 if any participant did not finish). Nobody thinks between requests, so
this is a saturation test: every latency includes the wait for the server's event loop,
about participants / throughput, and the ratios show what a route costs beyond that.

    .venv/bin/python benchmarks/study_load.py [--participants 200] [--study auto|small|paper]
"""

import argparse
import asyncio
import json
import secrets
import sys
import tempfile
import time
import uuid
from collections import defaultdict
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from app.bank.bundle import MANIFEST, shipped_dir  # noqa: E402
from app.pilot.bots import survey_answers  # noqa: E402
from app.server.flow.sessions import SESSION_HEADER, SESSION_PATH  # noqa: E402
from benchmarks._rawhttp import RawClient  # noqa: E402
from tests.conftest import (  # noqa: E402
    REPO,
    SmallStudy,
    cached_small_study,
    free_port,
    start_server,
)
from tests.server.flow import DEVICE, prediction_body  # noqa: E402

BARE = "GET bare"
ROUTES = ("POST sessions", "GET state", "POST consent", "POST instructions", "POST continue",
          "POST events", "PUT draft", "POST predictions", "POST survey")
PART_PHASES = ("world_intro", "practice_over")  # a part's screens (app/server/flow/plan.py)
EXPECTED_STATUS = {"POST sessions": (201,), "POST events": (202,), "POST predictions": (201,),
                   BARE: (200, 404)}  # any other route: (200,)
MAX_STEPS = 200  # a participant that has not finished after this many steps is stuck


def recruitment_params(study_param: str) -> dict:
    """Prolific's URL parameters for one participant (change here for MTurk or a preview)."""
    return {"PROLIFIC_PID": secrets.token_hex(12), "STUDY_ID": study_param,
            "SESSION_ID": secrets.token_hex(16)}


class SimulatedParticipant:
    """One participant's whole session over its own connection, every latency recorded."""

    def __init__(self, port: int, study_id: str, study_param: str, bare_path: str,
                 latencies: dict[str, list[float]], seed: int) -> None:
        self.client = RawClient(port)
        self.study_id, self.study_param, self.bare_path = study_id, study_param, bare_path
        self.latencies = latencies
        self.rng = np.random.default_rng(seed)
        self.headers: dict[str, str] = {}

    async def call(self, route: str, path: str, body: dict | None = None) -> bytes:
        """One timed request; a status other than the route's success is an error."""
        method = route.split()[0]
        t0 = time.perf_counter()
        status, payload = await self.client.request(method, path, body, self.headers)
        self.latencies[route].append(time.perf_counter() - t0)
        if status not in EXPECTED_STATUS.get(route, (200,)):
            raise RuntimeError(f"{route} {path}: {status} {payload[:200]!r}")
        return payload

    async def step(self, route: str, body: dict) -> dict:
        """Send one of the session's writes (the route's method) after a bare GET; returns the
        answer."""
        await self.call(BARE, self.bare_path)
        what = route.split()[1]
        return json.loads(await self.call(route, f"{SESSION_PATH}/{what}", body))

    async def run(self) -> None:
        """From session start to done."""
        try:
            state = await self.start()
            for _ in range(MAX_STEPS):
                if state["phase"] == "done":
                    return
                state = await self.answer(state)
            raise RuntimeError(f"not done after {MAX_STEPS} steps")
        finally:
            self.client.close()

    async def start(self) -> dict:
        """POST /api/sessions, then GET the state."""
        await self.call(BARE, self.bare_path)
        session = json.loads(await self.call("POST sessions", "/api/sessions", {
            "study_id": self.study_id, "recruitment": recruitment_params(self.study_param)}))
        self.headers = {SESSION_HEADER: session["session_token"]}
        return json.loads(await self.call("GET state", f"{SESSION_PATH}/state"))

    async def answer(self, state: dict) -> dict:
        """Do what the phase asks, as the browser would; returns the next state."""
        phase, step = state["phase"], state.get("step") or {}
        if phase == "consent":
            return await self.step("POST consent", write(agree=True, client=DEVICE))
        if phase == "instructions":
            return await self.step("POST instructions", write())
        if phase in PART_PHASES:
            return await self.step("POST continue", write(phase=phase))
        if phase == "survey":
            return await self.step("POST survey", write(answers=survey_answers(step, self.rng)))
        clip = {"trial_id": step["trial_id"], "replays": 0}
        await self.step("POST events", {"events": [
            event("clip_finished", clip), event("resize", {"w": 1600, "h": 900})]})
        body = prediction_body(step)
        for seq, draft in enumerate(drafts(step, body), start=1):  # the page saves every click
            await self.step("PUT draft", draft | {"seq": seq})
        return await self.step("POST predictions", body)


def drafts(trial: dict, body: dict) -> list[dict]:
    """The drafts the page saves while placing `body`'s clicks: one after each click."""
    saved = []
    for i, points in enumerate(body["points"]):
        for j in range(1, len(points) + 1):
            clicks = [p if k < i else (points[:j] if k == i else []) for k, p in
                      enumerate(body["points"])]
            times = [t if k < i else (body["click_times_ms"][i][:j] if k == i else [])
                     for k, t in enumerate(body["click_times_ms"])]
            saved.append({"trial_id": trial["trial_id"], "index": i,
                          "points": clicks, "click_times_ms": times, "history": [],
                          "shown_at_ms": body["shown_at_ms"], "replays": 0})
    return saved


def write(**fields) -> dict:
    """A write body with a fresh client UUID."""
    return {"submission_id": str(uuid.uuid4()), **fields}


def event(kind: str, data: dict) -> dict:
    """One telemetry event as the browser sends it."""
    return {"submission_id": str(uuid.uuid4()), "kind": kind,
            "t_client_ms": time.time() * 1000, "data": data}


async def run_load(port: int, study_id: str, participants: int, study_param: str,
                   bare_path: str, timeout_s: float) -> tuple[dict, list, float, float]:
    """All participants at once; (latencies by route, errors, wall s, this process's CPU s)."""
    latencies: dict[str, list[float]] = defaultdict(list)
    people = [SimulatedParticipant(port, study_id, study_param, bare_path, latencies, i)
              for i in range(participants)]
    started, cpu_started = time.perf_counter(), time.process_time()
    tasks = [asyncio.create_task(p.run()) for p in people]
    done, late = await asyncio.wait(tasks, timeout=timeout_s)
    for task in late:
        task.cancel()
    errors = [t.exception() for t in done if t.exception() is not None]
    errors += [TimeoutError(f"not done within {timeout_s:.0f} s")] * len(late)
    return latencies, errors, time.perf_counter() - started, time.process_time() - cpu_started


def choose_study(which: str, data_dir: Path) -> SmallStudy:
    """The paper's study if its bundle ships (or asked for), else the small one."""
    paper = SmallStudy(data_dir, REPO / "study_configs", "paper_study")
    has_paper = (shipped_dir(REPO / "study_configs", "paper_study") / MANIFEST).is_file()
    if which == "paper" and not has_paper:
        sys.exit("no paper_study bundle in study_configs/bundles/ (restore it from git)")
    if which == "paper" or (which == "auto" and has_paper):
        return paper
    return cached_small_study()  # the tests' cache, rebuilt when the pipeline code changes


def report(latencies: dict[str, list[float]], errors: list, wall_s: float, cpu_s: float,
           args: argparse.Namespace, study: SmallStudy) -> None:
    """One line per route: count, p50, p99 (ms) and both as ratios to the bare endpoint."""
    bare = np.asarray(latencies[BARE]) * 1000
    bare_p50, bare_p99 = np.percentile(bare, [50, 99])
    total = sum(len(v) for v in latencies.values())
    print(f"{args.participants} participants at once, study {study.study_id}, "
          f"{args.workers} worker(s), {args.database_url or 'SQLite WAL'}: "
          f"{args.participants - len(errors)} done, {total} requests in {wall_s:.1f} s "
          f"({total / wall_s:.0f} req/s)")
    print(f"{'route':<18} {'n':>6} {'p50 ms':>8} {'p99 ms':>8} {'p50/bare':>9} {'p99/bare':>9}")
    for route in (*ROUTES, BARE):
        ms = np.asarray(latencies[route]) * 1000
        if not len(ms):
            continue
        p50, p99 = np.percentile(ms, [50, 99])
        print(f"{route:<18} {len(ms):>6} {p50:>8.1f} {p99:>8.1f} "
              f"{p50 / bare_p50:>9.2f} {p99 / bare_p99:>9.2f}")
    print(f"bare = GET {args.bare_path}; the load generator used {cpu_s:.1f} CPU s of "
          f"{wall_s:.1f} s (near 1 CPU s per s: it, not the server, may be the limit)")
    for err in errors[:5]:
        print(f"error: {type(err).__name__}: {err}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--participants", type=int, default=200)
    parser.add_argument("--study", choices=("auto", "small", "paper"), default="auto")
    parser.add_argument("--data-dir", type=Path, default=REPO / "var",
                        help="where the paper's study is built (auto/paper)")
    parser.add_argument("--database-url", default="",
                        help="an empty database (default: a fresh SQLite file)")
    parser.add_argument("--workers", type=int, default=1)
    parser.add_argument("--study-param", default="b" * 24,
                        help="Prolific's STUDY_ID (24 hex characters)")
    parser.add_argument("--bare-path", default="/no-such-route",
                        help="the baseline: answered 200 or 404 (e.g. /static/css/style.css)")
    parser.add_argument("--timeout-s", type=float, default=600.0)
    args = parser.parse_args()
    study = choose_study(args.study, args.data_dir)
    port = free_port()
    with tempfile.TemporaryDirectory() as tmp:
        url = args.database_url or f"sqlite:///{tmp}/load.db"
        proc = start_server(study, url, port, workers=args.workers, log=Path(tmp) / "server.log")
        try:
            result = asyncio.run(run_load(port, study.study_id, args.participants,
                                          args.study_param, args.bare_path, args.timeout_s))
        finally:
            proc.terminate()
            proc.wait(timeout=10)
    report(*result, args, study)
    if result[1]:
        sys.exit(1)


if __name__ == "__main__":
    main()
