"""A crowd of pilot bots (200) taking the small study all at once against a real server,
then the exact-balance checks of tests/e2e/test_bots.py (which runs 40): every bot
completes and counts, both world orders get half, every bank trial's exposure within 1 of
its arm's others, the export equals the database. Prints the crowd's wall time.

SQLite with 1 worker by default; `--database postgres --workers 2` starts a throwaway
PostgreSQL 15 cluster (Debian's binaries) unless --postgres-url names a server.

    .venv/bin/python benchmarks/crowd_balance.py [--crowd 200] [--database sqlite|postgres]
        [--workers 1] [--bound-s 300]
"""

import argparse
import shutil
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from tests.conftest import (  # noqa: E402
    cached_small_study,
    free_port,
    fresh_database,
    start_cluster,
    start_server,
    stop_server,
)
from tests.e2e.crowd import crowd_in_exact_balance  # noqa: E402


def run(args: argparse.Namespace, tmp: Path) -> float:
    """One server, one crowd; returns its wall time (the checks raise on any imbalance)."""
    study = cached_small_study()
    if args.database == "postgres":
        db_url = fresh_database(args.postgres_url, "crowd")
    else:
        db_url = f"sqlite:///{tmp / 'crowd.db'}"
    port = free_port()
    proc = start_server(study, db_url, port, workers=args.workers, log=tmp / "server.log",
                        TOMSTUDY_TRUST_CLIENT_CLOCK="1")
    try:
        return crowd_in_exact_balance(study, f"http://127.0.0.1:{port}", db_url, args.crowd,
                                      args.bound_s, tmp)
    finally:
        stop_server(proc)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--crowd", type=int, default=200, help="bots at once (even)")
    parser.add_argument("--database", choices=("sqlite", "postgres"), default="sqlite")
    parser.add_argument("--workers", type=int, default=1)
    parser.add_argument("--postgres-url", default="", help="a PostgreSQL server (default: a "
                        "throwaway cluster from Debian's binaries)")
    parser.add_argument("--bound-s", type=float, default=300.0,
                        help="fail if the crowd has not finished within this")
    args = parser.parse_args()
    if args.crowd < 2 or args.crowd % 2:
        parser.error(f"--crowd: {args.crowd}; needs an even number (two world orders)")
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        stop_cluster = None
        if args.database == "postgres" and not args.postgres_url:
            # its own folder under /tmp: the private temp dir is not the postgres user's to enter
            pg_root = Path(tempfile.mkdtemp(prefix="tomstudy-crowd-pg-"))
            args.postgres_url, stop_cluster = start_cluster(pg_root)
        try:
            wall_s = run(args, tmp)
        finally:
            if stop_cluster is not None:
                stop_cluster()
                shutil.rmtree(pg_root, ignore_errors=True)
    print(f"{args.crowd} bots at once, {args.database}, {args.workers} worker(s): all "
          f"completed in exact balance in {wall_s:.1f} s (wall; depends on the machine's load)")


if __name__ == "__main__":
    main()
