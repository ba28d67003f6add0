"""Request and response bodies of the participant and researcher APIs (pydantic, no tables).

Every body refuses unknown keys, NaN/inf, text no UTF-8 encodes (a lone surrogate) and
JSON values of another type (`true` or "1.5" for a number) with the field named; sizes are
bounded here, so no write can grow a row past what these types allow.
"""

import uuid
from typing import Annotated, Literal

from pydantic import (
    AfterValidator,
    ConfigDict,
    StrictBool,
    StrictFloat,
    StrictInt,
    ValidationInfo,
    field_validator,
)
from pydantic import Field as PydField
from sqlmodel import SQLModel

# Limits the participant page applies too (app/http/routes/pages.py hands them over).
USER_AGENT_MAX_CHARS = 512  # the page cuts navigator.userAgent to this
HISTORY_MAX_ENTRIES = 500  # undo and reset presses kept with a trial (the newest)
EVENTS_PER_REQUEST = 100  # telemetry events in one POST .../events
ScreenOutReason = Literal["touch_only", "window_too_small"]  # device.js checks each on the device
EventKind = Literal["visibility_hidden", "visibility_shown", "resize", "clip_finished", "replay"]
ClickInput = Literal["mouse", "keyboard", "touch"]  # the device a click was placed with

# ---------------------------------------------------------------- request bodies

def _utf8(value: str) -> str:
    try:
        value.encode("utf-8")
    except UnicodeEncodeError:  # JSON's "\ud800": a lone surrogate no database can store
        raise ValueError("not valid text (a lone UTF-16 surrogate)") from None
    return value


# Every free text of a body; numbers and flags take JSON's own types (no `true` as 1,
# no "1.5" as a number), though a whole number is still a float.
Text = Annotated[str, AfterValidator(_utf8)]
Num = StrictFloat
Int = StrictInt
Flag = StrictBool

class _Body(SQLModel):
    """Request bodies: unknown keys and NaN/inf are refused with the field named."""

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)


class UrlParams(_Body):
    """URL parameters from Prolific or MTurk; which are required is the study's `platform`."""

    PROLIFIC_PID: Text | None = PydField(default=None, max_length=128)
    STUDY_ID: Text | None = PydField(default=None, max_length=128)
    SESSION_ID: Text | None = PydField(default=None, max_length=128)
    workerId: Text | None = PydField(default=None, max_length=128)
    assignmentId: Text | None = PydField(default=None, max_length=128)
    hitId: Text | None = PydField(default=None, max_length=128)
    turkSubmitTo: Text | None = PydField(default=None, max_length=256)


class ClientInfo(_Body):
    """The participant's device: sent with consent, never stored before it."""

    screen_w: Int = PydField(default=0, ge=0, le=100_000)
    screen_h: Int = PydField(default=0, ge=0, le=100_000)
    touch_only: Flag = False
    reduced_motion: Flag = False  # the browser's prefers-reduced-motion: reduce
    user_agent: Text = PydField(default="", max_length=USER_AGENT_MAX_CHARS)


class SessionCreate(_Body):
    """POST /api/sessions."""

    study_id: Text = PydField(max_length=64)
    recruitment: UrlParams = UrlParams()
    preview: Text | None = PydField(default=None, max_length=128)  # researcher preview key


class SubmissionBody(_Body):
    """Any write: carries the client's UUID."""

    submission_id: uuid.UUID


class ConsentCreate(SubmissionBody):
    """POST .../consent."""

    agree: Literal[True]  # consent is required to take part
    client: ClientInfo = ClientInfo()


Point = tuple[Num, Num]


class HistoryEntry(_Body):
    """One undo or reset press: which start state, and when (ms after the trial was shown)."""

    action: Literal["undo", "reset"]
    start_index: Int = PydField(ge=0, le=100)
    t_ms: Num = PydField(ge=0, le=6 * 3600 * 1000)


class PredictionCreate(SubmissionBody):
    """POST .../predictions: per start state (the study's `start_states`), the clicked robot
    positions of each step to predict (scene metres)."""

    trial_id: Text = PydField(max_length=64)
    points: list[list[Point]]
    click_times_ms: list[list[Num]]
    shown_at_ms: Num = PydField(ge=0)
    submitted_at_ms: Num = PydField(ge=0)
    replays: Int = PydField(default=0, ge=0, le=10_000)
    history: list[HistoryEntry] = PydField(default=[], max_length=HISTORY_MAX_ENTRIES)
    # as click_times_ms; None (unknown) from a client older than the field, as history was
    click_inputs: list[list[ClickInput]] | None = None
    # whether the clips played as reduced motion's stepped animation; None: not said
    reduced_motion: Flag | None = None


