"""SQLModel tables of the study database and the request/response models around them.

One participant row holds its plan (the ordered steps assigned at start) and its
position in it; every client write is keyed by a client-made UUID (`submission_id`,
unique), so a retried request is stored once. Prediction rows are long: one per
(start state, step), with each model's action and the baselines beside the human's.
"""

import uuid
from datetime import UTC, datetime
from typing import Literal

from pydantic import ConfigDict, ValidationInfo, field_validator
from pydantic import Field as PydField
from sqlalchemy import JSON, Column, Index, text
from sqlmodel import Field, SQLModel


def utcnow() -> datetime:
    """Timezone-aware now (UTC)."""
    return datetime.now(UTC)


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
    events_stored: int = 0  # telemetry rows; app/server/telemetry.py keeps it under its cap
    # the ending's receipt, stored before the browser is told where to go (OUTCOMES)
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


# How a session ends; each has its own completion code (config.Endings).
OUTCOMES = ("completed", "failed_checks", "excluded", "declined_consent", "screened_out")


class ParticipantPublic(SQLModel):
    """What a session start answers (`participant_id` is the random public id)."""

    session_token: str
    participant_id: str
    resumed: bool


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


# ---------------------------------------------------------------- request bodies

class _Body(SQLModel):
    """Request bodies: unknown keys and NaN/inf are refused with the field named."""

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)


class UrlParams(_Body):
    """URL parameters from Prolific or MTurk; which are required is the study's `platform`."""

    PROLIFIC_PID: str | None = PydField(default=None, max_length=128)
    STUDY_ID: str | None = PydField(default=None, max_length=128)
    SESSION_ID: str | None = PydField(default=None, max_length=128)
    workerId: str | None = PydField(default=None, max_length=128)
    assignmentId: str | None = PydField(default=None, max_length=128)
    hitId: str | None = PydField(default=None, max_length=128)
    turkSubmitTo: str | None = PydField(default=None, max_length=256)


class ClientInfo(_Body):
    """The participant's device: sent with consent, never stored before it."""

    screen_w: int = PydField(default=0, ge=0, le=100_000)
    screen_h: int = PydField(default=0, ge=0, le=100_000)
    touch_only: bool = False
    user_agent: str = PydField(default="", max_length=512)


class SessionCreate(_Body):
    """POST /api/sessions."""

    study_id: str = PydField(max_length=64)
    recruitment: UrlParams = UrlParams()
    preview: str | None = PydField(default=None, max_length=128)  # researcher preview key


class SubmissionBody(_Body):
    """Any write: carries the client's UUID."""

    submission_id: uuid.UUID


class ConsentCreate(SubmissionBody):
    """POST .../consent."""

    agree: Literal[True]  # consent is required to take part
    client: ClientInfo = ClientInfo()


Point = tuple[float, float]


class HistoryEntry(_Body):
    """One undo or reset press: which start state, and when (ms after the trial was shown)."""

    action: Literal["undo", "reset"]
    start_index: int = PydField(ge=0, le=100)
    t_ms: float = PydField(ge=0, le=6 * 3600 * 1000)


class PredictionCreate(SubmissionBody):
    """POST .../predictions: per start state (the study's `start_states`), the clicked robot
    positions of each step to predict (scene metres)."""

    trial_id: str = PydField(max_length=64)
    points: list[list[Point]]
    click_times_ms: list[list[float]]
    shown_at_ms: float = PydField(ge=0)
    submitted_at_ms: float = PydField(ge=0)
    replays: int = PydField(default=0, ge=0, le=10_000)
    history: list[HistoryEntry] = PydField(default=[], max_length=500)


class DraftSave(_Body):
    """PUT .../draft: the current trial's clicks so far, saved after every change."""

    trial_id: str = PydField(max_length=64)
    seq: int = PydField(ge=0, le=10**9)  # grows with every change the page makes
    index: int = PydField(ge=0, le=100)  # the start state being answered
    points: list[list[Point]] = PydField(max_length=100)
    click_times_ms: list[list[float]] = PydField(max_length=100)
    history: list[HistoryEntry] = PydField(default=[], max_length=500)
    shown_at_ms: float = PydField(ge=0)  # when the trial was first shown (browser epoch ms)
    replays: int = PydField(default=0, ge=0, le=10_000)
    predicting: bool = True  # false while the clips are still being watched


