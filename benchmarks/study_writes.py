"""Study server hot path: prediction POSTs (15 rows each) vs GET state, same server, same run.

Starts a real `tomstudy serve` (1 worker, SQLite WAL) on the small test study, creates
participants, then per round: every participant GETs its state (baseline), then every
participant POSTs its trial's predictions. A raw asyncio HTTP/1.1 client keeps the load
generator lighter than the server. Prints req/s and p99 of both and the POST/GET ratio.

    .venv/bin/python benchmarks/study_writes.py [--participants 100] [--concurrency 50]
"""

import argparse
import asyncio
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from app.server.flow.sessions import SESSION_HEADER, SESSION_PATH  # noqa: E402
from benchmarks._rawhttp import RawClient  # noqa: E402
from tests.conftest import cached_small_study, free_port, start_server  # noqa: E402
from tests.server.flow import new_id, prediction_body, prolific  # noqa: E402


async def request_json(client: RawClient, method: str, path: str, body: dict | None = None,
                       token: str | None = None):
    """One request through `client` (as session `token`); (status, parsed JSON answer)."""
    headers = {SESSION_HEADER: token} if token else None
    status, payload = await client.request(method, path, body, headers)
    try:
        return status, json.loads(payload)
    except ValueError as err:
        raise RuntimeError(f"{method} {path}: bad answer {status} {payload[:200]!r}") from err


async def timed_batch(clients, jobs) -> tuple[float, list[float]]:
    """Run jobs (client -> coroutine factories) over the clients; (wall s, latencies s)."""
    queue: asyncio.Queue = asyncio.Queue()
    for job in jobs:
        queue.put_nowait(job)
    latencies: list[float] = []

    async def worker(client):
        while not queue.empty():
            job = queue.get_nowait()
            t0 = time.perf_counter()
            status, _ = await job(client)
            latencies.append(time.perf_counter() - t0)
            assert status in (200, 201), status

    start = time.perf_counter()
    await asyncio.gather(*(worker(c) for c in clients))
    return time.perf_counter() - start, latencies


async def run(port: int, study_id: str, participants: int, concurrency: int) -> dict:
    clients = [RawClient(port) for _ in range(concurrency)]
    tokens = []
    for i in range(participants):
        _, body = await request_json(clients[0], "POST", "/api/sessions", {
            "study_id": study_id, "recruitment": prolific(f"bench{i}")})
        tokens.append(body["session_token"])
        for step in ("consent", "instructions"):
            await request_json(clients[0], "POST", f"{SESSION_PATH}/{step}",
                               {"submission_id": new_id(), "agree": True}
                               if step == "consent" else {"submission_id": new_id()},
                               body["session_token"])
    gets, posts, states = [], [], {}
    for _ in range(3):
        await past_part_screens(clients[0], tokens)
        wall, lat = await timed_batch(clients, [get_job(t, states) for t in tokens])
        gets.append((len(tokens) / wall, lat))
        wall, lat = await timed_batch(clients, [post_job(t, states) for t in tokens])
        posts.append((len(tokens) / wall, lat))
    return {"get": gets, "post": posts}


async def past_part_screens(client: RawClient, tokens: list[str]) -> None:
    """Untimed: move every session past a part's screens (world_intro, practice_over) to its
    next trial."""
    for token in tokens:
        while True:
            _, state = await request_json(client, "GET", f"{SESSION_PATH}/state", token=token)
            if state["phase"] not in ("world_intro", "practice_over"):
                break
            await request_json(client, "POST", f"{SESSION_PATH}/continue",
                               {"submission_id": new_id(), "phase": state["phase"]}, token)


def get_job(token: str, states: dict):
    """GET the state; remember it for the following POST."""
    async def job(client):
        status, body = await request_json(client, "GET", f"{SESSION_PATH}/state", token=token)
        states[token] = body
        return status, body
    return job


def post_job(token: str, states: dict):
    """POST a valid answer to the trial of the last GET."""
    body = prediction_body(states[token]["step"])
    return lambda client: request_json(client, "POST", f"{SESSION_PATH}/predictions", body,
                                       token)


def summarise(rounds) -> tuple[float, float]:
    rates = [r for r, _ in rounds]
    lat = np.concatenate([np.asarray(times) for _, times in rounds])
    return float(np.median(rates)), float(np.percentile(lat, 99) * 1000)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--participants", type=int, default=100)
    parser.add_argument("--concurrency", type=int, default=50)
    args = parser.parse_args()
    study = cached_small_study()  # the tests' cache, rebuilt when the pipeline code changes
    port = free_port()
    with tempfile.TemporaryDirectory() as tmp:
        proc = start_server(study, f"sqlite:///{tmp}/bench.db", port)
        try:
            result = asyncio.run(run(port, study.study_id, args.participants, args.concurrency))
        finally:
            proc.terminate()
            proc.wait(timeout=10)
    get_rate, get_p99 = summarise(result["get"])
    post_rate, post_p99 = summarise(result["post"])
    print(f"GET state          : {get_rate:8.0f} req/s  p99 {get_p99:6.1f} ms  (baseline)")
    print(f"POST predictions   : {post_rate:8.0f} req/s  p99 {post_p99:6.1f} ms  (15 rows each)")
    print(f"ratio POST/GET     : {post_rate / get_rate:.2f}  "
          f"({args.participants} participants, {args.concurrency} connections, SQLite WAL)")


if __name__ == "__main__":
    main()
