"""Simulated participants click valid moves that follow the behaviour they read; power runs."""

import numpy as np
import pytest

from analysis import predictors
from analysis.metrics import participant_means
from analysis.power import power_curve, simulate_participants
from tests.analysis.fixed_data import (
    HIGHWAY_SCENE,
    OBSTACLE_SCENE,
    highway_segment,
    obstacle_segment,
    payload,
    small_bank,
)


def _assert_valid(p: dict, clicks: np.ndarray) -> None:
    b = p["scene"]["bounds"]
    assert clicks.shape == (5, 3, 2)
    assert np.all((clicks[..., 0] > b["x_min_m"]) & (clicks[..., 0] < b["x_max_m"]))
    assert np.all((clicks[..., 1] > b["y_min_m"]) & (clicks[..., 1] < b["y_max_m"]))
    starts = predictors.start_positions(p)[:, None, :]
    steps = np.linalg.norm(np.diff(np.concatenate([starts, clicks], axis=1), axis=1), axis=-1)
    assert np.all(steps >= p["min_step_m"]) and np.all(steps <= p["max_step_m"])


@pytest.mark.parametrize(("lane_from", "lane_to"), [(1, 0), (1, 2), (1, 1), (0, 1)])
def test_coarse_reads_the_target_lane(lane_from, lane_to):
    p = payload(HIGHWAY_SCENE, highway_segment(lane_from, lane_to), [[20.0, 4.0]] * 5)
    assert predictors.highway_target_lane_y(p) == 4.0 * lane_to
    clicks = predictors.predict_coarse(p, np.random.default_rng(0), noise_deg=0.0)
    _assert_valid(p, clicks)
    assert np.sign(clicks[0, -1, 1] - 4.0) == np.sign(lane_to - 1)


@pytest.mark.parametrize("goal", range(4))
def test_coarse_reads_the_goal(goal):
    g = OBSTACLE_SCENE["goals"][goal]
    p = payload(OBSTACLE_SCENE, obstacle_segment([5.0, 5.5], [g["x_m"], g["y_m"]]),
                [[3.0, 4.0], [7.0, 6.0], [2.0, 8.0], [9.7, 0.3], [5.0, 2.0]])
    np.testing.assert_array_equal(predictors.obstacle_target_goal(p), [g["x_m"], g["y_m"]])
    _assert_valid(p, predictors.predict_coarse(p, np.random.default_rng(1)))


def test_random_and_precise_clicks_are_valid():
    rng = np.random.default_rng(2)
    for scene, seg in ((HIGHWAY_SCENE, highway_segment(0, 1)),
                       (OBSTACLE_SCENE, obstacle_segment([5, 5], [9, 9]))):
        p = payload(scene, seg, [[seg[-1][0][0], seg[-1][0][1]]] * 5)
        _assert_valid(p, predictors.predict_random(p, rng))
        actions = np.tile(np.array([0.0, 30.0]), (5, 3, 1))  # too long, points off the scene
        _assert_valid(p, predictors.predict_from_actions(p, actions, rng))


def test_power_grows_with_n_for_coarse_bots():
    frame = simulate_participants(small_bank(), "coarse", 40, 5, seed=0, show_progress=False)
    assert len(frame) == 40 * 2 * 5 * 5 * 3
    means = participant_means(frame)
    assert (means["err_ours"] < means["err_vae"]).mean() > 0.9
    curve = power_curve(means, [3, 5, 20], reps=300, alpha=0.01)
    for _, group in curve.groupby("world"):
        assert group["power"].is_monotonic_increasing
        assert group["power"].iloc[-1] > 0.95
