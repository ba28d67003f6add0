"""Every write to the study database, and the reads the writes depend on.

A participant's plan is fixed at session start; `position` indexes into it. A step is
advanced by a conditional UPDATE (`WHERE position = expected`), so two workers racing on
one participant cannot both advance it, and a client UUID (`submission_id`, unique) makes
a retried request a no-op that answers the current state.
"""

import secrets
import uuid
from contextlib import contextmanager
from dataclasses import dataclass, field
from datetime import datetime, timedelta
from itertools import permutations

import numpy as np
from sqlalchemy import case, func, select, update
from sqlalchemy.exc import IntegrityError
from sqlmodel import Session

from app.study.config import StudyConfig
from app.study.predictor import Predictor
from app.study.tables import (
    ConsentCreate,
    Participant,
    PredictionCreate,
    PredictionRow,
    SessionCreate,
    Submission,
    SubmissionBody,
    SurveyCreate,
    TrialResponse,
    utcnow,
)
from app.study.trials import TrialBank, TrialRecord

TRIAL_PHASES = ("practice", "trial")


class Refused(Exception):
    """A request the study cannot accept: HTTP status and `field: message`."""

    def __init__(self, status: int, detail: str) -> None:
        super().__init__(detail)
        self.status = status
        self.detail = detail


@dataclass(frozen=True)
class StudyContext:
    """What every participant write needs besides the database."""

    study_id: str
    config: StudyConfig
    bank: TrialBank
    predictor: Predictor
    # trial id -> the trial's static browser JSON, encoded once (see app/study/state.py)
    trial_json: dict[str, str] = field(default_factory=dict, compare=False, repr=False)


# ---------------------------------------------------------------- sessions

def external_identity(body: SessionCreate) -> tuple[str, str | None]:
    """(recruitment platform, external id) from the URL parameters."""
    rec = body.recruitment
    if rec.PROLIFIC_PID:
        return "prolific", rec.PROLIFIC_PID
    if rec.workerId:
        return "mturk", rec.workerId
    return "anonymous", None


def start_session(db: Session, ctx: StudyContext, body: SessionCreate,
                  rng: np.random.Generator | None = None) -> tuple[Participant, bool]:
    """A new participant with a balanced plan, or the unfinished one with this external id."""
    recruitment, external_id = external_identity(body)
    existing = find_participant(db, ctx.study_id, external_id)
    if existing is not None:
        db.commit()  # end the read transaction
        return _resume(existing, body), True
    rng = rng or np.random.default_rng()
    order, plan = assign_plan(db, ctx, rng)
    participant = Participant(
        study_id=ctx.study_id, recruitment=recruitment, external_id=external_id,
        session_token=secrets.token_urlsafe(24),
        recruitment_params=body.recruitment.model_dump(exclude_none=True),
        client=body.client.model_dump(), world_order=",".join(order), plan=plan,
    )
    db.add(participant)
    try:
        db.commit()
    except IntegrityError:  # the same external id started concurrently
        db.rollback()
        existing = find_participant(db, ctx.study_id, external_id)
        if existing is None:
            raise
        return _resume(existing, body), True
    db.refresh(participant)
    return participant, False


# The platform's per-attempt id: knowing a worker's public id alone must not open their session.
_ATTEMPT_KEYS = {"prolific": "SESSION_ID", "mturk": "assignmentId"}


def _resume(participant: Participant, body: SessionCreate) -> Participant:
    if participant.completed:
        raise Refused(409, "recruitment: this participant has already completed the study")
    key = _ATTEMPT_KEYS.get(participant.recruitment)
    stored = participant.recruitment_params.get(key) if key else None
    if stored is not None and getattr(body.recruitment, key) != stored:
        raise Refused(409, f"recruitment.{key}: does not match the session in progress for "
                           "this participant id; reopen the study from the original link")
    return participant


def find_participant(db: Session, study_id: str, external_id: str | None) -> Participant | None:
    """The participant of this study with this external id (None for anonymous)."""
    if external_id is None:
        return None
    query = select(Participant).where(Participant.study_id == study_id,
                                      Participant.external_id == external_id)
    return db.execute(query).scalars().first()


def participant_by_token(db: Session, token: str) -> Participant:
    """The participant holding this session token, or 404."""
    found = db.execute(select(Participant).where(Participant.session_token == token))
    participant = found.scalars().first()
    if participant is None:
        raise Refused(404, "token: unknown session")
    return participant


# ---------------------------------------------------------------- balanced assignment

