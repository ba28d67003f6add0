"""Shared fixtures: a small real study pipeline, servers, throwaway PostgreSQL and Redis
servers, and the study app on a fresh database of each backend (the server's, researcher's,
bank's and study's tests all use it)."""

import hashlib
import itertools
import json
import os
import re
import shutil
import socket
import subprocess
import sys
import tempfile
import time
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import httpx
import pytest

REPO = Path(__file__).resolve().parent.parent
SMALL_STUDY = "small_study"
PG_BIN = Path("/usr/lib/postgresql/15/bin")
REDIS_SERVER = Path("/usr/bin/redis-server")  # Debian's redis-server (the shared rate-limit store)
ADMIN_TOKEN = "test-token"  # the researcher token of every test server and app
# test clients send many requests from one address (TestClient's peer is "testclient"):
# rate limits are off unless a test turns them on (tests/http/test_traffic.py)
NO_RATE_LIMITS = {"rate_limit_starts": "", "rate_limit_requests": ""}
TOMSTUDY = str(Path(sys.executable).parent / "tomstudy")  # the installed CLI, for subprocesses

# A consent form as a lab fills it in (no [PLACEHOLDER] left): the shipped studies' placeholders
# keep a production server from serving them, so the small study carries this one.
FILLED_CONSENT = {
    "institution": "University of Examplestadt, Department of Informatics",
    "investigators": [{"name": "Dr. Ada Example", "role": "principal investigator",
                       "email": "ada.example@uni-examplestadt.de"},
                      {"name": "Ben Sample", "role": "doctoral researcher",
                       "email": "ben.sample@uni-examplestadt.de"}],
    "ethics_approval": "The Ethics Committee of the Faculty of Informatics approved this study "
                       "(approval EK-2026-041).",
    "purpose": "A study of how people predict motion (a lab's own words, for every world).",
    "recorded": "Your clicks, their timing, your survey answers and your screen size.",
    "retention": "Anonymised data are kept for ten years on university servers and may be "
                 "shared in an open repository.",
    "voluntary": "Taking part is voluntary; you may stop at any time.",
    "withdrawal": "Write to us with your platform ID within 30 days to have your data removed.",
    "risks": "No risks beyond everyday computer use.",
}

# The paper's study, shrunk: the same trial shape (4 examples, 5-7 step segment, 5 start
# states x 3 steps) and both selection arms, fewer trials and a family of two seeds, built into
# its own bundle, so the whole pipeline runs in well under a minute.
SMALL_SEEDS = [0, 1]
SMALL_STUDY_OVERRIDES = {
    "trials_per_world": 3, "bank_trials_per_world": 5, "practice_trials": 1,
    "in_progress_timeout_min": 90, "models": {"seeds": SMALL_SEEDS}, "bundle": "built",
    "consent": FILLED_CONSENT,
    "main_trial_selection": {"rule": "models_disagree", "candidates_per_trial": 2,
                             "random_arm_trials": 2},
}
SMALL_TRAINING = {"max_epochs": 2, "patience_epochs": 2, "encoder_hidden": [32, 32],
                  "decoder_hidden": [32, 32], "windows_per_trajectory": 5,
                  "val_fraction": 0.15, "test_fraction": 0.45}
SMALL_TRAJECTORIES = 70
PIPELINE_SOURCES = ["app/worlds", "app/data", "app/learning", "app/predictors",
                    "app/bank/build.py", "app/bank/start_states.py", "app/study/trials.py",
                    "app/study/config.py", "app/bank/bundle.py", "app/bank/freeze.py",
                    "app/bank/verify.py", "app/bank/training_report.py", "app/core",
                    "study_configs",
                    # the attention checks and the discriminability rule read the observers
                    "app/bank/attention.py", "app/observers", "app/prediction_view.py",
                    "app/study/clicks.py", "app/study/trial_payload.py", "analysis/crossed.py"]


