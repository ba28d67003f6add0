"""A small, fixed, hand-readable predictions table in the export CSV's columns."""

import copy
import hashlib
import json
import math

import numpy as np
import pandas as pd

from analysis.load import normalise
from app.core.contracts import EXPORT_COLUMNS, EXPORT_VERSION
from app.study.trials import TrialBank

DT_S = 0.5
START_KINDS = {"highway": ("own", "same_lane", "adjacent_lane", "same_lane", "adjacent_lane"),
               "obstacle": ("own", "near", "mid", "near", "mid")}



def cos_distance(a, b) -> float:
    """1 - cos of the angle between two 2-D vectors, by hand (the alignment error's reference)."""
    return 1 - (a[0] * b[0] + a[1] * b[1]) / (math.hypot(*a) * math.hypot(*b))

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
        "export_version": EXPORT_VERSION, "study_id": "paper_study",
        "participant_id": f"p{p:02d}", "recruitment": "prolific",
        "completed": True, "outcome": "completed", "replaced": False, "prolific_check": "",
        "attention_passed": True,
        "world": world, "world_position": w, "trial_id": f"{world}-{t}", "trial_index": t,
        "is_practice": False, "attention_check": False, "arm": ("random", "models_disagree")[t % 2],
        "clip_sha256": "c" * 8,
        "start_index": s, "start_kind": START_KINDS[world][s], "step": k, "start_x": start[0],
        "start_y": start[1],
        "human_x": 0.0, "human_y": 0.0, "participant_click_x": click[0],
        "participant_click_y": click[1], "participant_vx": human[0], "participant_vy": human[1],
        "ours_vx": ours[0], "ours_vy": ours[1],
        "vae_vx": vae[0], "vae_vy": vae[1], "cv_vx": cv[0], "cv_vy": cv[1],
        "policy_vx": policy[0], "policy_vy": policy[1], "ours_code": s % 2, "vae_code": t % 2,
        "ours_sha256": "o" * 8, "vae_sha256": "v" * 8, "click_time_ms": 100.0 * (k + 1),
        "click_input": "mouse", "trial_duration_ms": 8000.0, "replays": 0,
        "submission_id": f"sub-{p}-{w}-{t}",
        "submitted_at": "2026-01-01T00:00:00Z", "config_sha256": "f" * 8, "bank_sha256": "b" * 8,
    }
    return [values[c] for c in EXPORT_COLUMNS]


HIGHWAY_SCENE = {
    "world": "highway", "dt_s": 0.5, "frame": "test", "obstacles": [], "goals": [],
    "bounds": {"x_min_m": -10.0, "x_max_m": 60.0, "y_min_m": -2.0, "y_max_m": 10.0},
    "lanes": [{"index": i, "y_center_m": 4.0 * i, "width_m": 4.0} for i in range(3)],
    "agents": [{"name": "robot", "kind": "car", "length_m": 5.0, "width_m": 2.0,
                "color": "#0072B2"},
               {"name": "human", "kind": "car", "length_m": 5.0, "width_m": 2.0,
                "color": "#E69F00"}],
}
OBSTACLE_SCENE = {
    "world": "obstacle", "dt_s": 0.5, "frame": "test", "lanes": [],
    "bounds": {"x_min_m": 0.0, "x_max_m": 10.0, "y_min_m": 0.0, "y_max_m": 10.0},
    "obstacles": [{"x_m": 5.0, "y_m": 5.0, "radius_m": 0.8, "label": ""}],
    "goals": [{"x_m": gx, "y_m": gy, "radius_m": 0.5, "label": f"g{k}"}
              for k, (gx, gy) in enumerate([(1.0, 1.0), (9.0, 1.0), (1.0, 9.0), (9.0, 9.0)])],
    "agents": [{"name": "robot", "kind": "disc", "length_m": 0.6, "width_m": 0.6,
                "color": "#0072B2"},
               {"name": "human", "kind": "disc", "length_m": 0.6, "width_m": 0.6,
                "color": "#E69F00"}],
}


