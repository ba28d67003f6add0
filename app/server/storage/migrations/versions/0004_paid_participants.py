"""Issue 21's paid participants: answers in progress survive a reload, one tab writes, and
a session that ended early counts only the steps it took.

- `trialdraft`: the current trial's clicks so far, one row per session (drafts.py).
- `participant.live_tab`, `live_tab_seen_at`: the browser tab that may write (tabs.py).
- A session that declined consent or was screened out used to jump to its last step, so
  the dashboard showed every trial done; it now stays at the step that ended it. Existing
  such sessions are moved back to the step their ending was sent from.
"""

import sqlalchemy as sa
from alembic import op

revision = "0004"
down_revision = "0003"
branch_labels = None
depends_on = None

EARLY_ENDINGS = "('declined_consent', 'screened_out')"


def upgrade() -> None:
    """Add the draft table and the live-tab columns; early endings keep their real position."""
    op.add_column("participant", sa.Column("live_tab", sa.String(64), nullable=True))
    op.add_column("participant", sa.Column("live_tab_seen_at", sa.DateTime(timezone=True),
                                           nullable=True))
    op.create_table(
        "trialdraft",
        sa.Column("participant_id", sa.Integer(), nullable=False),
        sa.Column("trial_ref", sa.String(64), nullable=False),
        sa.Column("seq", sa.Integer(), nullable=False),
        sa.Column("data", sa.JSON(), nullable=True),
        sa.Column("saved_at", sa.DateTime(timezone=True), nullable=False),
        sa.ForeignKeyConstraint(["participant_id"], ["participant.id"]),
        sa.PrimaryKeyConstraint("participant_id"),
    )
    op.execute(sa.text(
        "UPDATE participant SET position = (SELECT MIN(submission.step_index) FROM submission "
        "WHERE submission.participant_id = participant.id "
        "AND submission.kind IN ('decline', 'screen_out')) "
        f"WHERE outcome IN {EARLY_ENDINGS} AND EXISTS (SELECT 1 FROM submission "
        "WHERE submission.participant_id = participant.id "
        "AND submission.kind IN ('decline', 'screen_out'))"))


def downgrade() -> None:
    """Drop what upgrade added; early endings go back to their plan's last step, where the
    older code looks for an ended session."""
    length = ("json_array_length(plan)" if op.get_bind().dialect.name == "sqlite"
              else "json_array_length(plan::json)")
    op.execute(sa.text(f"UPDATE participant SET position = {length} - 1 "
                       f"WHERE outcome IN {EARLY_ENDINGS}"))
    op.drop_table("trialdraft")
    with op.batch_alter_table("participant") as batch:
        batch.drop_column("live_tab_seen_at")
        batch.drop_column("live_tab")
