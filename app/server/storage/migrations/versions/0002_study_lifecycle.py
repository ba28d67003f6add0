"""Issue 11's study lifecycle (commit 4082fe5): each session's ending receipt and what it
ran, each trial's undo history, and the withdrawal audit.

Existing sessions get '' for the hashes and version (unknown: made before they were
stored) and existing trials an empty history.
"""

import sqlalchemy as sa
from alembic import op

revision = "0002"
down_revision = "0001"
branch_labels = None
depends_on = None

RECEIPT = ("outcome", "completion_code", "ended_at")
RAN = ("config_sha256", "bank_sha256", "app_version")


def upgrade() -> None:
    """Add the lifecycle columns and the withdrawalaudit table; completed sessions get their
    outcome."""
    op.add_column("participant", sa.Column("outcome", sa.String(20), nullable=True))
    op.add_column("participant", sa.Column("completion_code", sa.String(64), nullable=True))
    op.add_column("participant", sa.Column("ended_at", sa.DateTime(timezone=True), nullable=True))
    for name, length in zip(RAN, (64, 64, 32), strict=True):
        op.add_column("participant", sa.Column(name, sa.String(length), nullable=False,
                                               server_default=sa.text("''")))
    op.add_column("trialresponse", sa.Column("history", sa.JSON(), nullable=True,
                                             server_default=sa.text("'[]'")))
    op.create_table(
        "withdrawalaudit",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("study_id", sa.String(64), nullable=False),
        sa.Column("salt", sa.String(32), nullable=False),
        sa.Column("id_sha256", sa.String(64), nullable=False),
        sa.Column("withdrawn_at", sa.DateTime(timezone=True), nullable=False),
        sa.Column("via", sa.String(16), nullable=False),
        sa.Column("row_counts", sa.JSON(), nullable=True),
        sa.PrimaryKeyConstraint("id"),
    )
    op.create_index("ix_withdrawalaudit_study_id", "withdrawalaudit", ["study_id"])
    # Sessions completed before endings existed ended as `completed` (the only ending then);
    # the code they were shown came from the config of the day, so it stays unknown (NULL).
    op.execute(sa.text("UPDATE participant SET outcome = 'completed', ended_at = completed_at "
                       "WHERE completed AND outcome IS NULL"))


def downgrade() -> None:
    """Drop what upgrade added."""
    op.drop_index("ix_withdrawalaudit_study_id", "withdrawalaudit")
    op.drop_table("withdrawalaudit")
    with op.batch_alter_table("trialresponse") as batch:
        batch.drop_column("history")
    with op.batch_alter_table("participant") as batch:
        for name in RECEIPT + RAN:
            batch.drop_column(name)
