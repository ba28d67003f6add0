"""Simulated participants' predictions: what a bot clicks for one trial payload.

A trial payload is the `step` the server sends in a trial (app/study/API.md): scene,
dt_s, example clips, segment positions, start states, steps_to_predict, min/max step
length. Each observer preset returns clicked robot positions [starts, steps, 2] that the server
accepts (inside the scene bounds, every move within [min_step_m, max_step_m]). Observers
read only the payload (and, for `precise`, the world's own policy moves): never a
checkpoint nor a model's answer. Their parameters and sources: study_configs/observers.yaml.

One observer family, inverse planning (Baker, Saxe & Tenenbaum 2009):
- intents: Highway, the target lane (absolute lane index; or, in the relative reading, a
  change of -1/0/+1 lanes from the robot's lane at the segment's start); Obstacle, one
  of the scene's goals;
- prior: Dirichlet(pseudo-count) over intents updated with where the robot ends in the
  example clips;
- likelihood of each observed robot step: exp(beta * progress) normalised over the moves
  available at that state (a Boltzmann policy over action values), where progress is
  measured in units of one step's best progress: Obstacle, the straight-line distance
  gained towards the goal over the step's length (about cos of the angle to the goal),
  with the normaliser over all directions of the same length; Highway, the lateral
  distance gained towards the target lane centre over one nominal lateral step, with
  the normaliser over lateral moves of up to one nominal step (forward motion is common
  to every intent and carries no information about it);
- the observer acts on one intent, sampled from the posterior or its mode (config).

Presets:
- coarse: from each start state, moves the way its intent moves. Highway: forward at the
  robot's forward speed in the segment (displayed frame) plus a lateral move towards the
  target lane centre at lane width / nominal lane-change duration, never past the centre;
  Obstacle: straight at the goal at the segment's speed. Perceptual noise: the perceived
  speed is off by a Weber fraction (one draw per trial), each click's direction by a
  Gaussian angle.
- coarse_relative: coarse with the relative lane reading (a sensitivity preset).
- precise: the world's own next moves from each start state (policy actions, see
  app/study/bots.py for where they come from) with the same, smaller, noise.
- random: uniformly random directions and lengths.
"""

from dataclasses import dataclass

import numpy as np
from scipy.special import logsumexp

from app.observers.config import NoiseConfig, ObserversConfig, default_observers

PRESETS = ("coarse", "precise", "random", "coarse_relative")
LANE_OFFSETS = np.array([-1, 0, 1])  # relative reading: merge left (towards lane 0), keep, right
LATERAL_CANDIDATES = 41  # lateral moves the Highway likelihood normalises over
DIRECTION_CANDIDATES = 72  # directions (5 deg apart) the Obstacle likelihood normalises over
MIN_SPEED_FACTOR = 0.05  # a perceived speed never turns negative
STEP_MARGIN = 0.02  # keep clicked step lengths this fraction inside the server's limits


@dataclass(frozen=True)
class Reading:
    """An observer's reading of one trial: the intents, the prior and the posterior over them.

    `intents` are lane indices (absolute reading), lane offsets (relative) or goal indices.
    """

    intents: np.ndarray
    prior: np.ndarray
    posterior: np.ndarray


def robot_track(payload: dict) -> np.ndarray:
    """The robot's segment positions [T+1, 2]."""
    return np.asarray(payload["segment"]["positions"], dtype=np.float64)[:, 0, :]


def segment_speed(payload: dict) -> float:
    """The robot's mean speed over the segment [m/s]."""
    track = robot_track(payload)
    steps = np.linalg.norm(np.diff(track, axis=0), axis=1)
    return float(steps.mean() / payload["dt_s"]) if len(steps) else 0.0


def forward_speed(payload: dict) -> float:
    """The robot's mean x velocity over the segment in the displayed frame [m/s]."""
    track = robot_track(payload)
    return float((track[-1, 0] - track[0, 0]) / (payload["dt_s"] * max(len(track) - 1, 1)))


def is_highway(payload: dict) -> bool:
    """Whether the scene is a road (lanes) rather than a plane with goals."""
    return bool(payload["scene"]["lanes"])


