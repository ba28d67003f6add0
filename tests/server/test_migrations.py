"""Schema migrations: tables.py and the head revision agree, 0001 is the schema before
migrations, upgrading keeps every row, and the server refuses what needs `db upgrade`."""

import os
import sqlite3
import subprocess
import threading
from pathlib import Path

import pytest
from alembic import command
from alembic.autogenerate import compare_metadata
from alembic.runtime.migration import MigrationContext
from sqlalchemy import MetaData, inspect, select, text
from sqlmodel import SQLModel

from app.server.storage import migrate
from app.server.storage.db import create_tables, make_engine
from tests.conftest import TOMSTUDY, fresh_database, patience
from tests.server.flow import Participant, make_client

FIXTURE = Path(__file__).parent / "fixtures" / "db_9c39751.sql"
# rows per table in the fixture: 3 bots' completed sessions, a pilot and an unfinished one
FIXTURE_ROWS = {"participant": 5, "balancecount": 5, "submission": 20, "trialresponse": 9,
                "predictionrow": 27, "event": 18}
PARENTS_FIRST = ["participant", "balancecount", "submission", "trialresponse",
                 "predictionrow", "event"]


def load_fixture(path: Path) -> str:
    """A SQLite database at `path` made from the 9c39751 dump; returns its URL."""
    with sqlite3.connect(path) as conn:
        conn.executescript(FIXTURE.read_text())
    return f"sqlite:///{path}"


def migrate_to(engine, revision: str) -> None:
    """Run the migrations up to `revision` on an empty database."""
    with engine.begin() as conn:
        command.upgrade(migrate.alembic_config(conn), revision)


def copy_rows(source, target) -> None:
    """Every row of the study's tables from `source` into `target` (same revision)."""
    src, dst = MetaData(), MetaData()
    src.reflect(source)
    dst.reflect(target)
    with source.connect() as read, target.begin() as write:
        for name in PARENTS_FIRST:
            rows = [dict(r._mapping) for r in read.execute(select(src.tables[name]))]
            write.execute(dst.tables[name].insert(), rows)
            if target.dialect.name == "postgresql" and "id" in dst.tables[name].c:
                write.execute(text(f"SELECT setval(pg_get_serial_sequence('{name}', 'id'), "
                                   f"(SELECT max(id) FROM {name}))"))


def snapshot(engine, columns: dict[str, list[str]] | None = None) -> dict[str, list[tuple]]:
    """Every row of every study table (or only `columns` of them), in primary-key order."""
    meta = MetaData()
    meta.reflect(engine)
    tables = columns or {name: [c.name for c in meta.tables[name].c] for name in PARENTS_FIRST}
    with engine.connect() as conn:
        return {name: [tuple(r) for r in conn.execute(
                    select(*[meta.tables[name].c[c] for c in cols])
                    .order_by(*meta.tables[name].primary_key.columns))]
                for name, cols in tables.items()}


def schema_shape(engine) -> dict:
    """Columns (name, type family, length, nullable), keys and indexes of each study table."""
    inspector = inspect(engine)
    shape = {}
    for name in PARENTS_FIRST:
        columns = [(c["name"], c["type"]._type_affinity.__name__,
                    getattr(c["type"], "length", None), c["nullable"])
                   for c in inspector.get_columns(name)]
        indexes = sorted((i["name"], tuple(i["column_names"]), bool(i["unique"]),
                          any("where" in k for k in i.get("dialect_options", {})))
                         for i in inspector.get_indexes(name)
                         if not i.get("duplicates_constraint"))  # PostgreSQL's UNIQUE index
        uniques = sorted(tuple(u["column_names"]) for u in inspector.get_unique_constraints(name))
        keys = sorted((tuple(f["constrained_columns"]), f["referred_table"])
                      for f in inspector.get_foreign_keys(name))
        primary = inspector.get_pk_constraint(name)["constrained_columns"]
        shape[name] = (columns, indexes, uniques, keys, primary)
    return shape


def cli(*args: str, db_url: str) -> subprocess.CompletedProcess:
    """Run `tomstudy args...` against `db_url`."""
    env = dict(os.environ, DATABASE_URL=db_url)
    return subprocess.run([TOMSTUDY, *args], env=env, capture_output=True, text=True,
                          timeout=patience(120))


# ---------------------------------------------------------------- the schema itself

def test_tables_py_and_the_head_revision_agree(db_url):
    """Fails when a column, index or default of tables.py has no migration (add one)."""
    engine = make_engine(db_url)
    create_tables(engine)  # an empty database is made by running every migration
    with engine.connect() as conn:
        context = MigrationContext.configure(
            conn, opts={"compare_type": True,
                        "compare_server_default": migrate.server_default_differs})
        assert migrate.current(conn) == migrate.head()
        differences = compare_metadata(context, SQLModel.metadata)
    assert differences == [], (f"tables.py differs from revision {migrate.head()}: add a revision "
                               f"to app/server/storage/migrations/versions/ ({differences})")
    engine.dispose()


