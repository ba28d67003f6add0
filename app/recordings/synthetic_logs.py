# GENERATED, NOT REAL DATA: this module writes made-up lab logs for tests, demos and the docs.
# Nothing it writes was ever recorded from a robot or a person.
"""GENERATED, NOT REAL DATA: small lab logs in the generic CSV format (csv_logs.py).

A mobile robot (about 0.8 m/s) and a person (about 1.2 m/s) walk in a 12 m x 8 m room
(x in [0, 12], y in [0, 8], metres, y up), each visiting a few random waypoints in turn.
Both turn at a bounded rate and accelerate at a bounded rate, so paths are smooth; both slow
down on sharp turns and when the other comes within 2.5 m, and steer a little away from it.
Simulated at 50 Hz, written at 10 Hz: one file with a `recording` column (recordings named
`generated_NNN`, so every row says it is generated), several recordings, the same bytes for
the same seed. The robot has a length and width, the person leaves them empty.

    python -m app.recordings.synthetic_logs var/generated/lab_logs.csv --recordings 4
"""

import argparse
import csv
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from tqdm import tqdm

from app.core.files import atomic_path
from app.recordings.csv_logs import COLUMNS, HUMAN, LEADING, ROBOT, TRAILING

ROOM_M = (12.0, 8.0)
DT_S = 0.1
SUBSTEPS = 5
WAYPOINTS = 4
WAYPOINT_MARGIN_M = 1.0
WALL_MARGIN_M = 0.3
ARRIVED_M = 0.4
SLOW_FROM_M = 2.5  # each slows down (and steers away) when the other is nearer than this
MIN_SPEED_SHARE = 0.15  # the slowest share of its walking speed, right next to the other
AVOID_WEIGHT = 2.0  # how hard each steers away from the other, right next to it
ROBOT_SIZE_M = (0.7, 0.5)


@dataclass(frozen=True)
class Walker:
    """How one agent moves: walking speed [m/s], turn rate [rad/s], acceleration [m/s^2]."""

    agent_id: str
    role: str
    speed_mps: float
    turn_rate_rps: float
    accel_mps2: float


ROBOT_WALKER = Walker("robot_1", ROBOT, 0.8, 1.5, 0.5)
PERSON_WALKER = Walker("person_1", HUMAN, 1.2, 3.0, 1.0)


@dataclass
class _State:
    """Where an agent is, where it faces, how fast it goes and which waypoint it heads for."""

    xy: np.ndarray
    heading: float
    speed: float
    waypoints: np.ndarray
    target: int = 1


def generate_logs(out_path: Path, recordings: int = 4, seconds: float = 60.0, seed: int = 0,
                  velocities: bool = True) -> dict:
    """Write GENERATED (not real) lab logs to one CSV file; returns what was written."""
    header = [LEADING, *COLUMNS, *TRAILING]
    rows = []
    for k in tqdm(range(recordings), desc="generate logs", unit="recording", leave=False):
        rng = np.random.default_rng([seed, k])
        rows += _recording_rows(f"generated_{k + 1:03d}", rng, seconds, velocities)
    with atomic_path(Path(out_path)) as tmp, open(tmp, "w", newline="") as fh:
        writer = csv.writer(fh, lineterminator="\n")
        writer.writerow(header)
        writer.writerows(rows)
    return {"file": str(out_path), "recordings": recordings, "rows": len(rows), "dt_s": DT_S,
            "seed": seed, "generated": "NOT REAL DATA"}


def _recording_rows(name: str, rng: np.random.Generator, seconds: float,
                    velocities: bool) -> list[list[str]]:
    """One recording's rows, time by time, robot then person."""
    walkers = (ROBOT_WALKER, PERSON_WALKER)
    states = _start_states(rng)
    rows = []
    for frame in range(int(round(seconds / DT_S)) + 1):
        for walker, state in zip(walkers, states, strict=True):
            rows.append(_row(name, frame * DT_S, walker, state, velocities))
        for _ in range(SUBSTEPS):
            for me, (walker, state) in enumerate(zip(walkers, states, strict=True)):
                _step(walker, state, states[1 - me].xy, DT_S / SUBSTEPS)
    return rows


