"""Alembic's entry point for the study database: runs on the connection tomstudy hands it.

app/server/storage/migrate.py builds the Alembic config in code and passes an open connection in
`config.attributes["connection"]`; there is no alembic.ini and no URL here.
"""

from alembic import context
from sqlmodel import SQLModel

from app.server.storage import tables  # noqa: F401  (target metadata for autogenerate)
from app.server.storage.migrate import server_default_differs


def run_migrations() -> None:
    """Run the pending migrations on the caller's connection and transaction."""
    connection = context.config.attributes.get("connection")
    if context.is_offline_mode() or connection is None:
        raise RuntimeError("the study migrations run through `tomstudy db upgrade`")
    # SQLite alters most columns only by copying the table: batch mode does that
    context.configure(connection=connection, target_metadata=SQLModel.metadata,
                      render_as_batch=connection.dialect.name == "sqlite",
                      compare_type=True,
                      compare_server_default=server_default_differs)
    with context.begin_transaction():
        context.run_migrations()


run_migrations()
