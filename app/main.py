"""The study server: `create_app(settings)` mounts every route of app/http (participant and
researcher), with a lifespan that loads studies, banks and models.

Per process state is read-only (configs, trial banks, model answers); everything that
changes lives in the database, so several uvicorn workers can serve one study.
"""

import asyncio
import gc
import logging
import os
from collections.abc import Callable
from contextlib import asynccontextmanager, suppress

from fastapi import FastAPI, Request
from fastapi.encoders import jsonable_encoder
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from fastapi.staticfiles import StaticFiles
from fastapi.templating import Jinja2Templates
from limits import RateLimitItem
from sqlalchemy.exc import InterfaceError, OperationalError
from sqlalchemy.exc import TimeoutError as PoolTimeout
from starlette.middleware.trustedhost import TrustedHostMiddleware
from starlette.types import ASGIApp, Receive, Scope, Send

from app.bank.bundle import BundleError
from app.bank.model_answers import BankMismatch, ModelAnswers
from app.bank.prepare import prepare_study
from app.bank.verify import load_bundle
from app.http.headers import MTURK_FRAMERS, SecurityHeaders
from app.http.limitstore import LimitStore
from app.http.lockout import TokenLockout
from app.http.openapi import declare_error_responses
from app.http.preflight import (
    STUDY_ENV,
    NotServable,
    check_data_dir_writable,
    check_database,
    check_rate_limit_storage,
    check_workers,
    forwarded_allow_ips,
    needs_generated_token,
    serve_settings,
    with_generated_token,
)
from app.http.ratelimit import RateLimit, parse_limit
from app.http.routes import dashboard, health, pages, participant, researcher
from app.server.bank_guard import check_bank_unchanged
from app.server.flow.balance import ensure_rows, sweep_stale
from app.server.flow.completion_codes import PublicCode, refuse_public_codes, served_config
from app.server.flow.context import StudyContext
from app.server.flow.prolific_check import recheck_loop
from app.server.flow.recruitment import preview_key
from app.server.prolific import client_from
from app.server.storage.db import create_tables, make_engine
from app.settings import REPO_ROOT, Settings, get_settings
from app.study.config import StudyConfig, config_sha256, load_study_config
from app.study.consent import consent_problem
from app.study.errors import Refused

MAX_BODY_BYTES = 64 * 1024
FRONTEND_DIR = REPO_ROOT / "frontend"
MIN_ADMIN_TOKEN_CHARS = 32
DB_RETRY_AFTER_S = 5  # a restarting database or a dropped network is usually back by then
logger = logging.getLogger(__name__)
NEW_TOKEN_HINT = ("set one with TOMSTUDY_ADMIN_TOKEN=$(python -c 'import secrets;"
                  "print(secrets.token_urlsafe(32))')")


class UnsafeSettings(NotServable):
    """The server must not start with these settings."""


def check_production(settings: Settings) -> None:
    """Refuse a server without a researcher token (there is no default), and production mode
    with a weak token, client clocks trusted or rate limits off; unreadable limits too."""
    rate_limits(settings)
    lockout_limit(settings)
    token = settings.admin_token.strip()
    problem = weak_token_problem(token) if settings.production or not token else None
    if problem:
        mode = (" in production mode (TOMSTUDY_PRODUCTION=1, a --host other than loopback or a "
                "public name in TOMSTUDY_ALLOWED_HOSTS)" if settings.production else "")
        raise UnsafeSettings(f"refusing to start{mode}: TOMSTUDY_ADMIN_TOKEN {problem}; "
                             f"{NEW_TOKEN_HINT}")
    if not settings.production:
        return
    if settings.trust_client_clock:
        raise UnsafeSettings("TOMSTUDY_TRUST_CLIENT_CLOCK is for pilots with bots; a "
                             "production server times trials itself; refusing to start")
    for name in ("rate_limit_starts", "rate_limit_requests", "researcher_lockout"):
        if not getattr(settings, name).strip():
            raise UnsafeSettings(f"TOMSTUDY_{name.upper()} is empty (no limit); a production "
                                 "server limits anonymous traffic; refusing to start")


