"""`tomstudy check-display`: can a person give the robot's true moves as clicks, and do they
point one way per behaviour? Figures per world, on the built data and the trial bank.

- short_steps: share of the robot's true steps (all 2000 trajectories) shorter than the
  smallest click the study accepts (the bank's `min_step_m`): a person cannot answer those.
- against_travel: share of the robot's moving steps whose direction is more than 90 degrees
  from the direction of travel, measured two ways: the data's mean step direction (what
  "forward" means on a road) and each trajectory's own start-to-end displacement.
- same_label_spread: mean 1 - cos between the world policy's first moves at the bank's start
  states, over pairs of main trials that share a robot label (pairs within one trial are
  left out). 0 = one direction per behaviour; 1 = what random directions give. Measured on
  the screen (`same_label_spread`) and in each start's own heading frame
  (`same_label_spread_heading`: the move turned by minus the start's heading), where a
  recorded world's behaviour (a left turn, say) is one direction whichever way the road runs.
- click resolution: the prediction view's scale (app/prediction_view.py), the median true
  step on screen at that scale, and the degrees one pixel of click error turns a move of
  that length: the angular resolution of the measurement.
- start states (main trials, per start kind): the angle between the robot heading drawn at a
  start and the direction of its first reference move (`policy_actions`), its median and the
  share above 20 degrees; the share of reference steps below the smallest click and below
  5 cm; and the data states the start rule dropped because their next moves are too short
  to click (the bank meta's `start_candidates_dropped`, app/bank/start_states.py).
- robot outline: the robot's half-length and half-width (its median over the main trials, at
  each one's recorded size where the bank has sizes) in m and in px as the prediction view
  draws it (`outline_scale` of its size), the reach radius in m and px, drawn half-length /
  reach radius, median true step / drawn half-length, and the share of the reference first
  moves (the main trials' policy_actions[:, 0] from every start) whose end lies inside the
  robot's outline at its start (the rectangle turned to the start's robot_heading; a disc's
  circle), at its real size and as drawn. `passes`: the rule of app/prediction_view.py (the
  drawn half-length at most OUTLINE_STEP_SHARE median steps and OUTLINE_REACH_SHARE reach
  radii); a world that fails it is flagged in the table.
"""

import json
from pathlib import Path

import numpy as np

from app.bank.bundle import BANK_META
from app.core.files import read_bytes, write_json
from app.data.trajectory import ROBOT, TrajectorySet, wrap_angle
from app.layout import Layout
from app.prediction_view import (
    OUTLINE_REACH_SHARE,
    OUTLINE_STEP_SHARE,
    SCORED_KIND,
    main_robot_sizes_m,
    prediction_view,
)

MOVING_M = 1e-3  # a step shorter than this has no direction


def robot_steps(trajs: TrajectorySet) -> tuple[np.ndarray, np.ndarray]:
    """Every valid robot step [S, 2] (m) and its trajectory's net displacement [S, 2]."""
    steps, net = [], []
    for i in range(len(trajs)):
        track = trajs.positions[i, : trajs.lengths[i] + 1, ROBOT].astype(np.float64)
        steps.append(np.diff(track, axis=0))
        net.append(np.broadcast_to(track[-1] - track[0], steps[-1].shape))
    return np.concatenate(steps), np.concatenate(net)


def against_share(steps: np.ndarray, direction: np.ndarray) -> float:
    """Share of moving steps whose dot product with `direction` ([2] or [S, 2]) is negative."""
    moving = np.linalg.norm(steps, axis=1) > MOVING_M
    dots = (steps * direction).sum(-1) if direction.ndim > 1 else steps @ direction
    return float((dots[moving] < 0).mean())


def first_moves(trial: dict, heading_frame: bool) -> np.ndarray:
    """The policy's first move from each start state [K, 2]; in the heading frame, each turned
    by minus its start's robot heading."""
    moves = np.asarray(trial["policy_actions"], dtype=np.float64)[:, 0]
    if not heading_frame:
        return moves
    angle = -np.array([s["robot_heading"] for s in trial["start_states"]], dtype=np.float64)
    cos, sin = np.cos(angle), np.sin(angle)
    return np.stack([cos * moves[:, 0] - sin * moves[:, 1],
                     sin * moves[:, 0] + cos * moves[:, 1]], axis=1)


