"""Simulated participants' predictions: what a bot clicks for one trial payload.

A trial payload is the `step` the server sends in a trial (app/study/API.md): scene,
dt_s, segment positions, start states, steps_to_predict, min/max step length. Each
predictor returns clicked robot positions [starts, steps, 2] that the server accepts
(inside the scene bounds, every move within [min_step_m, max_step_m]).

- coarse: a "high-level" person. It reads the robot's behaviour from the segment's
  geometry and the scene only (Highway: the lane it is heading to; Obstacle: the goal
  its recent motion points at), then from every start state steps towards that lane or
  goal at the segment's speed, with Gaussian angular noise. It never sees labels.
- precise: the world's own next moves from each start state (given to it as actions;
  see app/study/bots.py for where they come from) with small angular noise.
- random: uniformly random directions and lengths.
"""

import numpy as np

KINDS = ("coarse", "precise", "random")
COARSE_NOISE_DEG = 15.0
PRECISE_NOISE_DEG = 5.0
LANE_TIME_CONSTANT_S = 1.0  # a coarse predictor closes the gap to its target lane in ~1 s
STEP_MARGIN = 0.02  # keep clicked step lengths this fraction inside the server's limits


def robot_track(payload: dict) -> np.ndarray:
    """The robot's segment positions [T+1, 2]."""
    return np.asarray(payload["segment"]["positions"], dtype=np.float64)[:, 0, :]


def segment_speed(payload: dict) -> float:
    """The robot's mean speed over the segment [m/s]."""
    track = robot_track(payload)
    steps = np.linalg.norm(np.diff(track, axis=0), axis=1)
    return float(steps.mean() / payload["dt_s"]) if len(steps) else 0.0


def highway_target_lane_y(payload: dict) -> float:
    """Centre y of the lane the robot heads to: the next lane in its drift, or its own lane."""
    track = robot_track(payload)
    lanes = sorted(lane["y_center_m"] for lane in payload["scene"]["lanes"])
    width = float(np.median([lane["width_m"] for lane in payload["scene"]["lanes"]]))
    y_end = track[-1, 1]
    recent = track[-1, 1] - track[max(0, len(track) - 3), 1]
    drift = track[-1, 1] - track[0, 1]
    direction = np.sign(recent) if abs(recent) > 0.1 * width else 0.0
    if direction == 0 and abs(drift) > 0.3 * width:
        direction = np.sign(drift)
    ahead = [c for c in lanes if (c - y_end) * direction > -0.25 * width]
    return min(ahead if direction != 0 and ahead else lanes, key=lambda c: abs(c - y_end))


def obstacle_target_goal(payload: dict) -> np.ndarray:
    """Centre of the goal the robot's recent motion points at most directly."""
    track = robot_track(payload)
    recent = track[-1] - track[max(0, len(track) - 4)]
    goals = np.array([[g["x_m"], g["y_m"]] for g in payload["scene"]["goals"]])
    to_goal = goals - track[-1]
    cos = to_goal @ recent / (np.linalg.norm(to_goal, axis=1) * np.linalg.norm(recent) + 1e-9)
    return goals[int(np.argmax(cos))]


def coarse_direction(payload: dict, position: np.ndarray, forward_vx: float,
                     target: float | np.ndarray) -> np.ndarray:
    """The direction a coarse predictor moves from `position` towards its target."""
    if payload["scene"]["lanes"]:
        lateral = (float(target) - position[1]) / LANE_TIME_CONSTANT_S
        return np.array([forward_vx, lateral])
    return np.asarray(target) - position


def rotate(vector: np.ndarray, angle_rad: float) -> np.ndarray:
    """`vector` rotated by `angle_rad`."""
    c, s = np.cos(angle_rad), np.sin(angle_rad)
    return np.array([c * vector[0] - s * vector[1], s * vector[0] + c * vector[1]])


def step_limits(payload: dict) -> tuple[float, float]:
    """The shortest and longest move [m] a bot clicks, just inside the server's limits."""
    return payload["min_step_m"] * (1 + STEP_MARGIN), payload["max_step_m"] * (1 - STEP_MARGIN)


def step_length(payload: dict, speed_mps: float) -> float:
    """A move of `speed_mps` for one dt, clipped inside the server's accepted lengths."""
    return float(np.clip(speed_mps * payload["dt_s"], *step_limits(payload)))


def inside_bounds(payload: dict, point: np.ndarray) -> bool:
    """Whether a point lies inside the scene bounds (with a small margin)."""
    b = payload["scene"]["bounds"]
    margin = 1e-3
    return (b["x_min_m"] + margin <= point[0] <= b["x_max_m"] - margin
            and b["y_min_m"] + margin <= point[1] <= b["y_max_m"] - margin)


