"""What a simulated observer can read into the robot's moves, per world, from the scene a bot sees.

An observer (app/observers/inverse_planning.py) explains a trial's segment by an intent and
then moves the way that intent moves. What an intent is depends on the world; this module
is the only place that knows it, behind one interface (`Intents`):
- lanes (Highway): a target lane, by its absolute index or, in the relative reading, as a
  change of -1/0/+1 lanes from the robot's lane at the segment's start. Progress of a step
  is the lateral distance gained towards the lane centre over one nominal lateral step
  (lane width / lane-change duration, times dt), normalised over lateral moves of up to
  one nominal step: forward motion is common to every intent and says nothing about it.
  The coarse move: forward at the segment's forward speed plus a lateral step towards the
  target lane centre, never past it.
- goals (Obstacle): one of the scene's goal discs. Progress of a step is the straight-line
  distance gained towards the goal over the step's length (about cos of the angle to the
  goal), normalised over all directions of the same length. The coarse move: straight at
  the goal at the segment's speed, or (scene-aware) along the shortest way to it around the
  scene's obstacles.
- turns (recorded worlds, whose roads have no lanes or goals a scene could name): the robot
  turns one way, goes straight on, or turns the other way. A turn's nominal rate is how
  sharply the robots of the trial's example clips turn (their median heading change per
  second, at least MIN_TURN_RATE_DEG_S). Progress of a step is how close its heading change
  comes to the intent's nominal change per step, in units of that change, normalised over
  heading changes up to three nominal ones either way. The coarse move: on from the robot's
  current heading, turning at the intent's rate, at the segment's speed; the scene-aware one
  turns no further than it must to keep each move's end on the road the scene draws (its
  driven area).

Everything is read from what the browser is shown: the scene as JSON (bank.json's
`scene`), dt and robot tracks [T+1, 2].
"""

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import lru_cache
from typing import Literal, Protocol

import numpy as np

from app.data.trajectory import wrap_angle
from app.worlds.geodesic import GeodesicFields

LANE_OFFSETS = np.array([-1, 0, 1])  # relative reading: merge left (towards lane 0), keep, right
LATERAL_CANDIDATES = 41  # lateral moves the lane likelihood normalises over
DIRECTION_CANDIDATES = 72  # directions (5 deg apart) the goal likelihood normalises over
TURN_SIGNS = np.array([-1, 0, 1])  # the heading's change in the scene's angle sense
TURN_CANDIDATES = 41  # heading changes the turn likelihood normalises over
TURN_THRESHOLD_DEG = 30.0  # a clip turning more than this ends in a turn (recorded worlds')
MIN_TURN_RATE_DEG_S = 5.0  # slower reads as straight on: under 30 deg over a 6 s clip
MOVING_M = 1e-3  # a shorter step has no direction
# the scene-aware route's grid: geometry of what is drawn, no parameter of a person
ROUTE_GRID_M = 0.1
ROUTE_BLOCKED_FACTOR = 1000.0  # an obstacle nobody drives through

# move(i, position) -> (direction, length [m]) of start state i's next move
Move = Callable[[int, np.ndarray], tuple[np.ndarray, float]]


@dataclass(frozen=True)
class IntentOptions:
    """How an observer reads lanes: absolute or relative, and how long a lane change takes."""

    relative_lanes: bool
    lane_change_duration_s: float
    # Obstacle: straight at the goal, or the shortest way around the drawn obstacles
    route: Literal["straight", "scene"] = "straight"


class Intents(Protocol):
    """One trial's intents: what they are called, which exist, the evidence, the moves."""

    labels: np.ndarray  # lane index, lane change (-1/0/+1) or goal index, per intent
    feasible: np.ndarray  # per intent: whether it exists from the segment's start

    def outcome(self, clip_track: np.ndarray) -> int:
        """Index (into `labels`) of the intent a full example clip's robot track ended in."""
        ...

    def progress(self) -> tuple[np.ndarray, np.ndarray]:
        """Progress of each observed segment step towards each intent [T, J], and that of
        every alternative move the likelihood normalises over [T, J, C]."""
        ...

    def course(self, label: int, starts: np.ndarray, speed_factor: float,
               headings: Sequence[float] = ()) -> Move:
        """How a coarse observer acting on intent `label` moves from each start state
        (`headings`: the robot's heading drawn at each start, rad, for intents that turn from
        it; lanes and goals set the direction themselves)."""
        ...