def same_label_spread(world_bank: dict, heading_frame: bool = False) -> dict:
    """Mean pairwise 1-cos of policy first moves between main trials sharing a robot label."""
    by_label: dict[int, list[tuple[int, np.ndarray]]] = {}
    for index, trial in enumerate(t for t in world_bank["trials"] if t["kind"] == "main"):
        for move in first_moves(trial, heading_frame):
            by_label.setdefault(int(trial["robot_label"]), []).append((index, move))
    per_label, pairs_total, sum_total = {}, 0, 0.0
    for label, items in sorted(by_label.items()):
        trial_of = np.array([i for i, _ in items])
        moves = np.array([m for _, m in items])
        unit = moves / (np.linalg.norm(moves, axis=1, keepdims=True) + 1e-12)
        distance = 1 - unit @ unit.T
        other_trial = trial_of[:, None] != trial_of[None, :]
        upper = np.triu(other_trial, 1)
        if upper.any():
            per_label[world_bank["label_names"][label]] = round(float(distance[upper].mean()), 4)
            pairs_total += int(upper.sum())
            sum_total += float(distance[upper].sum())
    return {"mean": round(sum_total / max(pairs_total, 1), 4), "per_label": per_label}


def world_figures(trajs: TrajectorySet, world_bank: dict) -> dict:
    """The three figures of one world."""
    steps, net = robot_steps(trajs)
    lengths = np.linalg.norm(steps, axis=1)
    mean_direction = steps.mean(axis=0)
    return {
        "trajectories": len(trajs),
        "robot_steps": len(steps),
        "min_click_m": world_bank["min_step_m"],
        "short_steps": round(float((lengths < world_bank["min_step_m"]).mean()), 4),
        "against_mean_direction": round(against_share(steps, mean_direction), 4),
        "against_own_displacement": round(against_share(steps, net), 4),
        "mean_direction": np.round(mean_direction / (np.linalg.norm(mean_direction) + 1e-12),
                                   3).tolist(),
        "same_label_spread": same_label_spread(world_bank),
        "same_label_spread_heading": same_label_spread(world_bank, heading_frame=True),
        "click_resolution": click_resolution(world_bank),
        "outline": robot_outline(world_bank),
    }


def click_resolution(world_bank: dict) -> dict:
    """The prediction view's px per metre, the median true step in m and px, degrees per px."""
    view = prediction_view(world_bank)
    return {"px_per_m": view.px_per_m, "median_step_m": view.median_step_m,
            "median_step_px": round(view.median_step_px, 1),
            "reach_px": round(world_bank["max_step_m"] * view.px_per_m, 1),
            "deg_per_px": round(view.resolution_deg, 3)}


def first_move_ends(world_bank: dict) -> tuple[np.ndarray, np.ndarray]:
    """Each main trial's reference first moves, ended in the robot's heading frame at its start
    [S, 2] m (x along the heading), and the robot's (length, width) [S, 2] m at each start."""
    ends, sizes = [], []
    for trial, size in zip((t for t in world_bank["trials"] if t["kind"] == SCORED_KIND),
                           main_robot_sizes_m(world_bank), strict=True):
        ends.append(first_moves(trial, heading_frame=True) * float(world_bank["dt_s"]))
        sizes.append(np.broadcast_to(size, ends[-1].shape))
    return np.concatenate(ends), np.concatenate(sizes)


def inside_share(ends: np.ndarray, sizes: np.ndarray, disc: bool, scale: float) -> float:
    """Share of move ends [S, 2] (heading frame) inside the robot's outline at `scale` of its
    size: the rectangle of its (length, width) [S, 2], or for a disc the circle of its length."""
    half = sizes * scale / 2
    if disc:
        inside = np.linalg.norm(ends, axis=1) <= half[:, 0]
    else:
        inside = (np.abs(ends[:, 0]) <= half[:, 0]) & (np.abs(ends[:, 1]) <= half[:, 1])
    return float(inside.mean())


