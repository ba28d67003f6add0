"""The attention check's angle rule, on its own (no server): pass within the angle, fail outside."""

from types import SimpleNamespace

import numpy as np
import pytest

from app.server.flow.validation import attention_passed
from app.study.config import AttentionChecks

RULE = AttentionChecks(max_angle_deg=45.0, min_passing_starts=4)


def trial_moving_east(k: int = 5) -> SimpleNamespace:
    """A stand-in trial: k start states at the origin, the robot's true first move east."""
    starts = [SimpleNamespace(robot=(0.0, 0.0)) for _ in range(k)]
    return SimpleNamespace(start_states=starts, policy_actions=[[[2.0, 0.0]]] * k)


def clicks_at(angles_deg: list[float]) -> np.ndarray:
    """First clicks [K, 1, 2] one metre from the origin at these angles."""
    rad = np.deg2rad(angles_deg)
    return np.stack([np.cos(rad), np.sin(rad)], axis=-1)[:, None, :]


@pytest.mark.parametrize(("angles", "passed"), [
    ([0, 10, -10, 44, -44], True),
    ([0, 10, -10, 44, 90], True),  # four of five within the angle are enough
    ([0, 10, -10, 46, 90], False),
    ([180, 180, 180, 180, 180], False),
])
def test_attention_check_counts_first_moves_within_the_angle(angles, passed):
    assert attention_passed(RULE, trial_moving_east(), clicks_at(angles)) is passed
