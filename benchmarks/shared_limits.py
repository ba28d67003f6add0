"""Session starts from one address against a limit of --limit a minute: accepted and refused
with the counts in each worker's memory (memory://) and in one shared Redis, for one server
with two workers and for two servers on two ports (two "hosts" on one PostgreSQL database).

Each start opens its own connection, one after another once every worker serves, so the
kernel hands each to either worker; the two servers get the starts in turn. How the starts
split between two workers is the kernel's and the workers' event loops' choice, so the
memory:// row of one server varies between runs (anything from 20 to 40 accepted); the
shared rows do not. Each case starts fresh servers, a fresh database and its
own client address (127.1.0.x), so no case sees another's counts.

    PYTHONPATH=. .venv/bin/python benchmarks/shared_limits.py [--starts 45] [--limit 20]

Needs Debian's postgresql and redis-server (apt-get install postgresql redis-server).
"""

import argparse
import shutil
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from tests.conftest import (  # noqa: E402
    PG_BIN,
    REDIS_SERVER,
    RedisServer,
    cached_small_study,
    free_port,
    fresh_database,
    start_cluster,
    start_server,
    stop_server,
    wait_for_log,
)
from tests.server.starts import send_starts  # noqa: E402

CASES = (("1 server, 2 workers", 1, 2), ("2 servers on 2 ports, 1 worker each", 2, 1))


def run_case(study, postgres_url: str, storage: str, servers: int, workers: int,
             args, tmp: Path, index: int) -> list[int]:
    """Fresh servers on a fresh database sharing `storage`; the statuses of the starts."""
    db_url = fresh_database(postgres_url, f"shared_limits_{index}")
    ports, procs = [], []
    try:
        for _ in range(servers):
            ports.append(free_port())
            procs.append(started(study, db_url, ports[-1], workers, tmp / f"case{index}.log",
                                 TOMSTUDY_RATE_LIMIT_STORAGE=storage,
                                 TOMSTUDY_RATE_LIMIT_STARTS=f"{args.limit}/minute"))
        # every worker serving (start_server returns once one answers): any may take a start
        wait_for_log(tmp / f"case{index}.log", "Application startup complete",
                     servers * workers)
        return send_starts(ports, study.study_id, f"127.1.0.{index + 1}", args.starts)
    finally:
        for proc in procs:
            stop_server(proc)


def started(study, db_url: str, port: int, workers: int, log: Path, **env: str):
    """`start_server`, tried up to three times: on a loaded machine uvicorn's supervisor may
    kill workers still importing (no answer to its 5 s health check) until the wait ends."""
    for _ in range(2):
        try:
            return start_server(study, db_url, port, workers=workers, log=log, **env)
        except RuntimeError as err:
            print(f"({err}; trying again)", file=sys.stderr)
    return start_server(study, db_url, port, workers=workers, log=log, **env)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--starts", type=int, default=45, help="starts sent from one address")
    parser.add_argument("--limit", type=int, default=20, help="starts a minute per address")
    args = parser.parse_args()
    for binary in (PG_BIN / "initdb", REDIS_SERVER):
        if not binary.exists():
            sys.exit(f"{binary} not found (apt-get install postgresql redis-server)")
    study = cached_small_study()
    pg_root = Path(tempfile.mkdtemp(prefix="tomstudy-bench-pg-"))  # the postgres user's to enter
    postgres_url, stop_cluster = start_cluster(pg_root)
    try:
        with tempfile.TemporaryDirectory() as tmp:
            redis = RedisServer(Path(tmp), free_port())
            redis.start()
            try:
                measure(study, postgres_url, redis.url, args, Path(tmp))
            finally:
                redis.stop()
    finally:
        stop_cluster()
        shutil.rmtree(pg_root, ignore_errors=True)


def measure(study, postgres_url: str, redis_url: str, args, tmp: Path) -> None:
    """Print one row per case: accepted and refused of the starts from one address."""
    print(f"{args.starts} session starts from one address, "
          f"TOMSTUDY_RATE_LIMIT_STARTS={args.limit}/minute\n")
    print("| servers | TOMSTUDY_RATE_LIMIT_STORAGE | accepted (201) | refused (429) | other |")
    print("|---|---|---|---|---|")
    index = 0
    for name, servers, workers in CASES:
        for storage in ("memory://", redis_url):
            statuses = run_case(study, postgres_url, storage, servers, workers, args, tmp,
                                index)
            index += 1
            other = len(statuses) - statuses.count(201) - statuses.count(429)
            print(f"| {name} | {storage} | {statuses.count(201)} | {statuses.count(429)} | "
                  f"{other} |", flush=True)


if __name__ == "__main__":
    main()
