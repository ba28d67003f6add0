"""Issue 20's selection arms: each answered trial records how its main trial was chosen
(`random` or `models_disagree`, trials.TrialRecord.arm).

Existing trials get '' (chosen before arms existed; practice and attention checks keep '').
"""

import sqlalchemy as sa
from alembic import op

revision = "0003"
down_revision = "0002"
branch_labels = None
depends_on = None


def upgrade() -> None:
    """Add trialresponse.arm."""
    op.add_column("trialresponse", sa.Column("arm", sa.String(16), nullable=False,
                                             server_default=sa.text("''")))


def downgrade() -> None:
    """Drop trialresponse.arm."""
    with op.batch_alter_table("trialresponse") as batch:
        batch.drop_column("arm")
