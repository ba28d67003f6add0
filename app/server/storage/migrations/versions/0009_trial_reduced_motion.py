"""Issue 32 item 9: each trial response records whether its clips played as reduced motion's
stepped animation (the participant's prefers-reduced-motion), so a trial seen that way can be
told from one seen animated.

A nullable boolean: rows stored before it get NULL, as nobody recorded how they were played.
"""

import sqlalchemy as sa
from alembic import op

revision = "0009"
down_revision = "0008"
branch_labels = None
depends_on = None


def upgrade() -> None:
    """Add trialresponse.reduced_motion."""
    op.add_column("trialresponse", sa.Column("reduced_motion", sa.Boolean(), nullable=True))


def downgrade() -> None:
    """Drop trialresponse.reduced_motion."""
    with op.batch_alter_table("trialresponse") as batch:
        batch.drop_column("reduced_motion")
