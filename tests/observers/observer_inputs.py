"""The observer tests' inputs: the repo's observers config and variants of it, and a small
bank whose trials carry example clips, as the real bank's do."""

import numpy as np

from app.observers.config import ObserversConfig, default_observers
from app.settings import REPO_ROOT
from tests.analysis.fixed_data import OBSTACLE_SCENE, obstacle_segment, small_bank

CONFIG = default_observers(REPO_ROOT / "study_configs")
GOALS = [[g["x_m"], g["y_m"]] for g in OBSTACLE_SCENE["goals"]]


def config_with(**changes) -> ObserversConfig:
    """The repo's config with keys replaced, e.g. inference__beta__value=1.0."""
    data = CONFIG.model_dump()
    for dotted, value in changes.items():
        *path, last = dotted.split("__")
        node = data
        for key in path:
            node = node[key]
        node[last] = value
    return ObserversConfig.model_validate(data)


MAP = config_with(inference__intent_choice__value="map")
QUIET = config_with(inference__intent_choice__value="map",
                    coarse_noise__speed_weber_fraction__value=0.0,
                    coarse_noise__direction_sd_deg__value=0.0)


def lane_clip(lane_from: int, lane_to: int, steps: int = 12) -> dict:
    """A full example clip: the robot drives from one lane centre to another."""
    ys = np.linspace(4.0 * lane_from, 4.0 * lane_to, steps + 1)
    return {"positions": [[[4.0 * t, float(y)], [4.0 * t - 10.0, 8.0]] for t, y in enumerate(ys)],
            "headings": [[0.0, 0.0]] * (steps + 1)}


def goal_clip(start, goal_index: int) -> dict:
    """A full example clip: the robot drives straight into a goal."""
    steps = int(np.ceil(np.linalg.norm(np.subtract(GOALS[goal_index], start)) / 0.4))
    positions = obstacle_segment(start, GOALS[goal_index], steps)
    return {"positions": positions, "headings": [[0.0, 0.0]] * len(positions)}


def bank_with_examples(seed: int = 0) -> dict:
    """small_bank with 4 example clips per trial, as the real bank has."""
    bank = small_bank(seed=seed)
    rng = np.random.default_rng(seed + 100)
    for name, world in bank["worlds"].items():
        for trial in world["trials"]:
            if name == "highway":
                trial["examples"] = [lane_clip(int(rng.integers(3)), int(rng.integers(3)))
                                     for _ in range(4)]
            else:
                trial["examples"] = [goal_clip(rng.uniform(3, 7, 2), int(rng.integers(4)))
                                     for _ in range(4)]
    return bank