class TabClaim(_Body):
    """POST .../tab: this tab asks to be the session's live one (on load, then as a heartbeat)."""

    tab_id: str = PydField(pattern=r"^[A-Za-z0-9_-]{8,64}$")
    takeover: bool = False  # the person chose to continue here, closing the other tab's turn
    opened: bool = False  # the page has just loaded (a first visit, reload or takeover)
    t_client_ms: float = PydField(default=0, ge=0)


class TabRelease(_Body):
    """POST .../tab/release: the live tab is closing (sent as a beacon on pagehide)."""

    tab_id: str = PydField(pattern=r"^[A-Za-z0-9_-]{8,64}$")


class ContinueCreate(SubmissionBody):
    """POST .../continue: a part's screen (world_intro, practice_over) was read."""

    phase: Literal["world_intro", "practice_over"]


class DeclineCreate(SubmissionBody):
    """POST .../decline: the participant does not agree to take part."""


class ScreenOutCreate(SubmissionBody):
    """POST .../screen-out: the device check failed and the participant cannot switch."""

    reason: Literal["touch_only", "window_too_small"]


class SurveyCreate(SubmissionBody):
    """POST .../survey."""

    answers: dict[str, str | int | float | None]


class WithdrawalByExternalId(_Body):
    """Withdraw a participant by their platform id (every session of that person)."""

    study_id: str = PydField(max_length=64)
    external_id: str = PydField(min_length=1, max_length=128)


class WithdrawalByParticipantId(_Body):
    """Withdraw by a session's public id: open and pilot sessions have no platform id."""

    study_id: str = PydField(max_length=64)
    participant_id: str = PydField(min_length=1, max_length=32)


# POST /api/researcher/withdrawals: exactly one of the two ids
WithdrawalCreate = WithdrawalByExternalId | WithdrawalByParticipantId


class EventIn(_Body):
    """One telemetry event: a kind the browser sends, with that kind's `data` (EVENT_DATA)."""

    submission_id: uuid.UUID
    kind: Literal["visibility_hidden", "visibility_shown", "resize", "clip_finished", "replay"]
    t_client_ms: float = PydField(ge=0)
    data: dict = {}

    @field_validator("data")
    @classmethod
    def _fits_kind(cls, value: dict, info: ValidationInfo) -> dict:
        kind = info.data.get("kind")
        if kind is None:  # the kind was refused; that error names `kind`
            return value
        # a ValidationError raised here keeps its field names under `data`
        return EVENT_DATA[kind].model_validate(value).model_dump()


class EventsCreate(_Body):
    """POST .../events (at most 100 per request)."""

    events: list[EventIn] = PydField(min_length=1, max_length=100)


class NoEventData(_Body):
    """visibility_hidden / visibility_shown: the kind says it all."""


class ResizeData(_Body):
    """resize: the window's new inner size (CSS pixels)."""

    w: int = PydField(ge=0, le=100_000)
    h: int = PydField(ge=0, le=100_000)


class ClipData(_Body):
    """clip_finished / replay: the trial on screen and how often its clip was replayed."""

    trial_id: str = PydField(max_length=64)
    replays: int = PydField(ge=0, le=10_000)


# Events the server records itself (tabs.py): a page opened, or took over from another tab,
# with the trial on screen, the start state its draft resumed and the clicks it restored.
PAGE_OPENED, TAB_TAKEOVER = "page_opened", "tab_takeover"
SERVER_EVENTS = (PAGE_OPENED, TAB_TAKEOVER)

# Every kind's `data`: small and flat by construction (no other keys, bounded values).
EVENT_DATA: dict[str, type[_Body]] = {
    "visibility_hidden": NoEventData, "visibility_shown": NoEventData,
    "resize": ResizeData, "clip_finished": ClipData, "replay": ClipData,
}
