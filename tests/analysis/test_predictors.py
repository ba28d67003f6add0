"""Every predictor against the people, on fixed data with a plug-in's columns, by hand."""

import math
from itertools import combinations

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from analysis import predictors
from analysis.load import load_csv, normalise
from analysis.metrics import add_alignment_errors
from analysis.predictors import pairwise_table, predictor_means, predictor_names, primary_fits
from analysis.report import run_analyze
from analysis.stats import ALPHA
from analysis.trial_effects import mixed_model_table
from app.core.contracts import EXPORT_COLUMNS, model_color, model_label, plugin_columns
from tests.analysis.fixed_data import cos_distance, fixed_predictions, holm_by_hand
from tests.analysis.report_inputs import simulated_export

NAMES = ["ours", "vae", "cv", "ctrv"]


def with_ctrv(frame, seed: int = 11):
    """The rows with a plug-in `ctrv`: the person's move plus noise, code -1, one hash."""
    rng = np.random.default_rng(seed)
    noisy = frame[["participant_vx", "participant_vy"]].to_numpy() + rng.normal(scale=0.8,
                                                                     size=(len(frame), 2))
    return normalise(frame.assign(ctrv_vx=noisy[:, 0], ctrv_vy=noisy[:, 1], ctrv_code=-1,
                                  ctrv_sha256="c" * 64))


@pytest.fixture(scope="module")
def kept():
    return add_alignment_errors(with_ctrv(fixed_predictions(n_participants=6)))


def means_by_hand(frame, name: str) -> dict:
    """(participant, world) -> mean 1-cos between the person's and `name`'s moves, by hand."""
    sums: dict = {}
    for r in frame.itertuples():
        error = cos_distance((r.participant_vx, r.participant_vy),
                             (getattr(r, f"{name}_vx"), getattr(r, f"{name}_vy")))
        sums.setdefault((r.participant_id, r.world), []).append(error)
    return {key: sum(v) / len(v) for key, v in sums.items()}


def test_plugin_columns_are_kept_typed_and_read_back(tmp_path):
    frame = with_ctrv(fixed_predictions())
    assert list(frame.columns) == [*EXPORT_COLUMNS, *plugin_columns("ctrv")]
    assert predictor_names(frame.columns) == NAMES
    frame.to_csv(tmp_path / "export.csv", index=False)
    back = load_csv(tmp_path / "export.csv")
    assert back.equals(frame) and back["ctrv_code"].dtype == np.int64


def test_every_predictors_mean_error_per_participant_by_hand(kept):
    means = predictor_means(kept, NAMES)
    assert [c for c in means.columns if c.startswith("err_")] == \
        ["err_ours", "err_vae", "err_cv", "err_ctrv", "err_policy"]
    for name in (*NAMES, "policy"):
        by_hand = means_by_hand(kept, name)
        got = {(r.participant_id, r.world): getattr(r, f"err_{name}")
               for r in means.itertuples()}
        assert got.keys() == by_hand.keys() and len(got) == 12
        assert all(math.isclose(got[k], by_hand[k], abs_tol=1e-12) for k in got)


