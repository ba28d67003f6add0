"""What a participant's answer must satisfy: clicks, attention checks, survey answers.

Pure functions of the request, the bank and the study config (no database): each
refusal is a `Refused(422, "field: message")` naming the offending field.
"""

import numpy as np

from analysis.alignment import alignment_error
from app.server.schemas import PredictionCreate
from app.study.config import AttentionChecks, SurveyQuestion
from app.study.errors import Refused
from app.study.trials import TrialBank, TrialRecord

MAX_TRIAL_MS = 6 * 3600 * 1000  # a trial "shown" longer than this is a broken clock


# ---------------------------------------------------------------- clicks

def validate_points(bank: TrialBank, trial: TrialRecord, body: PredictionCreate) -> np.ndarray:
    """Clicked positions [K, n, 2] after checking counts, bounds and move lengths."""
    world = bank.world(trial.world)
    k, n = len(trial.start_states), bank.data.steps_to_predict
    _check_counts("points", body.points, k, n)
    _check_counts("click_times_ms", body.click_times_ms, k, n)
    check_times(body)
    check_history(body, k)
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


# ---------------------------------------------------------------- attention checks

def attention_passed(rule: AttentionChecks, trial: TrialRecord, points: np.ndarray) -> bool:
    """Passed if enough first moves point within the allowed angle of the robot's true move."""
    first = step_moves(trial, points)[:, 0]
    truth = np.asarray(trial.policy_actions, dtype=np.float64)[:, 0]
    max_error = 1.0 - np.cos(np.deg2rad(rule.max_angle_deg))  # alignment error of that angle
    within = alignment_error(first, truth) <= max_error
    return int(within.sum()) >= rule.min_passing_starts


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