def weak_token_problem(token: str) -> str | None:
    """What makes `token` unfit to guard a public server, or None."""
    token = token.strip()
    if not token:
        return "is not set (there is no default; `tomstudy serve` on loopback makes one)"
    if len(token) < MIN_ADMIN_TOKEN_CHARS:
        return f"has {len(token)} characters, fewer than {MIN_ADMIN_TOKEN_CHARS}"
    return None


def load_study(settings: Settings, study_id: str) -> StudyContext:
    """Config, bundle (bank and every checkpoint, verified against its manifest and each other)
    of one study; BundleError or BankMismatch if it cannot be served as it is, UnsafeSettings
    if its consent cannot be shown (in production: a [PLACEHOLDER] or a hand-typed time)."""
    config = load_study_config(settings, study_id)
    if settings.production:
        refuse_public_codes(config, study_id)
    problem = consent_problem(config, settings.production)
    if problem:
        mode = " in production mode" if settings.production else ""
        raise UnsafeSettings(f"refusing to serve study {study_id}{mode}: {problem}")
    bundle = load_bundle(config, study_id, settings.configs_dir, settings.layout)
    ctx = StudyContext(study_id, served_config(config, settings.layout, study_id), bundle.bank,
                       ModelAnswers(bundle), config_sha256=config_sha256(config),
                       preview_key=preview_key(settings.admin_token, study_id),
                       trust_client_clock=settings.trust_client_clock)
    ctx.estimate()  # the time and pay the pages state, computed before the first request
    return ctx


def servable_study(settings: Settings, study_id: str) -> StudyContext:
    """`load_study`, refusing (NotServable) a study whose bundle, answers or codes do not
    hold."""
    try:
        return load_study(settings, study_id)
    except (BundleError, BankMismatch, PublicCode) as err:
        raise NotServable(str(err)) from err


def ready_to_serve(settings: Settings, host: str, workers: int, study_ids: list[str],
                   allow_bank_change: bool = False, prepare: bool = False,
                   say: Callable[[str], None] = print) -> Settings:
    """The settings `tomstudy serve` runs with, once every check before the workers start
    passed (NotServable names what to fix); `prepare` first builds a missing bundle."""
    settings = serve_settings(settings, host, allow_bank_change)
    if needs_generated_token(settings):
        settings = with_generated_token(settings)
        say(f"researcher token for this run (TOMSTUDY_ADMIN_TOKEN is not set; set it to "
            f"keep one across restarts): {settings.admin_token}")
    check_production(settings)
    forwarded_allow_ips(settings)
    check_workers(settings, workers)
    check_rate_limit_storage(settings, workers, say)
    check_data_dir_writable(settings.layout)
    if prepare:
        for study_id in study_ids:
            try:
                prepare_study(settings, study_id, say=say)
            except (FileNotFoundError, ValueError) as err:  # missing or malformed inputs
                raise NotServable(f"{study_id}: its bundle cannot be built: {err}") from err
    check_database(settings, [servable_study(settings, sid) for sid in study_ids])
    return settings


