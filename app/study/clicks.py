"""What a click means and where it may land, for a live participant and a simulated one alike.

A trial asks for n clicked positions from each of K start states; consecutive positions are
the robot's moves, and a move divided by the world's dt is an action (m/s). The server refuses
clicks outside the scene or with a move shorter or longer than the world's limits; the
simulated study runs every simulated answer through the same check.
"""

import numpy as np

from app.core.alignment import alignment_error
from app.study.config import AttentionChecks
from app.study.errors import Refused
from app.study.trials import TrialRecord, WorldBank

# a move up to this share longer than max_step_m counts: a click on the reach circle's edge
# may come out a rounding error longer (the page applies the same, from the page rules)
MAX_STEP_TOLERANCE = 1e-6


def robot_starts(trial: TrialRecord) -> np.ndarray:
    """The robot's position at each start state [K, 2] (m)."""
    return np.asarray([s.robot for s in trial.start_states], dtype=np.float64)


def step_moves(starts: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Clicked positions [K, n, 2] -> moves [K, n, 2] (m) from each start state, step by step."""
    return np.diff(np.concatenate([starts[:, None], points], axis=1), axis=1)


def clicks_to_actions(starts: np.ndarray, points: np.ndarray, dt_s: float) -> np.ndarray:
    """Clicked positions [K, n, 2] -> actions [K, n, 2] (m/s): each move divided by dt."""
    return step_moves(starts, points) / dt_s


def check_passed(rule: AttentionChecks, first_moves: np.ndarray, truth: np.ndarray) -> bool:
    """An attention check's verdict on first moves [K, 2]: at least `min_passing_starts` of
    them within `max_angle_deg` of the robot's true first moves [K, 2] (never where either
    has no direction)."""
    max_error = 1.0 - np.cos(np.deg2rad(rule.max_angle_deg))  # alignment error of that angle
    within = alignment_error(first_moves, truth) <= max_error
    return int(within.sum()) >= rule.min_passing_starts


def check_points(world: WorldBank, starts: np.ndarray, points: np.ndarray) -> None:
    """Refuse (422, naming `points.i.j`) a click outside the scene or a move out of limits."""
    bounds = world.scene["bounds"]
    for i, j in np.argwhere(~_inside(points, bounds)):
        x, y = points[i, j]
        raise Refused(422, f"points.{i}.{j}: ({x:g}, {y:g}) is outside the scene "
                           f"x [{bounds['x_min_m']:g}, {bounds['x_max_m']:g}] "
                           f"y [{bounds['y_min_m']:g}, {bounds['y_max_m']:g}] m")
    moves = step_moves(starts, points)
    lengths = np.hypot(moves[..., 0], moves[..., 1])
    for i, j in np.argwhere(lengths < world.min_step_m):
        raise Refused(422, f"points.{i}.{j}: move of {lengths[i, j]:.3g} m is shorter than "
                           f"the minimum {world.min_step_m:.3g} m")
    for i, j in np.argwhere(lengths > world.max_step_m * (1 + MAX_STEP_TOLERANCE)):
        raise Refused(422, f"points.{i}.{j}: move of {lengths[i, j]:.3g} m is longer than "
                           f"the reachable {world.max_step_m:.3g} m")


def _inside(points: np.ndarray, bounds: dict) -> np.ndarray:
    x, y = points[..., 0], points[..., 1]
    return ((x >= bounds["x_min_m"]) & (x <= bounds["x_max_m"])
            & (y >= bounds["y_min_m"]) & (y <= bounds["y_max_m"]))
