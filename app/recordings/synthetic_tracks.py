"""GENERATED, NOT REAL DATA: small INTERACTION-format files for tests, demos and labs without data.

Geometry: a four-arm roundabout (ring radius 18 m, counter-clockwise, right-hand traffic)
or a four-arm intersection, both centred at ORIGIN_M. Cars arrive on each arm at random,
follow a route (roundabout: exit after 1, 2 or 3 quarter turns; intersection: right,
straight or left), slow down for curvature and for any car just ahead of them, and leave.
A few pedestrians cross the arms. Vehicles come in recorded traffic's spread of sizes
(VEHICLE_SIZES: mostly cars of 4-5 m, some vans, a few buses and trucks up to 12.2 m),
drawn from a stream of their own, so a seed's arrivals and routes stay as they were; a car
keeps its distance to the car ahead bumper to bumper. Every car's manoeuvre per frame goes
to a sidecar CSV (generator_labels/), since the dataset's own columns have no place for it:
the arm it entered from and the arm it leaves by (east/north/west/south), its turn (left /
straight / right: roundabout exit after 3 / 2 / 1 quarter turns) and, on a roundabout, its
phase (enter / circle / exit; empty at the intersection).

Output layouts: v1.2 (train/<s>_train.csv, val/<s>_val.csv cut into 4 s cases) or v1.0
(recorded_trackfiles/<s>/vehicle_tracks_000.csv + pedestrian_tracks_000.csv), plus a
lanelet2-style map maps/<s>.osm in latitude/longitude (UTM projector at origin (0, 0)).
"""

import csv
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from tqdm import tqdm

from app.recordings.lanelet_map import OriginProjector
from app.recordings.tracks import CASE_COLUMNS, FRAME_MS, PEDESTRIAN_COLUMNS, VEHICLE_COLUMNS

ORIGIN_M = np.array([1000.0, 1000.0])
DT_S = FRAME_MS / 1000
RING_RADIUS_M = 18.0
ARM_LENGTH_M = 60.0
LANE_OFFSET_M = 1.75
INTERSECTION_BOX_M = 12.0
CASE_FRAMES = 40
MIN_ARRIVAL_GAP_S = 1.0  # between two cars arriving on one arm
CAR_LENGTH_M, CAR_WIDTH_M = 4.6, 1.9  # the size the dataset's devkit assumes
# (share of vehicles, (length min, max), (width min, max)) in m: cars, vans, buses and trucks
VEHICLE_SIZES = ((0.85, (4.0, 5.0), (1.7, 2.0)), (0.11, (5.0, 6.5), (1.9, 2.2)),
                 (0.04, (9.0, 12.2), (2.4, 2.6)))
SIZE_STREAM = 104729  # added to a stream's seed for its vehicles' sizes
ARM_ANGLES = (0.0, 0.5 * math.pi, math.pi, 1.5 * math.pi)
ARM_NAMES = ("east", "north", "west", "south")
TURNS = ("left", "straight", "right")
ROUNDABOUT_PHASES = ("enter", "circle", "exit")
NO_PHASE = -1
# the sidecar's label columns and the values each can take, in display order
LABEL_VALUES = {"entry_arm": ARM_NAMES, "exit_arm": ARM_NAMES, "turn": TURNS,
                "phase": ROUNDABOUT_PHASES}
INTERSECTION_TURNS = ("straight", "left", "right")  # intersection_route's manoeuvre index
ROUNDABOUT_TURNS = {1: "right", 2: "straight", 3: "left"}  # quarter turns counter-clockwise


def geometry_of(scenario: str) -> str:
    """'roundabout' or 'intersection' from the scenario name."""
    lowered = scenario.lower()
    for kind in ("roundabout", "intersection"):
        if kind in lowered:
            return kind
    raise ValueError(f"scenario {scenario!r}: name must contain Roundabout or Intersection")


def _unit(angle: float) -> np.ndarray:
    return np.array([math.cos(angle), math.sin(angle)])


