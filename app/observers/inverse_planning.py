"""Inverse-planning observers: what a simulated participant clicks for one trial payload.

A trial payload is the `step` the server sends in a trial (app/http/API.md): scene,
dt_s, example clips, segment positions, start states, steps_to_predict, min/max step
length. Each observer preset returns clicked robot positions [starts, steps, 2] that the
server accepts (inside the scene bounds, every move within [min_step_m, max_step_m]).
Observers read only the payload (and, for `precise`, the world's own policy moves): never
a checkpoint nor a model's answer. Their parameters and sources: study_configs/observers.yaml.

One observer family, inverse planning (Baker, Saxe & Tenenbaum 2009):
- intents: what the robot may be heading for in this world (app/worlds/intents.py: a
  target lane, absolute or relative to the robot's lane, one of the scene's goals, or, in a
  recorded world, turning one way, straight on or the other way);
- prior: Dirichlet(pseudo-count) over intents updated with where the robot ends in the
  example clips;
- likelihood of each observed robot step: exp(beta * progress) normalised over the moves
  available at that state (a Boltzmann policy over action values), where progress towards
  an intent is measured in units of one step's best progress (the world's intents say how);
- the observer acts on one intent, sampled from the posterior or its mode (config).

Presets:
- coarse: from each start state, moves the way its intent moves (the world's intents say
  how: towards the target lane centre or straight at the goal, at the segment's speed).
  Perceptual noise: the perceived speed is off by a Weber fraction (one draw per trial),
  each click's direction by a Gaussian angle.
- coarse_relative: coarse with the relative lane reading (a sensitivity preset).
- coarse_scene: coarse along the shortest way around the scene's obstacles (Obstacle; the
  lane course already follows the road in Highway, so there it is coarse).
- coarse_momentum: coarse with each move blended with the motion seen (the heading drawn at
  the start, then its own last move): people extrapolate motion (Freyd & Finke 1984).
- precise: the world's own next moves from each start state (policy actions, see
  app/pilot/bots.py for where they come from) with the same, smaller, noise.
- random: uniformly random directions and lengths.
"""

import math
from dataclasses import dataclass

import numpy as np
from scipy.special import logsumexp

from app.observers.config import NoiseConfig, ObserversConfig, default_observers
from app.worlds.intents import IntentOptions, Intents, Move, momentum_course, trial_intents

PRESETS = ("coarse", "precise", "random", "coarse_relative", "coarse_scene", "coarse_momentum")
# the coarse family (issue 30): what a coarse observer does with the intent it inferred
COARSE_PRESETS = ("coarse", "coarse_relative", "coarse_scene", "coarse_momentum")
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


def robot_track(positions) -> np.ndarray:
    """The robot's track [T+1, 2] of a clip's or segment's positions [T+1, agents, 2]."""
    return np.asarray(positions, dtype=np.float64)[:, 0, :]


def payload_intents(payload: dict, config: ObserversConfig, relative: bool,
                    route: str = "straight") -> Intents:
    """The intents an observer reads into this trial's segment, in the payload's world."""
    options = IntentOptions(relative_lanes=relative,
                            lane_change_duration_s=config.lane_change_duration_s.value,
                            route=route)
    examples = [robot_track(c["positions"]) for c in payload.get("examples") or []]
    return trial_intents(payload["scene"], payload["dt_s"],
                         robot_track(payload["segment"]["positions"]), options, examples)


def example_outcomes(payload: dict, intents: Intents) -> np.ndarray:
    """Index (into the intents) of where the robot ends in each example clip."""
    clips = payload.get("examples") or []
    return np.asarray([intents.outcome(robot_track(c["positions"])) for c in clips], dtype=int)


def intent_prior(payload: dict, intents: Intents, pseudo_count: float) -> np.ndarray:
    """Dirichlet(pseudo_count) prior over intents updated with the example clips' outcomes."""
    n_intents = len(intents.labels)
    counts = np.bincount(example_outcomes(payload, intents), minlength=n_intents)
    return (counts + pseudo_count) / (counts.sum() + n_intents * pseudo_count)


