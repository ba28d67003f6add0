"""Latent quality and prediction error of a trained model on held-out windows.

- code usage and perplexity (exp of the code-distribution entropy);
- purity and NMI of codes (VAE: k-means clusters) against each categorical label;
- MSE of predicted robot velocities, ADE/FDE of positions integrated from them over the
  n steps, for the model and for a constant-velocity baseline.

Derived labels, computed only when the needed step label exists:
- `<agent>_intent_in_progress`: a window whose segment ends at or after
  `<agent>_change_step` (lane change finished) counts as the intent named "keep";
- `<agent>_goal_before_arrival`: windows ending after `<agent>_arrival_step` are skipped.
"""

import numpy as np
from sklearn.metrics import normalized_mutual_info_score

from app.data.windows import Windows

SKIP = -1


def code_usage(codes: np.ndarray, min_share: float = 0.0) -> dict:
    """Counts per code, how many codes hold at least `min_share`, and the perplexity."""
    values, counts = np.unique(codes, return_counts=True)
    share = counts / counts.sum()
    entropy = float(-(share * np.log(share)).sum())
    return {"counts": {str(int(v)): int(c) for v, c in zip(values, counts, strict=True)},
            "n_codes_seen": int(len(values)), "n_codes_used": int((share >= min_share).sum()),
            "perplexity": float(np.exp(entropy))}


def purity(codes: np.ndarray, labels: np.ndarray) -> float:
    """Share of windows whose label is their code's majority label."""
    total = 0
    for code in np.unique(codes):
        total += np.bincount(labels[codes == code]).max()
    return float(total / len(codes))


def derived_labels(windows: Windows, label_names: dict[str, list[str]]) -> dict[str, np.ndarray]:
    """Per-window categorical labels (SKIP = not scored), raw and derived (module docstring)."""
    out = {}
    for name in sorted(label_names):
        if name not in windows.labels:
            continue
        raw = windows.labels[name].astype(np.int64)
        out[name] = raw
        agent, _, kind = name.rpartition("_")
        if kind == "intent" and f"{agent}_change_step" in windows.labels \
                and "keep" in label_names[name]:
            change = windows.labels[f"{agent}_change_step"]
            done = (change >= 0) & (windows.end_step >= change)
            out[f"{name}_in_progress"] = np.where(done, label_names[name].index("keep"), raw)
        if kind == "goal" and f"{agent}_arrival_step" in windows.labels:
            arrival = windows.labels[f"{agent}_arrival_step"]
            out[f"{name}_before_arrival"] = np.where(
                (arrival >= 0) & (windows.end_step > arrival), SKIP, raw)
    return out


def agreement(codes: np.ndarray, labels: dict[str, np.ndarray]) -> dict:
    """Purity and NMI of codes against every label, over the windows each label scores."""
    result = {}
    for name, values in labels.items():
        keep = values != SKIP
        if keep.sum() == 0:
            continue
        result[name] = {
            "purity": purity(codes[keep], values[keep]),
            # purity of a single cluster: the floor any clustering reaches
            "majority": float(np.bincount(values[keep]).max() / keep.sum()),
            "nmi": float(normalized_mutual_info_score(values[keep], codes[keep])),
            "n_windows": int(keep.sum()),
        }
    return result


def trajectory_errors(pred: np.ndarray, target: np.ndarray, dt_s: float) -> dict:
    """MSE of velocities [W, n, 2] and ADE/FDE (m) of positions integrated from them."""
    offsets = np.cumsum((pred - target) * dt_s, axis=1)
    dist = np.linalg.norm(offsets, axis=-1)
    return {"mse": float(((pred - target) ** 2).mean()), "ade_m": float(dist.mean()),
            "fde_m": float(dist[:, -1].mean())}


def constant_velocity(windows: Windows) -> np.ndarray:
    """Baseline: the robot keeps its last in-segment velocity for all n steps [W, n, 2]."""
    last = windows.actions[:, windows.segment_len - 1, 0]
    return np.repeat(last[:, None], windows.n_actions, axis=1)


def evaluate(model, windows: Windows, label_names: dict[str, list[str]],
             min_share: float = 0.0) -> dict:
    """Every metric of `model` (a TrainedModel) on `windows`, plus the baseline's errors."""
    z = model.encode_batch(windows.segment_positions)
    codes = model.codes_of(z)
    pred = model.predict_batch(z, windows.end_states)
    return {
        "n_windows": len(windows),
        "n_trajectories": int(len(np.unique(windows.traj_index))),
        "usage": code_usage(codes, min_share),
        "agreement": agreement(codes, derived_labels(windows, label_names)),
        "prediction": trajectory_errors(pred, windows.pred_targets, windows.dt_s),
        "constant_velocity": trajectory_errors(constant_velocity(windows),
                                               windows.pred_targets, windows.dt_s),
    }