class DraftSave(_Body):
    """PUT .../draft: the current trial's clicks so far, saved after every change."""

    trial_id: Text = PydField(max_length=64)
    seq: Int = PydField(ge=0, le=10**9)  # grows with every change the page makes
    index: Int = PydField(ge=0, le=100)  # the start state being answered
    points: list[list[Point]] = PydField(max_length=100)
    click_times_ms: list[list[Num]] = PydField(max_length=100)
    click_inputs: list[list[ClickInput]] | None = PydField(default=None, max_length=100)
    history: list[HistoryEntry] = PydField(default=[], max_length=HISTORY_MAX_ENTRIES)
    shown_at_ms: Num = PydField(ge=0)  # when the trial was first shown (browser epoch ms)
    replays: Int = PydField(default=0, ge=0, le=10_000)
    predicting: Flag = True  # false while the clips are still being watched


class TabClaim(_Body):
    """POST .../tab: this tab asks to be the session's live one (on load, then as a heartbeat)."""

    tab_id: Text = PydField(pattern=r"^[A-Za-z0-9_-]{8,64}$")
    takeover: Flag = False  # the person chose to continue here, closing the other tab's turn
    opened: Flag = False  # the page has just loaded (a first visit, reload or takeover)
    t_client_ms: Num = PydField(default=0, ge=0)


class TabRelease(_Body):
    """POST .../tab/release: the live tab is closing (sent as a beacon on pagehide)."""

    tab_id: Text = PydField(pattern=r"^[A-Za-z0-9_-]{8,64}$")


class ContinueCreate(SubmissionBody):
    """POST .../continue: a part's screen (world_intro, practice_over) was read."""

    phase: Literal["world_intro", "practice_over"]


class DeclineCreate(SubmissionBody):
    """POST .../decline: the participant does not agree to take part."""


class ScreenOutCreate(SubmissionBody):
    """POST .../screen-out: the device check failed and the participant cannot switch."""

    reason: ScreenOutReason


class SurveyCreate(SubmissionBody):
    """POST .../survey."""

    answers: dict[Text, Text | Int | Num | None]


class WithdrawalByExternalId(_Body):
    """Withdraw a participant by their platform id (every session of that person)."""

    study_id: Text = PydField(max_length=64)
    external_id: Text = PydField(min_length=1, max_length=128)


class WithdrawalByParticipantId(_Body):
    """Withdraw by a session's public id: open and pilot sessions have no platform id."""

    study_id: Text = PydField(max_length=64)
    participant_id: Text = PydField(min_length=1, max_length=32)


# POST /api/researcher/withdrawals: exactly one of the two ids
WithdrawalCreate = WithdrawalByExternalId | WithdrawalByParticipantId


class PaymentActionCreate(_Body):
    """Approve, or ask to return, these sessions' Prolific submissions (by public id)."""

    study_id: Text = PydField(max_length=64)
    participant_ids: list[Annotated[Text, PydField(min_length=1, max_length=32)]] = PydField(
        min_length=1, max_length=500)
    # a return request's reason as Prolific shows it to the participant (returns need one)
    reason: Text | None = PydField(default=None, min_length=1, max_length=300)


class EventIn(_Body):
    """One telemetry event: a kind the browser sends, with that kind's `data` (EVENT_DATA)."""

    submission_id: uuid.UUID
    kind: EventKind
    t_client_ms: Num = PydField(ge=0)
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

    events: list[EventIn] = PydField(min_length=1, max_length=EVENTS_PER_REQUEST)


class NoEventData(_Body):
    """visibility_hidden / visibility_shown: the kind says it all."""


class ResizeData(_Body):
    """resize: the window's new inner size (CSS pixels)."""

    w: Int = PydField(ge=0, le=100_000)
    h: Int = PydField(ge=0, le=100_000)


class ClipData(_Body):
    """clip_finished / replay: the trial on screen and how often its clip was replayed."""

    trial_id: Text = PydField(max_length=64)
    replays: Int = PydField(ge=0, le=10_000)


# Events the server records itself (tabs.py): a page opened, or took over from another tab,
# with the trial on screen, the start state its draft resumed and the clicks it restored.
PAGE_OPENED, TAB_TAKEOVER = "page_opened", "tab_takeover"
SERVER_EVENTS = (PAGE_OPENED, TAB_TAKEOVER)

# Every kind's `data`: small and flat by construction (no other keys, bounded values).
EVENT_DATA: dict[str, type[_Body]] = {
    "visibility_hidden": NoEventData, "visibility_shown": NoEventData,
    "resize": ResizeData, "clip_finished": ClipData, "replay": ClipData,
}


class ParticipantPublic(SQLModel):
    """What a session start answers (`participant_id` is the random public id)."""

    session_token: str
    participant_id: str
    resumed: bool