def counted_participants(db: Session, ctx: StudyContext) -> list[Participant]:
    """Participants that count for balance: valid completions and recent unfinished sessions.

    A completion is valid unless an enabled exclusion rule (failed attention check, too
    many too-fast trials) removes it; an unfinished session counts while it is younger
    than `in_progress_timeout_min`, so abandoned ones stop holding their trials.
    """
    cutoff = in_progress_cutoff(ctx.config)
    rows = db.execute(select(Participant).where(Participant.study_id == ctx.study_id))
    people = rows.scalars().all()
    too_fast = too_fast_participants(db, ctx, [p.id for p in people if p.completed])
    counted = []
    for p in people:
        if p.completed:
            failed = p.attention_failed > 0 and ctx.config.exclusions.failed_attention_check
            if not failed and p.id not in too_fast:
                counted.append(p)
        elif is_in_progress(p, cutoff):
            counted.append(p)
    return counted


def in_progress_cutoff(config: StudyConfig) -> datetime:
    """Unfinished sessions last updated before this are abandoned (stale)."""
    return utcnow() - timedelta(minutes=config.in_progress_timeout_min)


def is_in_progress(participant: Participant, cutoff: datetime) -> bool:
    """Unfinished and updated since `cutoff`."""
    return not participant.completed and as_utc(participant.updated_at) >= cutoff


def too_fast_participants(db: Session, ctx: StudyContext, ids: list[int]) -> set[int]:
    """Of `ids`, those whose share of too-fast scored trials exceeds the exclusion rule."""
    rule = ctx.config.exclusions
    if not ids:
        return set()
    fast = func.sum(case((TrialResponse.duration_ms < rule.too_fast_trial_ms, 1), else_=0))
    query = (select(TrialResponse.participant_id, fast, func.count())
             .where(TrialResponse.participant_id.in_(ids), TrialResponse.is_practice.is_(False),
                    TrialResponse.attention_check.is_(False))
             .group_by(TrialResponse.participant_id))
    return {pid for pid, n_fast, n in db.execute(query) if n and n_fast / n
            > rule.too_fast_max_fraction}


def as_utc(moment):
    """SQLite returns naive datetimes; they were written in UTC."""
    return moment if moment.tzinfo else moment.replace(tzinfo=utcnow().tzinfo)


def world_orders(config: StudyConfig) -> list[tuple[str, ...]]:
    """All orders when counterbalanced, else the configured one."""
    if config.counterbalance_world_order:
        return list(permutations(config.worlds))
    return [tuple(config.worlds)]


def least_used(candidates: list, counts: dict, k: int, rng: np.random.Generator) -> list:
    """The k candidates with the lowest counts, ties broken at random."""
    noise = rng.random(len(candidates))
    keys = np.lexsort((noise, [counts.get(c, 0) for c in candidates]))
    return [candidates[i] for i in keys[:k]]


def assign_plan(db: Session, ctx: StudyContext,
                rng: np.random.Generator) -> tuple[tuple[str, ...], list[dict]]:
    """Pick the least-used world order and least-exposed trials; lay out the steps."""
    counted = counted_participants(db, ctx)
    order_counts: dict = {}
    exposure: dict = {}
    for p in counted:
        key = tuple(p.world_order.split(","))
        order_counts[key] = order_counts.get(key, 0) + 1
        for step in p.plan:
            if "trial_id" in step:
                exposure[step["trial_id"]] = exposure.get(step["trial_id"], 0) + 1
    order = least_used(world_orders(ctx.config), order_counts, 1, rng)[0]
    return order, layout_plan(ctx, order, exposure, rng)


def layout_plan(ctx: StudyContext, order: tuple[str, ...], exposure: dict,
                rng: np.random.Generator) -> list[dict]:
    """consent, instructions, practice, per world its trials with attention checks, survey, done."""
    cfg = ctx.config
    plan: list[dict] = [{"phase": "consent"}, {"phase": "instructions"}]
    practice_pool = [t.trial_id for t in ctx.bank.trials_of(order[0], "practice")]
    for i, tid in enumerate(least_used(practice_pool, exposure, cfg.practice_trials, rng)):
        plan.append(_trial_step("practice", tid, order[0], 0, i, False))
    for position, world in enumerate(order):
        main = [t.trial_id for t in ctx.bank.trials_of(world, "main")]
        chosen = least_used(main, exposure, cfg.trials_per_world, rng)
        rng.shuffle(chosen)
        checks = [t.trial_id for t in ctx.bank.trials_of(world, "attention")]
        block = [(tid, False) for tid in chosen]
        for tid in least_used(checks, exposure, cfg.attention_checks.per_world, rng):
            block.insert(int(rng.integers(1, len(block) + 1)), (tid, True))
        plan += [_trial_step("trial", tid, world, position, index, check)
                 for index, (tid, check) in enumerate(block)]
    return plan + [{"phase": "survey"}, {"phase": "done"}]