def _left_of_inbound(angle: float) -> np.ndarray:
    """Normal pointing to the right-hand side of a car driving inwards on arm `angle`."""
    return np.array([-math.sin(angle), math.cos(angle)])


def _bezier(p0, d0, p1, d1, count: int = 24) -> np.ndarray:
    """Cubic Bezier from p0 (leaving along d0) to p1 (arriving along d1)."""
    reach = np.linalg.norm(p1 - p0) / 3
    c0, c1 = p0 + d0 * reach, p1 - d1 * reach
    t = np.linspace(0, 1, count)[:, None]
    return (1 - t) ** 3 * p0 + 3 * (1 - t) ** 2 * t * c0 + 3 * (1 - t) * t**2 * c1 + t**3 * p1


def _line(p0, p1, count: int = 20) -> np.ndarray:
    return p0 + np.linspace(0, 1, count)[:, None] * (p1 - p0)


@dataclass
class Route:
    """A path polyline [K, 2] (local metres), its arc length [K], per-point phase index
    (NO_PHASE off a roundabout) and the route's turn, entry and exit arms."""

    points: np.ndarray
    s: np.ndarray
    phase: np.ndarray
    turn: str
    arm: int = 0
    exit_arm: int = 0
    box_m: tuple[float, float] | None = None  # arc-length span inside an intersection box
    curvature: np.ndarray = field(init=False)

    def __post_init__(self) -> None:
        heading = np.unwrap(np.arctan2(*np.diff(self.points, axis=0).T[::-1]))
        ds = np.maximum(np.diff(self.s), 1e-6)
        turn = np.abs(np.diff(heading)) / ds[1:]
        self.curvature = np.concatenate([[0.0], turn, [0.0]])

    def at(self, s: float) -> tuple[np.ndarray, float, int, float]:
        """(point, heading, phase index, curvature) at arc length s."""
        k = int(np.clip(np.searchsorted(self.s, s) - 1, 0, len(self.s) - 2))
        frac = (s - self.s[k]) / max(self.s[k + 1] - self.s[k], 1e-9)
        d = self.points[k + 1] - self.points[k]
        return self.points[k] + frac * d, math.atan2(d[1], d[0]), int(self.phase[k]), \
            float(self.curvature[k])


def _route(pieces: list[tuple[np.ndarray, int]], turn: str, arm: int, exit_arm: int,
           box_piece: int | None = None) -> Route:
    points = np.concatenate([p if k == 0 else p[1:] for k, (p, _) in enumerate(pieces)])
    phase = np.concatenate([np.full(len(p) - (k > 0), ph) for k, (p, ph) in enumerate(pieces)])
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(points, axis=0), axis=1))])
    keep = np.concatenate([[True], np.diff(s) > 1e-6])
    box = None
    if box_piece is not None:
        lengths = [float(np.linalg.norm(np.diff(p, axis=0), axis=1).sum()) for p, _ in pieces]
        start = sum(lengths[:box_piece])
        box = (start, start + lengths[box_piece])
    return Route(points[keep], s[keep], phase[keep], turn, arm, exit_arm, box)


def roundabout_route(arm: int, quarter_turns: int) -> Route:
    """Enter on `arm`, drive counter-clockwise for `quarter_turns`, exit on the arm reached."""
    theta = ARM_ANGLES[arm]
    phi = theta + quarter_turns * 0.5 * math.pi
    start = _unit(theta) * ARM_LENGTH_M + _left_of_inbound(theta) * LANE_OFFSET_M
    entry_end = _unit(theta) * (RING_RADIUS_M + 9) + _left_of_inbound(theta) * LANE_OFFSET_M
    arc_a, arc_b = theta + 0.45, phi - 0.45
    angles = np.linspace(arc_a, arc_b, max(8, int(24 * (arc_b - arc_a))))
    arc = RING_RADIUS_M * np.stack([np.cos(angles), np.sin(angles)], axis=1)
    exit_start = _unit(phi) * (RING_RADIUS_M + 9) - _left_of_inbound(phi) * LANE_OFFSET_M
    end = _unit(phi) * ARM_LENGTH_M - _left_of_inbound(phi) * LANE_OFFSET_M

    def tangent(a):
        return np.array([-math.sin(a), math.cos(a)])

    pieces = [
        (_line(start, entry_end), 0),
        (_bezier(entry_end, -_unit(theta), arc[0], tangent(arc_a)), 0),
        (arc, 1),
        (_bezier(arc[-1], tangent(arc_b), exit_start, _unit(phi)), 2),
        (_line(exit_start, end), 2),
    ]
    return _route(pieces, turn=ROUNDABOUT_TURNS[quarter_turns], arm=arm,
                  exit_arm=(arm + quarter_turns) % 4)


