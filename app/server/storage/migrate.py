"""Schema revisions of the study database (Alembic, scripts in app/server/storage/migrations/).

The server creates an empty database at the newest revision and refuses any other
database that is not at it; `tomstudy db upgrade` moves one there, including a database
made before migrations existed (no alembic_version table), once its tables match a
known revision. On PostgreSQL an advisory lock makes both safe when several processes
start together. A schema change is a change to tables.py plus a new script in
migrations/versions/ (tests/server/test_migrations.py fails until the two agree).
"""

import hashlib
import re
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

from alembic import command
from alembic.config import Config
from alembic.runtime.migration import MigrationContext
from alembic.script import ScriptDirectory
from sqlalchemy import create_engine, func, inspect, select, table, text
from sqlalchemy.engine import Connection, Engine

MIGRATIONS_DIR = Path(__file__).resolve().parent / "migrations"
VERSION_TABLE = "alembic_version"
UPGRADE_HINT = ("back it up, then run `tomstudy db upgrade` with the same DATABASE_URL "
                "(docs/run/upgrading.md)")
_LOCK_KEY = int.from_bytes(hashlib.sha256(b"tomstudy:schema").digest()[:8], "big", signed=True)


class SchemaError(RuntimeError):
    """The database's schema is not one this tomstudy can serve or upgrade."""


class SchemaOutdated(SchemaError):
    """The database is at an older revision, or was made before migrations existed."""


class SchemaUnknown(SchemaError):
    """The database is at a revision this tomstudy does not know (a newer tomstudy's)."""


@dataclass(frozen=True)
class UpgradeReport:
    """What `upgrade` did: revisions (None = empty or unversioned) and rows per table."""

    before: str | None
    after: str
    stamped: str | None  # the revision an unversioned database was found to match
    rows_before: dict[str, int]
    rows_after: dict[str, int]


def upgrade_lines(report: UpgradeReport, where: str) -> list[str]:
    """What `db upgrade` did: from -> to revision, then rows per table before and after."""
    if report.stamped:
        before = f"no revision (made before migrations; its tables match {report.stamped})"
    else:
        before = report.before or "empty database"
    verb = "already at" if report.before == report.after else "upgraded to"
    lines = [f"{where}: {before} -> {verb} {report.after}",
             f"{'table':<16}{'rows before':>12}{'rows after':>12}"]
    for name in sorted(set(report.rows_before) | set(report.rows_after)):
        rows = [str(counts[name]) if name in counts else "-"
                for counts in (report.rows_before, report.rows_after)]
        lines.append(f"{name:<16}{rows[0]:>12}{rows[1]:>12}")
    return lines


def revision_lines(engine: Engine) -> list[str]:
    """What `db current` says: the database's revision, the newest, and what to do if they
    differ."""
    with engine.connect() as conn:
        revision, tables = current(conn), our_tables(conn)
    shown = revision or ("none (made before migrations)" if tables else "none (empty database)")
    lines = [f"revision: {shown}", f"head: {head()}"]
    if tables and revision != head():
        lines.append("back up the database, then run `tomstudy db upgrade` before serving it")
    return lines


def alembic_config(connection: Connection | None = None) -> Config:
    """Alembic's config, in code: the scripts folder and the connection to run on."""
    config = Config()
    config.set_main_option("script_location", str(MIGRATIONS_DIR))
    config.attributes["connection"] = connection
    return config


@lru_cache
def scripts() -> ScriptDirectory:
    """The revision scripts (read once per process)."""
    return ScriptDirectory.from_config(alembic_config())


def head() -> str:
    """The newest revision: the schema tables.py declares."""
    return scripts().get_current_head()


def revisions() -> list[str]:
    """Every revision, oldest first."""
    return [r.revision for r in reversed(list(scripts().walk_revisions()))]


def is_known(revision: str) -> bool:
    """True if `revision` is one of this tomstudy's scripts."""
    return revision in revisions()


def server_default_differs(_context, _inspected_column, _metadata_column, inspected: str | None,
                           _metadata_default, rendered: str | None) -> bool:
    """Alembic's `compare_server_default` hook: compare the SQL text of two defaults, with
    PostgreSQL's casts ('[]'::json) taken off (Alembic's own check cannot compare JSON)."""
    def bare(default: str | None) -> str | None:
        return None if default is None else re.sub(r"::[a-z ]+$", "", default.strip("() "))
    return bare(inspected) != bare(rendered)


def where(engine: Engine) -> str:
    """The database's URL without its password, for messages."""
    return engine.url.render_as_string(hide_password=True)


def lock(conn: Connection) -> None:
    """Serialise schema work until the transaction ends (PostgreSQL; SQLite has one writer)."""
    if conn.dialect.name == "postgresql":
        conn.execute(text("SELECT pg_advisory_xact_lock(:key)"), {"key": _LOCK_KEY})


def our_tables(conn: Connection) -> list[str]:
    """Tables of any revision (and alembic_version) that the database holds."""
    known = {t for r in revisions() for t in revision_columns(r)} | {VERSION_TABLE}
    return sorted(t for t in inspect(conn).get_table_names() if t in known)


