"""The forged-id attack of issue 32, re-run: made-up 24-hex PROLIFIC_PIDs that never consent,
all from one address (127.0.0.1), against a real `tomstudy serve` of the small study.

(a) For --seconds (default 600: the issue's 10 minutes) one address starts sessions with
    made-up ids as fast as the default rate limits let it, waiting out each 429's
    Retry-After: how many starts were accepted, and how many of them count (live cap, "full",
    balance: the sessions the database marks counted).
(b) With the rate limits off and the paper's live cap of 220 (10 x 22), 220 forged starts,
    then a real participant: their start and their consent.
(c) With `recruitment.max_counted_sessions: 22`, 22 forged starts, then a real participant.
(d) With a Prolific API token and the local stand-in of Prolific's API as Prolific
    (tests/server/prolific_standin.py; the live Prolific cannot be reached from here), 220 forged
    starts whose SESSION_ID Prolific does not know, then a participant whose submission it
    knows: how many forged sessions were stored or count, and the real one's start, consent and
    counted flag.

    PYTHONPATH=. .venv/bin/python benchmarks/forged_ids.py [--seconds 600] [--server-code DIR]

--server-code runs the server from another checkout (e.g. the main branch, for the before
figures); the attack and the counting are this checkout's.
"""

import argparse
import secrets
import shutil
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

import httpx
import yaml
from sqlalchemy import create_engine, func, select

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from app.server.flow.sessions import SESSION_HEADER  # noqa: E402
from app.server.storage.tables import Participant  # noqa: E402
from app.settings import Settings  # noqa: E402
from tests.conftest import SmallStudy, cached_small_study, free_port, start_server  # noqa: E402
from tests.server.flow import DEVICE, new_id  # noqa: E402
from tests.server.prolific_standin import ProlificStandIn, serve  # noqa: E402

FORGED_STUDY_ID = "f" * 24


def forged_start(client: httpx.Client, study_id: str) -> httpx.Response:
    """One start with a made-up Prolific id; it never consents."""
    pid = secrets.token_hex(12)
    return client.post("/api/sessions", json={"study_id": study_id, "recruitment": {
        "PROLIFIC_PID": pid, "STUDY_ID": FORGED_STUDY_ID, "SESSION_ID": pid[:8]}})


def counted(db_path: Path, only_counted: bool = True) -> int:
    """Sessions the server counts (toward the cap, "full" and balance); all stored ones with
    `only_counted` False."""
    query = select(func.count()).select_from(Participant)
    if only_counted:
        query = query.where(Participant.counted.is_(True))
    engine = create_engine(f"sqlite:///{db_path}")
    with engine.connect() as conn:
        n = conn.execute(query).scalar_one()
    engine.dispose()
    return n


def real_participant(client: httpx.Client, study_id: str,
                     standin: ProlificStandIn | None = None) -> tuple[int, int | None]:
    """A real participant's start and consent statuses (None: no session to consent in); with
    `standin`, their submission is one Prolific knows."""
    pid = secrets.token_hex(12)
    if standin is not None:
        standin.add("real", FORGED_STUDY_ID, pid)
    r = client.post("/api/sessions", json={"study_id": study_id, "recruitment": {
        "PROLIFIC_PID": pid, "STUDY_ID": FORGED_STUDY_ID, "SESSION_ID": "real"}})
    if r.status_code not in (200, 201):
        return r.status_code, None
    consent = client.post("/api/session/consent", headers={
        SESSION_HEADER: r.json()["session_token"]},
        json={"submission_id": new_id(), "agree": True, "client": DEVICE})
    return r.status_code, consent.status_code


def study_copy(small: SmallStudy, configs: Path, **changes) -> SmallStudy:
    """The small study served with these config keys changed (`recruitment` merged)."""
    shutil.copytree(small.configs_dir, configs)
    path = configs / f"{small.study_id}.yaml"
    config = yaml.safe_load(path.read_text())
    config["recruitment"] |= changes.pop("recruitment", {})
    path.write_text(yaml.safe_dump(config | changes))
    return SmallStudy(small.data_dir, configs, small.study_id)


