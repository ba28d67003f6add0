"""SQLModel tables of the study database (the request and response bodies are in schemas.py).

One participant row holds its plan (the ordered steps assigned at start) and its
position in it; every client write is keyed by a client-made UUID (`submission_id`,
unique), so a retried request is stored once. Prediction rows are long: one per
(start state, step), with each model's action, the baselines and every plug-in predictor's
beside the human's.
"""

from datetime import UTC, datetime

from sqlalchemy import JSON, Column, Index, text
from sqlalchemy.orm.attributes import set_committed_value
from sqlmodel import Field, SQLModel


def utcnow() -> datetime:
    """Timezone-aware now (UTC)."""
    return datetime.now(UTC)


def keep_loaded(row: SQLModel, **stored) -> None:
    """Show on a loaded row what an UPDATE just stored, without the ORM writing it again."""
    # a plain setattr marks the row dirty, and the commit's flush repeats the UPDATE
    for key, value in stored.items():
        set_committed_value(row, key, value)


# ---------------------------------------------------------------- participants

class ParticipantBase(SQLModel):
    """Who a participant is and how they arrived."""

    study_id: str = Field(index=True, max_length=64)
    recruitment: str = Field(max_length=16)  # prolific, mturk, open or pilot
    external_id: str | None = Field(default=None, max_length=128)


_LIVE = "replaced_at IS NULL"
_EMPTY = {"server_default": text("''")}  # what rows stored before a column existed hold


class Participant(ParticipantBase, table=True):
    """A participant's session: plan, position, outcome.

    `counted` says whether its plan is in the study's balance counts (BalanceCount);
    a replaced session (a new attempt took over a stale one) keeps its rows, but its
    external id is free again.
    """

    __table_args__ = (
        Index("uq_participant_live_ext", "study_id", "external_id", unique=True,
              sqlite_where=text(_LIVE), postgresql_where=text(_LIVE)),
        Index("ix_participant_stale", "study_id", "counted", "completed", "updated_at"),
    )

    id: int | None = Field(default=None, primary_key=True)
    public_id: str = Field(unique=True, max_length=32)  # what the browser sees, not `id`
    session_token: str = Field(unique=True, index=True, max_length=64)
    attempt_key: str | None = Field(default=None, max_length=128)
    pilot: bool = False
    counted: bool = False
    replaced_at: datetime | None = None
    recruitment_params: dict = Field(default_factory=dict, sa_column=Column(JSON))
    client: dict = Field(default_factory=dict, sa_column=Column(JSON))
    world_order: str = Field(max_length=64)
    plan: list = Field(default_factory=list, sa_column=Column(JSON))  # plan.Step entries as JSON
    position: int = 0
    completed: bool = False
    attention_failed: int = 0
    created_at: datetime = Field(default_factory=utcnow)
    updated_at: datetime = Field(default_factory=utcnow)
    completed_at: datetime | None = None
    events_stored: int = 0  # telemetry rows; app/server/flow/telemetry.py keeps it under its cap
    # the ending's receipt, stored before the browser is told where to go (endings.OUTCOMES)
    outcome: str | None = Field(default=None, max_length=20)
    completion_code: str | None = Field(default=None, max_length=64)
    ended_at: datetime | None = None
    # what this session ran: the study config, the trial bank (which pins both models'
    # answers) and the tomstudy version, so a changed study is visible per session
    # (sessions from before they were stored have '': migration 0002's server default)
    config_sha256: str = Field(default="", max_length=64, sa_column_kwargs=_EMPTY)
    bank_sha256: str = Field(default="", max_length=64, sa_column_kwargs=_EMPTY)
    app_version: str = Field(default="", max_length=32, sa_column_kwargs=_EMPTY)
    # the one browser tab that may write (tabs.py), and when it was last heard from
    live_tab: str | None = Field(default=None, max_length=64)
    live_tab_seen_at: datetime | None = None
    # Prolific's word on the link's SESSION_ID (app/server/flow/prolific_check.py): confirmed,
    # pending (not reachable yet: never counted until confirmed) or unknown (never counted,
    # excluded as prolific_unknown); NULL when not asked (another platform, no API token)
    prolific_check: str | None = Field(default=None, max_length=12)


class BalanceCount(SQLModel, table=True):
    """How many counted sessions hold a world order or a trial (key `order:..`/`trial:..`)."""

    study_id: str = Field(primary_key=True, max_length=64)
    key: str = Field(primary_key=True, max_length=96)
    count: int = 0


# ---------------------------------------------------------------- writes

class Submission(SQLModel, table=True):
    """Every accepted client write (consent, instructions, predictions, survey), once."""

    id: int | None = Field(default=None, primary_key=True)
    submission_id: str = Field(unique=True, max_length=36)
    participant_id: int = Field(foreign_key="participant.id", index=True)
    kind: str = Field(max_length=16)
    body_sha256: str = Field(max_length=64)  # a reused submission_id must carry the same body
    step_index: int
    payload: dict = Field(default_factory=dict, sa_column=Column(JSON))
    received_at: datetime = Field(default_factory=utcnow)


