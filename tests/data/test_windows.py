"""Windows: the right steps for segment, prediction and reconstruction; split by trajectory."""

import numpy as np
import pytest

from app.data.windows import (
    evenly_spaced_starts,
    make_windows,
    segment_features,
    split_by_trajectory,
)
from tests.learning.synthetic import make_lane_trajs


@pytest.fixture(scope="module")
def trajs():
    return make_lane_trajs(30, seed=1)


def test_evenly_spaced_starts_fit_inside_the_valid_steps():
    assert evenly_spaced_starts(10, 8, 5).tolist() == [0, 1, 2]
    assert evenly_spaced_starts(7, 8, 5).tolist() == []
    starts = evenly_spaced_starts(40, 8, 4)
    assert starts[0] == 0 and starts[-1] == 32 and len(starts) == 4


def test_windows_take_targets_from_the_right_steps(trajs):
    T, n = 5, 3
    w = make_windows(trajs, T, n, per_trajectory=4)
    actions = trajs.actions
    assert w.positions.shape[1:] == (T + n + 1, 2, 2)
    for i in [0, 7, len(w) - 1]:
        row, t0 = w.traj_index[i], w.start_step[i]
        assert t0 + T + n <= trajs.lengths[row]  # never past the trajectory's last action
        assert np.allclose(w.segment_positions[i], trajs.positions[row, t0:t0 + T + 1])
        assert np.allclose(w.end_states[i], trajs.positions[row, t0 + T])
        assert np.allclose(w.pred_targets[i], actions[row, t0 + T:t0 + T + n, 0], atol=1e-4)
        assert w.labels["robot_intent"][i] == trajs.labels["robot_intent"][row]
    t = np.arange(len(w)) % T
    states, targets = w.recon_pair(t)
    i = 3
    row, t0 = w.traj_index[i], w.start_step[i]
    assert np.allclose(states[i], trajs.positions[row, t0 + t[i]])
    assert np.allclose(targets[i], actions[row, t0 + t[i]:t0 + t[i] + n, 0], atol=1e-4)


def test_segment_features_pair_each_state_with_the_action_into_it():
    seg = np.cumsum(np.ones((6, 2, 2), np.float32), axis=0)  # s^i = i + 1 everywhere
    seg[:, 0, 1] *= 2  # robot y moves at 2 per step
    feats = segment_features(seg, dt_s=0.5)
    assert feats.shape == (5, 8)
    assert np.allclose(feats[:, :4], seg[1:].reshape(5, 4))
    assert np.allclose(feats[0, 4:], [2.0, 4.0, 2.0, 2.0])


def test_split_is_by_trajectory_disjoint_and_complete():
    split = split_by_trajectory(100, 0.15, 0.15, seed=0)
    joined = np.concatenate(list(split.values()))
    assert sorted(joined.tolist()) == list(range(100))
    assert len(split["test"]) == 15 and len(split["val"]) == 15
    assert np.array_equal(split["test"], split_by_trajectory(100, 0.15, 0.15, seed=0)["test"])
