"""Small analytic two-agent datasets for the learning tests (no simulator needed)."""

import numpy as np

from app.data.scene import AgentShape, Bounds, Lane, Scene
from app.data.trajectory import Episode, TrajectorySet

LANE_WIDTH_M = 4.0
INTENTS = ["keep", "left", "right"]


def lane_scene(dt_s: float) -> Scene:
    """Three straight lanes along x; lane 0 is the leftmost (smallest y)."""
    lanes = [Lane(index=i, y_center_m=LANE_WIDTH_M * i, width_m=LANE_WIDTH_M) for i in range(3)]
    return Scene(world="lanes", dt_s=dt_s, frame="x relative to the human's start",
                 bounds=Bounds(x_min_m=-10, x_max_m=60, y_min_m=-2, y_max_m=10), lanes=lanes,
                 agents=[AgentShape(name="robot", kind="car", length_m=5, width_m=2,
                                    color="#0072B2"),
                         AgentShape(name="human", kind="car", length_m=5, width_m=2,
                                    color="#E69F00")])


def lane_episode(rng: np.random.Generator, intent: int, steps: int, dt_s: float) -> Episode:
    """Robot keeps its lane or merges one lane left (-y) or right (+y) smoothly."""
    t = np.arange(steps + 1) * dt_s
    speed = rng.uniform(4.0, 6.0)
    robot_x = rng.uniform(0, 10) + speed * t
    start = rng.integers(0, 3)
    lane = {0: rng.integers(0, 3), 1: rng.integers(1, 3), 2: rng.integers(0, 2)}[intent]
    shift = {0: 0.0, 1: -LANE_WIDTH_M, 2: LANE_WIDTH_M}[intent]
    progress = np.clip((np.arange(steps + 1) - start) / 6.0, 0, 1)
    smooth = progress * progress * (3 - 2 * progress)
    robot_y = LANE_WIDTH_M * lane + shift * smooth + rng.normal(0, 0.02, steps + 1)
    human_x = rng.uniform(0, 10) + rng.uniform(4.0, 6.0) * t
    human_y = np.full(steps + 1, LANE_WIDTH_M * rng.integers(0, 3))
    positions = np.stack([np.stack([robot_x, robot_y], -1), np.stack([human_x, human_y], -1)], 1)
    change_step = -1 if intent == 0 else int(start + 6)
    return Episode(positions=positions.astype(np.float32),
                   headings=np.zeros((steps + 1, 2), np.float32),
                   speeds=np.full((steps + 1, 2), speed, np.float32),
                   labels={"robot_intent": intent, "robot_change_step": change_step})


def make_lane_trajs(n: int, seed: int = 0, steps: int = 20, dt_s: float = 0.5) -> TrajectorySet:
    """n analytic lane-keeping / merging trajectories with balanced robot intents."""
    rng = np.random.default_rng(seed)
    episodes = [lane_episode(rng, i % 3, steps - int(rng.integers(0, 3)), dt_s)
                for i in range(n)]
    return TrajectorySet.from_episodes("lanes", dt_s, episodes, {"robot_intent": INTENTS},
                                       lane_scene(dt_s))
