"""Where a trial's prediction starts: the robot's own state and states the models learned from.

Start states (K = the config's `start_states`, n = `steps_to_predict`, r = the reachable
radius `max_step_m`). The first is the robot's own segment-end state (`own`). The other
K - 1 are robot states that occur in the data the models learned from: every step of
every trajectory outside both checkpoints' test splits (their train and validation
trajectories, so no held-out future), kept if
- the point is at least r from every start already chosen (the robot's own included);
- the world keeps it as one of its two start kinds within reach n r of the robot
  (`World.data_start_candidates`: Highway `same_lane` / `adjacent_lane`, Obstacle
  `near` / `mid`, recorded worlds `near` / `far`; the rules are in highway.py, obstacle.py
  and recorded.py).
The two kinds take turns (the world's first kind first), each turn a uniform draw with
the bank's rng among that kind's points, so each gets half of K - 1 (the first kind the
odd one); a kind with no point left passes its turn to the other, and a segment where
neither has one is skipped (meta.json counts it).

What a start carries depends on the world (`World.starts_as_recorded`):
- simulated worlds (Highway, Obstacle): every start keeps the segment end's heading and
  speed, and its answer is the world's policy run from there. The question is what this
  robot, moving as the segment shows, does from there; the policy can answer any state, and
  a data state's own heading and speed belong to another rollout's behaviour, which the
  segment does not show.
- recorded worlds: a relocated start is the recorded state it was drawn from: that car's
  own heading and speed there, and its answer (the bank's `policy_actions`) is what that car
  did over its next n steps; the own start's answer is what the robot did next. Recordings
  cannot be run from a made-up state: the segment end's heading put on another car's
  position is a car pointing up to the heading tolerance off its lane, and the nearest other
  recorded car's future is not the future of the car drawn. So a data state is a candidate
  only if it has n recorded moves after it, each at least the smallest click (the bank's
  `min_step_m`): a shorter true move cannot be given as a click (`clickable_states`); the
  same holds for the robot's own segment end (build.py, `clickable_ends`), whose segment
  the world already requires to be under way at `min_moving_speed_mps`, a bound the
  smallest click need not meet. meta.json's `start_candidates_dropped` counts both.
Attention checks get their start states by the same rule (so their geometry cannot give
them away); they differ only in their segment. The worlds apply their rules to the scene
the trajectories were simulated in or recorded on.
"""

from dataclasses import dataclass, replace

import numpy as np

from app.data.trajectory import HUMAN, ROBOT, Covered, TrajectorySet
from app.study.trials import HEADING_DECIMALS, POS_DECIMALS, StartState
from app.worlds.registry import World


def next_moves(trajs: TrajectorySet, i: int, n_steps: int) -> np.ndarray:
    """What trajectory i's robot did over the n steps after each of its valid states
    [L+1, n, 2] (m/s; NaN past the trajectory's end)."""
    length = int(trajs.lengths[i])
    track = trajs.positions[i, : length + 1, ROBOT].astype(np.float64)
    moves = np.concatenate([np.diff(track, axis=0) / trajs.dt_s, np.full((n_steps, 2), np.nan)])
    return np.lib.stride_tricks.sliding_window_view(moves, n_steps, axis=0).transpose(0, 2, 1)


def covered_states(trajs: TrajectorySet, index: np.ndarray, n_steps: int) -> Covered:
    """The robot's position, heading, speed and next `n_steps` moves at every valid step of
    trajectories `index`."""
    if not len(index):
        raise ValueError(f"{trajs.world}: every trajectory is in a test split; no data "
                         "to draw start states from")
    def robot_steps(array: np.ndarray) -> np.ndarray:
        return np.concatenate([array[i, : trajs.lengths[i] + 1, ROBOT]
                               for i in index]).astype(np.float64)

    return Covered(robot_steps(trajs.positions), robot_steps(trajs.headings),
                   robot_steps(trajs.speeds),
                   np.concatenate([next_moves(trajs, int(i), n_steps) for i in index]))