def test_pairwise_tests_and_holm_by_hand(kept):
    table = pairwise_table(kept, NAMES, predictor_means(kept, NAMES))
    pairs = [f"{a}_vs_{b}" for a, b in combinations(NAMES, 2)]
    assert table.groupby("world")["pair"].apply(list).to_dict() == {
        "highway": pairs, "obstacle": pairs}
    for world, rows in table.groupby("world"):
        by_hand = {name: means_by_hand(kept[kept["world"] == world], name) for name in NAMES}
        p_values = []
        for row in rows.itertuples():
            keys = sorted(by_hand[row.a])
            a = np.array([by_hand[row.a][k] for k in keys])
            b = np.array([by_hand[row.b][k] for k in keys])
            diff = a - b
            t = diff.mean() / (diff.std(ddof=1) / math.sqrt(len(diff)))
            p = 2 * stats.t.sf(abs(t), len(diff) - 1)
            assert row.n == 6 and math.isclose(row.mean_diff, diff.mean(), abs_tol=1e-12)
            assert math.isclose(row.t, t, rel_tol=1e-9) and math.isclose(row.p_two_sided, p,
                                                                         rel_tol=1e-6)
            assert math.isclose(row.d_z, diff.mean() / diff.std(ddof=1), rel_tol=1e-9)
            assert row.ci95_low < diff.mean() < row.ci95_high
            p_values.append(row.p_two_sided)
        np.testing.assert_allclose(rows["p_holm"], holm_by_hand(p_values), rtol=1e-12)
        for row in rows.itertuples():
            lower = row.a if row.mean_diff < 0 else row.b
            assert row.verdict == (lower if row.p_holm < ALPHA else "neither")
    assert (table["verdict"] != "neither").any()  # the fixed data tells some pairs apart


def test_the_mixed_model_per_pair_is_the_primary_ones_for_ours_and_vae(kept, monkeypatch):
    means = predictor_means(kept, NAMES)
    fresh = pairwise_table(kept, NAMES, means)  # every pair fitted here
    primary = mixed_model_table({"primary": kept})
    fits = primary_fits(primary)
    assert sorted(fits) == ["highway", "obstacle"]
    fitted = []
    fit = predictors.crossed_mixed_model
    monkeypatch.setattr(predictors, "crossed_mixed_model",
                        lambda cells: fitted.append(list(cells.columns)) or fit(cells))
    reused = pairwise_table(kept, NAMES, means, fits)
    assert len(fitted) == 2 * 5  # each world's pairs but ours_vs_vae, whose fit is reused
    assert not [c for c in fitted if "sum_ours" in c and "sum_vae" in c]
    pd.testing.assert_frame_equal(reused, fresh, check_exact=True)  # as a fresh fit
    table = reused.set_index(["world", "pair"])
    for row in primary[primary["arm"] == "pooled"].itertuples():
        mine = table.loc[(row.world, "ours_vs_vae")]
        assert mine["mixed_estimate"] == pytest.approx(row.estimate, abs=1e-12)
        assert mine["mixed_p"] == pytest.approx(row.p, abs=1e-12)
        assert mine["mixed_status"] == row.status
    assert table["mixed_p_holm"].ge(table["mixed_p"]).all()


def test_plugins_have_a_colour_and_label_of_their_own():
    assert model_label("ctrv") == "ctrv" and model_label("ours") == "Ours"
    assert model_color("ctrv") == model_color("ctrv") != model_color("ours")
    assert model_color("ctrv").startswith("#") and len(model_color("ctrv")) == 7


def test_analyze_writes_every_predictor_side_by_side(tmp_path, inputs):
    frame = simulated_export("coarse", 10, seed=4)
    with_ctrv(frame).to_csv(tmp_path / "export.csv", index=False)
    out = tmp_path / "report"
    summary = run_analyze("paper_study", out, tmp_path / "export.csv", "", inputs)
    for name in ("predictors.csv", "pairwise.csv", "predictors.png", "predictors.svg"):
        assert (out / name).is_file(), name
    entry = summary["predictors"]
    assert entry["names"] == NAMES and entry["reference"] == "policy"
    assert set(entry["worlds"]["highway"]) == {*NAMES, "policy"}
    assert len(entry["pairwise"]["obstacle"]) == 6
    html = (out / "report.html").read_text()
    assert "ours vs ctrv" in html and "Holm over that world" in html
    assert "ours_vs_vae" in summary["predictors"]["pairwise"]["highway"]
    for world, pairs in summary["predictors"]["pairwise"].items():
        pooled = summary["mixed_model"][world]["pooled"]["primary"]
        assert {k: pairs["ours_vs_vae"][f"mixed_{k}"] for k in ("estimate", "p", "status")} == \
            {k: pooled[k] for k in ("estimate", "p", "status")}