def create_app(settings: Settings | None = None, studies: list[str] | None = None) -> FastAPI:
    """The FastAPI app serving `studies` (default: $TOMSTUDY_STUDY or paper_study)."""
    settings = settings or get_settings()
    check_production(settings)
    studies = studies or os.environ.get(STUDY_ENV, "paper_study").split(",")

    @asynccontextmanager
    async def lifespan(app: FastAPI):
        app.state.engine = make_engine(settings.resolved_database_url())
        create_tables(app.state.engine)
        app.state.studies = {sid: load_study(settings, sid) for sid in studies}
        for ctx in app.state.studies.values():
            if not settings.allow_bank_change:
                check_bank_unchanged(app.state.engine, ctx.study_id, ctx.bank.sha256)
            ensure_rows(app.state.engine, ctx)
        # The loaded banks, models and torch make ~330k long-lived objects: a full garbage
        # collection over them took 140 ms, a pause every request in flight would wait for.
        # They live as long as the process, so the collector stops scanning them.
        gc.collect()
        gc.freeze()
        sweep = asyncio.create_task(sweep_stale(app.state.engine, list(app.state.studies.values()),
                                                settings.stale_sweep_s))
        loops = [sweep, *prolific_loops(app, settings)]
        yield
        for loop in loops:
            loop.cancel()
            with suppress(asyncio.CancelledError):
                await loop
        app.state.engine.dispose()

    app = FastAPI(title="tomstudy", lifespan=lifespan, **docs_urls(settings),
                  description="Online study of how people predict a robot "
                              "(app/http/API.md).")
    app.state.settings = settings
    app.state.prolific = client_from(settings)  # None: no token, Prolific is not asked
    store = limit_store(settings)  # one per worker: the middleware and the lockout share it
    app.state.token_lockout = TokenLockout(lockout_limit(settings), store)
    app.state.default_study = studies[0]
    app.state.templates = Jinja2Templates(directory=FRONTEND_DIR / "templates")
    app.mount("/static", StaticFiles(directory=FRONTEND_DIR / "static"), name="static")
    for router in (pages.router, participant.router, researcher.router, dashboard.router,
                   health.router):
        app.include_router(router)
    add_error_handlers(app)
    add_database_down_handler(app)
    declare_error_responses(app)
    app.add_middleware(BodyLimit, max_bytes=MAX_BODY_BYTES)
    app.add_middleware(RateLimit, **rate_limits(settings), store=store)
    app.add_middleware(TrustedHostMiddleware, allowed_hosts=settings.trusted_hosts,
                       www_redirect=False)
    configs = [load_study_config(settings, sid) for sid in studies]
    if settings.production:  # before any worker serves: one line, not a lifespan traceback
        try:
            for sid, config in zip(studies, configs, strict=True):
                refuse_public_codes(config, sid)
        except PublicCode as err:
            raise UnsafeSettings(str(err)) from None
    app.add_middleware(SecurityHeaders, docs_paths=docs_paths(app),  # outermost: 413s too
                       framed_by=framing_origins(configs), form_targets=form_targets(configs))
    return app


def prolific_loops(app: FastAPI, settings: Settings) -> list[asyncio.Task]:
    """The task re-checking sessions Prolific could not be asked about (none without a token)."""
    if app.state.prolific is None:
        return []
    return [asyncio.create_task(recheck_loop(app.state.engine, app.state.prolific,
                                             list(app.state.studies.values()),
                                             settings.prolific_recheck_s))]


def rate_limits(settings: Settings) -> dict:
    """The RateLimit middleware's limits from the settings; UnsafeSettings if unreadable."""
    try:
        return {"starts": parse_limit("TOMSTUDY_RATE_LIMIT_STARTS", settings.rate_limit_starts),
                "requests": parse_limit("TOMSTUDY_RATE_LIMIT_REQUESTS",
                                        settings.rate_limit_requests)}
    except ValueError as err:
        raise UnsafeSettings(f"refusing to start: {err}") from None


def lockout_limit(settings: Settings) -> RateLimitItem | None:
    """The researcher routes' lockout limit after wrong tokens (None: off); UnsafeSettings if
    unreadable."""
    try:
        return parse_limit("TOMSTUDY_RESEARCHER_LOCKOUT", settings.researcher_lockout)
    except ValueError as err:
        raise UnsafeSettings(f"refusing to start: {err}") from None


def limit_store(settings: Settings) -> LimitStore:
    """The store the rate limits and the lockout count in; UnsafeSettings if its URI is not
    one the limits library can use."""
    try:
        return LimitStore(settings.rate_limit_storage)
    except ValueError as err:
        raise UnsafeSettings(f"refusing to start: {err}") from None


def framing_origins(configs: list[StudyConfig]) -> tuple[str, ...]:
    """Origins that may frame the pages: MTurk's when any served study recruits there."""
    platforms = {config.recruitment.platform for config in configs}
    return MTURK_FRAMERS if "mturk" in platforms else ()


def form_targets(configs: list[StudyConfig]) -> tuple[str, ...]:
    """Where a page may post a form: the MTurk submit hosts of the served MTurk studies."""
    hosts = {host for config in configs if config.recruitment.platform == "mturk"
             for host in config.recruitment.mturk_submit_hosts}
    return tuple(sorted(hosts))


def docs_urls(settings: Settings) -> dict:
    """FastAPI's defaults (/docs, /redoc, /openapi.json), or none of them in production."""
    if settings.production:  # a public map of every route helps nobody but a scanner
        return {"docs_url": None, "redoc_url": None, "openapi_url": None}
    return {}