def _trial_step(phase: str, trial_id: str, world: str, world_position: int, index: int,
                attention_check: bool) -> dict:
    return {"phase": phase, "trial_id": trial_id, "world": world,
            "world_position": world_position, "trial_index": index,
            "attention_check": attention_check}


# ---------------------------------------------------------------- step writes

def current_step(participant: Participant) -> dict:
    """The plan step the participant is at."""
    return participant.plan[min(participant.position, len(participant.plan) - 1)]


def already_stored(db: Session, participant: Participant, submission_id: uuid.UUID) -> bool:
    """True if this UUID was stored for this participant (a retry); 409 if for someone else."""
    owner = db.execute(select(Submission.participant_id).where(
        Submission.submission_id == str(submission_id))).scalar()
    if owner is None:
        return False
    if owner != participant.id:
        raise Refused(409, "submission_id: already used by another session")
    return True


def expect_phase(participant: Participant, *phases: str) -> dict:
    """The current step if its phase is one of `phases`, else 409."""
    step = current_step(participant)
    if step["phase"] not in phases:
        raise Refused(409, f"phase: this request belongs to {' or '.join(phases)}, "
                           f"but the session is at {step['phase']}")
    return step


def advance(db: Session, participant: Participant, body: SubmissionBody, kind: str,
            payload: dict, extra_inserts: list[tuple[object, list[dict]]] = (),
            completes: bool = False) -> bool:
    """Store the submission and its rows and move one step on, in one transaction.

    Returns False when a concurrent retry of the same UUID won the race (nothing stored).
    """
    expected = participant.position
    now = utcnow()
    values = {"position": expected + 1, "updated_at": now}
    if completes:
        values.update(completed=True, completed_at=now)
    if payload.get("attention_ok") is False:
        values["attention_failed"] = Participant.attention_failed + 1
    conn = db.connection()
    try:
        conn.execute(Submission.__table__.insert(), [{
            "submission_id": str(body.submission_id), "participant_id": participant.id,
            "kind": kind, "step_index": expected, "payload": payload, "received_at": now}])
        for table, rows in extra_inserts:
            conn.execute(table.__table__.insert(), rows)
        moved = conn.execute(update(Participant.__table__)
                             .where(Participant.id == participant.id,
                                    Participant.position == expected).values(**values))
        if moved.rowcount != 1:
            raise Refused(409, "position: the session moved on in another request; reload")
        db.commit()
    except IntegrityError:
        db.rollback()
        if already_stored(db, participant, body.submission_id):
            return False
        raise
    except Refused:
        db.rollback()
        raise
    for key, value in values.items():  # mirror the UPDATE instead of reading the row back
        if key != "attention_failed":
            setattr(participant, key, value)
    if "attention_failed" in values:
        participant.attention_failed += 1
    return True


def record_consent(db: Session, participant: Participant, body: ConsentCreate) -> None:
    """The participant agreed to take part."""
    with replay_if_stored(db, participant, body) as fresh:
        expect_phase(participant, "consent")
        fresh.stored = advance(db, participant, body, "consent", {"agree": True})


def record_instructions(db: Session, participant: Participant, body: SubmissionBody) -> None:
    """The participant has read the instructions."""
    with replay_if_stored(db, participant, body) as fresh:
        expect_phase(participant, "instructions")
        fresh.stored = advance(db, participant, body, "instructions", {})


def record_survey(db: Session, ctx: StudyContext, participant: Participant,
                  body: SurveyCreate) -> None:
    """Closing answers; the session is then complete."""
    with replay_if_stored(db, participant, body) as fresh:
        expect_phase(participant, "survey")
        answers = validate_survey(ctx.config, body.answers)
        fresh.stored = advance(db, participant, body, "survey", {"answers": answers},
                               completes=True)


class _Outcome:
    stored = False


@contextmanager
def replay_if_stored(db: Session, participant: Participant, body: SubmissionBody):
    """Run a write; if it is refused, a retry of a stored UUID is not an error.

    The common first-time path costs no lookup: a retry is recognised only when the
    write is refused (the session has moved on), and a concurrent duplicate by the
    unique key inside `advance`.
    """
    outcome = _Outcome()
    try:
        yield outcome
    except Refused:
        if already_stored(db, participant, body.submission_id):
            outcome.stored = False
            return
        raise