def valid_move(payload: dict, origin: np.ndarray, direction: np.ndarray,
               length: float) -> np.ndarray:
    """origin + length * unit(direction), turned towards the scene centre if it leaves bounds."""
    norm = np.linalg.norm(direction)
    unit = direction / norm if norm > 1e-9 else np.array([1.0, 0.0])
    b = payload["scene"]["bounds"]
    centre = np.array([(b["x_min_m"] + b["x_max_m"]) / 2, (b["y_min_m"] + b["y_max_m"]) / 2])
    for _ in range(12):
        point = origin + length * unit
        if inside_bounds(payload, point):
            return point
        inward = centre - origin
        unit = unit + inward / (np.linalg.norm(inward) + 1e-9)
        unit = unit / (np.linalg.norm(unit) + 1e-9)
    return origin + length * (centre - origin) / (np.linalg.norm(centre - origin) + 1e-9)


def start_positions(payload: dict) -> np.ndarray:
    """Robot start states [S, 2]."""
    return np.array([s["robot"] for s in payload["start_states"]], dtype=np.float64)


def walk(payload: dict, next_move) -> np.ndarray:
    """Clicks [S, K, 2]: from each start state, K valid moves; next_move(i, k, position)
    returns the (direction, length) of start state i's k-th move."""
    clicks = np.zeros((len(payload["start_states"]), payload["steps_to_predict"], 2))
    for i, start in enumerate(start_positions(payload)):
        position = start
        for k in range(payload["steps_to_predict"]):
            position = valid_move(payload, position, *next_move(i, k, position))
            clicks[i, k] = position
    return clicks


def predict_coarse(payload: dict, rng: np.random.Generator,
                   noise_deg: float = COARSE_NOISE_DEG) -> np.ndarray:
    """Clicks of a high-level predictor: towards the inferred lane or goal, with angular noise."""
    is_highway = bool(payload["scene"]["lanes"])
    target = highway_target_lane_y(payload) if is_highway else obstacle_target_goal(payload)
    track = robot_track(payload)
    forward_vx = float((track[-1, 0] - track[0, 0]) / (payload["dt_s"] * (len(track) - 1)))
    length = step_length(payload, segment_speed(payload))

    def next_move(i: int, k: int, position: np.ndarray) -> tuple[np.ndarray, float]:
        direction = coarse_direction(payload, position, forward_vx, target)
        return rotate(direction, np.deg2rad(rng.normal(0.0, noise_deg))), length

    return walk(payload, next_move)


def predict_from_actions(payload: dict, actions: np.ndarray, rng: np.random.Generator,
                         noise_deg: float = PRECISE_NOISE_DEG) -> np.ndarray:
    """Clicks that follow given actions [S, K, 2] (m/s) from each start state, with noise."""
    def next_move(i: int, k: int, position: np.ndarray) -> tuple[np.ndarray, float]:
        action = np.asarray(actions[i, k], dtype=np.float64)
        direction = rotate(action, np.deg2rad(rng.normal(0.0, noise_deg)))
        return direction, step_length(payload, float(np.linalg.norm(action)))

    return walk(payload, next_move)


def predict_random(payload: dict, rng: np.random.Generator) -> np.ndarray:
    """Clicks in uniformly random directions with uniformly random valid lengths."""
    low, high = step_limits(payload)

    def next_move(i: int, k: int, position: np.ndarray) -> tuple[np.ndarray, float]:
        direction = rotate(np.array([1.0, 0.0]), rng.uniform(0, 2 * np.pi))
        return direction, rng.uniform(low, high)

    return walk(payload, next_move)


def predict(kind: str, payload: dict, rng: np.random.Generator,
            policy_actions: np.ndarray | None = None) -> np.ndarray:
    """Clicks [S, K, 2] of a bot of `kind`; a precise bot follows `policy_actions` [S, K, 2]."""
    if kind == "coarse":
        return predict_coarse(payload, rng)
    if kind == "precise":
        if policy_actions is None:
            raise ValueError(f"precise bot: no policy actions for trial {payload['trial_id']}")
        return predict_from_actions(payload, np.asarray(policy_actions), rng)
    if kind == "random":
        return predict_random(payload, rng)
    raise ValueError(f"kind: unknown bot kind {kind!r}; choose one of {', '.join(KINDS)}")


def clicks_to_actions(payload: dict, clicks: np.ndarray) -> np.ndarray:
    """Actions [S, K, 2] (m/s) of clicked positions: differences from the start state / dt."""
    starts = start_positions(payload)[:, None, :]
    path = np.concatenate([starts, clicks], axis=1)
    return np.diff(path, axis=1) / payload["dt_s"]
