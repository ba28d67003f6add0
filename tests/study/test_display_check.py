"""The display check's three figures, against hand-made tracks and bank entries."""

import numpy as np
import pytest

from app.bank.display_check import (
    against_share,
    same_label_spread,
    start_state_figures,
    world_figures,
)
from app.data.scene import AgentShape, Bounds, Scene
from app.data.trajectory import TrajectorySet

SCENE = Scene(world="toy", dt_s=0.5, frame="toy", bounds=Bounds(x_min_m=-10, x_max_m=10,
              y_min_m=-10, y_max_m=10),
              agents=[AgentShape(name="robot", kind="disc", length_m=1, width_m=1, color="#000"),
                      AgentShape(name="human", kind="disc", length_m=1, width_m=1, color="#000")])


def _trajectories(robot_tracks: list[list[tuple[float, float]]]) -> TrajectorySet:
    steps = len(robot_tracks[0])
    positions = np.zeros((len(robot_tracks), steps, 2, 2), dtype=np.float32)
    positions[:, :, 0] = np.array(robot_tracks, dtype=np.float32)
    zeros = np.zeros((len(robot_tracks), steps, 2), dtype=np.float32)
    return TrajectorySet(world="toy", dt_s=0.5, positions=positions, headings=zeros,
                         speeds=zeros, lengths=np.full(len(robot_tracks), steps - 1),
                         labels={}, label_names={}, scene=SCENE)


def _trial(label: int, first_moves: list[tuple[float, float]],
           headings: list[float] | None = None) -> dict:
    actions = [[list(m), list(m)] for m in first_moves]
    starts = [{"robot_heading": h} for h in headings or [0.0] * len(first_moves)]
    return {"kind": "main", "robot_label": label, "policy_actions": actions,
            "start_states": starts}


def test_short_and_backward_steps_are_counted():
    forward = [(0, 0), (1, 0), (2, 0), (3, 0), (3.05, 0)]  # last step shorter than 0.1 m
    backward = [(0, 0), (1, 0), (0.5, 0), (1.5, 0), (2.5, 0)]  # one step against travel
    bank = {"min_step_m": 0.1, "max_step_m": 1.0, "dt_s": 0.5, "label_names": ["a"],
            "trials": [_trial(0, [(1, 0)] * 2)]}
    figures = world_figures(_trajectories([forward, backward]), bank)
    assert figures["short_steps"] == pytest.approx(1 / 8)
    assert figures["against_mean_direction"] == pytest.approx(1 / 8)
    assert figures["against_own_displacement"] == pytest.approx(1 / 8)


def test_against_share_ignores_standing_still():
    steps = np.array([[1.0, 0.0], [-1.0, 0.0], [0.0, 0.0]])
    assert against_share(steps, np.array([1.0, 0.0])) == pytest.approx(0.5)


def test_same_label_spread_is_zero_for_one_direction_and_one_for_opposites():
    same = {"label_names": ["keep"], "trials": [_trial(0, [(2, 0), (1, 0)]),
                                                _trial(0, [(3, 0)])]}
    assert same_label_spread(same)["mean"] == pytest.approx(0.0, abs=1e-9)
    opposite = {"label_names": ["keep"], "trials": [_trial(0, [(1, 0)]), _trial(0, [(-1, 0)])]}
    assert same_label_spread(opposite)["mean"] == pytest.approx(2.0)
    # pairs inside one trial are left out: only the cross-trial pair (1-cos 90 deg) counts
    mixed = {"label_names": ["a", "b"], "trials": [_trial(0, [(1, 0), (-1, 0)]),
                                                   _trial(1, [(0, 1)])]}
    assert same_label_spread(mixed)["per_label"] == {}


def test_in_the_heading_frame_one_turn_is_one_direction_whichever_way_the_road_runs():
    # a left turn seen from cars heading east and north: 45 deg off their own heading
    east, north = np.radians([0.0, 90.0])
    turn = {"label_names": ["left"],
            "trials": [_trial(0, [(1, 1)], [east]), _trial(0, [(-1, 1)], [north])]}
    assert same_label_spread(turn)["mean"] == pytest.approx(1.0)  # 90 deg apart on screen
    assert same_label_spread(turn, heading_frame=True)["mean"] == pytest.approx(0.0, abs=1e-9)


def test_start_state_figures_per_kind():
    # dt 0.5: a 2 m/s action is a 1 m step; min click 0.5 m
    trial = {"kind": "main", "robot_label": 0,
             "policy_actions": [[[2, 0], [2, 0]],  # own: along its heading
                                [[0, 2], [0.5, 0]],  # near: 90 deg off, then a 0.25 m step
                                [[2, 0], [0.05, 0]]],  # near: on heading, then 2.5 cm
             "start_states": [{"start_kind": "own", "robot_heading": 0.0},
                              {"start_kind": "near", "robot_heading": 0.0},
                              {"start_kind": "near", "robot_heading": 0.1}]}
    bank = {"dt_s": 0.5, "min_step_m": 0.5, "trials": [trial]}
    figures = start_state_figures(bank, {"start_candidates_dropped": {"short": 3}})
    own, near = figures["kinds"]["own"], figures["kinds"]["near"]
    assert own["heading_error_median_deg"] == 0.0 and own["steps_below_min_click"] == 0.0
    assert near["heading_error_median_deg"] == pytest.approx((90 + 5.73) / 2, abs=0.01)
    assert near["heading_error_over_20"] == 0.5
    assert near["steps_below_min_click"] == 0.5 and near["steps_below_5cm"] == 0.25
    assert figures["candidates_dropped"] == {"short": 3}
    assert start_state_figures(bank, None)["candidates_dropped"] is None
