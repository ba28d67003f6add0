"""The study schema before migrations existed (tomstudy at commit 9c39751).

A database made by that code (SQLModel's create_all) has exactly these tables, columns
and indexes; `tomstudy db upgrade` stamps such a database with this revision.
"""

import sqlalchemy as sa
from alembic import op

revision = "0001"
down_revision = None
branch_labels = None
depends_on = None

LIVE = "replaced_at IS NULL"


def upgrade() -> None:
    """Create the six tables of 9c39751."""
    create_participant()
    op.create_table(
        "balancecount",
        sa.Column("study_id", sa.String(64), nullable=False),
        sa.Column("key", sa.String(96), nullable=False),
        sa.Column("count", sa.Integer(), nullable=False),
        sa.PrimaryKeyConstraint("study_id", "key"),
    )
    op.create_table(
        "submission",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("submission_id", sa.String(36), nullable=False),
        sa.Column("participant_id", sa.Integer(), nullable=False),
        sa.Column("kind", sa.String(16), nullable=False),
        sa.Column("body_sha256", sa.String(64), nullable=False),
        sa.Column("step_index", sa.Integer(), nullable=False),
        sa.Column("payload", sa.JSON(), nullable=True),
        sa.Column("received_at", sa.DateTime(timezone=True), nullable=False),
        sa.PrimaryKeyConstraint("id"),
        sa.UniqueConstraint("submission_id"),
        sa.ForeignKeyConstraint(["participant_id"], ["participant.id"]),
    )
    op.create_index("ix_submission_participant_id", "submission", ["participant_id"])
    create_trialresponse()
    create_predictionrow()
    op.create_table(
        "event",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("submission_id", sa.String(36), nullable=False),
        sa.Column("participant_id", sa.Integer(), nullable=False),
        sa.Column("kind", sa.String(32), nullable=False),
        sa.Column("t_client_ms", sa.Float(), nullable=False),
        sa.Column("data", sa.JSON(), nullable=True),
        sa.Column("received_at", sa.DateTime(timezone=True), nullable=False),
        sa.PrimaryKeyConstraint("id"),
        sa.UniqueConstraint("submission_id"),
        sa.ForeignKeyConstraint(["participant_id"], ["participant.id"]),
    )
    op.create_index("ix_event_participant_id", "event", ["participant_id"])


def create_participant() -> None:
    """Sessions, with the partial unique index that frees a replaced session's external id."""
    op.create_table(
        "participant",
        sa.Column("study_id", sa.String(64), nullable=False),
        sa.Column("recruitment", sa.String(16), nullable=False),
        sa.Column("external_id", sa.String(128), nullable=True),
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("public_id", sa.String(32), nullable=False),
        sa.Column("session_token", sa.String(64), nullable=False),
        sa.Column("attempt_key", sa.String(128), nullable=True),
        sa.Column("pilot", sa.Boolean(), nullable=False),
        sa.Column("counted", sa.Boolean(), nullable=False),
        sa.Column("replaced_at", sa.DateTime(timezone=True), nullable=True),
        sa.Column("recruitment_params", sa.JSON(), nullable=True),
        sa.Column("client", sa.JSON(), nullable=True),
        sa.Column("world_order", sa.String(64), nullable=False),
        sa.Column("plan", sa.JSON(), nullable=True),
        sa.Column("position", sa.Integer(), nullable=False),
        sa.Column("completed", sa.Boolean(), nullable=False),
        sa.Column("attention_failed", sa.Integer(), nullable=False),
        sa.Column("created_at", sa.DateTime(timezone=True), nullable=False),
        sa.Column("updated_at", sa.DateTime(timezone=True), nullable=False),
        sa.Column("completed_at", sa.DateTime(timezone=True), nullable=True),
        sa.Column("events_stored", sa.Integer(), nullable=False),
        sa.PrimaryKeyConstraint("id"),
        sa.UniqueConstraint("public_id"),
    )
    op.create_index("ix_participant_study_id", "participant", ["study_id"])
    op.create_index("uq_participant_live_ext", "participant", ["study_id", "external_id"],
                    unique=True, sqlite_where=sa.text(LIVE), postgresql_where=sa.text(LIVE))
    op.create_index("ix_participant_stale", "participant",
                    ["study_id", "counted", "completed", "updated_at"])
    op.create_index("ix_participant_session_token", "participant", ["session_token"],
                    unique=True)


def create_trialresponse() -> None:
    """One answered trial."""
    op.create_table(
        "trialresponse",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("submission_id", sa.String(36), nullable=False),
        sa.Column("participant_id", sa.Integer(), nullable=False),
        sa.Column("trial_id", sa.String(64), nullable=False),
        sa.Column("world", sa.String(16), nullable=False),
        sa.Column("world_position", sa.Integer(), nullable=False),
        sa.Column("trial_index", sa.Integer(), nullable=False),
        sa.Column("is_practice", sa.Boolean(), nullable=False),
        sa.Column("attention_check", sa.Boolean(), nullable=False),
        sa.Column("attention_ok", sa.Boolean(), nullable=True),
        *[sa.Column(name, sa.Float(), nullable=False) for name in (
            "shown_at_ms", "submitted_at_ms", "duration_ms", "client_duration_ms",
            "server_duration_ms")],
        sa.Column("replays", sa.Integer(), nullable=False),
        sa.Column("clip_sha256", sa.String(64), nullable=False),
        sa.Column("received_at", sa.DateTime(timezone=True), nullable=False),
        sa.PrimaryKeyConstraint("id"),
        sa.UniqueConstraint("submission_id"),
        sa.ForeignKeyConstraint(["participant_id"], ["participant.id"]),
    )
    op.create_index("ix_trialresponse_participant_id", "trialresponse", ["participant_id"])


def create_predictionrow() -> None:
    """One (start state, step) of an answered trial, the human's action beside the models'."""
    floats = ["start_x", "start_y", "human_x", "human_y", "click_x", "click_y"]
    floats += [f"{who}_{axis}" for who in ("human", "ours", "vae", "cv", "policy")
               for axis in ("vx", "vy")]
    op.create_table(
        "predictionrow",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("submission_id", sa.String(36), nullable=False),
        sa.Column("participant_id", sa.Integer(), nullable=False),
        sa.Column("trial_id", sa.String(64), nullable=False),
        sa.Column("start_index", sa.Integer(), nullable=False),
        sa.Column("start_kind", sa.String(16), nullable=False),
        sa.Column("step", sa.Integer(), nullable=False),
        *[sa.Column(name, sa.Float(), nullable=False) for name in floats],
        sa.Column("ours_code", sa.Integer(), nullable=False),
        sa.Column("vae_code", sa.Integer(), nullable=False),
        sa.Column("ours_sha256", sa.String(64), nullable=False),
        sa.Column("vae_sha256", sa.String(64), nullable=False),
        sa.Column("click_time_ms", sa.Float(), nullable=False),
        sa.PrimaryKeyConstraint("id"),
        sa.ForeignKeyConstraint(["participant_id"], ["participant.id"]),
    )
    op.create_index("ix_predictionrow_submission_id", "predictionrow", ["submission_id"])
    op.create_index("ix_predictionrow_participant_id", "predictionrow", ["participant_id"])


def downgrade() -> None:
    """Drop every table (children first)."""
    for name in ("event", "predictionrow", "trialresponse", "submission", "balancecount",
                 "participant"):
        op.drop_table(name)