def validate_survey(config: StudyConfig, answers: dict) -> dict:
    """Answers checked against the configured questions (422 naming the question)."""
    known = {q.key: q for q in config.survey}
    for key in answers:
        if key not in known:
            raise Refused(422, f"answers.{key}: not a question of this study")
    clean = {}
    for key, q in known.items():
        value = answers.get(key)
        if value is None or value == "":
            if q.required:
                raise Refused(422, f"answers.{key}: an answer is required")
            continue
        clean[key] = _survey_value(q, key, value)
    return clean


def _survey_value(q, key: str, value):
    if q.kind == "likert":
        if isinstance(value, bool) or not isinstance(value, int | float) or value != int(value):
            raise Refused(422, f"answers.{key}: must be a whole number")
        if not q.scale_min <= value <= q.scale_max:
            raise Refused(422, f"answers.{key}: must be between {q.scale_min} and {q.scale_max}")
        return int(value)
    if q.kind == "choice" and value not in q.options:
        raise Refused(422, f"answers.{key}: must be one of {', '.join(q.options)}")
    text = str(value)
    if len(text) > q.max_chars:
        raise Refused(422, f"answers.{key}: at most {q.max_chars} characters")
    return text


# ---------------------------------------------------------------- predictions

def record_predictions(db: Session, ctx: StudyContext, participant: Participant,
                       body: PredictionCreate) -> bool:
    """Validate and store one trial's clicks with every predictor's actions. True if new."""
    with replay_if_stored(db, participant, body) as fresh:
        fresh.stored = _store_predictions(db, ctx, participant, body)
    return fresh.stored


def _store_predictions(db: Session, ctx: StudyContext, participant: Participant,
                       body: PredictionCreate) -> bool:
    trial = ctx.bank.by_id.get(body.trial_id)
    if trial is None:
        raise Refused(404, f"trial_id: unknown trial {body.trial_id!r}")
    if not any(s.get("trial_id") == body.trial_id for s in participant.plan):
        raise Refused(403, f"trial_id: trial {body.trial_id!r} is not assigned to this session")
    step = expect_phase(participant, *TRIAL_PHASES)
    if step["trial_id"] != body.trial_id:
        raise Refused(409, f"trial_id: the current trial is {step['trial_id']!r}, "
                           f"not {body.trial_id!r}")
    points = validate_points(ctx, trial, body)
    rows = prediction_rows(ctx, participant, trial, body, points)
    attention_ok = attention_verdict(ctx.config, trial, points) if step["attention_check"] else None
    response = {
        "submission_id": str(body.submission_id), "participant_id": participant.id,
        "trial_id": trial.trial_id, "world": trial.world,
        "world_position": step["world_position"], "trial_index": step["trial_index"],
        "is_practice": step["phase"] == "practice", "attention_check": step["attention_check"],
        "attention_ok": attention_ok, "shown_at_ms": body.shown_at_ms,
        "submitted_at_ms": body.submitted_at_ms,
        "duration_ms": body.submitted_at_ms - body.shown_at_ms, "replays": body.replays,
        "clip_sha256": trial.clip_sha256, "received_at": utcnow(),
    }
    payload = {"trial_id": trial.trial_id, "attention_ok": attention_ok}
    return advance(db, participant, body, "predictions", payload,
                   [(TrialResponse, [response]), (PredictionRow, rows)])


def validate_points(ctx: StudyContext, trial: TrialRecord, body: PredictionCreate) -> np.ndarray:
    """Clicked positions [K, n, 2] after checking counts, bounds and move lengths."""
    world = ctx.bank.world(trial.world)
    k, n = len(trial.start_states), ctx.bank.data.steps_to_predict
    _check_counts("points", body.points, k, n)
    _check_counts("click_times_ms", body.click_times_ms, k, n)
    if body.submitted_at_ms < body.shown_at_ms:
        raise Refused(422, "submitted_at_ms: earlier than shown_at_ms")
    points = np.asarray(body.points, dtype=np.float64)
    bounds = world.scene["bounds"]
    for i, j in np.argwhere(~_inside(points, bounds)):
        x, y = points[i, j]
        raise Refused(422, f"points.{i}.{j}: ({x:g}, {y:g}) is outside the scene "
                           f"x [{bounds['x_min_m']:g}, {bounds['x_max_m']:g}] "
                           f"y [{bounds['y_min_m']:g}, {bounds['y_max_m']:g}] m")
    moves = step_moves(trial, points)
    lengths = np.hypot(moves[..., 0], moves[..., 1])
    for i, j in np.argwhere(lengths < world.min_step_m):
        raise Refused(422, f"points.{i}.{j}: move of {lengths[i, j]:.3g} m is shorter than "
                           f"the minimum {world.min_step_m:.3g} m")
    for i, j in np.argwhere(lengths > world.max_step_m * (1 + 1e-6)):
        raise Refused(422, f"points.{i}.{j}: move of {lengths[i, j]:.3g} m is longer than "
                           f"the reachable {world.max_step_m:.3g} m")
    return points