def _start_states(rng: np.random.Generator) -> list[_State]:
    """Robot and person at rest on their first waypoints, at least 3 m apart."""
    while True:
        routes = [_waypoints(rng) for _ in range(2)]
        if np.linalg.norm(routes[0][0] - routes[1][0]) >= 3.0:
            break
    return [_State(route[0].copy(), _bearing(route[0], route[1]), 0.0, route)
            for route in routes]


def _waypoints(rng: np.random.Generator) -> np.ndarray:
    """WAYPOINTS points inside the room's margin, each at least 3 m from the one before."""
    points = [rng.uniform(WAYPOINT_MARGIN_M, np.subtract(ROOM_M, WAYPOINT_MARGIN_M))]
    while len(points) < WAYPOINTS:
        point = rng.uniform(WAYPOINT_MARGIN_M, np.subtract(ROOM_M, WAYPOINT_MARGIN_M))
        if np.linalg.norm(point - points[-1]) >= 3.0:
            points.append(point)
    return np.array(points)


def _bearing(a: np.ndarray, b: np.ndarray) -> float:
    return math.atan2(b[1] - a[1], b[0] - a[0])


def _step(walker: Walker, state: _State, other_xy: np.ndarray, h: float) -> None:
    """Advance one agent by h seconds: turn toward its waypoint (away from the other), move."""
    if np.linalg.norm(state.waypoints[state.target] - state.xy) < ARRIVED_M:
        state.target = (state.target + 1) % len(state.waypoints)
    away = state.xy - other_xy
    gap = float(np.linalg.norm(away))
    wanted = state.waypoints[state.target] - state.xy
    wanted = wanted / max(np.linalg.norm(wanted), 1e-9)
    wanted = wanted + AVOID_WEIGHT * away / max(gap, 1e-9) * max(0.0, 1 - gap / SLOW_FROM_M)
    error = (math.atan2(wanted[1], wanted[0]) - state.heading + math.pi) % (2 * math.pi) - math.pi
    turn = walker.turn_rate_rps * h
    state.heading += min(max(error, -turn), turn)
    near = min(1.0, max(MIN_SPEED_SHARE, gap / SLOW_FROM_M))
    target_speed = walker.speed_mps * near * max(MIN_SPEED_SHARE, math.cos(error))
    dv = walker.accel_mps2 * h
    state.speed += min(max(target_speed - state.speed, -dv), dv)
    step = state.speed * h * np.array([math.cos(state.heading), math.sin(state.heading)])
    state.xy = np.clip(state.xy + step, WALL_MARGIN_M, np.subtract(ROOM_M, WALL_MARGIN_M))


def _row(name: str, time_s: float, walker: Walker, state: _State,
         velocities: bool) -> list[str]:
    """One CSV row: the agent's state now (velocity cells empty unless `velocities`)."""
    v = state.speed * np.array([math.cos(state.heading), math.sin(state.heading)])
    vx, vy = (_decimals(v[0], 3), _decimals(v[1], 3)) if velocities else ("", "")
    heading = (state.heading + math.pi) % (2 * math.pi) - math.pi
    size = [f"{s:.2f}" for s in ROBOT_SIZE_M] if walker.role == ROBOT else ["", ""]
    return [name, walker.agent_id, f"{time_s:.1f}", _decimals(state.xy[0], 3),
            _decimals(state.xy[1], 3), vx, vy, walker.role, _decimals(heading, 4), *size]


def _decimals(value: float, places: int) -> str:
    """The value with `places` decimals, never '-0.000'."""
    return f"{round(float(value), places) + 0.0:.{places}f}"


def main() -> None:
    """Write generated (NOT REAL) lab logs from the command line."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", type=Path, help="the CSV file to write")
    parser.add_argument("--recordings", type=int, default=4)
    parser.add_argument("--seconds", type=float, default=60.0)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--no-velocities", action="store_true",
                        help="leave vx_mps, vy_mps empty (the reader derives them)")
    args = parser.parse_args()
    print(generate_logs(args.out, args.recordings, args.seconds, args.seed,
                        not args.no_velocities))


if __name__ == "__main__":
    main()