@dataclass(frozen=True)
class SmallStudy:
    """A data dir with trajectories, four checkpoints and a trial bank, plus its configs dir."""

    data_dir: Path
    configs_dir: Path
    study_id: str = SMALL_STUDY

    @property
    def layout(self):
        """The generated paths under this study's data dir."""
        from app.layout import Layout

        return Layout(self.data_dir)

    def env(self, db_url: str, **extra: str) -> dict:
        """Environment for a `tomstudy` subprocess using this study and database."""
        env = dict(os.environ, TOMSTUDY_DATA_DIR=str(self.data_dir),
                   TOMSTUDY_CONFIGS_DIR=str(self.configs_dir), DATABASE_URL=db_url,
                   TOMSTUDY_ADMIN_TOKEN=ADMIN_TOKEN,
                   **{f"TOMSTUDY_{k.upper()}": v for k, v in NO_RATE_LIMITS.items()})
        env.pop("TOMSTUDY_PRODUCTION", None)
        return env | extra

    def settings(self, db_url: str, **extra):
        """In-process `Settings` using this study and database (`extra` fields override)."""
        from app.settings import Settings

        return Settings(**dict(data_dir=self.data_dir, configs_dir=self.configs_dir,
                               database_url=db_url, admin_token=ADMIN_TOKEN,
                               **NO_RATE_LIMITS) | extra)


def local_client(app, **kwargs):
    """A TestClient that asks for the server by a loopback name (`localhost`): a public name
    in TOMSTUDY_ALLOWED_HOSTS would make the app a production server (issue 32 item 5)."""
    from fastapi.testclient import TestClient

    return TestClient(app, base_url="http://localhost", **kwargs)


def _sources_hash(roots: list[str] = PIPELINE_SOURCES) -> str:
    digest = hashlib.sha256()
    for root in roots + ["tests/conftest.py"]:
        path = REPO / root
        files = sorted(path.rglob("*")) if path.is_dir() else [path]
        for f in files:
            if f.is_file() and f.suffix in (".py", ".yaml"):
                digest.update(str(f.relative_to(REPO)).encode())
                digest.update(f.read_bytes())
    return digest.hexdigest()[:16]


def write_small_configs(configs_dir: Path, study_id: str = SMALL_STUDY,
                        source: str = "paper_study") -> None:
    """study_configs copy with the `source` study shrunk as `study_id` and a tiny training
    config."""
    import yaml

    shutil.copytree(REPO / "study_configs", configs_dir, dirs_exist_ok=True,
                    ignore=shutil.ignore_patterns("bundles"))  # the small study builds its own
    study = yaml.safe_load((REPO / "study_configs" / f"{source}.yaml").read_text())
    study.update(SMALL_STUDY_OVERRIDES)
    (configs_dir / f"{study_id}.yaml").write_text(yaml.safe_dump(study))
    (configs_dir / "training.yaml").write_text(yaml.safe_dump(SMALL_TRAINING))


def build_small_study(root: Path) -> SmallStudy:
    """Simulate both worlds, train both models' seeds per world for 2 epochs, build the bank
    and freeze the bundle."""
    from app.layout import Layout
    from app.learning.config import TrainConfig
    from app.learning.family import train_family
    from app.worlds.simulate import simulate

    data_dir, configs_dir = root / "var", root / "configs"
    write_small_configs(configs_dir)
    for world in ("highway", "obstacle"):
        simulate(world, SMALL_TRAJECTORIES, 0, Layout(data_dir),
                 configs_dir / "worlds" / f"{world}.yaml", workers=2)
    train_family(Layout(data_dir), ["highway", "obstacle"], SMALL_SEEDS,
                 TrainConfig(**SMALL_TRAINING), workers=1, say=lambda _: None)
    study = SmallStudy(data_dir, configs_dir)
    build_bundle_of(study)
    return study


def build_bundle_of(study: SmallStudy) -> None:
    """Build the study's bank from its data dir's checkpoints and freeze its bundle."""
    from app.bank.build import build_trials
    from app.configio import load_yaml_model
    from app.study.config import StudyConfig

    config = load_yaml_model(study.configs_dir / f"{study.study_id}.yaml", StudyConfig)
    build_trials(config, study.study_id, study.layout)
    freeze_bundle_of(study)