class TrialResponse(SQLModel, table=True):
    """One answered trial: timings, replays and the attention-check verdict."""

    id: int | None = Field(default=None, primary_key=True)
    submission_id: str = Field(unique=True, max_length=36)
    participant_id: int = Field(foreign_key="participant.id", index=True)
    trial_id: str = Field(max_length=64)
    world: str = Field(max_length=16)
    world_position: int
    trial_index: int
    is_practice: bool
    attention_check: bool
    attention_ok: bool | None = None
    shown_at_ms: float
    submitted_at_ms: float
    duration_ms: float  # what the too-fast rule reads: min(client, server) unless trusted
    client_duration_ms: float
    server_duration_ms: float  # from the server's receipt of the previous step
    replays: int
    clip_sha256: str = Field(max_length=64)
    arm: str = Field(default="", max_length=16, sa_column_kwargs=_EMPTY)  # TrialRecord.arm
    # the participant's undo and reset presses on this trial, in order (HistoryEntry)
    history: list = Field(default_factory=list,
                          sa_column=Column(JSON, server_default=text("'[]'")))
    # the clips played as reduced motion's stepped animation (the browser's preference);
    # NULL: unknown, as in rows stored before 0009 or sent by a client without it
    reduced_motion: bool | None = None
    received_at: datetime = Field(default_factory=utcnow)


class PredictionRow(SQLModel, table=True):
    """One (start state, step) of a trial: the human's action beside every predictor's."""

    id: int | None = Field(default=None, primary_key=True)
    submission_id: str = Field(index=True, max_length=36)
    participant_id: int = Field(foreign_key="participant.id", index=True)
    trial_id: str = Field(max_length=64)
    start_index: int
    start_kind: str = Field(max_length=16)  # trials.StartState.start_kind
    step: int
    start_x: float
    start_y: float
    human_x: float
    human_y: float
    click_x: float
    click_y: float
    human_vx: float
    human_vy: float
    ours_vx: float
    ours_vy: float
    vae_vx: float
    vae_vy: float
    cv_vx: float
    cv_vy: float
    policy_vx: float
    policy_vy: float
    ours_code: int
    vae_code: int
    ours_sha256: str = Field(max_length=64)
    vae_sha256: str = Field(max_length=64)
    click_time_ms: float
    # the device the click came from (schemas.ClickInput); NULL: unknown, as in rows stored
    # before 0007 or sent by a client without it
    click_input: str | None = Field(default=None, max_length=8)
    # each plug-in predictor's answer: {"<name>": {"vx", "vy", "code", "sha256"}} (migration
    # 0006 says why a JSON column); {} in a study without plug-ins
    plugins: dict = Field(default_factory=dict,
                          sa_column=Column(JSON, server_default=text("'{}'")))


class TrialDraft(SQLModel, table=True):
    """The current trial's answer in progress (drafts.py): kept until the trial is submitted.

    One row per session; `seq` only grows, so a late save of older clicks never overwrites
    newer ones. `data` is DraftSave's fields: clicks, click times, undo history, the start
    state being answered, when the trial was first shown and its replays.
    """

    participant_id: int = Field(foreign_key="participant.id", primary_key=True)
    trial_ref: str = Field(max_length=64)  # the plan step's `ref` (the browser's trial_id)
    seq: int
    data: dict = Field(default_factory=dict, sa_column=Column(JSON))
    saved_at: datetime = Field(default_factory=utcnow)


class Event(SQLModel, table=True):
    """A telemetry event (clip finished, replay, tab hidden, resize...)."""

    id: int | None = Field(default=None, primary_key=True)
    submission_id: str = Field(unique=True, max_length=36)
    participant_id: int = Field(foreign_key="participant.id", index=True)
    kind: str = Field(max_length=32)
    t_client_ms: float
    data: dict = Field(default_factory=dict, sa_column=Column(JSON))
    received_at: datetime = Field(default_factory=utcnow)


class WithdrawalAudit(SQLModel, table=True):
    """What a withdrawal deleted: a salted hash of the id it was given, never the id itself."""

    id: int | None = Field(default=None, primary_key=True)
    study_id: str = Field(index=True, max_length=64)
    # which id was given: external_id (platform id) or participant_id (a session's public id)
    id_kind: str = Field(default="external_id", max_length=16,
                         sa_column_kwargs={"server_default": text("'external_id'")})
    salt: str = Field(max_length=32)
    id_sha256: str = Field(max_length=64)  # sha256(salt + ":" + that id)
    withdrawn_at: datetime = Field(default_factory=utcnow)
    via: str = Field(max_length=16)  # cli or api
    row_counts: dict = Field(default_factory=dict, sa_column=Column(JSON))


class PaymentAudit(SQLModel, table=True):
    """One approval or return request sent to Prolific from the payment sheet, and its result."""

    id: int | None = Field(default=None, primary_key=True)
    study_id: str = Field(index=True, max_length=64)
    participant_id: str = Field(max_length=32)  # the session's public id, as in the exports
    action: str = Field(max_length=16)  # approve or return
    via: str = Field(max_length=16)  # cli or api
    sent_at: datetime = Field(default_factory=utcnow)
    ok: bool
    # Prolific's submission status after the action, or why it failed (one line)
    result: str = Field(max_length=300)