def trial_intents(scene: dict, dt_s: float, segment_track: np.ndarray,
                  options: IntentOptions, example_tracks: list[np.ndarray] = ()) -> Intents:
    """The intents of the scene's world for one trial (its robot segment track [T+1, 2]; the
    example clips' robot tracks)."""
    if scene["lanes"]:
        return LaneIntents(scene, dt_s, segment_track, options)
    if scene.get("recorded"):
        road = scene_road(scene) if options.route == "scene" else None
        return TurnIntents(dt_s, segment_track, example_tracks, road)
    return GoalIntents(scene, dt_s, segment_track, options.route == "scene")


def segment_speed(track: np.ndarray, dt_s: float) -> float:
    """The robot's mean speed over a track [m/s]."""
    steps = np.linalg.norm(np.diff(track, axis=0), axis=1)
    return float(steps.mean() / dt_s) if len(steps) else 0.0


def forward_speed(track: np.ndarray, dt_s: float) -> float:
    """The robot's mean x velocity over a track in the displayed frame [m/s]."""
    return float((track[-1, 0] - track[0, 0]) / (dt_s * max(len(track) - 1, 1)))


class LaneIntents:
    """Target lanes of a road scene (lane 0 on top)."""

    def __init__(self, scene: dict, dt_s: float, track: np.ndarray,
                 options: IntentOptions) -> None:
        lanes = sorted(scene["lanes"], key=lambda lane: lane["index"])
        self.centres = np.array([lane["y_center_m"] for lane in lanes], dtype=np.float64)
        width = float(np.median([lane["width_m"] for lane in scene["lanes"]]))
        self.step_m = width / options.lane_change_duration_s * dt_s  # one nominal lateral move
        self.dt_s, self.track, self.relative = dt_s, track, options.relative_lanes
        if self.relative:
            self.targets, self.feasible = self.relative_targets(self.nearest_lane(track[0, 1]))
            self.labels = LANE_OFFSETS
        else:
            self.targets = self.centres
            self.feasible = np.ones(len(self.centres), dtype=bool)
            self.labels = np.arange(len(self.centres))

    def nearest_lane(self, y: float) -> int:
        """Index of the lane whose centre is nearest to y."""
        return int(np.argmin(np.abs(np.asarray(y, dtype=np.float64)[..., None] - self.centres),
                             axis=-1))

    def relative_targets(self, lane: int) -> tuple[np.ndarray, np.ndarray]:
        """Lane centres [3] of merge left / keep / right from `lane`, and which of them exist."""
        lanes = lane + LANE_OFFSETS
        n = len(self.centres)
        return self.centres[np.clip(lanes, 0, n - 1)], (lanes >= 0) & (lanes < n)

    def outcome(self, clip_track: np.ndarray) -> int:
        """The lane a clip ends in, or (relative) its lane change clipped to one lane."""
        end = self.nearest_lane(clip_track[-1, 1])
        if not self.relative:
            return end
        return int(np.clip(end - self.nearest_lane(clip_track[0, 1]), -1, 1)) + 1

    def progress(self) -> tuple[np.ndarray, np.ndarray]:
        """Lateral progress towards each target lane centre, in nominal lateral steps."""
        y, step_m = self.track[:, 1], self.step_m
        moves = np.clip(np.diff(y), -step_m, step_m)[:, None]  # a faster move reads as a full one
        start = y[:-1, None]
        gap = np.abs(start - self.targets)
        progress = (gap - np.abs(start + moves - self.targets)) / step_m  # [T, J]
        lateral = np.linspace(-step_m, step_m, LATERAL_CANDIDATES)
        after = np.abs(start[..., None] + lateral - self.targets[:, None])
        return progress, (gap[..., None] - after) / step_m  # [T, J, C]

    def target_y(self, label: int, start: np.ndarray) -> float:
        """Centre y of the lane an observer acting on `label` heads for from `start`."""
        if not self.relative:
            return float(self.centres[label])
        targets, feasible = self.relative_targets(self.nearest_lane(start[1]))
        return float(targets[label + 1] if feasible[label + 1] else targets[1])

    def course(self, label: int, starts: np.ndarray, speed_factor: float,
               headings: Sequence[float] = ()) -> Move:
        """Forward at the segment's forward speed, sideways towards the target lane centre."""
        forward = forward_speed(self.track, self.dt_s) * speed_factor * self.dt_s
        lateral = self.step_m
        targets = [self.target_y(label, s) for s in starts]

        def move(i: int, position: np.ndarray) -> tuple[np.ndarray, float]:
            side = float(np.clip(targets[i] - position[1], -lateral, lateral))
            return np.array([forward, side]), float(np.hypot(forward, side))

        return move