def test_revision_0001_is_the_schema_made_before_migrations(db_url, tmp_path):
    before = make_engine(load_fixture(tmp_path / "old.db"))
    engine = make_engine(db_url)
    migrate_to(engine, "0001")
    assert schema_shape(engine) == schema_shape(before)
    if engine.dialect.name == "sqlite":  # the very DDL 9c39751's create_all wrote
        ddl = "SELECT type, name, sql FROM sqlite_master WHERE name != 'alembic_version' " \
              "AND name NOT LIKE 'sqlite_autoindex%' ORDER BY name"
        with before.connect() as old, engine.connect() as new:
            assert new.execute(text(ddl)).all() == old.execute(text(ddl)).all()
    engine.dispose()
    before.dispose()


def test_every_revision_downgrades_and_upgrades_again(db_url):
    engine = make_engine(db_url)
    create_tables(engine)
    with engine.begin() as conn:
        command.downgrade(migrate.alembic_config(conn), "base")
        assert migrate.our_tables(conn) == ["alembic_version"]
        command.upgrade(migrate.alembic_config(conn), "head")
        assert migrate.current(conn) == migrate.head()
    engine.dispose()


# ---------------------------------------------------------------- upgrades keep every row

def old_rows_at(db_url: str, tmp_path, revision: str):
    """The old fixture's engine, and its rows copied into `db_url` migrated to `revision`."""
    source = make_engine(load_fixture(tmp_path / "old.db"))
    engine = make_engine(db_url)
    migrate_to(engine, "0001")
    copy_rows(source, engine)
    migrate_to(engine, revision)
    return source, engine


def test_upgrading_keeps_every_row_and_value(db_url, tmp_path, small_study):
    source, engine = old_rows_at(db_url, tmp_path, "0001")
    before = snapshot(engine)
    assert {name: len(rows) for name, rows in before.items()} == FIXTURE_ROWS

    report = migrate.upgrade(engine)

    assert (report.before, report.after, report.stamped) == ("0001", migrate.head(), None)
    assert report.rows_before == FIXTURE_ROWS
    assert report.rows_after == FIXTURE_ROWS | {"withdrawalaudit": 0, "trialdraft": 0,
                                                "paymentaudit": 0}
    old_columns = {name: list(migrate.revision_columns("0001")[name]) for name in before}
    assert snapshot(engine, old_columns) == before
    added = snapshot(engine, {"participant": ["config_sha256", "bank_sha256", "app_version",
                                              "outcome", "completion_code", "completed",
                                              "completed_at", "ended_at"],
                              "trialresponse": ["history"],
                              "predictionrow": ["plugins", "click_input"]})
    # a session completed before endings existed ended as `completed`; its code is unknown
    assert {row[:5] for row in added["participant"]} == {("", "", "", None, None),
                                                         ("", "", "", "completed", None)}
    for *_, outcome, _code, completed, completed_at, ended_at in added["participant"]:
        assert (outcome == "completed") == bool(completed) and ended_at == completed_at
    assert added["trialresponse"] == [([],)] * FIXTURE_ROWS["trialresponse"]
    # rows answered before plug-in predictors existed hold none (0006); their clicks' input
    # device was never recorded (0007)
    assert added["predictionrow"] == [({}, None)] * FIXTURE_ROWS["predictionrow"]
    with make_client(small_study, db_url) as client:  # the ORM writes into the old tables
        Participant(client, small_study.study_id).start()
        assert client.get("/healthz").status_code == 200
    with engine.connect() as conn:
        assert conn.execute(text("SELECT count(*) FROM participant")).scalar_one() == 6
    engine.dispose()
    source.dispose()


def test_0004_moves_a_session_that_ended_early_back_to_the_step_it_ended_at(db_url, tmp_path):
    source, engine = old_rows_at(db_url, tmp_path, "0003")
    with engine.begin() as conn:  # the unfinished session declined, as 0003's code stored it
        conn.execute(text("UPDATE participant SET outcome = 'declined_consent', "
                          "position = 20 WHERE id = 5"))
        conn.execute(text("UPDATE submission SET kind = 'decline', step_index = 0 WHERE id = "
                          "(SELECT min(id) FROM submission WHERE participant_id = 5)"))
        positions = dict(conn.execute(text("SELECT id, position FROM participant")).all())

    migrate.upgrade(engine)

    with engine.connect() as conn:
        after = dict(conn.execute(text("SELECT id, position FROM participant")).all())
    assert after == positions | {5: 0}
    engine.dispose()
    source.dispose()


