"""Participants arriving open-loop with human think times: p50/p99 per route beside a bare
endpoint's, same run, and the largest arrival rate a server holds with p99 under 100 ms.

The paper's study has a target of 22 participants; on Prolific its places can all fill
within about two minutes, so its expected peak is 22 arrivals in 120 s (0.18 per s) and 22
sessions at once. The first table is 10x that: 1.8 arrivals per s for --window-s (120 s:
up to about 270 arrivals, against the study's cap of 220 live sessions). Arrivals are a Poisson
process: a participant arrives whether or not the server has answered the ones before
(open loop). Each one, from its own loopback address (127.1.x.y, so the server's
per-address rate limits apply as they would to real people, at their default values),
starts a session, reads the state, and thinks before each step as people did in the
walk: 10-20 s over the consent, 20-40 s over the instructions, 45-55 s per trial (the clip
events sent a third of the way in). Each request opens its own connection (a browser idle
for 45 s finds uvicorn's 5 s keep-alive closed). Beside them a probe GETs a path no route
serves (--bare-per-s a second): the server's own cost of a request under the same load.

Then the same run at rising arrival rates (--rates, each --step-s long, the study's cap
lifted so the server, not the cap, is measured) until a route's p99 reaches 100 ms: the
largest rate below that is what the server holds.

    .venv/bin/python benchmarks/study_arrivals.py [--database sqlite|postgres] [--workers 1]
"""

import argparse
import asyncio
import json
import shutil
import sys
import tempfile
import time
from collections import defaultdict
from pathlib import Path

import numpy as np
import yaml

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from app.layout import Layout  # noqa: E402
from app.server.sessions import SESSION_HEADER, SESSION_PATH  # noqa: E402
from app.settings import Settings  # noqa: E402
from benchmarks._rawhttp import RawClient  # noqa: E402
from benchmarks.study_load import event, recruitment_params, write  # noqa: E402
from tests.conftest import (  # noqa: E402
    REPO,
    SmallStudy,
    free_port,
    fresh_database,
    start_cluster,
    start_server,
)
from tests.study.flow import DEVICE, prediction_body  # noqa: E402

PEAK_PER_S = 22 / 120  # the paper study's target, all arriving within two minutes
BARE = "GET bare"
ROUTES = ("POST sessions", "GET state", "POST consent", "POST instructions", "POST events",
          "POST predictions", "POST survey")
THINK_S = {"consent": (10, 20), "instructions": (20, 40), "trial": (45, 55),
           "survey": (30, 60)}
P99_LIMIT_MS = 100.0


class Arrival:
    """One participant: their own address, think times, every latency recorded."""

    def __init__(self, port: int, index: int, study_id: str, latencies: dict, rng) -> None:
        self.port, self.study_id, self.latencies, self.rng = port, study_id, latencies, rng
        self.source = f"127.1.{index // 250}.{index % 250 + 1}"
        self.headers: dict[str, str] = {}
        self.refused: list[str] = []

    async def call(self, route: str, path: str, body: dict | None = None) -> dict | None:
        """One timed request on a new connection; None if refused (kept in `refused`)."""
        client = RawClient(self.port, self.source)
        t0 = time.perf_counter()
        try:
            status, payload = await client.request(route.split()[0], path, body, self.headers)
        finally:
            client.close()
        self.latencies[route].append(time.perf_counter() - t0)
        if status >= 400:
            self.refused.append(f"{route}: {status} {payload[:120]!r}")
            return None
        return json.loads(payload)

    async def think(self, phase: str) -> None:
        low, high = THINK_S[phase]
        await asyncio.sleep(self.rng.uniform(low, high))

    async def run(self, study_param: str) -> None:
        """Start, then each phase after its think time, until done or cancelled."""
        started = await self.call("POST sessions", "/api/sessions", {
            "study_id": self.study_id, "recruitment": recruitment_params(study_param)})
        if started is None:
            return
        self.headers = {SESSION_HEADER: started["session_token"]}
        state = await self.call("GET state", f"{SESSION_PATH}/state")
        while state is not None and state["phase"] != "done":
            state = await self.answer(state)

    async def answer(self, state: dict) -> dict | None:
        phase, step = state["phase"], state.get("step") or {}
        if phase in ("practice", "trial"):
            third = self.rng.uniform(*THINK_S["trial"]) / 3
            await asyncio.sleep(third)
            await self.call("POST events", f"{SESSION_PATH}/events", {"events": [
                event("clip_finished", {"trial_id": step["trial_id"], "replays": 0})]})
            await asyncio.sleep(2 * third)
            return await self.call("POST predictions", f"{SESSION_PATH}/predictions",
                                   prediction_body(step))
        await self.think(phase)
        bodies = {"consent": write(agree=True, client=DEVICE), "instructions": write(),
                  "survey": write(answers={"difficulty": 4, "confidence": 4, "driving": "yes"})}
        return await self.call(f"POST {phase}", f"{SESSION_PATH}/{phase}", bodies[phase])


async def probe(port: int, per_s: float, latencies: dict) -> None:
    """GET a path no route serves, `per_s` times a second, until cancelled."""
    client = RawClient(port, "127.2.0.1")
    while True:
        t0 = time.perf_counter()
        try:
            await client.request("GET", "/no-such-route")
        except (ConnectionError, OSError):
            client.close()
            continue
        latencies[BARE].append(time.perf_counter() - t0)
        await asyncio.sleep(1 / per_s)