class Server:
    """`tomstudy serve` of `study` on a fresh SQLite file, for a `with` block."""

    def __init__(self, study: SmallStudy, root: Path, name: str, code: Path | None,
                 **env: str) -> None:
        self.study, self.db = study, root / f"{name}.db"
        self.port = free_port()
        extra = {"PYTHONPATH": str(code)} if code else {}
        self.proc = start_server(study, f"sqlite:///{self.db}", self.port,
                                 log=root / f"{name}.log", **extra, **env)

    def __enter__(self) -> httpx.Client:
        self.client = httpx.Client(base_url=f"http://127.0.0.1:{self.port}", timeout=30)
        return self.client

    def __exit__(self, *exc) -> None:
        self.client.close()
        self.proc.terminate()
        self.proc.wait(timeout=20)


def attack_for(client: httpx.Client, study_id: str, seconds: float) -> dict:
    """(a): forged starts from one address for `seconds`, obeying Retry-After."""
    tally = {"accepted": 0, "429": 0, "other": 0}
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        r = forged_start(client, study_id)
        if r.status_code == 429:
            tally["429"] += 1
            wait_s = float(r.headers.get("retry-after", 1))
            time.sleep(min(wait_s, max(0.0, end - time.monotonic())))
        elif r.status_code in (200, 201):
            tally["accepted"] += 1
        else:
            tally["other"] += 1
    return tally


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=600.0)
    parser.add_argument("--server-code", type=Path, default=None)
    parser.add_argument("--starts", default=Settings().rate_limit_starts,
                        help="the start limit of (a) (default: this checkout's default)")
    args = parser.parse_args()
    small = cached_small_study()
    sid = small.study_id
    limits = {"TOMSTUDY_RATE_LIMIT_STARTS": args.starts}
    code = args.server_code
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        paper_cap = study_copy(small, root / "cap", target_sample_size=22,
                               max_live_sessions_per_target=10)
        server = Server(paper_cap, root, "a", code, **limits)
        with server as client:
            tally = attack_for(client, sid, args.seconds)
        print(f"(a) one address, {args.seconds:.0f} s at a start limit of {args.starts}: "
              f"{tally['accepted']} forged starts "
              f"accepted, {tally['429']} answered 429, {tally['other']} other; "
              f"{counted(server.db)} sessions counting")
        forged_then_real(paper_cap, root, "b", code, 220, "live cap 220 (10 x 22)")
        full = study_copy(small, root / "full", recruitment={"max_counted_sessions": 22})
        forged_then_real(full, root, "c", code, 22, "max_counted_sessions 22")
        checked_by_standin(small, root, code)


def forged_then_real(study: SmallStudy, root: Path, name: str, code: Path | None, n: int,
                     label: str) -> None:
    """(b), (c): `n` forged starts without rate limits, then a real participant; prints both."""
    with Server(study, root, name, code, TOMSTUDY_RATE_LIMIT_STARTS="") as client:
        statuses = [forged_start(client, study.study_id).status_code for _ in range(n)]
        real = real_participant(client, study.study_id)
    print(f"({name}) {label}: {n} forged starts ({statuses.count(201)} accepted), "
          f"{counted(root / f'{name}.db')} counting; a real participant then: start {real[0]}, "
          f"consent {real[1]}")


def checked_by_standin(small: SmallStudy, root: Path, code: Path | None) -> None:
    """(d): forged SESSION_IDs against a server that asks the Prolific stand-in."""
    standin = ProlificStandIn()
    (root / "prolific_token").write_text(standin.token)
    with serve(standin, free_port()) as api_url:
        server = Server(small, root, "d", code, TOMSTUDY_RATE_LIMIT_STARTS="",
                        TOMSTUDY_PROLIFIC_TOKEN_FILE=str(root / "prolific_token"),
                        TOMSTUDY_PROLIFIC_API_URL=api_url)
        with server as client:
            statuses = [forged_start(client, small.study_id).status_code for _ in range(220)]
            real = real_participant(client, small.study_id, standin)
        forged_stored = counted(server.db, only_counted=False) - (real[0] in (200, 201))
        print(f"(d) Prolific stand-in: 220 forged SESSION_IDs answered "
              f"{dict(sorted(Counter(statuses).items()))}, "
              f"{forged_stored} forged sessions stored; the known "
              f"participant: start {real[0]}, consent {real[1]}, {counted(server.db)} counting")


if __name__ == "__main__":
    main()
