"""A trial's answer: validated, scored beside every predictor and stored in one transaction.

The clicks are checked (validation.py for the request, app/study/clicks.py for where a click
may land), attention-check trials are judged, and the TrialResponse row and the long
prediction rows (app/study/prediction_rows.py, shared with the simulated study) are stored
with the step's advance (crud.advance), so a 2xx means the answer is kept.
"""

import numpy as np
from sqlmodel import Session

from app.core.contracts import PLUGIN_FIELDS, plugin_columns
from app.server.flow.context import StudyContext
from app.server.flow.drafts import discard_draft
from app.server.flow.plan import Phase, TrialStep, expect_trial
from app.server.flow.sessions import as_utc
from app.server.flow.validation import attention_passed, validate_points
from app.server.schemas import PredictionCreate
from app.server.storage.crud import advance, replay_if_stored
from app.server.storage.tables import Participant, PredictionRow, TrialResponse, utcnow
from app.study.prediction_rows import as_rows, prediction_columns
from app.study.trials import TrialRecord


def record_predictions(db: Session, ctx: StudyContext, participant: Participant,
                       body: PredictionCreate) -> bool:
    """Validate and store one trial's clicks with every predictor's actions. True if new."""
    with replay_if_stored(db, participant, body, "predictions") as fresh:
        fresh.stored = _store_predictions(db, ctx, participant, body)
    return fresh.stored


def _store_predictions(db: Session, ctx: StudyContext, participant: Participant,
                       body: PredictionCreate) -> bool:
    step = expect_trial(participant, body.trial_id)
    trial = ctx.bank.by_id[step.trial_id]
    points = validate_points(ctx.bank, trial, body)
    rows = prediction_rows(ctx, participant, trial, body, points)
    attention_ok = (attention_passed(ctx.config.attention_checks, trial, points)
                    if step.attention_check else None)
    response = trial_response(ctx, participant, step, trial, body, attention_ok)
    payload = {"trial_id": trial.trial_id, "attention_ok": attention_ok}
    return advance(db, participant, body, "predictions", payload,
                   [(TrialResponse, [response]), (PredictionRow, rows)],
                   before_commit=lambda: discard_draft(db, participant))


def trial_response(ctx: StudyContext, participant: Participant, step: TrialStep,
                   trial: TrialRecord, body: PredictionCreate,
                   attention_ok: bool | None) -> dict:
    """The TrialResponse row of one answered trial: timings, replays, undo history, verdict."""
    return {
        "submission_id": str(body.submission_id), "participant_id": participant.id,
        "trial_id": trial.trial_id, "world": trial.world,
        "world_position": step.world_position, "trial_index": step.trial_index,
        "is_practice": step.phase == Phase.PRACTICE, "attention_check": step.attention_check,
        "attention_ok": attention_ok, "shown_at_ms": body.shown_at_ms,
        "submitted_at_ms": body.submitted_at_ms, "replays": body.replays,
        "clip_sha256": trial.clip_sha256, "arm": trial.arm, "received_at": utcnow(),
        "history": [entry.model_dump() for entry in body.history],
        "reduced_motion": body.reduced_motion,
        **trial_durations(ctx, participant, body),
    }


def trial_durations(ctx: StudyContext, participant: Participant, body: PredictionCreate) -> dict:
    """Client and server durations of a trial, and the one the too-fast rule reads.

    The server's clock runs from its acknowledgement of the previous step, so it can only
    overstate the time a person had; taking the smaller of the two catches a client
    that claims to have taken longer than it did.
    """
    client_ms = body.submitted_at_ms - body.shown_at_ms
    server_ms = (utcnow() - as_utc(participant.updated_at)).total_seconds() * 1000
    used = client_ms if ctx.trust_client_clock else min(client_ms, server_ms)
    return {"client_duration_ms": client_ms, "server_duration_ms": server_ms,
            "duration_ms": used}


def prediction_rows(ctx: StudyContext, participant: Participant, trial: TrialRecord,
                    body: PredictionCreate, points: np.ndarray) -> list[dict]:
    """Long rows: one per (start state, step), human action beside each predictor's."""
    columns = prediction_columns(trial, ctx.model_answers.answers(trial.trial_id), points,
                                 ctx.bank.world(trial.world).dt_s)
    k, n = points.shape[:2]
    columns |= {"submission_id": np.full(k * n, str(body.submission_id)),
                "participant_id": np.full(k * n, participant.id),
                "trial_id": np.full(k * n, trial.trial_id),
                "click_time_ms": np.asarray(body.click_times_ms, dtype=np.float64).ravel(),
                "click_input": click_inputs(body, k * n)}
    return [with_plugins(row, ctx.bank.code_predictors) for row in as_rows(columns)]


def click_inputs(body: PredictionCreate, size: int) -> np.ndarray:
    """Each click's input device, start state major as the rows; None where not sent."""
    if body.click_inputs is None:
        return np.full(size, None, dtype=object)
    return np.asarray(body.click_inputs, dtype=object).ravel()


def with_plugins(row: dict, plugins: list[str]) -> dict:
    """A row whose code predictors' columns (coarse observers', plug-ins') are gathered into its
    `plugins` JSON."""
    gathered = {name: {field: row.pop(column) for field, column
                       in zip(PLUGIN_FIELDS, plugin_columns(name), strict=True)}
                for name in plugins}
    return row | {"plugins": gathered}
