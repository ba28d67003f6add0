"""Latent metrics and prediction errors on hand-checked examples."""

import numpy as np
import pytest

from app.data.windows import make_windows
from app.learning.model_metrics import (
    SKIP,
    agreement,
    code_usage,
    constant_velocity,
    derived_labels,
    purity,
    trajectory_errors,
)
from tests.learning.synthetic import INTENTS, make_lane_trajs


def test_purity_and_usage_on_a_small_example():
    codes = np.array([0, 0, 0, 1, 1, 2])
    labels = np.array([0, 0, 1, 2, 2, 1])
    assert purity(codes, labels) == pytest.approx(5 / 6)
    usage = code_usage(codes, min_share=0.2)
    assert usage["counts"] == {"0": 3, "1": 2, "2": 1}
    assert usage["n_codes_used"] == 2 and usage["n_codes_seen"] == 3
    assert code_usage(np.arange(8))["perplexity"] == pytest.approx(8)
    perfect = agreement(codes, {"x": np.array([0, 0, 0, 1, 1, SKIP])})
    assert perfect["x"]["purity"] == 1 and perfect["x"]["nmi"] == pytest.approx(1)
    assert perfect["x"]["n_windows"] == 5 and perfect["x"]["majority"] == pytest.approx(0.6)


def test_trajectory_errors_integrate_velocities():
    target = np.zeros((1, 3, 2), np.float32)
    pred = np.tile(np.array([1.0, 0.0], np.float32), (1, 3, 1))  # 1 m/s too fast in x
    errors = trajectory_errors(pred, target, dt_s=0.5)
    assert errors["mse"] == pytest.approx(0.5)
    assert errors["ade_m"] == pytest.approx((0.5 + 1.0 + 1.5) / 3)
    assert errors["fde_m"] == pytest.approx(1.5)


def test_in_progress_label_turns_finished_merges_into_keep():
    trajs = make_lane_trajs(30, seed=2)
    w = make_windows(trajs, 5, 3, per_trajectory=10)
    labels = derived_labels(w, {"robot_intent": INTENTS})
    change = w.labels["robot_change_step"]
    done = (change >= 0) & (w.end_step >= change)
    assert done.any() and (~done & (change >= 0)).any()
    assert (labels["robot_intent_in_progress"][done] == INTENTS.index("keep")).all()
    assert np.array_equal(labels["robot_intent_in_progress"][~done], labels["robot_intent"][~done])


def test_goal_label_skips_windows_after_arrival():
    trajs = make_lane_trajs(10, seed=3)
    trajs.labels["robot_goal"] = trajs.labels["robot_intent"]
    trajs.labels["robot_arrival_step"] = np.full(10, 8, np.int32)
    w = make_windows(trajs, 5, 3, per_trajectory=10)
    labels = derived_labels(w, {"robot_goal": ["a", "b", "c"]})
    assert (labels["robot_goal_before_arrival"][w.end_step > 8] == SKIP).all()
    assert (labels["robot_goal_before_arrival"][w.end_step <= 8] >= 0).all()


def test_constant_velocity_repeats_the_last_segment_action():
    w = make_windows(make_lane_trajs(5, seed=4), 5, 3, per_trajectory=2)
    baseline = constant_velocity(w)
    assert baseline.shape == (len(w), 3, 2)
    assert np.allclose(baseline[:, 2], w.actions[:, 4, 0])
