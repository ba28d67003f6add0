"""The display check's figures, against hand-made tracks and bank entries."""

import numpy as np
import pytest

from app.bank.display_check import (
    against_share,
    robot_outline,
    same_label_spread,
    start_state_figures,
    world_figures,
)
from app.data.scene import AgentShape, Bounds, Scene
from app.data.trajectory import TrajectorySet
from app.prediction_view import prediction_view

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
            "start_states": starts, "segment": {}}


def test_short_and_backward_steps_are_counted():
    forward = [(0, 0), (1, 0), (2, 0), (3, 0), (3.05, 0)]  # last step shorter than 0.1 m
    backward = [(0, 0), (1, 0), (0.5, 0), (1.5, 0), (2.5, 0)]  # one step against travel
    bank = {"min_step_m": 0.1, "max_step_m": 1.0, "dt_s": 0.5, "label_names": ["a"],
            "trials": [_trial(0, [(1, 0)] * 2)], "scene": SCENE.model_dump()}
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
def _outline_bank(recorded: bool, robot_sizes: list | None = None) -> dict:
    """A 4 x 2 m car; two trials heading east and south (screen y down), each with two first
    moves: ends (1, 0) and (3, 0) m ahead, then (1, 0) ahead and 1.5 m to its right."""
    car = {"kind": "car", "length_m": 4.0, "width_m": 2.0}
    trials = [_trial(0, [(2, 0), (6, 0)], [0.0]), _trial(0, [(0, 2), (-3, 0)], [np.pi / 2])]
    for trial, sizes in zip(trials, robot_sizes or [None, None], strict=True):
        trial["start_states"] *= 2
        if sizes:
            trial["segment"] = {"sizes": [sizes, [4.0, 2.0]]}
    return {"dt_s": 0.5, "max_step_m": 4.0, "trials": trials,
            "scene": {"agents": [car, car], "recorded": {"source": "x"} if recorded else None}}


def test_a_simulated_world_draws_its_robot_at_size_and_is_flagged_when_steps_end_inside():
    bank = _outline_bank(recorded=False)
    assert "outline_scale" not in prediction_view(bank).payload()  # the page as before
    outline = robot_outline(bank)
    assert outline["outline_scale"] == 1.0 and outline["half_length_m"] == 2.0
    assert outline["first_moves_inside"] == outline["first_moves_inside_drawn"] == 0.5
    # median step 1.25 m against a 2 m half-length: the rule wants 4/3 half-lengths
    assert outline["step_over_half_length"] == pytest.approx(0.625)
    assert outline["half_length_over_reach"] == 0.5 and not outline["passes"]


def test_a_recorded_world_draws_its_agents_small_enough_that_the_median_step_clears_the_robot():
    bank = _outline_bank(recorded=True)
    view = prediction_view(bank)
    assert view.payload()["outline_scale"] == view.outline_scale == 0.468  # 0.75 * 1.25 / 2
    outline = robot_outline(bank)
    assert outline["first_moves_inside"] == 0.5 and outline["first_moves_inside_drawn"] == 0.0
    assert outline["half_length_px"] == pytest.approx(0.936 * view.px_per_m, abs=0.05)
    assert outline["step_over_half_length"] >= 4 / 3 and outline["passes"]


def test_each_trial_s_robot_is_measured_at_its_recorded_size():
    bank = _outline_bank(recorded=False, robot_sizes=[[12.0, 2.5], [4.0, 2.0]])
    outline = robot_outline(bank)
    assert outline["half_length_m"] == 4.0  # the median of 12 m and 4 m, halved
    assert outline["first_moves_inside"] == 0.75  # the bus holds the 3 m move too
