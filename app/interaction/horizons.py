"""The pre-specified secondary results: displacement direction at 1-3 s, by stratum, Holm-corrected.

For each horizon h (study_configs/interaction.yaml, `secondary`), val windows are 1 s
observed + h. Each model predicts the robot's displacement over h:
- constant velocity keeps the last observed robot velocity;
- Ours and the VAE hold the window's code (the high-level behaviour) and roll their decoder
  forward n actions at a time from the predicted robot state, the human moving on at its
  last observed velocity (the models are never told the human's future).
Scores: alignment error between predicted and true mean velocity over h (the displacement
direction), ADE/FDE over the h steps. Windows whose true mean speed is below
`min_speed_mps` are not scored.

Strata: a window is a decision moment when, within the horizon, the robot's travel direction
turns more than `decision_heading_deg` from its last observed direction (turning at an
intersection, entering or leaving a ring) or, when the generator's labels exist, its
manoeuvre changes (roundabout entry -> circling, circling -> exit); otherwise steady driving.
Every paired test (3 model pairs x horizons x strata) is one family, Holm-corrected.
"""

from dataclasses import dataclass

import numpy as np

from analysis.stats import holm
from app.core.alignment import alignment_error
from app.data.trajectory import HUMAN, ROBOT
from app.data.windows import Windows, make_windows
from app.interaction.config import SecondaryConfig
from app.interaction.dataset import PairData

STRATA = ("all", "decision", "steady")
MODEL_PAIRS = (("ours", "vae"), ("ours", "cv"), ("vae", "cv"))


@dataclass
class HorizonWindows:
    """Val windows of one horizon, which of them are scored, and each one's stratum masks."""

    horizon_s: float
    steps: int
    windows: Windows
    scored: np.ndarray
    strata: dict[str, np.ndarray]


def horizon_key(horizon_s: float) -> str:
    """The summary key of a horizon: '1', '2', '3' (seconds)."""
    return f"{horizon_s:g}"


def _travel_turn_deg(windows: Windows, steps: int, min_speed: float) -> np.ndarray:
    """Largest turn [W] (deg) of the robot's travel direction within the horizon, measured
    from the last observed action; steps slower than `min_speed` carry no direction."""
    t = windows.segment_len
    actions = windows.actions[:, t - 1: t + steps, ROBOT].astype(np.float64)
    angle = np.arctan2(actions[..., 1], actions[..., 0])
    turn = np.abs((angle[:, 1:] - angle[:, :1] + np.pi) % (2 * np.pi) - np.pi)
    moving = np.hypot(actions[..., 0], actions[..., 1]) >= min_speed
    turn = np.where(moving[:, 1:] & moving[:, :1], turn, 0.0)
    return np.degrees(turn.max(axis=1))


def _manoeuvre_changes(windows: Windows, data: PairData, steps: int) -> np.ndarray:
    """Whether the robot's generator phase (roundabout enter/circle/exit) changes within the
    horizon [W]; a car's route labels never change, so only the phase can."""
    if "phase" not in data.step_labels:
        return np.zeros(len(windows), dtype=bool)
    coarse = data.step_labels["phase"]
    rows = windows.traj_index[:, None]
    span = windows.end_step[:, None] + np.arange(steps + 1)[None, :]
    labels = coarse[rows, span]
    known = (labels >= 0) & (labels[:, :1] >= 0)
    return ((labels != labels[:, :1]) & known).any(axis=1)


def horizon_windows(data: PairData, segment_len: int, cfg: SecondaryConfig,
                    min_speed_mps: float) -> list[HorizonWindows]:
    """One HorizonWindows per configured horizon that fits in the pairs (others are left out)."""
    out = []
    dt = data.trajs.dt_s
    for horizon_s in cfg.horizons_s:
        steps = int(round(horizon_s / dt))
        windows = make_windows(data.trajs, segment_len, steps, cfg.windows_per_pair)
        if len(windows) == 0:
            continue
        mean_velocity = windows.pred_targets.mean(axis=1)
        scored = np.hypot(mean_velocity[:, 0], mean_velocity[:, 1]) >= min_speed_mps
        decision = (_travel_turn_deg(windows, steps, min_speed_mps) > cfg.decision_heading_deg) \
            | _manoeuvre_changes(windows, data, steps)
        strata = {"all": scored, "decision": scored & decision, "steady": scored & ~decision}
        out.append(HorizonWindows(horizon_s, steps, windows, scored, strata))
    return out


