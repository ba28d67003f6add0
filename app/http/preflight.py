"""What `tomstudy serve` checks before any worker starts, and what it hands the workers.

A refusal here names the setting or file to fix and comes before uvicorn forks, so an
unservable study fails once, clearly, instead of in every worker's traceback.
"""

import asyncio
import ipaddress
import os
import secrets
import tempfile
from collections.abc import Callable

from app.http.limitstore import SETTING as STORAGE_SETTING
from app.http.limitstore import LimitStore, reachable, shown
from app.layout import Layout
from app.server.bank_guard import BankChanged, check_bank_unchanged
from app.server.flow.context import StudyContext
from app.server.storage.db import create_tables, is_sqlite, make_engine
from app.server.storage.migrate import SchemaError
from app.settings import Settings, get_settings

STUDY_ENV = "TOMSTUDY_STUDY"  # the studies a worker serves (comma-separated ids)


class NotServable(RuntimeError):
    """The server must not start: the message names what to fix."""


def serve_settings(settings: Settings, host: str, allow_bank_change: bool = False) -> Settings:
    """`settings` for a server bound to `host` (production unless loopback), with
    --allow-bank-change applied."""
    settings = settings.for_host(host)
    if allow_bank_change:
        settings = settings.model_copy(update={"allow_bank_change": True})
    return settings


def forwarded_allow_ips(settings: Settings) -> str:
    """The peers uvicorn takes a client address from (X-Forwarded-For): the configured
    proxies, or 127.0.0.1; NotServable for `*` or an entry that is no address or network."""
    if os.environ.get("FORWARDED_ALLOW_IPS"):
        raise NotServable("FORWARDED_ALLOW_IPS: tomstudy serve does not read it; name your "
                          "reverse proxy's address in TOMSTUDY_TRUSTED_PROXIES instead")
    proxies = [p.strip() for p in settings.trusted_proxies.split(",") if p.strip()]
    for proxy in proxies:
        if proxy == "*":
            raise NotServable("TOMSTUDY_TRUSTED_PROXIES: '*' lets any client name its own "
                              "address (and so its own rate-limit key); give the proxy's "
                              "address or network, e.g. 172.17.0.1 or 10.0.0.0/16")
        try:
            ipaddress.ip_network(proxy, strict=False)
        except ValueError:
            raise NotServable(f"TOMSTUDY_TRUSTED_PROXIES: {proxy!r} is not an IP address or "
                              "network (host names are not resolved)") from None
    return ",".join(proxies) or "127.0.0.1"


def needs_generated_token(settings: Settings) -> bool:
    """True for a loopback server without a researcher token: it gets one for this run."""
    return not settings.admin_token.strip() and not settings.production


def with_generated_token(settings: Settings) -> Settings:
    """`settings` with a strong researcher token made for this run."""
    return settings.model_copy(update={"admin_token": secrets.token_urlsafe(32)})


def check_workers(settings: Settings, workers: int) -> None:
    """Refuse several workers on SQLite: one process at a time may write to it."""
    if workers > 1 and is_sqlite(settings.resolved_database_url()):
        raise NotServable(
            f"--workers {workers} needs a database several processes can share: set "
            f"DATABASE_URL to PostgreSQL (postgresql+psycopg://user:password@host:5432/db), "
            f"or serve SQLite with --workers 1")


def check_rate_limit_storage(settings: Settings, workers: int,
                             say: Callable[[str], None] = print) -> None:
    """Refuse a rate-limit store that is not a `limits` URI or cannot be reached, and (in
    production) several workers with limits on that each count in their own memory; on
    loopback that gets a warning."""
    try:
        store = LimitStore(settings.rate_limit_storage)
    except ValueError as err:
        raise NotServable(str(err)) from None
    if store.shared:
        if not asyncio.run(reachable(store.storage)):
            raise NotServable(f"{STORAGE_SETTING}: cannot reach {shown(store.uri)} (no answer "
                              "to PING); start it, or fix the address")
        return
    limits_on = any(getattr(settings, name).strip() for name in (
        "rate_limit_starts", "rate_limit_requests", "researcher_lockout"))
    if workers == 1 or not limits_on:
        return
    problem = (f"--workers {workers} with {STORAGE_SETTING}={store.uri}: each worker counts "
               f"the rate limits in its own memory, so a client gets up to {workers} times "
               "each limit; set it to a Redis every worker shares (redis://host:6379/0)")
    if settings.production:
        raise NotServable(problem)
    say(f"warning: {problem}")


def check_data_dir_writable(layout: Layout) -> None:
    """Refuse a data dir this user cannot write (a bind mount owned by another user,
    typically), saying what to do, instead of a traceback from the first file written."""
    data_dir = layout.root
    try:
        data_dir.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=data_dir):
            pass
    except OSError as err:
        raise NotServable(
            f"TOMSTUDY_DATA_DIR: {data_dir} is not writable by this user (uid {os.getuid()}): "
            f"{err.strerror}. Give it to this user (on the host of a bind mount: "
            f"`sudo chown -R {os.getuid()} <the mounted folder>`), or use a volume") from None


def check_database(settings: Settings, studies: list[StudyContext]) -> None:
    """Make an empty database; refuse one that needs `tomstudy db upgrade` or whose sessions
    ran another trial bank (unless allowed)."""
    engine = make_engine(settings.resolved_database_url())
    try:
        create_tables(engine)  # once, before workers race to create them
        if not settings.allow_bank_change:
            for ctx in studies:
                check_bank_unchanged(engine, ctx.study_id, ctx.bank.sha256)
    except (SchemaError, BankChanged) as err:
        raise NotServable(str(err)) from err
    finally:
        engine.dispose()


def worker_environment(settings: Settings, study_ids: list[str]) -> dict[str, str]:
    """The variables a worker needs to rebuild `settings` and serve `study_ids`.

    uvicorn starts each worker from an import string (app.main:app_from_env), which reads
    Settings from the environment: so what serve decided (production off loopback,
    --allow-bank-change, a token made for this run) must be in it. A token read from a file
    stays in its file."""
    env = {STUDY_ENV: ",".join(study_ids)}
    if settings.allow_bank_change:
        env["TOMSTUDY_ALLOW_BANK_CHANGE"] = "1"
    if settings.production:
        env["TOMSTUDY_PRODUCTION"] = "1"
    if settings.admin_token_file is None and settings.admin_token:
        env["TOMSTUDY_ADMIN_TOKEN"] = settings.admin_token
    return env


def hand_to_workers(settings: Settings, study_ids: list[str]) -> None:
    """Put `worker_environment` into this process's environment (workers inherit it) and
    forget the cached settings (a single worker runs in this process)."""
    os.environ.update(worker_environment(settings, study_ids))
    get_settings.cache_clear()