def docs_paths(app: FastAPI) -> tuple[str, ...]:
    """The paths of the interactive API docs pages this app serves."""
    paths = (app.docs_url, app.redoc_url, app.swagger_ui_oauth2_redirect_url)
    return tuple(p for p in paths if p)


def add_error_handlers(app: FastAPI) -> None:
    """Refusals and validation errors become 4xx JSON naming the field; never echo input."""

    @app.exception_handler(Refused)
    async def refused(_: Request, err: Refused) -> JSONResponse:
        headers = {"WWW-Authenticate": "Bearer"} if err.status == 401 else {}
        body = {"detail": err.detail}
        if err.notice is not None:  # what the participant's page shows instead of `detail`
            body["notice"] = err.notice.as_dict()
        return JSONResponse(body, status_code=err.status, headers=headers | err.headers)

    @app.exception_handler(RequestValidationError)
    async def invalid(_: Request, err: RequestValidationError) -> JSONResponse:
        # FastAPI's default echoes the input, and a NaN in it cannot be written as JSON
        items = [{"loc": [_printable(p) for p in e["loc"]], "msg": e["msg"], "type": e["type"]}
                 for e in err.errors()]
        message = "; ".join(f"{'.'.join(str(p) for p in i['loc'][1:]) or 'body'}: {i['msg']}"
                            for i in items)
        return JSONResponse(jsonable_encoder({"detail": items, "message": message}),
                            status_code=422)


def _printable(part: str | int) -> str | int:
    """A location part as UTF-8 can carry it: a dict key may hold a lone surrogate."""
    if isinstance(part, str):
        return part.encode("utf-8", "backslashreplace").decode("utf-8")
    return part


def add_database_down_handler(app: FastAPI) -> None:
    """No connection to the database (down, unreachable, pool exhausted): 503 with
    Retry-After, and one log line per request instead of a traceback."""

    @app.exception_handler(OperationalError)
    @app.exception_handler(InterfaceError)
    @app.exception_handler(PoolTimeout)
    async def unavailable(request: Request, err: Exception) -> JSONResponse:
        cause = type(getattr(err, "orig", None) or err).__name__  # the driver's class, no host
        logger.warning("database unavailable (%s): %s %s answered 503", cause, request.method,
                       request.url.path)
        return JSONResponse({"detail": "database: unavailable, try again shortly"},
                            status_code=503, headers={"Retry-After": str(DB_RETRY_AFTER_S)})


class BodyLimit:
    """Answer 413 to request bodies over `max_bytes`, declared or streamed.

    The body (at most `max_bytes`) is read before the app runs and replayed to it, so an
    oversized chunked upload is refused before any handler sees it.
    """

    def __init__(self, app: ASGIApp, max_bytes: int) -> None:
        self.app = app
        self.max_bytes = max_bytes

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            return await self.app(scope, receive, send)
        declared = dict(scope.get("headers", [])).get(b"content-length")
        if declared is not None and (not declared.isdigit() or int(declared) > self.max_bytes):
            return await self._too_large(scope, send)
        chunks, size, more = [], 0, True
        while more:
            message = await receive()
            if message["type"] != "http.request":  # client went away
                return None
            chunks.append(message.get("body", b""))
            size += len(chunks[-1])
            more = message.get("more_body", False)
            if size > self.max_bytes:
                return await self._too_large(scope, send)
        body = b"".join(chunks)
        replayed = False

        async def replay() -> dict:
            nonlocal replayed
            if not replayed:
                replayed = True
                return {"type": "http.request", "body": body, "more_body": False}
            return await receive()

        await self.app(scope, replay, send)

    async def _too_large(self, scope: Scope, send: Send) -> None:
        response = JSONResponse({"detail": f"body: request body larger than {self.max_bytes} "
                                           f"bytes"}, status_code=413)
        await response(scope, _no_receive, send)


async def _no_receive() -> dict:
    return {"type": "http.disconnect"}


def app_from_env() -> FastAPI:
    """Factory for `uvicorn --factory` (several workers): settings from the environment."""
    return create_app(get_settings())