async def arrivals(port: int, study_id: str, rate_per_s: float, window_s: float,
                   bare_per_s: float, seed: int) -> tuple[dict, list[Arrival]]:
    """Poisson arrivals at `rate_per_s` for `window_s`; then every participant stops."""
    rng = np.random.default_rng(seed)
    latencies: dict[str, list[float]] = defaultdict(list)
    people, tasks = [], [asyncio.create_task(probe(port, bare_per_s, latencies))]
    end = time.perf_counter() + window_s
    while (now := time.perf_counter()) < end:
        person = Arrival(port, len(people), study_id, latencies,
                         np.random.default_rng([seed, len(people)]))
        people.append(person)
        tasks.append(asyncio.create_task(person.run("b" * 24)))
        await asyncio.sleep(min(rng.exponential(1 / rate_per_s), end - now))
    for task in tasks:
        task.cancel()
    await asyncio.gather(*tasks, return_exceptions=True)
    return latencies, people


def study_with_cap(data_dir: Path, configs: Path, per_target: float) -> SmallStudy:
    """The paper study with max_live_sessions_per_target set, in a copy of study_configs."""
    shutil.copytree(REPO / "study_configs", configs, dirs_exist_ok=True)
    path = configs / "paper_study.yaml"
    config = yaml.safe_load(path.read_text())
    config["max_live_sessions_per_target"] = per_target
    path.write_text(yaml.safe_dump(config))
    return SmallStudy(data_dir, configs, "paper_study")


def run_once(args, study: SmallStudy, rate: float, window_s: float, tmp: Path,
             name: str) -> tuple[dict, list[Arrival]]:
    """A fresh server and database, one arrival rate; (latencies, participants)."""
    port = free_port()
    url = (fresh_database(args.postgres_url, name) if args.database == "postgres"
           else f"sqlite:///{tmp}/{name}.db")
    defaults = Settings()
    proc = start_server(study, url, port, workers=args.workers, log=tmp / f"{name}.log",
                        TOMSTUDY_RATE_LIMIT_STARTS=defaults.rate_limit_starts,
                        TOMSTUDY_RATE_LIMIT_REQUESTS=defaults.rate_limit_requests)
    try:
        return asyncio.run(arrivals(port, study.study_id, rate, window_s, args.bare_per_s,
                                    args.seed))
    finally:
        proc.terminate()
        proc.wait(timeout=20)


def table(latencies: dict, people: list[Arrival], title: str) -> float:
    """Print p50/p99 per route and beside the bare one's; returns the largest route p99."""
    bare_p50, bare_p99 = np.percentile(np.asarray(latencies[BARE]) * 1000, [50, 99])
    refused = [r for p in people for r in p.refused]
    print(f"\n{title}: {len(people)} arrivals, {len(refused)} refused requests")
    print("| route | n | p50 ms | p99 ms | p50 / bare | p99 / bare |\n|---|---|---|---|---|---|")
    worst = 0.0
    for route in (*ROUTES, BARE):
        ms = np.asarray(latencies.get(route, [])) * 1000
        if not len(ms):
            continue
        p50, p99 = np.percentile(ms, [50, 99])
        worst = max(worst, p99) if route != BARE else worst
        print(f"| {route} | {len(ms)} | {p50:.1f} | {p99:.1f} | {p50 / bare_p50:.2f} | "
              f"{p99 / bare_p99:.2f} |")
    for line in refused[:3]:
        print(f"refused: {line}")
    return worst


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--database", choices=("sqlite", "postgres"), default="sqlite")
    parser.add_argument("--workers", type=int, default=1)
    parser.add_argument("--window-s", type=float, default=150.0)
    parser.add_argument("--step-s", type=float, default=120.0)
    parser.add_argument("--rates", type=float, nargs="+", default=[2, 5, 10, 20, 40])
    parser.add_argument("--bare-per-s", type=float, default=5.0)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--postgres-url", default="", help="a PostgreSQL server (default: a "
                        "throwaway cluster from Debian's binaries)")
    parser.add_argument("--data-dir", type=Path, default=REPO / "var")
    args = parser.parse_args()
    if not Layout(args.data_dir).bank("paper_study").is_file():
        sys.exit(f"no paper_study trial bank in {args.data_dir} (make serve builds it)")
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        stop = None
        if args.database == "postgres" and not args.postgres_url:
            # its own folder under /tmp: the private temp dir is not the postgres user's to enter
            pg_root = Path(tempfile.mkdtemp(prefix="tomstudy-bench-pg-"))
            url, stop_cluster = start_cluster(pg_root, fsync=True)
            args.postgres_url = url

            def stop() -> None:
                stop_cluster()
                shutil.rmtree(pg_root, ignore_errors=True)
        try:
            measure(args, tmp)
        finally:
            if stop is not None:
                stop()


def measure(args: argparse.Namespace, tmp: Path) -> None:
    """The 10x-peak table, then the rate sweep."""
    where = f"{args.database}, {args.workers} worker(s)"
    study = study_with_cap(args.data_dir, tmp / "configs", 10)
    rate = 10 * PEAK_PER_S
    worst = table(*run_once(args, study, rate, args.window_s, tmp, "peak"),
                  f"10x the expected peak ({rate:.2f} arrivals/s for {args.window_s:.0f} s), "
                  f"{where}")
    print(f"largest route p99 {worst:.1f} ms")
    uncapped = study_with_cap(args.data_dir, tmp / "uncapped", 1e6)
    held = 0.0
    for rate in args.rates:
        worst = table(*run_once(args, uncapped, rate, args.step_s, tmp, f"r{int(rate)}"),
                      f"{rate:g} arrivals/s for {args.step_s:.0f} s, {where}")
        if worst >= P99_LIMIT_MS:
            break
        held = rate
    print(f"\n{where}: holds {held:g} arrivals/s with every route's p99 under "
          f"{P99_LIMIT_MS:.0f} ms ({held / PEAK_PER_S:.0f}x the expected peak)")


if __name__ == "__main__":
    main()
