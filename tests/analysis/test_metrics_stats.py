"""The analysis numbers against a direct, by-hand computation on a small fixed dataset."""

import math

import numpy as np
import pytest
from scipy import stats

from analysis.load import load_csv
from analysis.metrics import apply_exclusions, participant_means
from analysis.stats import (
    compare_per_world,
    displacement_errors,
    holm,
    infer_dt_s,
    mean_ci95,
    paired_comparison,
)
from app.core.alignment import alignment_error
from app.core.contracts import ExclusionRules
from tests.analysis.fixed_data import DT_S, cos_distance, fixed_predictions, holm_by_hand


def test_alignment_error_known_angles():
    a = np.array([[1.0, 0.0]] * 4)
    b = np.array([[2.0, 0.0], [0.0, 3.0], [-1.0, 0.0], [1.0, 1.0]])
    np.testing.assert_allclose(alignment_error(a, b), [0.0, 1.0, 2.0, 1 - math.sqrt(0.5)])


def test_zero_vector_is_uninformative():
    err = alignment_error(np.array([[1.0, 0.0], [0.0, 0.0]]), np.array([[0.0, 0.0], [1.0, 2.0]]))
    np.testing.assert_array_equal(err, [1.0, 1.0])


def test_participant_means_and_ttest_match_a_hand_computation():
    frame = fixed_predictions()
    means = participant_means(frame)
    results = compare_per_world(means)
    for world in ("highway", "obstacle"):
        by_hand = {"ours": [], "vae": []}
        for pid in sorted(set(frame["participant_id"])):
            rows = frame[(frame["participant_id"] == pid) & (frame["world"] == world)]
            for model in by_hand:
                errs = [cos_distance((r.participant_vx, r.participant_vy),
                                      (r[f"{model}_vx"], r[f"{model}_vy"]))
                        for _, r in rows.iterrows()]
                by_hand[model].append(sum(errs) / len(errs))
        ours, vae = np.array(by_hand["ours"]), np.array(by_hand["vae"])
        got = means[means["world"] == world]
        np.testing.assert_allclose(got["err_ours"], ours, rtol=1e-12)
        np.testing.assert_allclose(got["err_vae"], vae, rtol=1e-12)
        expected = stats.ttest_rel(ours, vae)
        diff = ours - vae
        sd = math.sqrt(sum((d - diff.mean()) ** 2 for d in diff) / (len(diff) - 1))
        res = results[world]
        assert res.n == 4
        assert res.t == pytest.approx(expected.statistic, rel=1e-12)
        assert res.p_two_sided == pytest.approx(expected.pvalue, rel=1e-12)
        assert res.d_z == pytest.approx(diff.mean() / sd, rel=1e-12)
        half = stats.t.ppf(0.975, 3) * sd / 2.0
        assert res.ci95_low == pytest.approx(diff.mean() - half, rel=1e-12)
        assert res.ci95_high == pytest.approx(diff.mean() + half, rel=1e-12)
        assert res.wilcoxon_p == pytest.approx(stats.wilcoxon(ours, vae).pvalue)


def test_paired_comparison_one_sided_matches_direction():
    a = np.array([0.1, 0.2, 0.15, 0.12, 0.18])
    b = a + np.array([0.1, 0.05, 0.2, 0.1, 0.12])
    res = paired_comparison(a, b)
    assert res.mean_diff < 0 and res.p_one_sided_less == pytest.approx(res.p_two_sided / 2)



def _by_hand_ci95(values: np.ndarray) -> tuple[float, float]:
    """mean +- t(0.975, n - 1) * sd / sqrt(n), sd with n - 1."""
    n, mean = len(values), sum(values) / len(values)
    sd = math.sqrt(sum((v - mean) ** 2 for v in values) / (n - 1))
    half = stats.t.ppf(0.975, n - 1) * sd / math.sqrt(n)
    return mean - half, mean + half


@pytest.mark.filterwarnings("ignore:Precision loss:RuntimeWarning")  # the equal values
@pytest.mark.parametrize("values", [[0.31, 0.12, 0.4], [0.5, 0.25], [0.2, 0.2, 0.2, 0.2],
                                    list(np.linspace(0.0, 2.0, 40) ** 2)])