def lane_centres(payload: dict) -> np.ndarray:
    """Lane centre y [L] in lane-index order (lane 0 on top)."""
    lanes = sorted(payload["scene"]["lanes"], key=lambda lane: lane["index"])
    return np.array([lane["y_center_m"] for lane in lanes], dtype=np.float64)


def nearest_lane(payload: dict, y) -> np.ndarray:
    """Index of the lane whose centre is nearest to each y."""
    return np.argmin(np.abs(np.asarray(y, dtype=np.float64)[..., None] - lane_centres(payload)),
                     axis=-1)


def goal_centres(payload: dict) -> np.ndarray:
    """Goal centres [G, 2]."""
    return np.array([[g["x_m"], g["y_m"]] for g in payload["scene"]["goals"]], dtype=np.float64)


def lateral_step_m(payload: dict, config: ObserversConfig) -> float:
    """One nominal lateral move [m]: lane width / lane-change duration, times dt."""
    width = float(np.median([lane["width_m"] for lane in payload["scene"]["lanes"]]))
    return width / config.lane_change_duration_s.value * payload["dt_s"]


def example_outcomes(payload: dict, relative: bool) -> np.ndarray:
    """Index (into the intents) of where the robot ends in each example clip."""
    outcomes = []
    for clip in payload.get("examples") or []:
        track = np.asarray(clip["positions"], dtype=np.float64)[:, 0, :]
        if not is_highway(payload):
            outcomes.append(np.argmin(np.linalg.norm(goal_centres(payload) - track[-1], axis=1)))
        elif relative:
            change = nearest_lane(payload, track[-1, 1]) - nearest_lane(payload, track[0, 1])
            outcomes.append(int(np.clip(change, -1, 1)) + 1)
        else:
            outcomes.append(nearest_lane(payload, track[-1, 1]))
    return np.asarray(outcomes, dtype=int)


def intent_prior(payload: dict, n_intents: int, relative: bool, pseudo_count: float) -> np.ndarray:
    """Dirichlet(pseudo_count) prior over intents updated with the example clips' outcomes."""
    counts = np.bincount(example_outcomes(payload, relative), minlength=n_intents)
    return (counts + pseudo_count) / (counts.sum() + n_intents * pseudo_count)


def boltzmann_loglik(progress: np.ndarray, candidates: np.ndarray, beta: float) -> np.ndarray:
    """log P(step | intent) of exp(beta * progress), normalised over candidates (last axis)."""
    n = candidates.shape[-1]
    return beta * progress - (logsumexp(beta * candidates, axis=-1) - np.log(n))


def lane_loglik(payload: dict, targets_y: np.ndarray, step_m: float, beta: float) -> np.ndarray:
    """Summed log-likelihood [J] of the segment's lateral moves for each target lane centre."""
    y = robot_track(payload)[:, 1]
    moves = np.clip(np.diff(y), -step_m, step_m)[:, None]  # a faster move reads as a full one
    start = y[:-1, None]
    gap = np.abs(start - targets_y)
    progress = (gap - np.abs(start + moves - targets_y)) / step_m  # [T, J]
    lateral = np.linspace(-step_m, step_m, LATERAL_CANDIDATES)
    after = np.abs(start[..., None] + lateral - targets_y[:, None])
    candidates = (gap[..., None] - after) / step_m  # [T, J, C]
    return boltzmann_loglik(progress, candidates, beta).sum(axis=0)


def goal_loglik(payload: dict, goals: np.ndarray, beta: float) -> np.ndarray:
    """Summed log-likelihood [G] of the segment's moves for each goal (straight-line distances)."""
    track = robot_track(payload)
    moves = np.diff(track, axis=0)
    length = np.linalg.norm(moves, axis=1)
    moving = length > 1e-9  # a standing robot says nothing about its direction
    start, moves, length = track[:-1][moving], moves[moving], length[moving]
    gap = np.linalg.norm(start[:, None, :] - goals, axis=-1)  # [T, G]
    progress = (gap - np.linalg.norm(start[:, None, :] + moves[:, None, :] - goals, axis=-1))
    angles = np.linspace(0.0, 2 * np.pi, DIRECTION_CANDIDATES, endpoint=False)
    turns = length[:, None, None] * np.stack([np.cos(angles), np.sin(angles)], axis=-1)  # [T, C, 2]
    ends = start[:, None, None, :] + turns[:, None, :, :] - goals[None, :, None, :]
    candidates = gap[..., None] - np.linalg.norm(ends, axis=-1)  # [T, G, C]
    scale = length[:, None]
    return boltzmann_loglik(progress / scale, candidates / scale[..., None], beta).sum(axis=0)