def highway_segment(lane_from: int, lane_to: int, steps: int = 6) -> list:
    """Robot drives at 10 m/s and drifts from one lane centre towards another."""
    ys = np.linspace(4.0 * lane_from, 4.0 * lane_from + 0.6 * 4.0 * (lane_to - lane_from),
                     steps + 1)
    return [[[5.0 * t, float(y)], [5.0 * t - 10.0, 8.0]] for t, y in enumerate(ys)]


def obstacle_segment(start, goal, steps: int = 6) -> list:
    """Robot moves 0.4 m per step straight at a goal."""
    start, goal = np.asarray(start, float), np.asarray(goal, float)
    unit = (goal - start) / np.linalg.norm(goal - start)
    return [[(start + 0.4 * t * unit).tolist(), [5.0, 1.0]] for t in range(steps + 1)]


def payload(scene: dict, segment: list, starts: list, trial_id: str = "t0") -> dict:
    """A trial payload as the server sends it (only the keys the observers read)."""
    return {"trial_id": trial_id, "world": scene["world"], "scene": scene, "dt_s": 0.5,
            "segment": {"positions": segment, "headings": [[0.0, 0.0]] * len(segment)},
            "start_states": [{"robot": s, "human": segment[-1][1], "robot_heading": 0.0,
                              "human_heading": 0.0} for s in starts],
            "steps_to_predict": 3, "max_step_m": 8.0 if scene["lanes"] else 0.6,
            "min_step_m": 0.8 if scene["lanes"] else 0.06}


def toward_actions(scene: dict, starts: list, target, speed: float, steps: int = 3) -> list:
    """Actions [K, n, 2] that head at a lane (y) or a goal (x, y) from each start state."""
    out = []
    for s in starts:
        if scene["lanes"]:
            v = np.array([10.0, (target - s[1]) / 1.0])
        else:
            v = np.asarray(target) - np.asarray(s)
        v = speed * v / np.linalg.norm(v)
        out.append([v.tolist()] * steps)
    return out


def small_bank(trials: int = 6, seed: int = 0) -> dict:
    """A trial bank in bank.json's layout, a family of two seeds per model: Ours heads at the
    segment's target (seed 1 a little off it), the VAE drifts (each seed its own way)."""
    rng = np.random.default_rng(seed)
    worlds = {}
    for world, scene in (("highway", HIGHWAY_SCENE), ("obstacle", OBSTACLE_SCENE)):
        records = []
        for t in range(trials):
            if scene["lanes"]:
                lane_from = int(rng.integers(3))
                lane_to = int(np.clip(lane_from + rng.choice([-1, 0, 1]), 0, 2))
                segment = highway_segment(lane_from, lane_to)
                starts = [[float(rng.uniform(20, 40)), float(rng.uniform(0, 8))] for _ in range(5)]
                target, speed, code = 4.0 * lane_to, 10.0, lane_to
            else:
                goal = OBSTACLE_SCENE["goals"][int(rng.integers(4))]
                target = [goal["x_m"], goal["y_m"]]
                segment = obstacle_segment([5.0 + rng.uniform(-1, 1), 5.0], target)
                starts = [[float(rng.uniform(2, 8)), float(rng.uniform(2, 8))] for _ in range(5)]
                speed, code = 0.8, OBSTACLE_SCENE["goals"].index(goal)
            ours = toward_actions(scene, starts, target, speed)
            family = {"ours": [ours, (np.asarray(ours) + rng.normal(scale=0.1, size=(5, 3, 2))
                                      * speed).tolist()],
                      "vae": [(np.asarray(ours) + rng.normal(scale=1.2, size=(5, 3, 2))
                               * speed).tolist() for _ in range(2)]}
            records.append({
                "trial_id": f"{world}-{t}", "world": world, "kind": "main",
                "clip_sha256": f"clip{t}",
                "source_index": t, "segment_start": 0, "robot_label": code, "examples": [],
                "model_input": segment,
                "segment": {"positions": segment, "headings": [[0.0, 0.0]] * len(segment)},
                "start_states": [{"robot": s, "human": segment[-1][1], "robot_heading": 0.0,
                                  "human_heading": 0.0, "robot_speed": speed, "start_kind": kind}
                                 for s, kind in zip(starts, START_KINDS[world], strict=True)],
                "arm": ("random", "models_disagree")[t % 2],
                "predictions": {model: [{"seed": s, "z": [],
                                         "code": code if model == "ours" else t % 3,
                                         "actions": actions, "content_hash": f"{model[0]}{s}"}
                                        for s, actions in enumerate(answers)]
                                for model, answers in family.items()},
                "cv_actions": [[[speed, 0.0]] * 3] * 5, "policy_actions": ours,
            })
        worlds[world] = {"world": world, "dt_s": 0.5, "scene": scene,
                         "robot_label_name": "intent", "label_names": ["a", "b", "c", "d"],
                         "max_step_m": 8.0 if scene["lanes"] else 0.6,
                         "min_step_m": 0.8 if scene["lanes"] else 0.06, "trials": records}
    return {"study_id": "paper_study", "steps_to_predict": 3, "worlds": worlds}


