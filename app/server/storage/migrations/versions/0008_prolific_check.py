"""Issue 32 item 2: Prolific's check of each session's SESSION_ID, and the payment audit.

`participant.prolific_check` is NULL for every existing row: no session was checked with
Prolific before, and no value would be true of them (the analysis treats NULL as not asked,
as for another platform). `paymentaudit` keeps one line per approval or return request sent to
Prolific's API.
"""

import sqlalchemy as sa
from alembic import op

revision = "0008"
down_revision = "0007"
branch_labels = None
depends_on = None


def upgrade() -> None:
    """Add participant.prolific_check and the paymentaudit table."""
    op.add_column("participant", sa.Column("prolific_check", sa.String(12), nullable=True))
    op.create_table(
        "paymentaudit",
        sa.Column("id", sa.Integer(), primary_key=True),
        sa.Column("study_id", sa.String(64), nullable=False),
        sa.Column("participant_id", sa.String(32), nullable=False),
        sa.Column("action", sa.String(16), nullable=False),
        sa.Column("via", sa.String(16), nullable=False),
        sa.Column("sent_at", sa.DateTime(timezone=True), nullable=False),
        sa.Column("ok", sa.Boolean(), nullable=False),
        sa.Column("result", sa.String(300), nullable=False),
    )
    op.create_index("ix_paymentaudit_study_id", "paymentaudit", ["study_id"])


def downgrade() -> None:
    """Drop the paymentaudit table and participant.prolific_check."""
    op.drop_index("ix_paymentaudit_study_id", table_name="paymentaudit")
    op.drop_table("paymentaudit")
    # not batch mode: on SQLite it rebuilds `participant`, which its child rows' foreign keys
    # refuse; SQLite >= 3.35 drops a plain column in place, as PostgreSQL does
    op.drop_column("participant", "prolific_check")