class GoalIntents:
    """The goal discs of a plane scene; the coarse move goes straight at the goal or, with
    `around_obstacles`, along the shortest way around the scene's obstacles."""

    def __init__(self, scene: dict, dt_s: float, track: np.ndarray,
                 around_obstacles: bool = False) -> None:
        self.goals = np.array([[g["x_m"], g["y_m"]] for g in scene["goals"]], dtype=np.float64)
        self.dt_s, self.track = dt_s, track
        self.routes = scene_routes(scene) if around_obstacles else None
        self.labels = np.arange(len(self.goals))
        self.feasible = np.ones(len(self.goals), dtype=bool)

    def outcome(self, clip_track: np.ndarray) -> int:
        """The goal nearest to where the clip's robot ends."""
        return int(np.argmin(np.linalg.norm(self.goals - clip_track[-1], axis=1)))

    def progress(self) -> tuple[np.ndarray, np.ndarray]:
        """Straight-line distance gained towards each goal, per metre moved."""
        track, goals = self.track, self.goals
        moves = np.diff(track, axis=0)
        length = np.linalg.norm(moves, axis=1)
        moving = length > 1e-9  # a standing robot says nothing about its direction
        start, moves, length = track[:-1][moving], moves[moving], length[moving]
        gap = np.linalg.norm(start[:, None, :] - goals, axis=-1)  # [T, G]
        progress = (gap - np.linalg.norm(start[:, None, :] + moves[:, None, :] - goals, axis=-1))
        angles = np.linspace(0.0, 2 * np.pi, DIRECTION_CANDIDATES, endpoint=False)
        turns = length[:, None, None] * np.stack([np.cos(angles), np.sin(angles)], axis=-1)
        ends = start[:, None, None, :] + turns[:, None, :, :] - goals[None, :, None, :]
        candidates = gap[..., None] - np.linalg.norm(ends, axis=-1)  # [T, G, C]
        scale = length[:, None]
        return progress / scale, candidates / scale[..., None]

    def course(self, label: int, starts: np.ndarray, speed_factor: float,
               headings: Sequence[float] = ()) -> Move:
        """Straight at the goal at the segment's speed, stopping on it."""
        goal = self.goals[label]
        reach = segment_speed(self.track, self.dt_s) * speed_factor * self.dt_s
        routes = self.routes

        def move(i: int, position: np.ndarray) -> tuple[np.ndarray, float]:
            to_goal = goal - position
            length = min(reach, float(np.linalg.norm(to_goal)))
            if routes is None:
                return to_goal, length
            downhill = routes.downhill(label, position)
            return (downhill if downhill.any() else to_goal), length

        return move


def scene_routes(scene: dict) -> GeodesicFields:
    """Shortest ways to the scene's goals around its obstacles grown by the robot's radius."""
    robot = next(a for a in scene["agents"] if a["name"] == "robot")
    radius = max(robot["width_m"], robot["length_m"]) / 2
    bounds = scene["bounds"]
    if bounds["x_min_m"] != 0 or bounds["y_min_m"] != 0:
        raise ValueError("scene.bounds: scene-aware routes need a plane from (0, 0)")
    return _routes((bounds["x_max_m"], bounds["y_max_m"]),
                   tuple((o["x_m"], o["y_m"], o["radius_m"] + radius) for o in scene["obstacles"]),
                   tuple((g["x_m"], g["y_m"]) for g in scene["goals"]))


@lru_cache(maxsize=8)
def _routes(size: tuple, discs: tuple, goals: tuple) -> GeodesicFields:
    return GeodesicFields(size, list(discs), list(goals), ROUTE_GRID_M, ROUTE_BLOCKED_FACTOR)


def momentum_course(move: Move, start_headings: list[float], weight: float) -> Move:
    """`move` with each direction blended with the previous move's (at first the heading
    drawn at the start): `weight` on the intent, 1 - weight on the motion seen."""
    previous = {i: np.array([np.cos(h), np.sin(h)]) for i, h in enumerate(start_headings)}

    def blended(i: int, position: np.ndarray) -> tuple[np.ndarray, float]:
        direction, length = move(i, position)
        norm = float(np.hypot(*direction))
        intent = direction / norm if norm > 1e-9 else previous[i]
        mixed = weight * intent + (1 - weight) * previous[i]
        mixed_norm = float(np.hypot(*mixed))
        previous[i] = mixed / mixed_norm if mixed_norm > 1e-9 else intent
        return previous[i], length

    return blended


def move_headings(track: np.ndarray) -> np.ndarray:
    """Heading [rad] of each move of a track [T+1, 2] that has a direction."""
    moves = np.diff(track, axis=0)
    moving = np.hypot(moves[:, 0], moves[:, 1]) > MOVING_M
    return np.arctan2(moves[moving, 1], moves[moving, 0])


def heading_changes(track: np.ndarray) -> np.ndarray:
    """Change of heading [rad] between consecutive moves of a track, wrapped into (-pi, pi]."""
    angles = move_headings(track)
    return wrap_angle(np.diff(angles))


