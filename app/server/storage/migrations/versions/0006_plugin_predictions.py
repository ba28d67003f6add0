"""Issue 24: every plug-in predictor's answer beside the person's, in each prediction row.

`predictionrow.plugins` is JSON: {"<name>": {"vx", "vy", "code", "sha256"}} for each plug-in
predictor of the study (app/predictors/), in the same row as Ours', the VAE's, constant
velocity's and the policy's columns. A JSON column rather than a child table: a study names
its own plug-ins, so they cannot be columns of a shared schema; kept in the row, a plug-in's
answer is inserted by the same statement as the person's (one transaction, no second insert),
is read with it by the exports without a join, and leaves with it when a withdrawal deletes
the row. Existing rows, answered before plug-ins existed, get '{}'.
"""

import sqlalchemy as sa
from alembic import op

revision = "0006"
down_revision = "0005"
branch_labels = None
depends_on = None


def upgrade() -> None:
    """Add predictionrow.plugins."""
    op.add_column("predictionrow", sa.Column("plugins", sa.JSON(), nullable=True,
                                             server_default=sa.text("'{}'")))


def downgrade() -> None:
    """Drop predictionrow.plugins."""
    with op.batch_alter_table("predictionrow") as batch:
        batch.drop_column("plugins")
