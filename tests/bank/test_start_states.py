"""Start states on a small hand-made recorded TrajectorySet: a recorded world's relocated starts
are the recorded states they were drawn from (heading, speed, next moves), states whose next
moves cannot be clicked are never starts, and a simulated world keeps the segment end's
heading and speed everywhere."""

import numpy as np
import pytest

from app.bank.start_states import (
    clickable_ends,
    clickable_states,
    covered_states,
    start_states,
)
from app.data.scene import AgentShape, Bounds, Scene
from app.data.trajectory import ROBOT, TrajectorySet
from app.recordings.config import RecordedConfig
from app.worlds.recorded import RecordedWorld
from app.worlds.registry import build_world

DT, N, MAX_STEP, MIN_STEP = 0.4, 3, 3.0, 0.5
STEPS = 20
HUMAN_AT = (30.0, 30.0)


def car_track(start: tuple[float, float], heading: float, step_lengths: list[float]) -> np.ndarray:
    """Positions [len+1, 2] of a car driving `step_lengths` along `heading`."""
    direction = np.array([np.cos(heading), np.sin(heading)])
    return np.asarray(start) + np.concatenate([[0.0], np.cumsum(step_lengths)])[:, None] * direction


TRACKS = {
    # 0: the robot of the segment, held out: 2 m per step along +x, at (0, 0) at step 5
    "robot": (car_track((-10.0, 0.0), 0.0, [2.0] * STEPS), 0.0),
    # 1: a car heading 0.2 rad, speeding up, so each state's next moves are its own
    "driver": (car_track((-6.0, -1.0), 0.2, [1.0 + 0.05 * k for k in range(STEPS)]), 0.2),
    # 2: a car that crawls 0.1 m (below the smallest click) at its step 8
    "crawler": (car_track((-4.0, 2.0), 0.0, [1.5] * 8 + [0.1] + [1.5] * (STEPS - 9)), 0.0),
}


def recorded_set() -> TrajectorySet:
    """The three cars as robots (the human standing at HUMAN_AT), speeds from their moves."""
    positions = np.zeros((len(TRACKS), STEPS + 1, 2, 2))
    headings = np.zeros((len(TRACKS), STEPS + 1, 2))
    speeds = np.zeros((len(TRACKS), STEPS + 1, 2))
    for i, (track, heading) in enumerate(TRACKS.values()):
        positions[i, :, ROBOT] = track
        positions[i, :, 1] = HUMAN_AT
        headings[i, :, ROBOT] = heading
        speeds[i, 1:, ROBOT] = np.linalg.norm(np.diff(track, axis=0), axis=1) / DT
    car = AgentShape(name="robot", kind="car", length_m=4.6, width_m=1.9, color="#000000")
    scene = Scene(world="roundabout", dt_s=DT, frame="f", agents=[car, car],
                  bounds=Bounds(x_min_m=-50, x_max_m=50, y_min_m=-50, y_max_m=50))
    return TrajectorySet(world="roundabout", dt_s=DT, positions=positions.astype(np.float32),
                         headings=headings.astype(np.float32), speeds=speeds.astype(np.float32),
                         lengths=np.full(len(TRACKS), STEPS), labels={}, label_names={},
                         scene=scene)


def recorded_world() -> RecordedWorld:
    return RecordedWorld("roundabout", RecordedConfig.model_validate({
        "kind": "recorded", "source": {"format": "interaction", "path": "INTERACTION",
                                       "scenario": "DR_USA_Roundabout_FT"}}))


def starts_of(world, trajs: TrajectorySet, covered, seed: int):
    segment = trajs.positions[0, :6].astype(np.float64)  # ends at step 5, the robot at (0, 0)
    return start_states(world, trajs, covered, (0, 5), segment, 3, N, MAX_STEP,
                        np.random.default_rng(seed))


def test_only_states_with_n_clickable_recorded_moves_are_candidates():
    trajs = recorded_set()
    covered, dropped = clickable_states(covered_states(trajs, np.array([1, 2]), N), MIN_STEP, DT)
    # the last N states of each track have fewer than N moves after them; the crawler's states
    # 6, 7 and 8 have its 0.1 m move among their next N
    assert dropped == {"data_states_without_n_moves": 2 * N, "data_states_short_moves": 3}
    crawler = TRACKS["crawler"][0]
    kept = {tuple(p) for p in np.round(covered.positions, 4)}
    for step in (6, 7, 8):
        assert tuple(np.round(crawler[step], 4)) not in kept
    assert tuple(np.round(crawler[5], 4)) in kept and tuple(np.round(crawler[9], 4)) in kept


def test_segment_ends_before_a_short_recorded_move_are_dropped():
    trajs = recorded_set()
    ends = np.arange(3, STEPS - N + 1)
    kept = clickable_ends(trajs, 2, ends, N, MIN_STEP)
    assert sorted(set(ends) - set(kept)) == [6, 7, 8]


@pytest.mark.parametrize("seed", range(8))
def test_a_relocated_recorded_start_is_the_recorded_state_and_its_future(seed):
    trajs = recorded_set()
    covered, _ = clickable_states(covered_states(trajs, np.array([1, 2]), N), MIN_STEP, DT)
    starts = starts_of(recorded_world(), trajs, covered, seed)
    own, *others = starts.states
    assert own.start_kind == "own" and own.robot == [0.0, 0.0]
    assert np.allclose(starts.recorded_moves[0], [[5.0, 0.0]] * N)  # what the robot did next
    assert [s.start_kind for s in others] == ["near", "far"]
    for state, moves in zip(others, starts.recorded_moves[1:], strict=True):
        car, step = recorded_state_at(state.robot)
        track, heading = TRACKS[car]
        assert state.robot_heading == pytest.approx(heading, abs=1e-3)
        assert state.robot_speed == pytest.approx(trajs.speeds[list(TRACKS).index(car), step,
                                                              ROBOT], abs=1e-4)
        assert np.allclose(moves, np.diff(track[step: step + N + 1], axis=0) / DT, atol=1e-4)
        lengths = np.linalg.norm(np.diff(track[step: step + N + 1], axis=0), axis=1)
        assert (lengths >= MIN_STEP).all()  # never the crawler's states before its short move


def recorded_state_at(point: list[float]) -> tuple[str, int]:
    """The car and step whose recorded position is `point` (rounded as a start is)."""
    for car, (track, _) in TRACKS.items():
        gaps = np.linalg.norm(track - np.asarray(point), axis=1)
        if gaps.min() < 1e-3:
            return car, int(gaps.argmin())
    raise AssertionError(f"{point} is no recorded state")


def test_a_simulated_world_keeps_the_segment_ends_heading_and_speed_at_every_start():
    trajs = recorded_set()
    covered = covered_states(trajs, np.array([1, 2]), N)
    starts = starts_of(build_world("obstacle"), trajs, covered, 0)
    assert starts.recorded_moves is None  # the world's policy answers
    assert len(starts.states) == 3
    assert {(s.robot_heading, s.robot_speed) for s in starts.states} == {
        (0.0, round(float(trajs.speeds[0, 5, ROBOT]), 4))}
