"""What a participant's answer must satisfy: its shape and times, attention checks, survey answers.

Pure functions of the request, the bank and the study config (no database): each
refusal is a `Refused(422, "field: message")` naming the offending field. Where a click may
land is app/study/clicks.py's rule, shared with the simulated study; when an attention check
passes is its rule too, shared with the bank that chooses the checks.
"""

import numpy as np

from app.server.schemas import PredictionCreate
from app.study.clicks import check_passed, check_points, robot_starts, step_moves
from app.study.config import AttentionChecks, SurveyQuestion
from app.study.errors import Refused
from app.study.trials import TrialBank, TrialRecord

MAX_TRIAL_MS = 6 * 3600 * 1000  # a trial "shown" longer than this is a broken clock


# ---------------------------------------------------------------- clicks

def validate_points(bank: TrialBank, trial: TrialRecord, body: PredictionCreate) -> np.ndarray:
    """Clicked positions [K, n, 2] after checking counts (of clicks, their times and
    inputs), bounds and move lengths."""
    world = bank.world(trial.world)
    k, n = len(trial.start_states), bank.data.steps_to_predict
    _check_counts("points", body.points, k, n)
    _check_counts("click_times_ms", body.click_times_ms, k, n)
    if body.click_inputs is not None:
        _check_counts("click_inputs", body.click_inputs, k, n)
    check_times(body)
    check_history(body, k)
    points = np.asarray(body.points, dtype=np.float64)
    check_points(world, robot_starts(trial), points)
    return points


def check_times(body: PredictionCreate) -> None:
    """Client times: submitted after shown, within MAX_TRIAL_MS; every click time (ms since
    the trial was shown, as the browser measures it) inside that span."""
    if body.submitted_at_ms < body.shown_at_ms:
        raise Refused(422, "submitted_at_ms: earlier than shown_at_ms")
    if body.submitted_at_ms - body.shown_at_ms > MAX_TRIAL_MS:
        raise Refused(422, f"submitted_at_ms: more than {MAX_TRIAL_MS // 3_600_000} h after "
                           "shown_at_ms")
    span = body.submitted_at_ms - body.shown_at_ms
    for i, row in enumerate(body.click_times_ms):
        for j, t in enumerate(row):
            if not 0 <= t <= span:
                raise Refused(422, f"click_times_ms.{i}.{j}: {t:g} ms is outside the trial "
                                   f"(0 to submitted_at_ms - shown_at_ms = {span:g} ms)")


def check_history(body: PredictionCreate, k: int) -> None:
    """Undo/reset presses name one of the `k` start states, in time order, inside the trial."""
    span = body.submitted_at_ms - body.shown_at_ms
    last = 0.0
    for i, entry in enumerate(body.history):
        if entry.start_index >= k:
            raise Refused(422, f"history.{i}.start_index: {entry.start_index} is not one of "
                               f"the {k} start states")
        if not last <= entry.t_ms <= span:
            raise Refused(422, f"history.{i}.t_ms: {entry.t_ms:g} ms is out of order or "
                               f"outside the trial (0 to {span:g} ms)")
        last = entry.t_ms


def _check_counts(field: str, values: list, k: int, n: int) -> None:
    if len(values) != k:
        raise Refused(422, f"{field}: expected {k} start states, got {len(values)}")
    for i, row in enumerate(values):
        if len(row) != n:
            raise Refused(422, f"{field}.{i}: expected {n} steps, got {len(row)}")


# ---------------------------------------------------------------- attention checks

def attention_passed(rule: AttentionChecks, trial: TrialRecord, points: np.ndarray) -> bool:
    """Passed if enough first moves point within the allowed angle of the robot's true move."""
    first = step_moves(robot_starts(trial), points)[:, 0]
    return check_passed(rule, first, np.asarray(trial.policy_actions, dtype=np.float64)[:, 0])


# ---------------------------------------------------------------- survey

def validate_survey(questions: list[SurveyQuestion], answers: dict) -> dict:
    """Answers checked against the configured questions (422 naming the question)."""
    known = {q.key: q for q in questions}
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


def _survey_value(q: SurveyQuestion, key: str, value: str | int | float) -> str | int:
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