def intersection_route(arm: int, manoeuvre: int) -> Route:
    """From `arm`, go straight (0), left (1) or right (2) through the box."""
    theta = ARM_ANGLES[arm]
    phi = theta + (math.pi, 1.5 * math.pi, 0.5 * math.pi)[manoeuvre]
    box = INTERSECTION_BOX_M
    start = _unit(theta) * ARM_LENGTH_M + _left_of_inbound(theta) * LANE_OFFSET_M
    stop = _unit(theta) * box + _left_of_inbound(theta) * LANE_OFFSET_M
    leave = _unit(phi) * box - _left_of_inbound(phi) * LANE_OFFSET_M
    end = _unit(phi) * ARM_LENGTH_M - _left_of_inbound(phi) * LANE_OFFSET_M
    pieces = [(_line(start, stop), NO_PHASE),
              (_bezier(stop, -_unit(theta), leave, _unit(phi)), NO_PHASE),
              (_line(leave, end), NO_PHASE)]
    exit_arm = (arm + (2, 3, 1)[manoeuvre]) % 4
    return _route(pieces, turn=INTERSECTION_TURNS[manoeuvre], arm=arm, exit_arm=exit_arm,
                  box_piece=1)


@dataclass
class _Car:
    track_id: int
    route: Route
    s: float
    v: float
    v_des: float
    granted: bool = False  # may enter the intersection box
    length_m: float = CAR_LENGTH_M
    width_m: float = CAR_WIDTH_M
    log: list = field(default_factory=list)  # (frame, x, y, vx, vy, psi, manoeuvre)


def _pick_route(kind: str, rng: np.random.Generator, arm: int) -> Route:
    if kind == "roundabout":
        return roundabout_route(arm, int(rng.choice([1, 2, 3], p=[0.35, 0.4, 0.25])))
    return intersection_route(arm, int(rng.choice([0, 1, 2], p=[0.4, 0.3, 0.3])))


def vehicle_size(rng: np.random.Generator) -> tuple[float, float]:
    """A (length, width) in m drawn from VEHICLE_SIZES."""
    shares = np.array([share for share, _, _ in VEHICLE_SIZES])
    _, length, width = VEHICLE_SIZES[int(rng.choice(len(shares), p=shares / shares.sum()))]
    return round(float(rng.uniform(*length)), 2), round(float(rng.uniform(*width)), 2)


def _gap_ahead(car: _Car, pos: np.ndarray, heading: float, others: list) -> float:
    """Bumper-to-bumper distance to the nearest other car whose centre lies in a 35-degree
    cone ahead (inf if none)."""
    best = math.inf
    forward = np.array([math.cos(heading), math.sin(heading)])
    for other, other_pos, other_heading in others:
        if other is car:
            continue
        rel = other_pos - pos
        dist = float(np.linalg.norm(rel))
        if dist < 1e-6 or dist > 25 or rel @ forward / dist < math.cos(math.radians(35)):
            continue
        if car.route.box_m is not None and math.cos(other_heading - heading) < 0.5:
            continue  # at the intersection, crossing traffic is handled by the box rule
        # symmetric conflicts resolve by priority: the older car (lower id) goes first
        if other.track_id > car.track_id and dist > 7:
            continue
        best = min(best, dist - (car.length_m + other.length_m) / 2)
    return best


