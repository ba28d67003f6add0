"""Participants' vs a model's vector field: the numbers behind the report's field figures.

Only numpy and pandas (no matplotlib): the researcher dashboard draws the same panels in
the browser from these tables.
"""

import numpy as np
import pandas as pd

FIELD_MODELS = ("ours", "vae")


def state_table(rows: pd.DataFrame) -> pd.DataFrame:
    """Per (trial, start state): position, participants' mean first move, each model's first
    move and code, and the sums and counts of each model's error over all steps."""
    first = rows[rows["step"] == rows["step"].min()]
    table = first.groupby(["trial_id", "start_index"], sort=True).agg(
        x=("start_x", "first"), y=("start_y", "first"),
        participant_vx=("participant_vx", "mean"), participant_vy=("participant_vy", "mean"),
        ours_vx=("ours_vx", "first"),
        ours_vy=("ours_vy", "first"), vae_vx=("vae_vx", "first"), vae_vy=("vae_vy", "first"),
        ours_code=("ours_code", "first"), vae_code=("vae_code", "first"))
    errors = rows.groupby(["trial_id", "start_index"], sort=True).agg(
        ours_sum=("err_ours", "sum"), vae_sum=("err_vae", "sum"), count=("err_ours", "size"))
    return table.join(errors).reset_index()


def top_codes(states: pd.DataFrame, model: str, k: int) -> list[int]:
    """The model's k most common latent codes over the answered trials (trials, not rows)."""
    trials = states.drop_duplicates(["trial_id"])
    return trials[f"{model}_code"].value_counts().index[:k].tolist()


def unit(vx: np.ndarray, vy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit vectors of (vx, vy); a vector of length ~0 stays 0."""
    norm = np.hypot(vx, vy)
    norm = np.where(norm > 1e-9, norm, 1.0)
    return vx / norm, vy / norm


def panel_error(states: pd.DataFrame, model: str) -> float:
    """The model's mean alignment error over every step of the panel's start states."""
    return float(states[f"{model}_sum"].sum() / states["count"].sum())


def code_panels(states_w: pd.DataFrame, model: str, k: int) -> list[tuple[int, pd.DataFrame]]:
    """The start states of each of the model's k most common codes in one world."""
    return [(code, states_w[states_w[f"{model}_code"] == code])
            for code in top_codes(states_w, model, k)]


def scene_size(scene: dict) -> tuple[float, float]:
    """Width and height [m] of a scene's bounds (scene JSON, as in bank.json)."""
    b = scene["bounds"]
    return b["x_max_m"] - b["x_min_m"], b["y_max_m"] - b["y_min_m"]


def is_long_and_thin(scene: dict) -> bool:
    """Whether a scene is more than twice as wide as high (a road rather than a plane)."""
    width, height = scene_size(scene)
    return width > 2 * height


def arrow_length(scene: dict | None) -> float:
    """Arrow length [m] that reads well on a scene: 8% of its width, at most a quarter of its
    height (so arrows stay inside a road's lanes)."""
    if scene is None:
        return 0.5
    width, height = scene_size(scene)
    return min(0.08 * width, 0.25 * height)