def robot_outline(world_bank: dict) -> dict:
    """The robot's outline at its start against its reach and its first moves (docstring)."""
    view = prediction_view(world_bank)
    disc = world_bank["scene"]["agents"][0]["kind"] == "disc"
    half = np.median(main_robot_sizes_m(world_bank), axis=0) / 2
    drawn_m = half * view.outline_scale
    reach = world_bank["max_step_m"]
    ends, sizes = first_move_ends(world_bank)
    passes = bool(drawn_m[0] <= OUTLINE_STEP_SHARE * view.median_step_m + 1e-9
                  and drawn_m[0] <= OUTLINE_REACH_SHARE * reach)
    return {"outline_scale": view.outline_scale,
            "half_length_m": round(float(half[0]), 3), "half_width_m": round(float(half[1]), 3),
            "half_length_px": round(float(drawn_m[0] * view.px_per_m), 1),
            "half_width_px": round(float(drawn_m[1] * view.px_per_m), 1),
            "reach_m": reach, "reach_px": round(reach * view.px_per_m, 1),
            "half_length_over_reach": round(float(drawn_m[0] / reach), 3),
            "step_over_half_length": round(float(view.median_step_m / drawn_m[0]), 3),
            "first_moves_inside": round(inside_share(ends, sizes, disc, 1.0), 4),
            "first_moves_inside_drawn": round(
                inside_share(ends, sizes, disc, view.outline_scale), 4),
            "passes": passes}


def check_display(layout: Layout, study_id: str, bank_path: Path) -> dict:
    """Figures for every world of a study's bank (the one it is served from) on the data dir's
    trajectories; also written to the data dir's trials/<study>/ folder."""
    bank = json.loads(read_bytes(bank_path))
    result = {}
    for name, world_bank in sorted(bank["worlds"].items()):
        if not layout.trajectories(name).is_file():
            raise FileNotFoundError(f"{layout.trajectories(name)}: no trajectories; run "
                                    f"`tomstudy simulate {name}` (the figures need the data)")
        trajs = TrajectorySet.load(layout.trajectories(name))
        result[name] = world_figures(trajs, world_bank)
        result[name]["start_states"] = start_state_figures(world_bank, meta_of(bank_path, name))
    write_json(layout.display_check(study_id), result)
    return result


def meta_of(bank_path: Path, world: str) -> dict | None:
    """The world's entry of the bank's meta beside `bank_path` (None without one)."""
    path = Path(bank_path).parent / BANK_META
    if not path.is_file():
        return None
    return json.loads(read_bytes(path)).get("worlds", {}).get(world)


def format_table(result: dict) -> str:
    """Markdown tables, one row per world (and start kind): the display figures, click
    resolution, start states and the robot outline."""
    lines = ["| world | min click (m) | true steps shorter | against mean direction "
             "| against own displacement | same-label policy 1-cos (screen / heading frame) |",
             "|---|---|---|---|---|---|"]
    for name, f in result.items():
        lines.append(f"| {name} | {f['min_click_m']:.3f} | {f['short_steps']:.1%} "
                     f"| {f['against_mean_direction']:.1%} | {f['against_own_displacement']:.1%} "
                     f"| {f['same_label_spread']['mean']:.3f} / "
                     f"{f['same_label_spread_heading']['mean']:.3f} |")
    lines += ["", "| world | px per m | median true step (m) | median step (px) "
                  "| reach radius (px) | deg per px of click error |",
              "|---|---|---|---|---|---|"]
    for name, f in result.items():
        r = f["click_resolution"]
        lines.append(f"| {name} | {r['px_per_m']:.1f} | {r['median_step_m']:.3f} "
                     f"| {r['median_step_px']:.1f} | {r['reach_px']:.1f} | {r['deg_per_px']:.3f} |")
    lines += ["", *start_state_table(result)]
    lines += ["", outline_table(result)]
    return "\n".join(lines)


def outline_table(result: dict) -> str:
    """The robot-outline figures, one row per world; a world failing the rule is flagged."""
    lines = ["| world | drawn at | half-length m (px) | half-width m (px) | reach m (px) "
             "| half-length / reach | median step / half-length "
             "| first moves ending inside: real size / drawn | rule |",
             "|---|---|---|---|---|---|---|---|---|"]
    for name, f in result.items():
        o = f["outline"]
        lines.append(f"| {name} | {o['outline_scale']:.3f} "
                     f"| {o['half_length_m']:.2f} ({o['half_length_px']:.0f}) "
                     f"| {o['half_width_m']:.2f} ({o['half_width_px']:.0f}) "
                     f"| {o['reach_m']:.2f} ({o['reach_px']:.0f}) "
                     f"| {o['half_length_over_reach']:.2f} | {o['step_over_half_length']:.2f} "
                     f"| {o['first_moves_inside']:.1%} / {o['first_moves_inside_drawn']:.1%} "
                     f"| {'ok' if o['passes'] else 'FAILS'} |")
    return "\n".join(lines)


