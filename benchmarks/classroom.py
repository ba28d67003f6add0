"""A classroom of --size participants behind one address (127.0.0.1), each starting,
consenting and answering its first trial the way the page does (tests/server/classroom.py:
the page's requests and retries), against a real `tomstudy serve` of the small study at the
default rate limits. Prints the 429s seen (retried by the page, or reaching it), the
requests, and how long until every participant had started and had answered.

    PYTHONPATH=. .venv/bin/python benchmarks/classroom.py [--size 30] [--click-s 0]
        [--server-code DIR --starts 20/minute --requests 300/minute]

--server-code runs the server from another checkout (e.g. the main branch, for the before
figures) with the limits given; the participants are this checkout's.
"""

import argparse
import asyncio
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from app.settings import Settings  # noqa: E402
from tests.conftest import cached_small_study, free_port, start_server  # noqa: E402
from tests.server.classroom import NOT_RETRIED, classroom  # noqa: E402


def main() -> None:
    defaults = Settings()
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=int, default=30)
    parser.add_argument("--click-s", type=float, default=0.0, help="time between two clicks")
    parser.add_argument("--starts", default=defaults.rate_limit_starts)
    parser.add_argument("--requests", default=defaults.rate_limit_requests)
    parser.add_argument("--server-code", type=Path, default=None)
    args = parser.parse_args()
    study = cached_small_study()
    extra = {"PYTHONPATH": str(args.server_code)} if args.server_code else {}
    with tempfile.TemporaryDirectory() as tmp:
        port = free_port()
        proc = start_server(study, f"sqlite:///{tmp}/class.db", port, log=Path(tmp) / "log",
                            TOMSTUDY_RATE_LIMIT_STARTS=args.starts,
                            TOMSTUDY_RATE_LIMIT_REQUESTS=args.requests, **extra)
        try:
            began = time.monotonic()
            pupils = asyncio.run(classroom(f"http://127.0.0.1:{port}", study.study_id,
                                           args.size, args.click_s))
            took_s = time.monotonic() - began
        finally:
            proc.terminate()
            proc.wait(timeout=20)
    refused = Counter(r for p in pupils for r in p.refused)
    reached = sum(n for r, n in refused.items() if r.split()[1] in NOT_RETRIED)
    server = args.server_code or "this checkout"
    print(f"{args.size} participants behind one address; server {server}, "
          f"TOMSTUDY_RATE_LIMIT_STARTS={args.starts}, TOMSTUDY_RATE_LIMIT_REQUESTS={args.requests}")
    print(f"answered a trial: {sum(p.answered for p in pupils)} of {args.size} in {took_s:.0f} s")
    print(f"requests: {sum(p.requests for p in pupils)} "
          f"({min(p.requests for p in pupils)}-{max(p.requests for p in pupils)} a participant)")
    print(f"429s seen: {sum(refused.values())} ({dict(refused) or 'none'}); "
          f"reaching the page (not retried): {reached}")


if __name__ == "__main__":
    main()