def _check_counts(field: str, values: list, k: int, n: int) -> None:
    if len(values) != k:
        raise Refused(422, f"{field}: expected {k} start states, got {len(values)}")
    for i, row in enumerate(values):
        if len(row) != n:
            raise Refused(422, f"{field}.{i}: expected {n} steps, got {len(row)}")


def _inside(points: np.ndarray, bounds: dict) -> np.ndarray:
    x, y = points[..., 0], points[..., 1]
    return ((x >= bounds["x_min_m"]) & (x <= bounds["x_max_m"])
            & (y >= bounds["y_min_m"]) & (y <= bounds["y_max_m"]))


def step_moves(trial: TrialRecord, points: np.ndarray) -> np.ndarray:
    """Clicked positions [K, n, 2] -> moves [K, n, 2] (m) from each start state, step by step."""
    starts = np.asarray([s.robot for s in trial.start_states], dtype=np.float64)
    return np.diff(np.concatenate([starts[:, None], points], axis=1), axis=1)


def human_actions(trial: TrialRecord, points: np.ndarray, dt_s: float) -> np.ndarray:
    """Clicked positions [K, n, 2] -> actions [K, n, 2] = position differences / dt."""
    return step_moves(trial, points) / dt_s


def attention_verdict(config: StudyConfig, trial: TrialRecord, points: np.ndarray) -> bool:
    """Passed if enough first moves point within the allowed angle of the robot's true move."""
    rule = config.attention_checks
    first = step_moves(trial, points)[:, 0]
    truth = np.asarray(trial.policy_actions, dtype=np.float64)[:, 0]
    cos = (first * truth).sum(-1) / (np.linalg.norm(first, axis=-1)
                                     * np.linalg.norm(truth, axis=-1) + 1e-12)
    within = cos >= np.cos(np.deg2rad(rule.max_angle_deg))
    return int(within.sum()) >= rule.min_passing_starts


def prediction_rows(ctx: StudyContext, participant: Participant, trial: TrialRecord,
                    body: PredictionCreate, points: np.ndarray) -> list[dict]:
    """Long rows: one per (start state, step), human action beside each predictor's."""
    dt_s = ctx.bank.world(trial.world).dt_s
    human = human_actions(trial, points, dt_s)
    answers = ctx.predictor.answers(trial.trial_id)
    ours, vae = answers["ours"], answers["vae"]
    cv = np.asarray(trial.cv_actions)
    policy = np.asarray(trial.policy_actions)
    rows = []
    for i, start in enumerate(trial.start_states):
        for j in range(points.shape[1]):
            rows.append({
                "submission_id": str(body.submission_id), "participant_id": participant.id,
                "trial_id": trial.trial_id, "start_index": i, "start_kind": start.start_kind,
                "step": j,
                "start_x": start.robot[0], "start_y": start.robot[1],
                "human_x": start.human[0], "human_y": start.human[1],
                "click_x": float(points[i, j, 0]), "click_y": float(points[i, j, 1]),
                "human_vx": float(human[i, j, 0]), "human_vy": float(human[i, j, 1]),
                "ours_vx": float(ours.actions[i, j, 0]), "ours_vy": float(ours.actions[i, j, 1]),
                "vae_vx": float(vae.actions[i, j, 0]), "vae_vy": float(vae.actions[i, j, 1]),
                "cv_vx": float(cv[i, j, 0]), "cv_vy": float(cv[i, j, 1]),
                "policy_vx": float(policy[i, j, 0]), "policy_vy": float(policy[i, j, 1]),
                "ours_code": ours.code, "vae_code": vae.code,
                "ours_sha256": ours.content_hash, "vae_sha256": vae.content_hash,
                "click_time_ms": float(body.click_times_ms[i][j]),
            })
    return rows