def clickable_states(covered: Covered, min_step: float, dt_s: float) -> tuple[Covered, dict]:
    """The covered states with n recorded moves after them, each at least `min_step` (m) long,
    and how many were dropped: for fewer than n moves left, for a move shorter than that."""
    lengths = np.linalg.norm(covered.next_moves, axis=2) * dt_s  # NaN where no move was left
    complete = ~np.isnan(lengths).any(axis=1)
    keep = complete & (np.where(complete[:, None], lengths, 0.0) >= min_step).all(axis=1)
    kept = replace(covered, positions=covered.positions[keep], headings=covered.headings[keep],
                   speeds=covered.speeds[keep], next_moves=covered.next_moves[keep])
    return kept, {"data_states_without_n_moves": int((~complete).sum()),
                  "data_states_short_moves": int((complete & ~keep).sum())}


def clickable_ends(trajs: TrajectorySet, i: int, ends: np.ndarray, n_steps: int,
                   min_step: float) -> np.ndarray:
    """The segment ends among `ends` of trajectory i after which each of the robot's n
    recorded moves is at least `min_step` (m) long."""
    lengths = np.linalg.norm(next_moves(trajs, i, n_steps)[ends], axis=2) * trajs.dt_s
    return ends[(np.nan_to_num(lengths, nan=0.0) >= min_step).all(axis=1)]


class NoStartStates(ValueError):
    """Too few points near the robot for the study's start states."""


@dataclass(frozen=True)
class Starts:
    """A trial's start states and, where the world's starts are recorded states, what the
    robot did next from each [K, n, 2] (m/s; None: the world's policy answers)."""

    states: list[StartState]
    recorded_moves: np.ndarray | None


def start_states(world: World, trajs: TrajectorySet, covered: Covered,
                 segment_end: tuple[int, int], segment: np.ndarray, count: int,
                 steps_to_predict: int, max_step: float, rng: np.random.Generator) -> Starts:
    """The robot's segment-end state plus `count` - 1 others by the module docstring's rule
    (`segment_end`: trajectory and step the segment ends at); the human stays at its
    segment-end position. A world whose starts are recorded states needs `covered` from
    `clickable_states`."""
    src, end = segment_end
    robot, human = segment[-1, ROBOT], segment[-1, HUMAN]
    pools = world.data_start_candidates(trajs.scene_of(src), segment, covered,
                                        steps_to_predict * max_step)
    picks, kinds = take_turns(robot, covered.positions, pools, count - 1, max_step, rng)
    heading = trajs.headings[src, end]
    own = (robot, float(heading[ROBOT]), float(trajs.speeds[src, end, ROBOT]))
    if world.starts_as_recorded:
        robots = [own, *((covered.positions[i], covered.headings[i], covered.speeds[i])
                         for i in picks)]
        moves = np.concatenate([next_moves(trajs, src, steps_to_predict)[end][None],
                                covered.next_moves[picks]])
        if np.isnan(moves).any():
            raise ValueError(f"{world.name}: a start without {steps_to_predict} recorded moves "
                             "after it; draw starts from clickable_states(covered)")
    else:
        robots = [own, *((covered.positions[i], own[1], own[2]) for i in picks)]
        moves = None
    states = [StartState(robot=np.round(p, POS_DECIMALS).tolist(),
                         human=np.round(human, POS_DECIMALS).tolist(),
                         robot_heading=round(float(h), HEADING_DECIMALS),
                         human_heading=round(float(heading[HUMAN]), HEADING_DECIMALS),
                         robot_speed=round(float(v), 4), start_kind=kind)
              for (p, h, v), kind in zip(robots, ["own", *kinds], strict=True)]
    return Starts(states, moves)


def take_turns(robot: np.ndarray, positions: np.ndarray, pools: dict[str, np.ndarray],
               count: int, min_gap: float, rng: np.random.Generator
               ) -> tuple[list[int], list[str]]:
    """`count` states (indices into `positions`), the kinds taking turns; each a uniform draw
    among its kind's states at least `min_gap` from every start chosen so far (a kind with
    none passes its turn)."""
    chosen, picks, kinds = [np.asarray(robot, dtype=np.float64)], [], []
    order = list(pools)
    for turn in range(count):
        for kind in order[turn % len(order):] + order[: turn % len(order)]:
            pts = positions[pools[kind]]
            gaps = np.min([np.linalg.norm(pts - c, axis=1) for c in chosen], axis=0)
            free = np.flatnonzero(gaps >= min_gap)
            if len(free):
                pick = int(pools[kind][int(rng.choice(free))])
                chosen.append(positions[pick])
                picks.append(pick)
                kinds.append(kind)
                break
        else:
            raise NoStartStates(f"only {turn} of {count} data-covered start states "
                                "near the robot")
    return picks, kinds
