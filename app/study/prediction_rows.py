"""One answered trial as long rows: per start state and step, the person's click and action
beside every predictor's action, the models' codes and checkpoints, and each plug-in
predictor's action, code and content hash (`<name>_vx`, `_vy`, `_code`, `_sha256`).

The server stores these rows (app/server/flow/predictions.py adds who answered and when each click
came); the simulated study builds its export rows from the same columns, so the instrument
scores exactly what a live participant's answer stores.
"""

from collections.abc import Mapping
from typing import Protocol

import numpy as np

from app.study.clicks import clicks_to_actions, robot_starts
from app.study.trials import TrialRecord

MODELS = ("ours", "vae")


class ModelAnswerLike(Protocol):
    """A model's answer to a trial: the bank's stored one or a server's recomputed one."""

    code: int
    actions: object  # [K, n, 2] m/s, array or nested lists
    content_hash: str


def prediction_columns(trial: TrialRecord, answers: Mapping[str, ModelAnswerLike],
                       points: np.ndarray, dt_s: float) -> dict[str, np.ndarray]:
    """Columns of K x n rows (start state major): the clicks, the person's actions and each
    predictor's (models and plug-ins from `answers`, constant velocity and the policy from
    the bank)."""
    k, n = points.shape[:2]
    starts = robot_starts(trial)
    humans = np.asarray([s.human for s in trial.start_states], dtype=np.float64)
    cols = {"start_index": np.repeat(np.arange(k), n),
            "start_kind": np.repeat([s.start_kind for s in trial.start_states], n),
            "step": np.tile(np.arange(n), k),
            "start_x": np.repeat(starts[:, 0], n), "start_y": np.repeat(starts[:, 1], n),
            "human_x": np.repeat(humans[:, 0], n), "human_y": np.repeat(humans[:, 1], n),
            "click_x": points[..., 0].ravel(), "click_y": points[..., 1].ravel()}
    plugins = [name for name in answers if name not in MODELS]
    actions = {"human": clicks_to_actions(starts, points, dt_s),
               **{m: answers[m].actions for m in MODELS},
               "cv": trial.cv_actions, "policy": trial.policy_actions,
               **{p: answers[p].actions for p in plugins}}
    for name, values in actions.items():
        values = np.asarray(values, dtype=np.float64)[:, :n]
        cols[f"{name}_vx"] = values[..., 0].ravel()
        cols[f"{name}_vy"] = values[..., 1].ravel()
    for model in (*MODELS, *plugins):
        cols[f"{model}_code"] = np.full(k * n, answers[model].code)
        cols[f"{model}_sha256"] = np.full(k * n, answers[model].content_hash)
    return cols


def as_rows(columns: Mapping[str, np.ndarray]) -> list[dict]:
    """Columns of equal length -> one dict of plain Python values per row."""
    names = list(columns)
    return [dict(zip(names, values, strict=True))
            for values in zip(*(columns[name].tolist() for name in names), strict=True)]
