"""Issue 22: a withdrawal may name a session by its public id (open and pilot sessions have
no platform id), so each audit line records which kind of id its hash is of.

Existing lines were all by platform id: they get 'external_id'.
"""

import sqlalchemy as sa
from alembic import op

revision = "0005"
down_revision = "0004"
branch_labels = None
depends_on = None


def upgrade() -> None:
    """Add withdrawalaudit.id_kind."""
    op.add_column("withdrawalaudit", sa.Column("id_kind", sa.String(16), nullable=False,
                                               server_default=sa.text("'external_id'")))


def downgrade() -> None:
    """Drop withdrawalaudit.id_kind."""
    with op.batch_alter_table("withdrawalaudit") as batch:
        batch.drop_column("id_kind")
