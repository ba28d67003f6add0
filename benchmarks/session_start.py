"""Session start cost against the number of stored participants: 100 vs 20,000, same run;
and what 100,000 stale sessions cost.

Seeds a fresh SQLite study database with N completed participants (each with a real
plan), then times POST /api/sessions in-process (FastAPI TestClient, no network) for new
Prolific participants. Prints the median and p99 start latency for both sizes and their
ratio: a start that reads only the balance counts stays flat (ratio near 1).

Then seeds --stale counted sessions abandoned a day ago (what made-up PIDs leave behind),
times a session start among them (it releases nothing: before issue 22 the next start
released them one by one, 1.6 ms each, in one transaction on the event loop), and times
every batch of the background sweep (balance.release_stale_batch) until all are released:
the longest batch is the longest the sweep holds SQLite's write lock.

    .venv/bin/python benchmarks/session_start.py [--small 100] [--large 20000] [--starts 200]
        [--stale 100000]
"""

import argparse
import dataclasses
import secrets
import sys
import tempfile
import time
from datetime import timedelta
from pathlib import Path

import numpy as np
from sqlalchemy import insert

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from fastapi.testclient import TestClient  # noqa: E402

from app.main import create_app  # noqa: E402
from app.server.flow.balance import STALE_BATCH, release_stale_batch  # noqa: E402
from app.server.storage.tables import Participant, utcnow  # noqa: E402
from tests.conftest import cached_small_study  # noqa: E402
from tests.server.flow import make_client, prolific  # noqa: E402


def seed(client, study_id: str, n: int, completed: bool = True) -> None:
    """Store n participants (completed, or abandoned a day ago) that copy one real plan."""
    first = client.post("/api/sessions", json={"study_id": study_id,
                                               "recruitment": prolific("seed")}).json()
    with client.app.state.engine.begin() as conn:
        plan = conn.execute(Participant.__table__.select().where(
            Participant.session_token == first["session_token"])).mappings().one()["plan"]
        rows = [{"study_id": study_id, "recruitment": "prolific", "public_id": secrets.token_hex(8),
                 "external_id": f"{i:024x}", "session_token": secrets.token_urlsafe(24),
                 "attempt_key": "s", "pilot": False, "counted": True, "recruitment_params": {},
                 "client": {}, "world_order": "highway,obstacle", "plan": plan,
                 "position": len(plan) - 1 if completed else 3, "completed": completed,
                 "attention_failed": 0, "updated_at": utcnow() - timedelta(days=1)}
                for i in range(n - 1)]
        for chunk in range(0, len(rows), 5000):
            conn.execute(insert(Participant.__table__), rows[chunk:chunk + 5000])


def start_latencies(client, study_id: str, starts: int, name: str) -> np.ndarray:
    """Seconds per session start of `starts` new participants called name0, name1..."""
    out = []
    for i in range(starts):
        t0 = time.perf_counter()
        r = client.post("/api/sessions", json={"study_id": study_id,
                                               "recruitment": prolific(f"{name}{i}")})
        out.append(time.perf_counter() - t0)
        assert r.status_code == 201, r.text
    return np.asarray(out)


def measure(study, stored: int, starts: int) -> np.ndarray:
    """Start latencies on a fresh database holding `stored` participants."""
    with (tempfile.TemporaryDirectory() as tmp,
          make_client(study, f"sqlite:///{tmp}/bench.db") as client):
        without_cap(client, study.study_id)
        seed(client, study.study_id, stored)
        start_latencies(client, study.study_id, 20, "warm-up")
        return start_latencies(client, study.study_id, starts, "new")


def without_cap(client, study_id: str) -> None:
    """Lift the study's cap on live sessions (these starts never finish)."""
    ctx = client.app.state.studies[study_id]
    config = ctx.config.model_copy(update={"max_live_sessions_per_target": 1e6})
    client.app.state.studies[study_id] = dataclasses.replace(ctx, config=config)


def stale_release(study, stale: int) -> tuple[np.ndarray, np.ndarray]:
    """(start latencies among `stale` abandoned sessions, seconds per sweep batch)."""
    with tempfile.TemporaryDirectory() as tmp:
        # the app's own background sweep stays off: this loop is the sweep, timed
        settings = study.settings(f"sqlite:///{tmp}/stale.db", stale_sweep_s=3600)
        # a loopback name: a public one in TOMSTUDY_ALLOWED_HOSTS makes the app production
        with TestClient(create_app(settings, [study.study_id]),
                        base_url="http://localhost") as client:
            return sweep_timed(client, study, stale)


def sweep_timed(client, study, stale: int) -> tuple[np.ndarray, np.ndarray]:
    """Seed `stale` abandoned sessions, time starts among them, then every sweep batch."""
    without_cap(client, study.study_id)
    seed(client, study.study_id, stale, completed=False)
    starts = start_latencies(client, study.study_id, 50, "among-stale")
    ctx, batches = client.app.state.studies[study.study_id], []
    while True:
        t0 = time.perf_counter()
        released = release_stale_batch(client.app.state.engine, ctx)
        batches.append(time.perf_counter() - t0)
        if released < STALE_BATCH:
            return starts, np.asarray(batches)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--small", type=int, default=100)
    parser.add_argument("--large", type=int, default=20_000)
    parser.add_argument("--starts", type=int, default=200)
    parser.add_argument("--stale", type=int, default=100_000)
    args = parser.parse_args()
    study = cached_small_study()
    results = {n: measure(study, n, args.starts) for n in (args.small, args.large)}
    for n, lat in results.items():
        print(f"{n:6d} stored participants: session start median "
              f"{np.median(lat) * 1000:6.2f} ms  p99 {np.percentile(lat, 99) * 1000:6.2f} ms")
    small, large = (np.median(results[n]) for n in (args.small, args.large))
    print(f"ratio {args.large}/{args.small}: {large / small:.2f} (flat = about 1)")
    starts, batches = stale_release(study, args.stale)
    print(f"{args.stale} stale sessions: session start median {np.median(starts) * 1000:.2f} ms "
          f"p99 {np.percentile(starts, 99) * 1000:.2f} ms (releases nothing); sweep: "
          f"{len(batches)} batches of {STALE_BATCH}, median {np.median(batches) * 1000:.1f} ms, "
          f"longest {batches.max() * 1000:.1f} ms, all {batches.sum():.1f} s in a worker thread")


if __name__ == "__main__":
    main()