def boltzmann_loglik(progress: np.ndarray, candidates: np.ndarray, beta: float) -> np.ndarray:
    """log P(step | intent) of exp(beta * progress), normalised over candidates (last axis)."""
    n = candidates.shape[-1]
    return beta * progress - (logsumexp(beta * candidates, axis=-1) - np.log(n))


def infer_intent(payload: dict, config: ObserversConfig, relative: bool = False) -> Reading:
    """Posterior over the world's intents from the segment (likelihood) and examples (prior)."""
    return read_intents(payload, payload_intents(payload, config, relative), config)


def read_intents(payload: dict, intents: Intents, config: ObserversConfig) -> Reading:
    """Posterior over `intents`: Boltzmann likelihood of the segment's steps, example prior."""
    loglik = boltzmann_loglik(*intents.progress(), config.inference.beta.value).sum(axis=0)
    prior = intent_prior(payload, intents, config.inference.prior_pseudo_count.value)
    log_post = np.where(intents.feasible, np.log(prior) + loglik, -np.inf)
    return Reading(intents.labels, prior, np.exp(log_post - logsumexp(log_post)))


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
    return math.radians(rng.normal(0.0, noise.direction_sd_deg.value))


# the functions below run once per simulated click (hundreds of thousands in an instrument
# run), so they use plain float arithmetic rather than numpy calls on two numbers
def rotate(vector: np.ndarray, angle_rad: float) -> np.ndarray:
    """`vector` rotated by `angle_rad`."""
    c, s = math.cos(angle_rad), math.sin(angle_rad)
    return np.array([c * vector[0] - s * vector[1], s * vector[0] + c * vector[1]])


def step_limits(payload: dict) -> tuple[float, float]:
    """The shortest and longest move [m] a bot clicks, just inside the server's limits."""
    return payload["min_step_m"] * (1 + STEP_MARGIN), payload["max_step_m"] * (1 - STEP_MARGIN)


def clip_length(payload: dict, length_m: float) -> float:
    """A move length [m] clipped inside the server's accepted lengths."""
    low, high = step_limits(payload)
    return min(max(float(length_m), low), high)


def inside_bounds(payload: dict, point: np.ndarray) -> bool:
    """Whether a point lies inside the scene bounds (with a small margin)."""
    b = payload["scene"]["bounds"]
    margin = 1e-3
    return (b["x_min_m"] + margin <= point[0] <= b["x_max_m"] - margin
            and b["y_min_m"] + margin <= point[1] <= b["y_max_m"] - margin)


def valid_move(payload: dict, origin: np.ndarray, direction: np.ndarray,
               length: float) -> np.ndarray:
    """origin + length * unit(direction), turned towards the scene centre if it leaves bounds."""
    norm = math.hypot(direction[0], direction[1])
    unit = direction / norm if norm > 1e-9 else np.array([1.0, 0.0])
    point = origin + length * unit
    if inside_bounds(payload, point):
        return point
    b = payload["scene"]["bounds"]
    inward = np.array([(b["x_min_m"] + b["x_max_m"]) / 2, (b["y_min_m"] + b["y_max_m"]) / 2]
                      ) - origin
    inward = inward / (math.hypot(inward[0], inward[1]) + 1e-9)
    wanted = unit
    for _ in range(11):  # 12 directions tried in all
        unit = unit + inward
        unit = unit / (math.hypot(unit[0], unit[1]) + 1e-9)
        point = origin + length * unit
        if inside_bounds(payload, point):
            return point
    return turned_inside(payload, origin, wanted, length)


def turned_inside(payload: dict, origin: np.ndarray, unit: np.ndarray, length: float
                  ) -> np.ndarray:
    """The move of `length` turned least from `unit` that stays in the scene (10 deg steps).

    A move towards the centre can overshoot the far edge of a narrow scene (a road is a
    few lanes wide); the server refuses such a click, so no simulated participant makes it.
    """
    for angle in np.radians(np.arange(10, 181, 10)):
        for sign in (1.0, -1.0):
            point = origin + length * rotate(unit, sign * angle)
            if inside_bounds(payload, point):
                return point
    b = payload["scene"]["bounds"]
    return np.clip(origin + length * unit, [b["x_min_m"], b["y_min_m"]],
                   [b["x_max_m"], b["y_max_m"]])


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