def relative_targets(payload: dict, lane: int) -> tuple[np.ndarray, np.ndarray]:
    """Lane centres [3] of merge left / keep / right from `lane`, and which of them exist."""
    centres = lane_centres(payload)
    lanes = lane + LANE_OFFSETS
    return centres[np.clip(lanes, 0, len(centres) - 1)], (lanes >= 0) & (lanes < len(centres))


def infer_intent(payload: dict, config: ObserversConfig, relative: bool = False) -> Reading:
    """Posterior over the world's intents from the segment (likelihood) and examples (prior)."""
    beta = config.inference.beta.value
    if is_highway(payload):
        if relative:
            lane = int(nearest_lane(payload, robot_track(payload)[0, 1]))
            targets, feasible = relative_targets(payload, lane)
            intents = LANE_OFFSETS
        else:
            targets = lane_centres(payload)
            feasible = np.ones(len(targets), dtype=bool)
            intents = np.arange(len(targets))
        loglik = lane_loglik(payload, targets, lateral_step_m(payload, config), beta)
    else:
        goals = goal_centres(payload)
        intents, feasible = np.arange(len(goals)), np.ones(len(goals), dtype=bool)
        loglik = goal_loglik(payload, goals, beta)
    prior = intent_prior(payload, len(intents), relative, config.inference.prior_pseudo_count.value)
    log_post = np.where(feasible, np.log(prior) + loglik, -np.inf)
    return Reading(intents, prior, np.exp(log_post - logsumexp(log_post)))


def choose_intent(reading: Reading, choice: str, rng: np.random.Generator) -> int:
    """The intent the observer acts on: a posterior sample, or the posterior mode ("map")."""
    if choice == "map":
        return int(reading.intents[int(np.argmax(reading.posterior))])
    return int(reading.intents[int(rng.choice(len(reading.intents), p=reading.posterior))])


def speed_factor(noise: NoiseConfig | None, rng: np.random.Generator) -> float:
    """The perceived / true speed of one trial: 1 + Weber fraction * N(0, 1)."""
    if noise is None:
        return 1.0
    return max(1.0 + noise.speed_weber_fraction.value * rng.normal(), MIN_SPEED_FACTOR)


def direction_noise(noise: NoiseConfig | None, rng: np.random.Generator) -> float:
    """One click's direction error [rad]."""
    if noise is None:
        return 0.0
    return float(np.deg2rad(rng.normal(0.0, noise.direction_sd_deg.value)))


def rotate(vector: np.ndarray, angle_rad: float) -> np.ndarray:
    """`vector` rotated by `angle_rad`."""
    c, s = np.cos(angle_rad), np.sin(angle_rad)
    return np.array([c * vector[0] - s * vector[1], s * vector[0] + c * vector[1]])


def step_limits(payload: dict) -> tuple[float, float]:
    """The shortest and longest move [m] a bot clicks, just inside the server's limits."""
    return payload["min_step_m"] * (1 + STEP_MARGIN), payload["max_step_m"] * (1 - STEP_MARGIN)


def clip_length(payload: dict, length_m: float) -> float:
    """A move length [m] clipped inside the server's accepted lengths."""
    return float(np.clip(length_m, *step_limits(payload)))


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


def highway_lane_target(payload: dict, intent: int, relative: bool, start: np.ndarray) -> float:
    """Centre y of the lane a coarse observer heads for from `start`."""
    if not relative:
        return float(lane_centres(payload)[intent])
    targets, feasible = relative_targets(payload, int(nearest_lane(payload, start[1])))
    return float(targets[intent + 1] if feasible[intent + 1] else targets[1])