def trial_bank(bank: dict) -> TrialBank:
    """A bank.json-shaped dict, read as the server and the simulated study read a bank file."""
    return TrialBank.parse(json.dumps(bank).encode())


def with_seeds(bank: dict, n_seeds: int = 3, seed: int = 0) -> dict:
    """`bank` with a family of `n_seeds` answers per model and trial (seeds 100, 101, ...):
    the primary seed's actions as stored, the others those plus noise (a family's spread)."""
    rng = np.random.default_rng(seed)
    out = copy.deepcopy(bank)
    for world, world_bank in out["worlds"].items():
        for trial in world_bank["trials"]:
            for model, answers in trial["predictions"].items():
                primary = answers[0] if isinstance(answers, list) else answers
                actions = np.asarray(primary["actions"], dtype=np.float64)
                spread = 0.5 * np.abs(actions).mean()
                trial["predictions"][model] = [
                    {"seed": 100 + k, "z": [], "code": primary["code"],
                     "actions": (actions + (k > 0) * rng.normal(scale=spread, size=actions.shape))
                     .tolist(), "content_hash": f"{model}-{world}-{100 + k}"}
                    for k in range(n_seeds)]
    return out


def family_bank(frame: pd.DataFrame, seeds: dict[str, list[int]], seed: int = 0) -> dict:
    """A bank with, for each trial of `frame`, random answers [K, n, 2] of every training seed
    of each model (`seeds`: model -> seeds, primary first); K and n as in `frame`."""
    rng = np.random.default_rng(seed)
    k, n = frame["start_index"].max() + 1, frame["step"].max() + 1
    worlds: dict = {}
    for world, trial_id in frame[["world", "trial_id"]].drop_duplicates().itertuples(index=False):
        answers = {model: [{"seed": s, "z": [0.0], "code": 0, "content_hash": f"{model}{s}",
                            "actions": rng.normal(size=(k, n, 2)).tolist()} for s in family]
                   for model, family in seeds.items()}
        worlds.setdefault(world, {"dt_s": DT_S, "scene": {}, "trials": []})["trials"].append(
            {"trial_id": trial_id, "kind": "main", "arm": "random",
             "start_states": [{}] * k, "predictions": answers})
    return {"study_id": "paper_study", "worlds": worlds}


def on_bank(frame: pd.DataFrame, bank: dict) -> tuple[pd.DataFrame, bytes]:
    """`frame` as a study served from `bank` answers it: ours/vae columns the bank's primary
    answers, `bank_sha256` the hash of the bank's JSON; and those JSON bytes."""
    raw = json.dumps(bank).encode()
    out = frame.copy()
    out["bank_sha256"] = hashlib.sha256(raw).hexdigest()
    trials = {t["trial_id"]: t for w in bank["worlds"].values() for t in w["trials"]}
    for model in ("ours", "vae"):
        actions = np.array([trials[r.trial_id]["predictions"][model][0]["actions"]
                            [r.start_index][r.step] for r in out.itertuples()])
        out[f"{model}_vx"], out[f"{model}_vy"] = actions[:, 0], actions[:, 1]
    return out, raw


def holm_by_hand(p: list[float]) -> list[float]:
    """Step-down: the k-th smallest p times (m - k), running maximum, capped at 1."""
    ranked = sorted(range(len(p)), key=lambda i: p[i])
    out, running = [0.0] * len(p), 0.0
    for k, i in enumerate(ranked):
        running = max(running, p[i] * (len(p) - k))
        out[i] = min(running, 1.0)
    return out
