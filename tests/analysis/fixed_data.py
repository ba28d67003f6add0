"""A small, fixed, hand-readable predictions table in the export CSV's columns."""

import numpy as np
import pandas as pd

from analysis.load import EXPORT_COLUMNS, normalise

DT_S = 0.5


def fixed_predictions(n_participants: int = 4, trials: int = 2, starts: int = 2,
                      steps: int = 3, seed: int = 7) -> pd.DataFrame:
    """Rows for 2 worlds; human and model actions at known angles, clicks consistent with dt."""
    rng = np.random.default_rng(seed)
    rows = []
    for p in range(n_participants):
        for w, world in enumerate(("highway", "obstacle")):
            for t in range(trials):
                for s in range(starts):
                    start = np.array([1.0 + s, 2.0 + t])
                    pos = start.copy()
                    for k in range(steps):
                        human = rng.normal(size=2) + np.array([2.0, 0.0])
                        pos = pos + DT_S * human
                        rows.append(_row(p, world, w, t, s, k, start, pos, human, rng))
    return normalise(pd.DataFrame(rows, columns=EXPORT_COLUMNS))


def _row(p, world, w, t, s, k, start, click, human, rng) -> list:
    ours = human + rng.normal(scale=0.3, size=2)
    vae = human + rng.normal(scale=1.5, size=2)
    cv = np.array([1.0, 0.0])
    policy = human + rng.normal(scale=0.1, size=2)
    values = {
        "study_id": "paper_study", "participant_id": f"p{p:02d}", "recruitment": "prolific",
        "external_id": f"ext{p}", "completed": True, "attention_passed": True,
        "world": world, "world_position": w, "trial_id": f"{world}-{t}", "trial_index": t,
        "is_practice": False, "attention_check": False, "clip_sha256": "c" * 8,
        "start_index": s, "step": k, "start_x": start[0], "start_y": start[1],
        "human_x": 0.0, "human_y": 0.0, "click_x": click[0], "click_y": click[1],
        "human_vx": human[0], "human_vy": human[1], "ours_vx": ours[0], "ours_vy": ours[1],
        "vae_vx": vae[0], "vae_vy": vae[1], "cv_vx": cv[0], "cv_vy": cv[1],
        "policy_vx": policy[0], "policy_vy": policy[1], "ours_code": s % 2, "vae_code": t % 2,
        "ours_sha256": "o" * 8, "vae_sha256": "v" * 8, "click_time_ms": 100.0 * (k + 1),
        "trial_duration_ms": 8000.0, "replays": 0, "submission_id": f"sub-{p}-{w}-{t}",
        "submitted_at": "2026-01-01T00:00:00Z",
    }
    return [values[c] for c in EXPORT_COLUMNS]
