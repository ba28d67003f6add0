"""Replay of one participant's trial from the stored rows and the trial bank on disk.

The clip is the bank's, sent only if its hash equals the `clip_sha256` stored with the
answer (what the participant was shown); the clicks, their times, the undo history and
every model's actions are the stored rows, not recomputed.
"""

import numpy as np
from sqlalchemy import func, select
from sqlmodel import Session

from app.server.queries import (
    Participant,
    PredictionRow,
    StudyContext,
    TrialResponse,
    as_utc,
    static_trial,
)
from app.study.config import stored_predictors
from app.study.errors import Refused

REPLAY_MODELS = ("ours", "vae", "policy", "cv")
DRAWN = ("ours", "vae", "policy")  # the replay's canvas draws these and each plug-in


def participant_of(db: Session, ctx: StudyContext, public_id: str) -> Participant:
    """The study's session with this public id, or 404."""
    found = db.execute(select(Participant).where(Participant.study_id == ctx.study_id,
                                                 Participant.public_id == public_id))
    participant = found.scalars().first()
    if participant is None:
        raise Refused(404, f"public_id: no session {public_id!r} in study {ctx.study_id!r}")
    return participant


def trial_rows(db: Session, ctx: StudyContext, public_id: str) -> dict:
    """A participant's answered trials in the order answered, with click and undo counts."""
    participant = participant_of(db, ctx, public_id)
    clicks = dict(db.execute(select(PredictionRow.submission_id, func.count())
                             .where(PredictionRow.participant_id == participant.id)
                             .group_by(PredictionRow.submission_id)).all())
    responses = db.execute(select(TrialResponse).where(
        TrialResponse.participant_id == participant.id).order_by(TrialResponse.id)).scalars()
    return {"public_id": public_id, "trials": [_trial_row(r, clicks) for r in responses]}


def _trial_row(r: TrialResponse, clicks: dict[str, int]) -> dict:
    return {"trial_id": r.trial_id, "world": r.world, "is_practice": r.is_practice,
            "world_position": r.world_position, "trial_index": r.trial_index,
            "attention_check": r.attention_check, "attention_ok": r.attention_ok,
            "duration_ms": r.duration_ms, "replays": r.replays,
            "clicks": clicks.get(r.submission_id, 0), "history": len(r.history or [])}


def shown_trial(ctx: StudyContext, response: TrialResponse) -> dict:
    """What the participant's browser was given for this trial; 409 if the bank differs."""
    trial = ctx.bank.by_id.get(response.trial_id)
    if trial is None:
        raise Refused(409, f"clip_sha256: trial {response.trial_id!r} is not in the trial bank "
                           f"this server loaded ({ctx.bank.sha256[:12]})")
    if trial.clip_sha256 != response.clip_sha256:  # the hash the answer was stored with
        raise Refused(409, f"clip_sha256: the bank's clip of {response.trial_id!r} is not the "
                           f"one this participant saw ({response.clip_sha256[:12]}); replay "
                           "needs the bank the session ran under")
    return static_trial(ctx, response.trial_id)


def row_action(row: PredictionRow, model: str) -> list[float]:
    """A row's action of one predictor: a column of the row, or a plug-in's from its JSON."""
    if model in REPLAY_MODELS:
        return [getattr(row, f"{model}_vx"), getattr(row, f"{model}_vy")]
    return [row.plugins[model]["vx"], row.plugins[model]["vy"]]


def start_replays(rows: list[PredictionRow], dt_s: float,
                  plugins: list[str] = ()) -> list[dict]:
    """Per start state: its clicks in step order and each predictor's rolled-out positions
    (the models', the baselines' and each plug-in's)."""
    from app.core.alignment import alignment_error

    starts: dict[int, list[PredictionRow]] = {}
    for row in sorted(rows, key=lambda r: (r.start_index, r.step)):
        starts.setdefault(row.start_index, []).append(row)
    out = []
    for index, steps in starts.items():
        start = np.array([steps[0].start_x, steps[0].start_y])
        human = np.array([[r.human_vx, r.human_vy] for r in steps])
        paths, errors = {}, {}
        for model in (*REPLAY_MODELS, *plugins):
            actions = np.array([row_action(r, model) for r in steps])
            paths[model] = (start + dt_s * np.cumsum(actions, axis=0)).round(4).tolist()
            errors[model] = alignment_error(human, actions).round(4).tolist()
        out.append({"start_index": index, "start_kind": steps[0].start_kind,
                    "robot": start.tolist(), "human": [steps[0].human_x, steps[0].human_y],
                    "ours_code": steps[0].ours_code, "vae_code": steps[0].vae_code,
                    "clicks": [{"step": r.step, "at": [r.click_x, r.click_y],
                                "t_ms": r.click_time_ms} for r in steps],
                    "paths": paths, "errors": errors})
    return out


def trial_replay(db: Session, ctx: StudyContext, public_id: str, trial_id: str) -> dict:
    """The clip as shown, the clicks in order with times, the undo history, model moves."""
    participant = participant_of(db, ctx, public_id)
    response = db.execute(select(TrialResponse).where(
        TrialResponse.participant_id == participant.id,
        TrialResponse.trial_id == trial_id)).scalars().first()
    if response is None:
        raise Refused(404, f"trial_id: {public_id!r} answered no trial {trial_id!r}")
    trial = shown_trial(ctx, response)
    rows = db.execute(select(PredictionRow).where(
        PredictionRow.submission_id == response.submission_id)).scalars().all()
    order = sorted((r.click_time_ms, r.start_index, r.step) for r in rows)
    code_predictors = [name for name in stored_predictors(ctx.config)
                       if all(name in r.plugins for r in rows)]  # older rows lack the observers
    return {
        "public_id": public_id, "trial_id": trial_id, "clip_sha256": response.clip_sha256,
        "trial": trial,
        "response": {
            "world": response.world, "is_practice": response.is_practice,
            "world_position": response.world_position, "trial_index": response.trial_index,
            "attention_check": response.attention_check,
            "attention_ok": response.attention_ok, "duration_ms": response.duration_ms,
            "client_duration_ms": response.client_duration_ms,
            "server_duration_ms": response.server_duration_ms, "replays": response.replays,
            "received_at": as_utc(response.received_at).isoformat(),
            "history": response.history or []},
        "starts": start_replays(rows, trial["dt_s"], code_predictors),
        "models": [*DRAWN, *code_predictors],
        "click_order": [{"t_ms": t, "start_index": i, "step": j} for t, i, j in order],
    }
