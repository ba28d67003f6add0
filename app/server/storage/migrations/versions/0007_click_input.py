"""Issue 30: each prediction row records the device its click came from (`mouse`,
`keyboard` or `touch`, schemas.ClickInput), so keyboard answers can be told from pointed ones.

A nullable column beside `click_time_ms`, one value per click as the rows are one per click.
Existing rows get NULL: which device placed them was never recorded, and no default would be
true of them.
"""

import sqlalchemy as sa
from alembic import op

revision = "0007"
down_revision = "0006"
branch_labels = None
depends_on = None


def upgrade() -> None:
    """Add predictionrow.click_input."""
    op.add_column("predictionrow", sa.Column("click_input", sa.String(8), nullable=True))


def downgrade() -> None:
    """Drop predictionrow.click_input."""
    with op.batch_alter_table("predictionrow") as batch:
        batch.drop_column("click_input")