def freeze_bundle_of(study: SmallStudy) -> None:
    """Freeze the study's bundle from its data dir's working bank as it is (after a test
    changed it, say)."""
    from app.bank.freeze import freeze
    from app.configio import load_yaml_model
    from app.study.config import StudyConfig

    config = load_yaml_model(study.configs_dir / f"{study.study_id}.yaml", StudyConfig)
    freeze(config, study.study_id, study.configs_dir, study.layout,
           study.layout.bundle_dir(study.study_id))


@pytest.fixture(scope="session")
def small_study() -> SmallStudy:
    """The small real pipeline (see `cached_small_study`)."""
    return cached_small_study()


def cached_small_study() -> SmallStudy:
    """The small real pipeline, cached in the temp dir by a hash of the code it runs."""
    return cached_build("tomstudy-small-study", PIPELINE_SOURCES, build_small_study)


def cached_build(prefix: str, sources: list[str], build) -> SmallStudy:
    """`build(root)`'s study, cached in the temp dir under `prefix` and a hash of `sources`.

    A lock file serialises test sessions that share the machine (and the cache).
    """
    import fcntl

    root = Path(tempfile.gettempdir()) / f"{prefix}-{_sources_hash(sources)}"
    with open(f"{root}.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if not (root / "done").exists():
            shutil.rmtree(root, ignore_errors=True)
            root.mkdir(parents=True)
            study = build(root)
            (root / "done").write_text(study.study_id)
            remove_stale_caches(root, prefix)
    return SmallStudy(root / "var", root / "configs", (root / "done").read_text() or SMALL_STUDY)


CTRV_STUDY = "ctrv_study"


def plugin_study(small: SmallStudy, root: Path, predictors: list[str],
                 study_id: str = CTRV_STUDY) -> SmallStudy:
    """The small study with plug-in `predictors` under `root`: its data and checkpoints
    linked, its configs copied with study `study_id` naming them, the bank built and frozen."""
    import yaml

    data, configs = root / "var", root / "configs"
    data.mkdir(parents=True)
    for sub in ("data", "models"):
        (data / sub).symlink_to(small.data_dir / sub)
    shutil.copytree(small.configs_dir, configs)
    study = yaml.safe_load((configs / f"{SMALL_STUDY}.yaml").read_text())
    (configs / f"{study_id}.yaml").write_text(yaml.safe_dump(study | {"predictors": predictors}))
    built = SmallStudy(data, configs, study_id)
    build_bundle_of(built)
    return built


@pytest.fixture(scope="session")
def ctrv_study(small_study, tmp_path_factory) -> SmallStudy:
    """The small study whose config names the CTRV plug-in, built into its own bundle."""
    return plugin_study(small_study, tmp_path_factory.mktemp("ctrv"), ["ctrv"])


def remove_stale_caches(keep: Path, prefix: str, max_age_s: float = 3 * 3600) -> None:
    """Delete other caches of `prefix` untouched for 3 hours (the code they ran changed)."""
    for other in keep.parent.glob(f"{prefix}-*"):
        if other != keep and other.is_dir() and time.time() - other.stat().st_mtime > max_age_s:
            shutil.rmtree(other, ignore_errors=True)


# ---------------------------------------------------------------- the interaction study

# study_configs/interaction_study.yaml shrunk as the small study is, on GENERATED (not real)
# INTERACTION files of its roundabout and intersection: 150 s of traffic each.
INTERACTION_STUDY = "interaction_study"
INTERACTION_SECONDS = 150.0
INTERACTION_SOURCES = [*PIPELINE_SOURCES, "app/recordings", "app/interaction", "app/bank"]


@pytest.fixture(scope="session")
def interaction_study() -> SmallStudy:
    """The interaction study through the real pipeline (see `cached_interaction_study`)."""
    return cached_interaction_study()


def cached_interaction_study() -> SmallStudy:
    """`build_interaction_study`, cached as the small study is."""
    return cached_build("tomstudy-interaction-study", INTERACTION_SOURCES,
                        build_interaction_study)


def build_interaction_study(root: Path) -> SmallStudy:
    """Generate recordings of both scenarios, then `tomstudy bundle build`'s steps: import
    them, select the models' sizes, train both models' seeds, build the bank, freeze."""
    from app.bank.prepare import build_bundle
    from app.recordings.generated import generate_study_recordings

    study = SmallStudy(root / "var", root / "configs", INTERACTION_STUDY)
    write_small_configs(study.configs_dir, INTERACTION_STUDY, source=INTERACTION_STUDY)
    generate_study_recordings(study.layout.recordings() / "INTERACTION", INTERACTION_SECONDS)
    with settings_of(study) as settings:
        build_bundle(settings, INTERACTION_STUDY, workers=2, say=lambda _: None)
    return study


@contextmanager
def settings_of(study: SmallStudy):
    """The process' settings (which the pipeline reads, its worker processes too) set to the
    study's data and configs dirs for the block; yields them."""
    from app.settings import get_settings

    keys = {"TOMSTUDY_DATA_DIR": str(study.data_dir),
            "TOMSTUDY_CONFIGS_DIR": str(study.configs_dir),
            "TOMSTUDY_RECORDINGS_DIR": str(study.layout.recordings())}
    before = {key: os.environ.get(key) for key in keys}
    os.environ.update(keys)
    get_settings.cache_clear()
    try:
        yield get_settings()
    finally:
        for key, value in before.items():
            if value is None:
                os.environ.pop(key, None)
            else:
                os.environ[key] = value
        get_settings.cache_clear()


# ---------------------------------------------------------------- patience

# A hang guard's bound is set for a quiet machine of the reference's speed and scaled by how
# much slower this one runs right now, from two measures: the 1-minute load average per core
# (sustained contention, e.g. a parallel suite or a CPU hog) and a ~30 ms calibration loop
# timed against its uncontended time on the reference machine (reacts at once, and sees a
# slower CPU). Either alone misses a case: the load average lags a hog that just started;
# the short loop can fall between another process's time slices. The larger one wins.
CALIBRATION_CHUNKS = 40
REFERENCE_CHUNK_S = 0.00075  # one chunk's fastest time on the reference (2 cores, Python 3.11)
MAX_SLOWDOWN = 12.0  # beyond this a run is broken, not slow: a real hang still fails
_slowdown_cache: list[float] = [0.0, 1.0]  # (monotonic time measured, factor)


def _calibration_chunk() -> None:
    total = 0
    for i in range(20_000):
        total += i * i


def machine_slowdown() -> float:
    """How many times slower than the quiet reference machine this one runs now (1 to 12);
    remeasured at most every 5 s."""
    measured_at, factor = _slowdown_cache
    if time.monotonic() - measured_at < 5:
        return factor
    start = time.perf_counter()
    for _ in range(CALIBRATION_CHUNKS):
        _calibration_chunk()
    loop = (time.perf_counter() - start) / (CALIBRATION_CHUNKS * REFERENCE_CHUNK_S)
    load = os.getloadavg()[0] / (os.cpu_count() or 1)
    factor = min(MAX_SLOWDOWN, max(1.0, loop, load))
    _slowdown_cache[:] = [time.monotonic(), factor]
    return factor


def patience(seconds: float) -> float:
    """A hang guard's bound of `seconds` on a quiet machine, scaled by machine_slowdown()."""
    return seconds * machine_slowdown()


def researcher_get(url: str, token: str = ADMIN_TOKEN, **kwargs) -> httpx.Response:
    """GET a running server's researcher endpoint `url` with bearer `token`, waiting
    patience(30) unless `timeout` is given: a first export loads pandas and the analysis code,
    which httpx's fixed 5 s default does not wait for beside other busy processes."""
    kwargs.setdefault("timeout", patience(30))
    return httpx.get(url, headers={"Authorization": f"Bearer {token}"}, **kwargs)


# ---------------------------------------------------------------- servers

def free_port() -> int:
    """A TCP port nobody listens on right now."""
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


def start_server(study: SmallStudy, db_url: str, port: int, workers: int = 1,
                 log: Path | None = None, args: tuple[str, ...] = (), ready_s: float = 60,
                 **env: str) -> subprocess.Popen:
    """`tomstudy serve` as a real process (extra `args` and `env` variables); returns once
    it answers (RuntimeError if not within `ready_s` on a quiet machine, scaled by `patience`;
    the paper study's start recomputes every model answer of its bundle: give it more)."""
    out = open(log, "ab") if log else subprocess.DEVNULL  # noqa: SIM115 (the child keeps it)
    proc = subprocess.Popen(
        [TOMSTUDY, "serve", "--host", "127.0.0.1",
         "--port", str(port), "--workers", str(workers), "--study", study.study_id, *args],
        env=study.env(db_url, **env), stdout=out, stderr=subprocess.STDOUT, cwd=REPO)
    bound_s = patience(ready_s)
    deadline = time.monotonic() + bound_s
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            raise RuntimeError(f"server exited with {proc.returncode}; see {log}")
        try:
            page = httpx.get(f"http://127.0.0.1:{port}/s/{study.study_id}",
                             timeout=patience(1))
            if page.status_code == 200:
                return proc
        except httpx.TransportError:
            pass
        time.sleep(0.2)
    proc.kill()
    raise RuntimeError(f"server did not answer within {bound_s:.0f} s; see {log or 'its output'}")


def wait_for_log(log: Path, pattern: str, count: int, timeout_s: float = 60) -> list[str]:
    """The first `count` matches of `pattern` in the server's log, once it holds them."""
    deadline = time.monotonic() + patience(timeout_s)
    while True:
        found = re.findall(pattern, log.read_text())
        if len(found) >= count or time.monotonic() > deadline:
            return found
        time.sleep(0.2)


def stop_server(proc: subprocess.Popen, grace_s: float = 10) -> None:
    """Terminate a server a test started; kill it if it does not stop (it must not outlive
    the test)."""
    proc.terminate()
    try:
        proc.wait(timeout=patience(grace_s))
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait(timeout=patience(10))


@pytest.fixture(scope="session")
def live_server(small_study, tmp_path_factory):
    """A running `tomstudy serve` of the small study on SQLite; yields its base URL."""
    root = tmp_path_factory.mktemp("live")
    port = free_port()
    proc = start_server(small_study, f"sqlite:///{root / 'study.db'}", port,
                        log=root / "server.log")
    yield f"http://127.0.0.1:{port}"
    stop_server(proc)


# ---------------------------------------------------------------- PostgreSQL

@pytest.fixture(scope="session")
def postgres_url():
    """A throwaway PostgreSQL 15 cluster (Debian binaries); yields its SQLAlchemy URL."""
    if not (PG_BIN / "initdb").exists():
        pytest.skip(f"PostgreSQL binaries not found in {PG_BIN} (apt-get install postgresql)")
    root = Path(tempfile.mkdtemp(prefix="tomstudy-pg-"))  # pytest's tmp is private to root
    url, stop = start_cluster(root)
    yield url
    stop()
    shutil.rmtree(root, ignore_errors=True)


def start_cluster(root: Path, fsync: bool = False):
    """A PostgreSQL 15 cluster in `root` on a free loopback port; (URL, stop function)."""
    data = root / "data"
    as_postgres = ["runuser", "-u", "postgres", "--"] if os.geteuid() == 0 else []
    if as_postgres:
        shutil.chown(root, "postgres")
    subprocess.run([*as_postgres, str(PG_BIN / "initdb"), "-D", str(data), "-A", "trust",
                    "--no-sync", "-U", "postgres"], check=True, capture_output=True)
    port = free_port()
    options = (f"-c listen_addresses=127.0.0.1 -p {port} -k {root} -c max_connections=200"
               + ("" if fsync else " -c fsync=off"))
    subprocess.run([*as_postgres, str(PG_BIN / "pg_ctl"), "-D", str(data), "-o", options,
                    "-l", str(root / "pg.log"), "-w", "-t", str(round(patience(60))), "start"],
                   check=True, capture_output=True)

    def stop() -> None:
        subprocess.run([*as_postgres, str(PG_BIN / "pg_ctl"), "-D", str(data), "-m",
                        "immediate", "stop"], capture_output=True)

    return f"postgresql+psycopg://postgres@127.0.0.1:{port}/postgres", stop


def fresh_database(server_url: str, name: str) -> str:
    """Create an empty database `name` on the PostgreSQL server; returns its URL."""
    from sqlalchemy import create_engine, text

    engine = create_engine(server_url, isolation_level="AUTOCOMMIT")
    with engine.connect() as conn:
        conn.execute(text(f'DROP DATABASE IF EXISTS "{name}"'))
        conn.execute(text(f'CREATE DATABASE "{name}"'))
    engine.dispose()
    return server_url.rsplit("/", 1)[0] + f"/{name}"


# ---------------------------------------------------------------- Redis

@dataclass
class RedisServer:
    """A throwaway redis-server on a loopback port, no persistence; `stop` and `start` again
    (same port, empty) to take it away mid-run."""

    root: Path
    port: int
    proc: subprocess.Popen | None = None

    @property
    def url(self) -> str:
        """Its address as TOMSTUDY_RATE_LIMIT_STORAGE takes it."""
        return f"redis://127.0.0.1:{self.port}/0"

    def start(self) -> None:
        """Start it and return once it answers PING."""
        self.proc = subprocess.Popen(
            [str(REDIS_SERVER), "--port", str(self.port), "--bind", "127.0.0.1", "--save", "",
             "--appendonly", "no", "--dir", str(self.root), "--daemonize", "no"],
            stdout=open(self.root / "redis.log", "ab"), stderr=subprocess.STDOUT)  # noqa: SIM115
        deadline = time.monotonic() + 20
        while not self.answers():
            if self.proc.poll() is not None or time.monotonic() > deadline:
                self.stop()
                raise RuntimeError(f"redis-server did not start; see {self.root / 'redis.log'}")
            time.sleep(0.05)

    def answers(self) -> bool:
        """True if it answers PING."""
        try:
            with socket.create_connection(("127.0.0.1", self.port), timeout=1) as sock:
                sock.sendall(b"PING\r\n")
                return sock.recv(16).startswith(b"+PONG")
        except OSError:
            return False

    def stop(self) -> None:
        """Stop it (its counts are gone)."""
        if self.proc is not None:
            stop_server(self.proc)
            self.proc = None


@pytest.fixture
def redis_server(tmp_path_factory):
    """A throwaway redis-server (Debian's) on a free loopback port, stopped after the test."""
    if not REDIS_SERVER.exists():
        pytest.skip(f"{REDIS_SERVER} not found (apt-get install redis-server)")
    server = RedisServer(tmp_path_factory.mktemp("redis"), free_port())
    server.start()
    yield server
    server.stop()


# ---------------------------------------------------------------- the study app on each backend

_db_counter = itertools.count()


@pytest.fixture(params=["sqlite", pytest.param("postgres", marks=pytest.mark.postgres)])
def db_url(request, tmp_path):
    """A fresh empty database of each backend."""
    if request.param == "sqlite":
        return f"sqlite:///{tmp_path / 'study.db'}"
    return fresh_database(request.getfixturevalue("postgres_url"), f"api{next(_db_counter)}")


@pytest.fixture(scope="session")
def served_study(small_study):
    """The study `client` serves and `bank` reads (a test module may serve another)."""
    return small_study


@pytest.fixture
def client(served_study, db_url):
    """The app on a fresh database."""
    from tests.server.flow import make_client  # flow imports this module

    with make_client(served_study, db_url) as c:
        yield c


@pytest.fixture
def codes(client, served_study) -> dict[str, str]:
    """Each outcome's completion code as `client`'s app gives it (the study's generated ones)."""
    from app.server.flow.completion_codes import OUTCOMES

    recruitment = client.app.state.studies[served_study.study_id].config.recruitment
    return {outcome: recruitment.ending(outcome).completion_code for outcome in OUTCOMES}


@pytest.fixture(scope="module")
def bank(served_study) -> dict:
    """Bank trials by id (the test reads the true moves for attention checks)."""
    from app.layout import Layout

    raw = json.loads(Layout(served_study.data_dir).bank(served_study.study_id).read_text())
    return {t["trial_id"]: t for w in raw["worlds"].values() for t in w["trials"]}
