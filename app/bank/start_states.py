"""Where a trial's prediction starts: the robot's own state and states the models learned from.

Start states (K = the config's `start_states`, n = `steps_to_predict`, r = the reachable
radius `max_step_m`). The first is the robot's own segment-end state (`own`). The other
K - 1 are robot positions that occur in the data the models learned from: every step of
every trajectory outside both checkpoints' test splits (their train and validation
trajectories, so no held-out future), kept if
- the point is at least r from every start already chosen (the robot's own included);
- the world keeps it as one of its two start kinds within reach n r of the robot
  (`World.data_start_candidates`: Highway `same_lane` / `adjacent_lane`, Obstacle
  `near` / `mid`; the rules are in highway.py and obstacle.py).
The two kinds take turns (the world's first kind first), each turn a uniform draw with
the bank's rng among that kind's points, so each gets half of K - 1 (the first kind the
odd one); a kind with no point left passes its turn to the other, and a segment where
neither has one is skipped (meta.json counts it). Every start keeps the segment end's
heading and speed: the question is what this robot, moving as the segment shows, does
from there; a data state's own heading and speed belong to another trajectory's
behaviour, would be drawn in the browser and would make the world's policy answer a
situation the segment does not show. Attention checks get their start states by the same
rule (so their geometry cannot give them away); they differ only in their segment. The
worlds apply their rules to the scene the trajectories were simulated in.
"""

import numpy as np

from app.data.trajectory import HUMAN, ROBOT, Covered, TrajectorySet
from app.study.trials import HEADING_DECIMALS, POS_DECIMALS, StartState
from app.worlds.registry import World


def covered_states(trajs: TrajectorySet, index: np.ndarray) -> Covered:
    """The robot's position and heading at every valid step of trajectories `index`."""
    if not len(index):
        raise ValueError(f"{trajs.world}: every trajectory is in a test split; no data "
                         "to draw start states from")
    def robot_steps(array: np.ndarray) -> np.ndarray:
        return np.concatenate([array[i, : trajs.lengths[i] + 1, ROBOT]
                               for i in index]).astype(np.float64)

    return Covered(robot_steps(trajs.positions), robot_steps(trajs.headings))


class NoStartStates(ValueError):
    """Too few points near the robot for the study's start states."""


def start_states(world: World, trajs: TrajectorySet, covered: Covered,
                 segment_end: tuple[int, int], segment: np.ndarray, count: int,
                 steps_to_predict: int, max_step: float, rng: np.random.Generator
                 ) -> list[StartState]:
    """The robot's segment-end state plus `count` - 1 others by the module docstring's rule
    (`segment_end`: trajectory and step the segment ends at); the human stays at its
    segment-end position."""
    src, end = segment_end
    robot, human = segment[-1, ROBOT], segment[-1, HUMAN]
    pools = world.data_start_candidates(trajs.scene_of(src), segment, covered,
                                        steps_to_predict * max_step)
    points, kinds = take_turns(robot, pools, count - 1, max_step, rng)
    heading = trajs.headings[src, end]
    speed = float(trajs.speeds[src, end, ROBOT])
    return [StartState(robot=np.round(p, POS_DECIMALS).tolist(),
                       human=np.round(human, POS_DECIMALS).tolist(),
                       robot_heading=round(float(heading[ROBOT]), HEADING_DECIMALS),
                       human_heading=round(float(heading[HUMAN]), HEADING_DECIMALS),
                       robot_speed=round(speed, 4), start_kind=kind)
            for p, kind in zip([robot, *points], ["own", *kinds], strict=True)]


def take_turns(robot: np.ndarray, pools: dict[str, np.ndarray], count: int, min_gap: float,
               rng: np.random.Generator) -> tuple[list[np.ndarray], list[str]]:
    """`count` points, the kinds taking turns; each a uniform draw among its kind's points at
    least `min_gap` from every start chosen so far (a kind with none passes its turn)."""
    chosen, kinds = [np.asarray(robot, dtype=np.float64)], []
    order = list(pools)
    for turn in range(count):
        for kind in order[turn % len(order):] + order[: turn % len(order)]:
            pts = pools[kind]
            gaps = np.min([np.linalg.norm(pts - c, axis=1) for c in chosen], axis=0)
            free = np.flatnonzero(gaps >= min_gap)
            if len(free):
                chosen.append(pts[int(rng.choice(free))])
                kinds.append(kind)
                break
        else:
            raise NoStartStates(f"only {turn} of {count} data-covered start states "
                                "near the robot")
    return chosen[1:], kinds