def turn_rate(example_tracks: list[np.ndarray], dt_s: float) -> float:
    """The examples' median |heading change| per second over their turning clips [rad/s]."""
    rates = []
    for track in example_tracks:
        changes = heading_changes(track)
        if len(changes) and abs(changes.sum()) > np.radians(TURN_THRESHOLD_DEG):
            rates.append(abs(changes.sum()) / (len(changes) * dt_s))
    floor = np.radians(MIN_TURN_RATE_DEG_S)
    return max(float(np.median(rates)), floor) if rates else floor


class TurnIntents:
    """Turning one way, straight on, or the other way (recorded worlds); with a `road` (where
    the scene draws road), the coarse move turns no further than it must to stay on it."""

    labels = TURN_SIGNS

    def __init__(self, dt_s: float, track: np.ndarray, example_tracks: list[np.ndarray],
                 road: "Road | None" = None) -> None:
        self.dt_s, self.track, self.road = dt_s, track, road
        self.step_rad = turn_rate(example_tracks, dt_s) * dt_s  # a nominal turn per step
        self.feasible = np.ones(len(TURN_SIGNS), dtype=bool)

    def outcome(self, clip_track: np.ndarray) -> int:
        """Index of the way a clip's robot turned over the whole clip."""
        total = float(np.degrees(heading_changes(clip_track).sum()))
        sign = 0 if abs(total) <= TURN_THRESHOLD_DEG else int(np.sign(total))
        return int(np.flatnonzero(sign == TURN_SIGNS)[0])

    def progress(self) -> tuple[np.ndarray, np.ndarray]:
        """Closeness of each observed heading change to each intent's nominal change."""
        nominal = TURN_SIGNS * self.step_rad  # [J]
        changes = heading_changes(self.track)[:, None]  # [T, 1]
        progress = -np.abs(changes - nominal) / self.step_rad  # [T, J]
        others = np.linspace(-3, 3, TURN_CANDIDATES) * self.step_rad
        candidates = -np.abs(others[None, None, :] - nominal[None, :, None]) / self.step_rad
        return progress, np.broadcast_to(candidates, (len(changes), *candidates.shape[1:]))

    def course(self, label: int, starts: np.ndarray, speed_factor: float,
               headings: Sequence[float] = ()) -> Move:
        """On from the robot's heading drawn at each start (a recorded start is drawn as the
        recorded car stood there; without `headings`, the segment's last move), turning
        `label` nominal turns per step."""
        angles = move_headings(self.track)
        last = float(angles[-1]) if len(angles) else 0.0
        drawn = list(headings) or [last] * len(starts)
        facing = dict(enumerate(float(h) for h in drawn))
        length = segment_speed(self.track, self.dt_s) * speed_factor * self.dt_s

        road = self.road

        def move(i: int, position: np.ndarray) -> tuple[np.ndarray, float]:
            facing[i] += label * self.step_rad
            if road is not None:
                facing[i] = road.keep_on(position, facing[i], length, label)
            return np.array([np.cos(facing[i]), np.sin(facing[i])]), length

        return move


ROAD_TURNS_DEG = np.arange(5, 91, 5)  # how far a scene-aware observer turns to stay on road


class Road:
    """The road a recorded scene draws: its driven-area cells (app/data/scene.py DrivenArea)."""

    def __init__(self, driven: dict) -> None:
        self.cell, self.x0, self.y0 = driven["cell_m"], driven["x0_m"], driven["y0_m"]
        self.cells = {(row, col) for row, first, last in driven["runs"]
                      for col in range(first, last + 1)}

    def contains(self, point: np.ndarray) -> bool:
        """Whether a point lies on a drawn road cell."""
        cell = (int((point[1] - self.y0) // self.cell), int((point[0] - self.x0) // self.cell))
        return cell in self.cells

    def keep_on(self, position: np.ndarray, heading: float, length: float, sign: int) -> float:
        """`heading`, or the one turned least (the intent's way first) whose move of `length`
        ends on the road; `heading` when none does within 90 degrees."""
        first = -1.0 if sign < 0 else 1.0
        for turn in np.radians(np.concatenate([[0.0], ROAD_TURNS_DEG])):
            for side in ((first, -first) if turn else (1.0,)):
                angle = heading + side * turn
                end = position + length * np.array([np.cos(angle), np.sin(angle)])
                if self.contains(end):
                    return float(angle)
        return heading


def scene_road(scene: dict) -> Road | None:
    """The recorded scene's road, or None where it draws no driven area."""
    driven = (scene.get("recorded") or {}).get("driven")
    return Road(driven) if driven else None