def constant_velocity_rollout(windows: Windows, steps: int) -> np.ndarray:
    """The robot's last observed velocity repeated for `steps` [W, steps, 2]."""
    last = windows.actions[:, windows.segment_len - 1, ROBOT]
    return np.repeat(last[:, None], steps, axis=1)


def model_rollout(model, windows: Windows, steps: int) -> np.ndarray:
    """Robot velocities [W, steps, 2]: the code held, decoded n actions at a time from the
    predicted robot state; the human moves on at its last observed velocity."""
    z = model.encode_batch(windows.segment_positions)
    state = windows.end_states.astype(np.float64).copy()
    human_v = windows.actions[:, windows.segment_len - 1, HUMAN].astype(np.float64)
    chunks, done = [], 0
    while done < steps:
        actions = model.predict_batch(z, state.astype(np.float32))
        for k in range(min(actions.shape[1], steps - done)):
            state[:, ROBOT] += actions[:, k] * windows.dt_s
            state[:, HUMAN] += human_v * windows.dt_s
            chunks.append(actions[:, k])
            done += 1
    return np.stack(chunks, axis=1)


def horizon_scores(pred: np.ndarray, hw: HorizonWindows) -> dict[str, dict[str, float]]:
    """Per stratum: mean alignment error of the displacement direction, ADE and FDE (m)."""
    target = hw.windows.pred_targets.astype(np.float64)
    errors = alignment_error(pred.mean(axis=1), target.mean(axis=1))
    dist = np.linalg.norm(np.cumsum((pred - target) * hw.windows.dt_s, axis=1), axis=-1)
    out = {}
    for name, mask in hw.strata.items():
        if mask.sum() == 0:
            continue
        out[name] = {"alignment_error": float(errors[mask].mean()),
                     "ade_m": float(dist[mask].mean()), "fde_m": float(dist[mask, -1].mean())}
    return out


def _mean_sd(values: list[float]) -> dict:
    arr = np.asarray(values, dtype=np.float64)
    return {"mean": float(arr.mean()), "sd": float(arr.std(ddof=1)) if len(arr) > 1 else 0.0,
            "per_seed": [float(v) for v in arr]}


def summarise_by_horizon(hws: list[HorizonWindows], per_seed: list[dict], cv: dict,
                         alpha: float) -> tuple[dict, dict]:
    """(by_horizon[h][stratum][model], tests[h][stratum][pair] with Holm-adjusted p and the
    winner per cell); per_seed[i][h][stratum][model] holds one seed's Ours and VAE scores."""
    from analysis.stats import paired_comparison

    by_horizon, tests, flat = {}, {}, []
    for hw in hws:
        h = horizon_key(hw.horizon_s)
        by_horizon[h], tests[h] = {}, {}
        for stratum in STRATA:
            if stratum not in cv[h]:
                continue
            cell = {m: {key: _mean_sd([seed[h][stratum][m][key] for seed in per_seed])
                        for key in ("alignment_error", "ade_m", "fde_m")} for m in ("ours", "vae")}
            cell["cv"] = {key: _mean_sd([cv[h][stratum][key]] * len(per_seed))
                          for key in ("alignment_error", "ade_m", "fde_m")}
            for m in cell:
                cell[m]["n_windows"] = int(hw.strata[stratum].sum())
            by_horizon[h][stratum] = cell
            tests[h][stratum] = {}
            for a, b in MODEL_PAIRS:
                result = paired_comparison(np.array(cell[a]["alignment_error"]["per_seed"]),
                                           np.array(cell[b]["alignment_error"]["per_seed"]))
                tests[h][stratum][f"{a}_vs_{b}"] = result.as_dict()
                flat.append(tests[h][stratum][f"{a}_vs_{b}"])
    for test, adjusted in zip(flat, holm([t["p_two_sided"] for t in flat]), strict=True):
        test["p_holm"] = adjusted
    winners = {h: {s: _winner(by_horizon[h][s], tests[h][s], alpha) for s in by_horizon[h]}
               for h in by_horizon}
    return by_horizon, {"tests": tests, "winners": winners, "family_size": len(flat),
                        "correction": "holm", "alpha": alpha}


def _winner(cell: dict, tests: dict, alpha: float) -> dict:
    """The model with the lowest mean error, and whether it beats both others after Holm."""
    means = {m: cell[m]["alignment_error"]["mean"] for m in cell}
    best = min(means, key=means.get)
    beats = [t["p_holm"] < alpha for name, t in tests.items() if best in name.split("_vs_")]
    return {"model": best, "holds_after_holm": bool(all(beats))}