def test_mean_ci95_is_the_t_interval_by_hand(values):
    mean, low, high = mean_ci95(np.array(values))
    assert mean == pytest.approx(sum(values) / len(values), rel=1e-12)
    assert [low, high] == pytest.approx(_by_hand_ci95(values), rel=1e-12, abs=1e-15)


def test_mean_ci95_of_one_value_has_no_interval():
    mean, low, high = mean_ci95(np.array([0.7]))
    assert mean == 0.7 and math.isnan(low) and math.isnan(high)


@pytest.mark.filterwarnings("ignore:Precision loss:RuntimeWarning")  # the equal values
@pytest.mark.parametrize("gap", [[0.1, 0.05, 0.2, 0.1, 0.12], [0.25, 0.25, 0.25], [-0.5, 0.5]])
def test_paired_ci95_is_the_t_interval_of_the_differences_by_hand(gap):
    a = np.linspace(0.1, 0.3, len(gap))
    res = paired_comparison(a, a + np.array(gap))
    diff = list(a - (a + np.array(gap)))
    assert [res.ci95_low, res.ci95_high] == pytest.approx(_by_hand_ci95(diff), rel=1e-12,
                                                          abs=1e-15)

def test_ade_fde_by_hand():
    frame = fixed_predictions(n_participants=2)
    assert infer_dt_s(frame).to_dict() == pytest.approx({"highway": DT_S, "obstacle": DT_S})
    got = displacement_errors(frame)
    rows = frame[(frame["participant_id"] == "p00") & (frame["world"] == "obstacle")]
    ade, fde = [], []
    for _, pred in rows.groupby(["trial_id", "start_index"]):
        pos = np.array([pred["start_x"].iloc[0], pred["start_y"].iloc[0]])
        dists = []
        for _, r in pred.iterrows():
            pos = pos + DT_S * np.array([r.ours_vx, r.ours_vy])
            dists.append(math.hypot(pos[0] - r.participant_click_x, pos[1] - r.participant_click_y))
        ade.extend(dists)
        fde.append(dists[-1])
    row = got[(got["participant_id"] == "p00") & (got["world"] == "obstacle")].iloc[0]
    assert row["ade_ours"] == pytest.approx(np.mean(ade), rel=1e-9)
    assert row["fde_ours"] == pytest.approx(np.mean(fde), rel=1e-9)


def test_exclusions_are_counted_per_rule():
    frame = fixed_predictions()
    frame.loc[frame["participant_id"] == "p01", "attention_passed"] = False
    frame.loc[frame["participant_id"] == "p02", "completed"] = False
    fast = (frame["participant_id"] == "p03") & (frame["trial_id"] == "highway-0")
    frame.loc[fast, "trial_duration_ms"] = 500.0
    rules = ExclusionRules(too_fast_trial_ms=1000, too_fast_max_fraction=0.5)
    result = apply_exclusions(frame, rules)
    counts = result.counts()
    assert counts["excluded_failed_attention_check"] == 1
    assert counts["excluded_incomplete"] == 1
    assert counts["excluded_too_fast"] == 0
    assert counts["too_fast_trials_dropped"] == 1
    assert counts["participants_kept"] == 2
    assert not (result.kept["trial_duration_ms"] < 1000).any()


def test_csv_round_trip_is_identical(tmp_path):
    frame = fixed_predictions()
    frame.to_csv(tmp_path / "export.csv", index=False)
    back = load_csv(tmp_path / "export.csv")
    assert back.equals(frame)


def test_an_export_older_than_the_arm_column_reads_with_an_empty_arm(tmp_path):
    frame = fixed_predictions()
    frame.drop(columns="arm").to_csv(tmp_path / "old.csv", index=False)
    back = load_csv(tmp_path / "old.csv")
    assert (back["arm"] == "").all()
    assert back.drop(columns="arm").equals(frame.drop(columns="arm"))


def test_holm_adjusts_in_order_and_caps_at_one():
    np.testing.assert_allclose(holm([0.01, 0.04, 0.03, 0.5]), [0.04, 0.09, 0.09, 0.5])
    assert holm([0.6, float("nan")]) == [1.0, 1.0]
    assert holm([]) == []


def test_holm_equals_the_step_down_by_hand_with_ties():
    rng = np.random.default_rng(5)
    for m in (1, 2, 7, 30):
        p = np.round(rng.random(m) ** 3, 2).tolist()  # rounding makes ties
        assert holm(p) == holm_by_hand(p)
