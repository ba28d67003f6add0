"""Evidence for a null beside the primary test: the crossed CI, TOST against the smallest
effect of interest, the JZS Bayes factor and the conclusion they give."""

import numpy as np
import pandas as pd
import pytest
from scipy import integrate, stats

from analysis.crossed import crossed_standard_error, crossed_test, primary_table
from analysis.equivalence import conclusion, jzs_bf10, paired_bf10, t_interval, tost_p

ALPHA = 0.01
SESOI = 0.005


def bf10_by_effect_size(t: float, n: int, r: float) -> float:
    """BF10 the other way round: the noncentral t likelihood of the observed t averaged over
    the Cauchy(0, r) prior on the standardised effect, over the central t's."""
    df = n - 1

    def likelihood(delta):
        return stats.nct.pdf(t, df, delta * np.sqrt(n)) * stats.cauchy.pdf(delta, 0, r)

    marginal = integrate.quad(likelihood, -np.inf, np.inf, limit=200, epsrel=1e-10)[0]
    return marginal / stats.t.pdf(t, df)


def test_bf10_matches_the_published_value_and_a_second_computation():
    # pingouin's documentation (validated there against JASP and BayesFactor): paired t = 3.5,
    # n = 20, r = 0.707 gives BF10 17.185
    assert jzs_bf10(3.5, 20, 0.707) == pytest.approx(17.185, abs=5e-4)
    for t, n, r in [(2.0, 20, 0.707), (0.0, 30, 0.707), (1.0, 10, 1.0), (-2.5, 40, 0.5),
                    (6.0, 12, 0.707)]:
        assert jzs_bf10(t, n, r) == pytest.approx(bf10_by_effect_size(t, n, r), rel=1e-6)
    assert jzs_bf10(2.0, 20, 0.707) == pytest.approx(1.206, abs=5e-4)
    assert jzs_bf10(0.0, 30) < 1 / 3  # no difference in 30 pairs: evidence for the null


def test_paired_bf10_reads_the_t_of_the_differences():
    diffs = np.array([0.3, -0.1, 0.5, 0.2, 0.4, 0.0, 0.6, 0.1])
    t = stats.ttest_1samp(diffs, 0).statistic
    assert paired_bf10(diffs) == pytest.approx(jzs_bf10(t, 8))
    assert np.isnan(paired_bf10([0.2])) and np.isnan(paired_bf10([0.1, 0.1, 0.1]))


def crossed_cells(rng, people: int, clips: int, seen: int, effect: float, noise: float,
                  clip_sd: float = 0.0) -> pd.DataFrame:
    """Each participant sees `seen` of the clips (balanced exposure): the Ours - VAE cell
    difference is effect + clip effect + noise; the VAE's error is 0.3 plus noise."""
    clip_effect = rng.normal(0, clip_sd, clips)
    rows = []
    for p in range(people):
        for k in range(seen):
            clip = (p * seen + k) % clips
            vae = 0.3 + rng.normal(0, 0.05)
            diff = effect + clip_effect[clip] + rng.normal(0, noise)
            rows.append({"world": "highway", "participant_id": f"p{p:03d}",
                         "trial_id": f"t{clip:03d}", "err_ours": vae + diff, "err_vae": vae})
    return pd.DataFrame(rows)


def test_the_crossed_se_is_the_one_min_f_divides_by_on_a_balanced_design():
    cells = crossed_cells(np.random.default_rng(0), 12, 6, 6, 0.02, 0.03, clip_sd=0.01)
    diff = cells["err_ours"] - cells["err_vae"]
    se, df = crossed_standard_error(diff, cells["participant_id"], cells["trial_id"])
    result = crossed_test(diff, cells["participant_id"], cells["trial_id"])
    assert (result.mean_diff / se) ** 2 == pytest.approx(result.min_f)
    assert df == pytest.approx(result.df)
    low, high = t_interval(result.mean_diff, se, df)
    assert high - result.mean_diff == pytest.approx(result.mean_diff - low)
    assert stats.f.sf(((result.mean_diff - low) / se) ** 2, 1, df) == pytest.approx(0.05)


def test_tost_is_the_larger_one_sided_p_and_the_90_percent_interval_rule():
    assert tost_p(0.0, 0.001, 30, SESOI) == pytest.approx(stats.t.sf(5, 30))
    assert tost_p(0.004, 0.001, 30, SESOI) == pytest.approx(stats.t.cdf(-1, 30))
    assert tost_p(0.008, 0.001, 30, SESOI) > 0.5  # outside the bounds: no equivalence
    for mean in np.linspace(-0.006, 0.006, 25):
        low, high = t_interval(mean, 0.0015, 20, level=0.90)
        inside = low > -SESOI and high < SESOI
        assert (tost_p(mean, 0.0015, 20, SESOI) < 0.05) == inside
    assert np.isnan(tost_p(0.0, float("nan"), 30, SESOI))


def test_conclusion_names_the_model_then_equivalence_then_nothing():
    assert conclusion("ours", 0.5, ALPHA) == "ours"
    assert conclusion("vae", 0.001, ALPHA) == "vae"
    assert conclusion("neither", 0.001, ALPHA) == "equivalent"
    assert conclusion("neither", 0.2, ALPHA) == "inconclusive"
    assert conclusion("neither", float("nan"), ALPHA) == "inconclusive"


def test_equal_models_with_little_noise_are_equivalent():
    cells = crossed_cells(np.random.default_rng(1), 30, 60, 10, 0.0, 0.01, clip_sd=0.002)
    row = primary_table(cells, ALPHA, {}, SESOI).iloc[0]
    assert row["verdict"] == "neither" and row["conclusion"] == "equivalent"
    assert row["tost_p"] < ALPHA and row["sesoi"] == SESOI
    assert -SESOI < row["ci95_low"] < row["mean_diff"] < row["ci95_high"] < SESOI
    assert row["bf10"] < 1 / 3


def test_equal_but_noisy_models_with_few_participants_are_inconclusive():
    cells = crossed_cells(np.random.default_rng(2), 4, 8, 4, 0.0, 0.08, clip_sd=0.02)
    row = primary_table(cells, ALPHA, {}, SESOI).iloc[0]
    assert row["verdict"] == "neither" and row["conclusion"] == "inconclusive"
    assert row["tost_p"] > ALPHA and row["ci95_high"] - row["ci95_low"] > 2 * SESOI


def test_a_clear_difference_keeps_the_primary_verdict():
    cells = crossed_cells(np.random.default_rng(3), 30, 60, 10, -0.02, 0.01, clip_sd=0.002)
    row = primary_table(cells, ALPHA, {"highway": "a reason long enough"}, SESOI).iloc[0]
    assert row["verdict"] == "ours" == row["conclusion"] and row["exploratory"]
    assert row["ci95_high"] < 0 and row["tost_p"] > 0.5 and row["bf10"] > 100
    assert list(row.index[-6:]) == ["ci95_low", "ci95_high", "sesoi", "tost_p", "bf10",
                                    "conclusion"]
