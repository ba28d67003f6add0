"""Database engine for any SQLAlchemy URL: SQLite (WAL) by default, PostgreSQL via psycopg 3."""

from collections.abc import Iterator
from pathlib import Path

from sqlalchemy import Table, event, inspect
from sqlalchemy.dialects import postgresql, sqlite
from sqlalchemy.engine import URL, Connection, Engine, make_url
from sqlmodel import Session, create_engine

from app.server.storage import migrate, tables  # noqa: F401  (tables registers them on SQLModel.metadata)

CONNECT_TIMEOUT_S = 10


class NoDatabase(RuntimeError):
    """DATABASE_URL names no database holding a study's tables."""


def normalise_url(url: str) -> str:
    """Use psycopg 3 for plain postgresql:// URLs (SQLAlchemy would pick psycopg2)."""
    if url.startswith("postgresql://") or url.startswith("postgres://"):
        return "postgresql+psycopg://" + url.split("://", 1)[1]
    return url


def is_sqlite(url: str) -> bool:
    """True if `url` is a SQLite database (one process at a time may write to it)."""
    return make_url(normalise_url(url)).get_backend_name() == "sqlite"


def make_engine(url: str, connect_timeout_s: int = CONNECT_TIMEOUT_S) -> Engine:
    """An engine for `url`; SQLite files get WAL, a busy timeout and their folder created."""
    url = normalise_url(url)
    parsed = make_url(url)
    if parsed.get_backend_name() != "sqlite":
        return create_engine(url, pool_pre_ping=True, pool_size=10, max_overflow=20,
                             connect_args=server_connect_args(parsed, connect_timeout_s))
    if parsed.database and parsed.database != ":memory:":
        Path(parsed.database).parent.mkdir(parents=True, exist_ok=True)
    engine = create_engine(url, connect_args={"check_same_thread": False, "timeout": 30},
                           pool_size=20, max_overflow=20)
    event.listen(engine, "connect", _sqlite_pragmas)
    return engine


def open_existing(url: str) -> Engine:
    """An engine on a database that already holds the study tables at the newest revision;
    NoDatabase or migrate.SchemaError (each naming DATABASE_URL) otherwise."""
    url = normalise_url(url)
    parsed = make_url(url)
    if parsed.get_backend_name() == "sqlite" and not Path(parsed.database or "").is_file():
        raise NoDatabase(f"DATABASE_URL: no database file at {parsed.database}")
    engine = make_engine(url)
    try:
        if not inspect(engine).has_table("participant"):
            raise NoDatabase(f"DATABASE_URL: {migrate.where(engine)} holds no study tables")
        migrate.check_at_head(engine)
    except (NoDatabase, migrate.SchemaError):
        engine.dispose()
        raise
    return engine


def server_connect_args(url: URL, connect_timeout_s: int) -> dict:
    """A connect timeout for PostgreSQL, unless the URL sets its own."""
    # without one a dead database holds a worker for the operating system's TCP timeout
    if url.get_backend_name() == "postgresql" and "connect_timeout" not in url.query:
        return {"connect_timeout": connect_timeout_s}
    return {}


def _sqlite_pragmas(dbapi_connection, _record) -> None:
    cursor = dbapi_connection.cursor()
    # WAL lets readers run beside the writer; synchronous=NORMAL in WAL mode keeps every
    # commit across a process crash (SIGKILL) and only risks the last ones on power loss.
    cursor.execute("PRAGMA journal_mode=WAL")
    cursor.execute("PRAGMA synchronous=NORMAL")
    cursor.execute("PRAGMA foreign_keys=ON")
    # a withdrawal's deleted rows are overwritten with zeros, not left in free pages
    cursor.execute("PRAGMA secure_delete=ON")
    cursor.execute("PRAGMA busy_timeout=30000")
    cursor.close()


def insert_skipping_duplicates(conn: Connection, table: Table):
    """An INSERT that skips rows whose unique key is already stored (SQLite, PostgreSQL)."""
    return upsert(conn, table).on_conflict_do_nothing()


def upsert(conn: Connection, table: Table):
    """An INSERT that can say what to do on a conflict (ON CONFLICT: SQLite, PostgreSQL)."""
    dialect = postgresql if conn.dialect.name == "postgresql" else sqlite
    return dialect.insert(table)


def create_tables(engine: Engine) -> None:
    """Create an empty database at the newest schema revision; refuse (migrate.SchemaError)
    one at an older, unknown or no revision (safe when several workers start together)."""
    migrate.prepare(engine)


def session_scope(engine: Engine) -> Iterator[Session]:
    """A session per request (a FastAPI dependency body)."""
    with Session(engine) as session:
        yield session
