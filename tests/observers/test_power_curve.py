"""power_curve: the share of resampled studies whose one-sided one-sample t-test of
err_ours - err_vae gives p < alpha, checked against the textbook formula."""

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from app.observers.simulated_study import power_curve

N_VALUES = [2, 3, 5, 12]
REPS = 400


def textbook_power(means: pd.DataFrame, seed: int, alpha: float) -> list[float]:
    """Power by hand: t = mean / (sd / sqrt(n)), p = t.cdf(t, n - 1); a draw of one value
    (sd 0) has p 0 if that value is negative, else 1. Draws in power_curve's order."""
    rng = np.random.default_rng(seed)
    power = []
    for _, group in means.groupby("world", sort=True):
        diff = (group["err_ours"] - group["err_vae"]).to_numpy()
        for n in N_VALUES:
            sample = diff[rng.integers(len(diff), size=(REPS, n))]
            mean, sd = sample.mean(axis=1), sample.std(axis=1, ddof=1)
            with np.errstate(divide="ignore", invalid="ignore"):
                p = stats.t.cdf(mean / (sd / np.sqrt(n)), df=n - 1)
            power.append(float(np.mean(np.where(sd > 0, p, np.where(mean < 0, 0.0, 1.0))
                                       < alpha)))
    return power


@pytest.mark.filterwarnings("ignore:divide by zero:RuntimeWarning",
                            "ignore:invalid value:RuntimeWarning")
def test_power_curve_equals_the_textbook_t_test_including_draws_of_one_value():
    rng = np.random.default_rng(7)
    ours = np.concatenate([rng.random(24), np.full(24, 0.25)])
    gap = np.concatenate([rng.normal(0.08, 0.1, 12),   # a noisy effect
                          rng.normal(0.0, 0.1, 12),    # none
                          np.full(12, 0.125),          # every draw exactly -0.125: sd 0
                          np.zeros(12)])               # every draw exactly 0: sd 0, t NaN
    means = pd.DataFrame({"world": np.repeat(["effect", "none", "same", "zero"], 12),
                          "err_ours": ours, "err_vae": ours + gap})
    curve = power_curve(means, N_VALUES, reps=REPS, alpha=0.05, seed=3)
    assert len(curve) == 4 * len(N_VALUES)
    assert curve["power"].tolist() == textbook_power(means, seed=3, alpha=0.05)
    power = curve.set_index(["world", "n"])["power"]
    assert power["same"].eq(1.0).all() and power["zero"].eq(0.0).all()
    assert power["effect", 12] > power["effect", 2]