def current(conn: Connection) -> str | None:
    """The database's revision, or None if it has no alembic_version row."""
    return MigrationContext.configure(conn).get_current_revision()


def prepare(engine: Engine) -> None:
    """Create an empty database at the head revision; refuse one at any other revision."""
    with engine.begin() as conn:
        lock(conn)  # a second worker waits here, then finds the tables made
        if not our_tables(conn):
            command.upgrade(alembic_config(conn), "head")
            return
        refuse_unless_head(conn, engine)


def check_at_head(engine: Engine) -> None:
    """Raise SchemaOutdated or SchemaUnknown unless the database is at the head revision."""
    with engine.connect() as conn:
        refuse_unless_head(conn, engine)


def refuse_unless_head(conn: Connection, engine: Engine) -> None:
    """check_at_head on an open connection."""
    revision = current(conn)
    if revision == head():
        return
    if revision is None:
        raise SchemaOutdated(
            f"DATABASE_URL: the database at {where(engine)} was made by an older tomstudy, "
            f"before schema migrations (it has no {VERSION_TABLE} table); {UPGRADE_HINT}")
    if not is_known(revision):
        raise SchemaUnknown(
            f"DATABASE_URL: the database at {where(engine)} is at schema revision "
            f"{revision}, which this tomstudy does not know (its newest is {head()}): a "
            "newer tomstudy made it; serve it with that version")
    raise SchemaOutdated(
        f"DATABASE_URL: the database at {where(engine)} is at schema revision {revision}; "
        f"this tomstudy needs {head()}; {UPGRADE_HINT}")


def upgrade(engine: Engine) -> UpgradeReport:
    """Bring the database to the head revision in one transaction, stamping an unversioned
    one with the revision its tables match; counts every table's rows before and after."""
    with engine.begin() as conn:
        lock(conn)
        before, rows_before = current(conn), row_counts(conn)
        if before is not None and not is_known(before):
            raise SchemaUnknown(f"DATABASE_URL: the database at {where(engine)} is at schema "
                                f"revision {before}, newer than this tomstudy's {head()}")
        stamped = None
        if before is None and rows_before:
            stamped = matching_revision(conn, engine)
            command.stamp(alembic_config(conn), stamped)
        command.upgrade(alembic_config(conn), "head")
        return UpgradeReport(before, current(conn), stamped, rows_before, row_counts(conn))


def row_counts(conn: Connection) -> dict[str, int]:
    """Rows in each of the study's tables present in the database."""
    return {name: conn.execute(select(func.count()).select_from(table(name))).scalar_one()
            for name in our_tables(conn) if name != VERSION_TABLE}


def matching_revision(conn: Connection, engine: Engine) -> str:
    """The newest revision whose tables and columns the unversioned database has exactly."""
    present = table_columns(conn)
    differences = {r: schema_differences(revision_columns(r), present) for r in revisions()}
    matches = [r for r, diff in differences.items() if not diff]
    if matches:
        return matches[-1]
    closest = min(differences, key=lambda r: len(differences[r]))
    raise SchemaError(
        f"DATABASE_URL: the database at {where(engine)} has no {VERSION_TABLE} table and its "
        f"tables match no schema revision; against revision {closest} (the closest): "
        f"{'; '.join(differences[closest])}. It was not made by a tomstudy release, or was "
        "changed by hand: leave it as it is and export its data with the version that made it")


def table_columns(conn: Connection) -> dict[str, list[str]]:
    """Column names of each of the study's tables in the database."""
    inspector = inspect(conn)
    return {name: [c["name"] for c in inspector.get_columns(name)]
            for name in our_tables(conn) if name != VERSION_TABLE}


@lru_cache
def revision_columns(revision: str) -> dict[str, list[str]]:
    """Column names of each table at `revision`, read from a scratch in-memory database."""
    scratch = create_engine("sqlite://")
    with scratch.begin() as conn:
        command.upgrade(alembic_config(conn), revision)
        inspector = inspect(conn)
        columns = {name: [c["name"] for c in inspector.get_columns(name)]
                   for name in inspector.get_table_names() if name != VERSION_TABLE}
    scratch.dispose()
    return columns


def schema_differences(expected: dict[str, list[str]], present: dict[str, list[str]]
                       ) -> list[str]:
    """What `present` lacks or has beyond `expected`, as readable items (empty if equal)."""
    items = [f"missing table {t}" for t in sorted(set(expected) - set(present))]
    items += [f"unexpected table {t}" for t in sorted(set(present) - set(expected))]
    for name in sorted(set(expected) & set(present)):
        missing = [c for c in expected[name] if c not in present[name]]
        extra = [c for c in present[name] if c not in expected[name]]
        if missing:
            items.append("missing columns " + ", ".join(f"{name}.{c}" for c in missing))
        if extra:
            items.append("unexpected columns " + ", ".join(f"{name}.{c}" for c in extra))
    return items
