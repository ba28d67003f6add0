"""The human noise ceiling: leave-one-out against the others, the upper bound with oneself,
split-half reliability; near chance for random clickers, near 0 for people who agree."""

import numpy as np
import pandas as pd
import pytest

from analysis.ceiling import ceiling_table, cell_errors, explainable_share, split_half
from app.core.alignment import alignment_error


def rows_from(directions: np.ndarray, world: str = "highway") -> pd.DataFrame:
    """Rows of participants [P] x cells [C] with the given move angles [P, C] (rad)."""
    people, cells = directions.shape
    p, c = np.meshgrid(np.arange(people), np.arange(cells), indexing="ij")
    return pd.DataFrame({"participant_id": [f"p{i}" for i in p.ravel()], "world": world,
                         "trial_id": [f"t{j // 6}" for j in c.ravel()],
                         "start_index": (c.ravel() // 3) % 2, "step": c.ravel() % 3,
                         "participant_vx": 2 * np.cos(directions.ravel()),
                         "participant_vy": 2 * np.sin(directions.ravel())})


def test_leave_one_out_is_against_the_others_mean_direction():
    angles = np.array([[0.0], [np.pi / 2], [np.pi / 2]])
    errors = cell_errors(rows_from(angles)).set_index("participant_id")
    others = np.array([[0.0, 2.0]])  # the two others' unit vectors summed: straight up
    assert errors.loc["p0", "lower"] == pytest.approx(alignment_error(np.array([[1, 0]]),
                                                                      others)[0])
    assert errors.loc["p1", "lower"] == pytest.approx(1 - np.cos(np.pi / 4))
    assert errors.loc["p0", "upper"] < errors.loc["p0", "lower"]  # oneself included


def test_random_clickers_sit_near_chance_and_agreeing_ones_near_zero():
    rng = np.random.default_rng(0)
    random = ceiling_table(rows_from(rng.uniform(0, 2 * np.pi, (20, 30))))
    assert random["lower"].iloc[0] == pytest.approx(1.0, abs=0.1)
    assert abs(random["split_half_r"].iloc[0]) < 0.3
    truth = rng.uniform(0, 2 * np.pi, 30)
    agree = ceiling_table(rows_from(truth + rng.normal(0, 0.05, (20, 30))))
    assert agree["lower"].iloc[0] < 0.01 and agree["upper"].iloc[0] < agree["lower"].iloc[0]
    assert agree["split_half_r"].iloc[0] > 0.95 and agree["n_participants"].iloc[0] == 20


def test_split_half_needs_four_people_and_a_share_needs_a_ceiling():
    assert np.isnan(split_half(rows_from(np.zeros((3, 6)))))
    assert explainable_share(0.5, 0.0, 0.1) == 0.5
    assert np.isnan(explainable_share(0.5, 0.98, 1.02))  # people agree no better than chance