def test_0006_adds_plugin_answers_and_takes_them_away_again(db_url):
    engine = make_engine(db_url)
    migrate_to(engine, "0006")
    assert "plugins" in migrate.revision_columns("0006")["predictionrow"]
    assert "plugins" not in migrate.revision_columns("0005")["predictionrow"]
    with engine.begin() as conn:
        command.downgrade(migrate.alembic_config(conn), "0005")
        columns = [c["name"] for c in inspect(conn).get_columns("predictionrow")]
    assert "plugins" not in columns and "vae_sha256" in columns
    migrate_to(engine, "0006")
    with engine.connect() as conn:
        assert "plugins" in [c["name"] for c in inspect(conn).get_columns("predictionrow")]
    engine.dispose()


def test_0007_leaves_the_input_of_clicks_stored_before_it_unknown(db_url, tmp_path):
    source, engine = old_rows_at(db_url, tmp_path, "0006")
    columns = {"predictionrow": ["id", "click_x", "click_time_ms", "plugins"]}
    before = snapshot(engine, columns)

    migrate_to(engine, "0007")

    assert snapshot(engine, columns) == before
    inputs = snapshot(engine, {"predictionrow": ["click_input"]})["predictionrow"]
    assert inputs == [(None,)] * FIXTURE_ROWS["predictionrow"]
    with engine.begin() as conn:
        command.downgrade(migrate.alembic_config(conn), "0006")
        columns_0006 = [c["name"] for c in inspect(conn).get_columns("predictionrow")]
    assert "click_input" not in columns_0006 and "plugins" in columns_0006
    assert snapshot(engine, columns) == before
    engine.dispose()
    source.dispose()


def test_0008_leaves_sessions_stored_before_it_unchecked_by_prolific(db_url, tmp_path):
    source, engine = old_rows_at(db_url, tmp_path, "0007")
    columns = {"participant": ["id", "external_id", "counted", "attempt_key"]}
    before = snapshot(engine, columns)

    migrate_to(engine, "0008")

    assert snapshot(engine, columns) == before
    checks = snapshot(engine, {"participant": ["prolific_check"]})["participant"]
    assert checks == [(None,)] * FIXTURE_ROWS["participant"]  # never asked, so not excluded
    with engine.begin() as conn:
        command.downgrade(migrate.alembic_config(conn), "0007")
        found = inspect(conn)
        assert "prolific_check" not in [c["name"] for c in found.get_columns("participant")]
        assert "paymentaudit" not in found.get_table_names()
    assert snapshot(engine, columns) == before
    engine.dispose()
    source.dispose()


def test_db_upgrade_on_the_database_9c39751_made(tmp_path):
    url = load_fixture(tmp_path / "study.db")
    engine = make_engine(url)
    with pytest.raises(migrate.SchemaOutdated,
                       match=r"`tomstudy db upgrade` .*\(docs/run/upgrading\.md\)"):
        create_tables(engine)
    with engine.connect() as conn:
        plan = conn.execute(text("SELECT plan FROM participant WHERE id = 1")).scalar_one()
        human = conn.execute(text("SELECT human_vx, human_vy FROM predictionrow "
                                  "ORDER BY id")).all()
        attention = conn.execute(text("SELECT attention_ok FROM trialresponse "
                                      "WHERE attention_check ORDER BY id")).all()

    run = cli("db", "upgrade", db_url=url)

    assert run.returncode == 0, run.stderr
    lines = run.stdout.splitlines()
    assert "no revision (made before migrations; its tables match 0001) -> upgraded to " \
           f"{migrate.head()}" in lines[0]
    counted = {line.split()[0]: line.split()[1:] for line in lines[2:]}
    assert counted == {name: [str(n), str(n)] for name, n in FIXTURE_ROWS.items()} \
        | {"withdrawalaudit": ["-", "0"], "trialdraft": ["-", "0"], "paymentaudit": ["-", "0"]}
    create_tables(engine)  # the server accepts it now
    with engine.connect() as conn:
        assert conn.execute(text("SELECT plan FROM participant WHERE id = 1")).scalar_one() \
            == plan
        assert conn.execute(text("SELECT human_vx, human_vy FROM predictionrow "
                                 "ORDER BY id")).all() == human
        assert conn.execute(text("SELECT attention_ok FROM trialresponse "
                                 "WHERE attention_check ORDER BY id")).all() == attention
        pilots = conn.execute(text("SELECT count(*) FROM participant WHERE pilot")).scalar_one()
    assert pilots == 1 and len(human) == 27 and len(attention) == 3
    assert cli("db", "current", db_url=url).stdout.splitlines()[0] == \
        f"revision: {migrate.head()}"
    engine.dispose()


def test_an_unversioned_database_at_the_newest_schema_is_stamped_as_such(db_url):
    engine = make_engine(db_url)
    SQLModel.metadata.create_all(engine)  # this schema, made without Alembic's version table
    report = migrate.upgrade(engine)
    assert (report.before, report.stamped, report.after) == (None, migrate.head(),
                                                             migrate.head())
    engine.dispose()