def trial_reading(payload: dict, config: ObserversConfig, relative: bool,
                  route: str = "straight") -> tuple[Intents, Reading]:
    """The intents of a trial and the observer's posterior over them (no randomness: a simulated
    study may compute it once per trial and pass it to `predict`)."""
    intents = payload_intents(payload, config, relative, route)
    return intents, read_intents(payload, intents, config)


def preset_route(preset: str) -> str:
    """How a coarse preset moves to an intent: straight, or the scene's way round obstacles."""
    return "scene" if preset == "coarse_scene" else "straight"


def start_headings(payload: dict) -> list[float]:
    """The robot's heading [rad] drawn at each start state."""
    return [float(s["robot_heading"]) for s in payload["start_states"]]


def intent_course(payload: dict, intents: Intents, intent: int, factor: float,
                  momentum: float | None) -> Move:
    """How an observer acting on `intent` moves from each start (momentum: blended with the
    motion seen, `momentum` the intent's weight)."""
    move = intents.course(intent, start_positions(payload), factor, start_headings(payload))
    return move if momentum is None else momentum_course(move, start_headings(payload), momentum)


def predict_coarse(payload: dict, rng: np.random.Generator, config: ObserversConfig,
                   relative: bool | None = None, noise: NoiseConfig | None = None,
                   reading: tuple[Intents, Reading] | None = None, route: str = "straight",
                   momentum: float | None = None) -> np.ndarray:
    """Clicks of the coarse observer: infer an intent, then move the way that intent moves."""
    if relative is None:
        relative = config.inference.lane_reading.value == "relative"
    noise = config.coarse_noise if noise is None else noise
    intents, posterior = reading or trial_reading(payload, config, relative, route)
    intent = choose_intent(posterior, config.inference.intent_choice.value, rng)
    move = intent_course(payload, intents, intent, speed_factor(noise, rng), momentum)

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
        length = math.hypot(action[0], action[1]) * factor * payload["dt_s"]
        return rotate(action, direction_noise(noise, rng)), clip_length(payload, length)

    return walk(payload, next_move)


def predict_random(payload: dict, rng: np.random.Generator) -> np.ndarray:
    """Clicks in uniformly random directions with uniformly random valid lengths."""
    low, high = step_limits(payload)

    def next_move(i: int, k: int, position: np.ndarray) -> tuple[np.ndarray, float]:
        direction = rotate(np.array([1.0, 0.0]), rng.uniform(0, 2 * np.pi))
        return direction, rng.uniform(low, high)

    return walk(payload, next_move)


def reads_relative(preset: str, config: ObserversConfig) -> bool:
    """Whether a coarse preset reads Highway lanes relative to the robot's."""
    return preset == "coarse_relative" or config.inference.lane_reading.value == "relative"


def predict(preset: str, payload: dict, rng: np.random.Generator,
            policy_actions: np.ndarray | None = None,
            config: ObserversConfig | None = None,
            reading: tuple[Intents, Reading] | None = None) -> np.ndarray:
    """Clicks [S, K, 2] of an observer `preset`; `precise` follows `policy_actions` [S, K, 2];
    a coarse preset may be given its `trial_reading` of the payload."""
    if preset not in PRESETS:
        raise ValueError(f"preset: unknown observer preset {preset!r}; "
                         f"choose one of {', '.join(PRESETS)}")
    config = config or default_observers()
    if preset in COARSE_PRESETS:
        momentum = config.momentum_weight.value if preset == "coarse_momentum" else None
        return predict_coarse(payload, rng, config, reads_relative(preset, config),
                              reading=reading, route=preset_route(preset), momentum=momentum)
    if preset == "precise":
        if policy_actions is None:
            raise ValueError(f"precise bot: no policy actions for trial {payload['trial_id']}")
        return predict_from_actions(payload, np.asarray(policy_actions), rng,
                                    config.precise_noise)
    return predict_random(payload, rng)