# ---------------------------------------------------------------- start states

STOPPED_STEP_M = 0.05  # a reference step shorter than this is a car standing still
HEADING_ERROR_DEG = 20.0  # a drawn heading this far off the first true move looks wrong


def start_state_figures(world_bank: dict, world_meta: dict | None) -> dict:
    """Per start kind of the main trials: how far the drawn robot heading is from the
    direction of the start's first reference move (median, share > HEADING_ERROR_DEG), the
    share of reference steps below the smallest click and below STOPPED_STEP_M; and how many
    data states the start rule dropped for short moves (bank meta; None before it counted)."""
    by_kind: dict[str, dict[str, list]] = {}
    for trial in (t for t in world_bank["trials"] if t["kind"] == "main"):
        steps = np.asarray(trial["policy_actions"], dtype=np.float64) * world_bank["dt_s"]
        for state, moves in zip(trial["start_states"], steps, strict=True):
            kind = by_kind.setdefault(state["start_kind"], {"error": [], "length": []})
            kind["length"].extend(np.linalg.norm(moves, axis=1))
            if np.linalg.norm(moves[0]) > MOVING_M:
                kind["error"].append(heading_error_deg(state["robot_heading"], moves[0]))
    dropped = (world_meta or {}).get("start_candidates_dropped")
    return {"kinds": {kind: kind_figures(v["error"], v["length"], world_bank["min_step_m"])
                      for kind, v in by_kind.items()},
            "candidates_dropped": dropped}


def heading_error_deg(heading: float, move: np.ndarray) -> float:
    """Angle [deg] between a heading [rad] and a move's direction."""
    return float(np.degrees(np.abs(wrap_angle(np.arctan2(move[1], move[0]) - heading))))


def kind_figures(errors: list[float], lengths: list[float], min_click_m: float) -> dict:
    """One start kind's heading error and short reference steps."""
    lengths = np.asarray(lengths)
    errors = np.asarray(errors)
    return {"starts_moving": len(errors),
            "heading_error_median_deg": round(float(np.median(errors)), 2) if len(errors)
            else None,
            "heading_error_over_20": round(float((errors > HEADING_ERROR_DEG).mean()), 4)
            if len(errors) else None,
            "steps": len(lengths),
            "steps_below_min_click": round(float((lengths < min_click_m).mean()), 4),
            "steps_below_5cm": round(float((lengths < STOPPED_STEP_M).mean()), 4)}


def start_state_table(result: dict) -> list[str]:
    """Markdown rows of the start-state figures: one per world and start kind, then one per
    world of what the start rule dropped."""
    lines = ["| world | start kind | heading error median (deg) | heading error > 20 deg "
             "| reference steps < min click | < 5 cm |", "|---|---|---|---|---|---|"]
    for name, f in result.items():
        for kind, k in f["start_states"]["kinds"].items():
            median, over = k["heading_error_median_deg"], k["heading_error_over_20"]
            lines.append(f"| {name} | {kind} | {'-' if median is None else f'{median:.1f}'} "
                         f"| {'-' if over is None else f'{over:.1%}'} "
                         f"| {k['steps_below_min_click']:.1%} | {k['steps_below_5cm']:.1%} |")
    lines += ["", "| world | data states without n moves after | data states with a move "
                  "< min click | segment ends with a move < min click |", "|---|---|---|---|"]
    for name, f in result.items():
        dropped = f["start_states"]["candidates_dropped"]
        counts = ["not applied"] * 3 if dropped is None else [
            dropped.get(key, "-") for key in ("data_states_without_n_moves",
                                              "data_states_short_moves",
                                              "segment_ends_short_moves")]
        lines.append(f"| {name} | " + " | ".join(str(c) for c in counts) + " |")
    return lines