def predict_coarse(payload: dict, rng: np.random.Generator, config: ObserversConfig,
                   relative: bool | None = None, noise: NoiseConfig | None = None) -> np.ndarray:
    """Clicks of the coarse observer: infer an intent, then move the way that intent moves."""
    if relative is None:
        relative = config.inference.lane_reading.value == "relative"
    noise = config.coarse_noise if noise is None else noise
    intent = choose_intent(infer_intent(payload, config, relative),
                           config.inference.intent_choice.value, rng)
    factor = speed_factor(noise, rng)
    dt = payload["dt_s"]
    starts = start_positions(payload)
    if is_highway(payload):
        forward = forward_speed(payload) * factor * dt
        lateral = lateral_step_m(payload, config)
        targets = [highway_lane_target(payload, intent, relative, s) for s in starts]

        def move(i: int, position: np.ndarray) -> tuple[np.ndarray, float]:
            side = float(np.clip(targets[i] - position[1], -lateral, lateral))
            return np.array([forward, side]), float(np.hypot(forward, side))
    else:
        goal = goal_centres(payload)[intent]
        reach = segment_speed(payload) * factor * dt

        def move(i: int, position: np.ndarray) -> tuple[np.ndarray, float]:
            to_goal = goal - position
            return to_goal, min(reach, float(np.linalg.norm(to_goal)))

    def next_move(i: int, k: int, position: np.ndarray) -> tuple[np.ndarray, float]:
        direction, length = move(i, position)
        return rotate(direction, direction_noise(noise, rng)), clip_length(payload, length)

    return walk(payload, next_move)


def predict_from_actions(payload: dict, actions: np.ndarray, rng: np.random.Generator,
                         noise: NoiseConfig | None = None) -> np.ndarray:
    """Clicks that follow given actions [S, K, 2] (m/s) from each start state, with noise."""
    factor = speed_factor(noise, rng)

    def next_move(i: int, k: int, position: np.ndarray) -> tuple[np.ndarray, float]:
        action = np.asarray(actions[i, k], dtype=np.float64)
        length = float(np.linalg.norm(action)) * factor * payload["dt_s"]
        return rotate(action, direction_noise(noise, rng)), clip_length(payload, length)

    return walk(payload, next_move)


def predict_random(payload: dict, rng: np.random.Generator) -> np.ndarray:
    """Clicks in uniformly random directions with uniformly random valid lengths."""
    low, high = step_limits(payload)

    def next_move(i: int, k: int, position: np.ndarray) -> tuple[np.ndarray, float]:
        direction = rotate(np.array([1.0, 0.0]), rng.uniform(0, 2 * np.pi))
        return direction, rng.uniform(low, high)

    return walk(payload, next_move)


def predict(preset: str, payload: dict, rng: np.random.Generator,
            policy_actions: np.ndarray | None = None,
            config: ObserversConfig | None = None) -> np.ndarray:
    """Clicks [S, K, 2] of an observer `preset`; `precise` follows `policy_actions` [S, K, 2]."""
    if preset not in PRESETS:
        raise ValueError(f"preset: unknown observer preset {preset!r}; "
                         f"choose one of {', '.join(PRESETS)}")
    config = config or default_observers()
    if preset == "coarse":
        return predict_coarse(payload, rng, config)
    if preset == "coarse_relative":
        return predict_coarse(payload, rng, config, relative=True)
    if preset == "precise":
        if policy_actions is None:
            raise ValueError(f"precise bot: no policy actions for trial {payload['trial_id']}")
        return predict_from_actions(payload, np.asarray(policy_actions), rng,
                                    config.precise_noise)
    return predict_random(payload, rng)


def clicks_to_actions(payload: dict, clicks: np.ndarray) -> np.ndarray:
    """Actions [S, K, 2] (m/s) of clicked positions: differences from the start state / dt."""
    starts = start_positions(payload)[:, None, :]
    path = np.concatenate([starts, clicks], axis=1)
    return np.diff(path, axis=1) / payload["dt_s"]