def _box_gap(car: _Car, occupied_arms: set[int]) -> float:
    """Intersection rule: enter the box only when no car from another arm is in it."""
    box = car.route.box_m
    if box is None or car.granted or car.s > box[0]:
        return math.inf
    to_line = box[0] - car.s
    if to_line > 15:
        return math.inf
    if occupied_arms <= {car.route.arm}:
        car.granted = True
        occupied_arms.add(car.route.arm)
        return math.inf
    return to_line + 1.0  # as a bumper gap: the centre stops 1 m before the line


def _in_box(car: _Car) -> bool:
    box = car.route.box_m
    return box is not None and car.granted and car.s < box[1] + car.length_m


def _step_car(car: _Car, pos, heading, curvature, others, occupied_arms: set[int]) -> None:
    gap = min(_gap_ahead(car, pos, heading, others), _box_gap(car, occupied_arms))
    target = min(car.v_des, math.sqrt(2.2 / max(curvature, 1e-3)),
                 max(0.0, (gap - 2.0) / 1.2))
    accel = float(np.clip((target - car.v) / 0.8, -6.0, 2.0))
    car.v = max(0.0, car.v + accel * DT_S)
    car.s += car.v * DT_S


def arrival_gap_s(kind: str, arrivals_per_arm_min: float | None = None) -> float:
    """The random part of the gap between arrivals on an arm [s]: each gap is this,
    exponentially distributed, plus MIN_ARRIVAL_GAP_S; by default 4 s (roundabout) / 6 s."""
    if arrivals_per_arm_min is None:
        return 4.0 if kind == "roundabout" else 6.0
    if not 0 < arrivals_per_arm_min < 60 / MIN_ARRIVAL_GAP_S:
        raise ValueError(f"arrivals per arm per minute: {arrivals_per_arm_min:g} is not in "
                         f"(0, {60 / MIN_ARRIVAL_GAP_S:g}) (arrivals are at least "
                         f"{MIN_ARRIVAL_GAP_S:g} s apart)")
    return 60 / arrivals_per_arm_min - MIN_ARRIVAL_GAP_S


def simulate_stream(kind: str, duration_s: float, seed: int,
                    arrivals_per_arm_min: float | None = None,
                    ) -> tuple[list[_Car], list[dict]]:
    """Cars and pedestrians over `duration_s` at 10 Hz; logs are in local metres."""
    rng = np.random.default_rng(seed)
    size_rng = np.random.default_rng(seed + SIZE_STREAM)
    arrival_s = arrival_gap_s(kind, arrivals_per_arm_min)  # mean random gap per arm
    frames = int(round(duration_s / DT_S))
    cars: list[_Car] = []
    active: list[_Car] = []
    next_id = 1
    next_arrival = rng.exponential(arrival_s, size=4)
    for frame in range(1, frames + 1):
        t = frame * DT_S
        for arm in range(4):
            if t < next_arrival[arm]:
                continue
            next_arrival[arm] = t + rng.exponential(arrival_s) + MIN_ARRIVAL_GAP_S
            route = _pick_route(kind, rng, arm)
            if any(np.linalg.norm(c.route.at(c.s)[0] - route.points[0]) < 12 for c in active):
                continue
            length, width = vehicle_size(size_rng)
            car = _Car(next_id, route, 0.0, float(rng.uniform(7, 10)), float(rng.uniform(8, 11)),
                       length_m=length, width_m=width)
            next_id += 1
            cars.append(car)
            active.append(car)
        states = [(c, c.route.at(c.s)) for c in active]
        others = [(c, st[0], st[1]) for c, st in states]
        occupied_arms = {c.route.arm for c in active if _in_box(c)}
        for car, (pos, heading, phase, curvature) in states:
            car.log.append((frame, *pos, car.v * math.cos(heading), car.v * math.sin(heading),
                            heading, phase))
            _step_car(car, pos, heading, curvature, others, occupied_arms)
        active = [c for c in active if c.s < c.route.s[-1] - 0.5]
    return cars, _pedestrians(rng, frames, next_id)