def test_db_upgrade_refuses_tables_that_match_no_revision(tmp_path):
    db = tmp_path / "odd.db"
    with sqlite3.connect(db) as conn:
        conn.execute("CREATE TABLE participant (id INTEGER PRIMARY KEY, study_id VARCHAR, "
                     "nickname VARCHAR)")
    run = cli("db", "upgrade", db_url=f"sqlite:///{db}")
    assert run.returncode == 2 and "Traceback" not in run.stderr
    assert "match no schema revision" in run.stderr
    assert "missing columns participant.recruitment" in run.stderr
    assert "unexpected columns participant.nickname" in run.stderr
    assert "missing table predictionrow" in run.stderr
    with sqlite3.connect(db) as conn:  # left as it was
        tables = [r[0] for r in conn.execute("SELECT name FROM sqlite_master WHERE "
                                             "type = 'table'")]
    assert tables == ["participant"]


def test_db_upgrade_makes_an_empty_database(tmp_path):
    url = f"sqlite:///{tmp_path / 'new.db'}"
    assert cli("db", "current", db_url=url).stdout.startswith("revision: none (empty")
    run = cli("db", "upgrade", db_url=url)
    assert run.returncode == 0 and f"empty database -> upgraded to {migrate.head()}" in run.stdout


# ---------------------------------------------------------------- the server refuses

def test_the_server_refuses_a_database_at_an_older_revision(db_url):
    engine = make_engine(db_url)
    migrate_to(engine, "0001")
    with pytest.raises(migrate.SchemaOutdated, match=r"revision 0001; this tomstudy needs "
                                                     rf"{migrate.head()}; .*`tomstudy db upgrade`"):
        create_tables(engine)
    engine.dispose()


def test_the_server_refuses_an_unknown_revision(db_url):
    engine = make_engine(db_url)
    create_tables(engine)
    with engine.begin() as conn:
        conn.execute(text("UPDATE alembic_version SET version_num = '0999'"))
    with pytest.raises(migrate.SchemaUnknown, match="revision 0999, which this tomstudy "
                                                    "does not know"):
        create_tables(engine)
    with pytest.raises(migrate.SchemaUnknown, match="0999, newer than"):
        migrate.upgrade(engine)
    engine.dispose()


def test_serve_refuses_an_unversioned_database_naming_the_command(small_study, tmp_path):
    url = load_fixture(tmp_path / "study.db")
    run = subprocess.run([TOMSTUDY, "serve", "--port", "1", "--study", small_study.study_id],
                         env=small_study.env(url), capture_output=True, text=True,
                         timeout=patience(120))
    assert run.returncode == 2 and "Traceback" not in run.stderr
    assert "before schema migrations" in run.stderr and "`tomstudy db upgrade`" in run.stderr


@pytest.mark.postgres
def test_workers_starting_together_make_the_database_once(postgres_url):
    url = fresh_database(postgres_url, "together")
    engines = [make_engine(url) for _ in range(4)]
    start, errors = threading.Barrier(len(engines)), []

    def prepare(engine) -> None:
        start.wait()
        try:
            create_tables(engine)
        except Exception as err:  # noqa: BLE001 (collected and asserted below)
            errors.append(err)

    threads = [threading.Thread(target=prepare, args=(e,)) for e in engines]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert errors == []
    with engines[0].connect() as conn:
        assert conn.execute(text("SELECT version_num FROM alembic_version")).all() == \
            [(migrate.head(),)]
    for engine in engines:
        engine.dispose()


def test_export_refuses_a_database_that_needs_an_upgrade(tmp_path):
    run = cli("export", "--study", "paper_study", "--what", "participants",
              db_url=load_fixture(tmp_path / "study.db"))
    assert run.returncode == 2 and "Traceback" not in run.stderr
    assert "`tomstudy db upgrade`" in run.stderr


def test_0009_leaves_how_earlier_trials_were_played_unknown(db_url, tmp_path):
    source, engine = old_rows_at(db_url, tmp_path, "0008")
    columns = {"trialresponse": ["id", "trial_id", "replays", "history"]}
    before = snapshot(engine, columns)

    migrate_to(engine, "0009")

    assert snapshot(engine, columns) == before
    played = snapshot(engine, {"trialresponse": ["reduced_motion"]})["trialresponse"]
    assert played == [(None,)] * FIXTURE_ROWS["trialresponse"]
    with engine.begin() as conn:
        command.downgrade(migrate.alembic_config(conn), "0008")
        columns_0008 = [c["name"] for c in inspect(conn).get_columns("trialresponse")]
    assert "reduced_motion" not in columns_0008 and "history" in columns_0008
    assert snapshot(engine, columns) == before
    engine.dispose()
    source.dispose()