def _pedestrians(rng: np.random.Generator, frames: int, first_id: int) -> list[dict]:
    """A few people crossing an arm at walking speed (never robot or human of a pair)."""
    walkers = []
    for k in range(max(1, frames // 300)):
        arm = ARM_ANGLES[int(rng.integers(4))]
        along = _unit(arm) * (RING_RADIUS_M + 16)
        across = _left_of_inbound(arm)
        start = int(rng.integers(1, max(2, frames - 80)))
        speed = float(rng.uniform(1.1, 1.6))
        steps = np.arange(0, min(80, frames - start + 1))
        xy = along - across * 6 + across * speed * DT_S * steps[:, None]
        walkers.append({"track_id": first_id + k, "frames": start + steps, "xy": xy,
                        "v": np.repeat((across * speed)[None], len(steps), axis=0)})
    return walkers


# ---------------------------------------------------------------- writing files


def _fmt(value: float) -> str:
    return f"{value:.3f}"


def _car_rows(car: _Car, rng: np.random.Generator, offset: np.ndarray):
    for frame, x, y, vx, vy, psi, phase in car.log:
        noise = rng.normal(0, 0.02, size=2)
        yield frame, [x + offset[0] + noise[0], y + offset[1] + noise[1], vx, vy, psi,
                      car.length_m, car.width_m], phase


def _manoeuvre(car: _Car, phase: int) -> tuple[str, str, str, str]:
    """The sidecar's label values (LABEL_VALUES order) of `car` at a point with `phase`."""
    route = car.route
    phase_name = "" if phase == NO_PHASE else ROUNDABOUT_PHASES[phase]
    return ARM_NAMES[route.arm], ARM_NAMES[route.exit_arm], route.turn, phase_name


def _collect(cars: list[_Car], walkers: list[dict], seed: int):
    """Per frame: list of (track_id, type, values, manoeuvre|None); values [x, y, vx, vy, psi,
    length, width] of a car, [x, y, vx, vy, None] of a pedestrian."""
    rng = np.random.default_rng(seed + 7919)
    by_frame: dict[int, list] = {}
    for car in cars:
        for frame, values, phase in _car_rows(car, rng, ORIGIN_M):
            by_frame.setdefault(frame, []).append(
                (car.track_id, "car", values, _manoeuvre(car, phase)))
    for walker in walkers:
        for frame, xy, v in zip(walker["frames"], walker["xy"], walker["v"], strict=True):
            values = [*(xy + ORIGIN_M), *v, None]
            by_frame.setdefault(int(frame), []).append(
                (walker["track_id"], "pedestrian/bicycle", values, None))
    return by_frame


def _row(track_id: int, frame: int, stamp_frame: int, agent_type: str, values: list,
         with_shape: bool = True) -> list[str]:
    x, y, vx, vy, psi, *size = values  # a car's values end with its length and width
    row = [str(track_id), str(frame), str(stamp_frame * FRAME_MS), agent_type,
           _fmt(x), _fmt(y), _fmt(vx), _fmt(vy)]
    if with_shape:
        if psi is None:
            row += ["", "", ""]
        else:
            row += [_fmt(psi), *(_fmt(v) for v in size)]
    return row


def write_cases(path: Path, scenario: str, split: str, by_frame: dict,
                labels: list) -> int:
    """v1.2 file: the stream cut into consecutive 4 s cases, frames 1..40, ids renumbered."""
    last = max(by_frame)
    rows = []
    case = 0
    for first in range(1, last - CASE_FRAMES + 2, CASE_FRAMES):
        case += 1
        recording = f"{scenario}_{split}#case{case}"
        ids: dict[int, int] = {}
        per_track: dict[int, list] = {}
        for frame in range(first, first + CASE_FRAMES):
            for track_id, agent_type, values, manoeuvre in by_frame.get(frame, []):
                new_id = ids.setdefault(track_id, len(ids) + 1)
                local = frame - first + 1
                per_track.setdefault(new_id, []).append(
                    [f"{case:.1f}", *_row(new_id, local, local, agent_type, values)])
                if manoeuvre is not None:
                    labels.append((recording, new_id, local, *manoeuvre))
        for new_id in sorted(per_track):
            rows.extend(per_track[new_id])
    _write_csv(path, CASE_COLUMNS, rows)
    return case


def write_recording(folder: Path, index: int, by_frame: dict, labels: list) -> None:
    """v1.0 files: vehicle_tracks_NNN.csv and pedestrian_tracks_NNN.csv, rows sorted by track."""
    vehicles: dict[int, list] = {}
    walkers: dict[int, list] = {}
    name = f"vehicle_tracks_{index:03d}"
    for frame in sorted(by_frame):
        for track_id, agent_type, values, manoeuvre in by_frame[frame]:
            if agent_type == "car":
                vehicles.setdefault(track_id, []).append(
                    _row(track_id, frame, frame, agent_type, values))
                labels.append((name, track_id, frame, *manoeuvre))
            else:
                walkers.setdefault(track_id, []).append(
                    _row(track_id, frame, frame, agent_type, values, with_shape=False))
    _write_csv(folder / f"{name}.csv", VEHICLE_COLUMNS,
               [r for k in sorted(vehicles) for r in vehicles[k]])
    _write_csv(folder / f"pedestrian_tracks_{index:03d}.csv", PEDESTRIAN_COLUMNS,
               [r for k in sorted(walkers) for r in walkers[k]])


def _write_csv(path: Path, header, rows) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w", newline="", encoding="utf-8") as fh:
        writer = csv.writer(fh, lineterminator="\n")
        writer.writerow(header)
        writer.writerows(rows)


LABEL_COLUMNS = ("recording", "track_id", "frame", *LABEL_VALUES)


def _write_labels(path: Path, labels: list) -> None:
    _write_csv(path, LABEL_COLUMNS, labels)


def read_manoeuvre_labels(path: Path) -> dict[tuple[str, int, int], dict[str, str]]:
    """(recording, track_id, frame) -> {label: value} (empty values left out), from a
    generator's sidecar CSV."""
    out = {}
    with open(path, newline="", encoding="utf-8") as fh:
        for row in csv.DictReader(fh):
            key = (row["recording"], int(row["track_id"]), int(row["frame"]))
            out[key] = {name: row[name] for name in LABEL_VALUES if row[name]}
    return out


def generate(out_dir: Path, scenario: str, layout: str = "v1.2", train_s: float = 180.0,
             val_s: float = 60.0, seed: int = 0,
             arrivals_per_arm_min: float | None = None) -> dict:
    """Write a generated scenario in `layout` ('v1.2' or 'v1.0') under out_dir; returns counts."""
    if layout not in ("v1.0", "v1.2"):
        raise ValueError(f"layout must be 'v1.0' or 'v1.2', not {layout!r}")
    kind = geometry_of(scenario)
    out_dir = Path(out_dir)
    summary = {"scenario": scenario, "layout": layout, "geometry": kind}
    streams = {"train": (train_s, seed), "val": (val_s, seed + 1)}
    for index, (split, (seconds, stream_seed)) in enumerate(
            tqdm(streams.items(), desc=f"generate {scenario}", unit="split")):
        cars, walkers = simulate_stream(kind, seconds, stream_seed, arrivals_per_arm_min)
        by_frame = _collect(cars, walkers, stream_seed)
        labels: list = []
        if layout == "v1.2":
            summary[f"{split}_cases"] = write_cases(
                out_dir / split / f"{scenario}_{split}.csv", scenario, split, by_frame, labels)
        else:
            write_recording(out_dir / "recorded_trackfiles" / scenario, index, by_frame, labels)
        _write_labels(out_dir / "generator_labels" / f"{scenario}_{split}.csv", labels)
        summary[f"{split}_cars"] = len(cars)
        summary[f"{split}_pedestrians"] = len(walkers)
    write_map(out_dir / "maps" / f"{scenario}.osm", kind)
    return summary


REAL_SIZE_ARRIVALS_PER_ARM_MIN = 24.0  # about 30 cars in view, as on a real INTERACTION file


def generate_recordings(out_dir: Path, scenario: str, files: int, seconds: float,
                        seed: int = 0, arrivals_per_arm_min: float | None = None) -> dict:
    """Write `files` v1.0 recordings (vehicle_tracks_000.csv, ...) of `seconds` of traffic
    each under out_dir, recording k from seed `seed + k`; returns counts."""
    if files < 1:
        raise ValueError(f"files: {files} recordings; need at least 1")
    kind = geometry_of(scenario)
    out_dir = Path(out_dir)
    cars = 0
    for index in tqdm(range(files), desc=f"generate {scenario}", unit="file"):
        stream, walkers = simulate_stream(kind, seconds, seed + index, arrivals_per_arm_min)
        labels: list = []
        write_recording(out_dir / "recorded_trackfiles" / scenario, index,
                        _collect(stream, walkers, seed + index), labels)
        _write_labels(out_dir / "generator_labels" / f"{scenario}_vehicle_tracks_{index:03d}.csv",
                      labels)
        cars += len(stream)
    write_map(out_dir / "maps" / f"{scenario}.osm", kind)
    return {"scenario": scenario, "layout": "v1.0", "geometry": kind, "files": files,
            "cars": cars}


# ---------------------------------------------------------------- map


def lane_lines(kind: str) -> list[tuple[str, str, np.ndarray]]:
    """(type, subtype, points [K, 2] local metres) of the generated geometry's lane lines."""
    edge = 2 * LANE_OFFSET_M
    lines = []
    if kind == "roundabout":
        angles = np.linspace(0, 2 * math.pi, 97)
        circle = np.stack([np.cos(angles), np.sin(angles)], axis=1)
        lines += [("curbstone", "high", circle * (RING_RADIUS_M - edge / 2 - 1)),
                  ("line_thin", "solid", circle * (RING_RADIUS_M + edge / 2 + 1))]
        inner_r = RING_RADIUS_M + edge / 2 + 1
    else:
        inner_r = INTERSECTION_BOX_M
    for theta in ARM_ANGLES:
        side = _left_of_inbound(theta)
        for offset, kind_tag, sub in ((edge, "line_thin", "solid"), (0.0, "line_thin", "dashed"),
                                      (-edge, "line_thin", "solid")):
            r0 = math.sqrt(max(inner_r**2 - offset**2, 1.0))
            a = _unit(theta) * r0 + side * offset
            b = _unit(theta) * ARM_LENGTH_M + side * offset
            lines.append((kind_tag, sub, _line(a, b, 2)))
    if kind == "intersection":
        for theta in ARM_ANGLES:
            a = _unit(theta) * inner_r
            lines.append(("stop_line", "", np.stack([a, a + _left_of_inbound(theta) * edge])))
    return lines


def write_map(path: Path, kind: str) -> None:
    """A lanelet2-style .osm (nodes in lat/lon, ways with type/subtype tags) of the geometry."""
    projector = OriginProjector()
    node_id = 0
    nodes, ways = [], []
    for way_id, (tag_type, subtype, points) in enumerate(lane_lines(kind), start=100000):
        lat, lon = projector.to_latlon(points + ORIGIN_M)
        refs = []
        for la, lo in zip(lat, lon, strict=True):
            node_id += 1
            nodes.append(f'  <node id="{node_id}" visible="true" version="1" '
                         f'lat="{la:.11f}" lon="{lo:.11f}"/>')
            refs.append(f'    <nd ref="{node_id}"/>')
        tags = [f'    <tag k="type" v="{tag_type}"/>']
        if subtype:
            tags.append(f'    <tag k="subtype" v="{subtype}"/>')
        ways.append("\n".join([f'  <way id="{way_id}" visible="true" version="1">', *refs,
                               *tags, "  </way>"]))
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("\n".join(['<?xml version="1.0" encoding="UTF-8"?>',
                               '<osm version="0.6" generator="tomstudy">', *nodes, *ways,
                               "</osm>"]) + "\n")
