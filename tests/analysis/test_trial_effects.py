"""The crossed mixed model and leave-one-trial-out influence on simulated data with planted
participant and trial effects (seeded)."""

import numpy as np
import pandas as pd
import pytest

from analysis.stats import paired_comparison
from analysis.trial_effects import (
    crossed_mixed_model,
    influence_summary,
    leave_one_trial_out,
    mixed_model_table,
    trial_cells,
)


def planted_rows(n_participants: int, n_trials: int, seen: int, sd_participant: float,
                 sd_trial: float, sd_residual: float, effect: float = -0.02, seed: int = 0,
                 rows_per_cell: int = 2, trial_shift: dict | None = None) -> pd.DataFrame:
    """Export-like rows (err_ours, err_vae) where each participant sees `seen` of the trials
    and err_ours - err_vae = effect + participant effect + trial effect + residual."""
    rng = np.random.default_rng(seed)
    person = rng.normal(0, sd_participant, n_participants)
    trial = rng.normal(0, sd_trial, n_trials)
    for index, shift in (trial_shift or {}).items():
        trial[index] = shift
    rows = []
    for p in range(n_participants):
        for t in sorted(rng.choice(n_trials, seen, replace=False)):
            diff = effect + person[p] + trial[t] + rng.normal(0, sd_residual)
            for _ in range(rows_per_cell):
                rows.append({"participant_id": f"p{p:02d}", "world": "obstacle",
                             "trial_id": f"t{t:02d}", "arm": ("random", "models_disagree")[t % 2],
                             "err_ours": 0.5 + diff, "err_vae": 0.5})
    frame = pd.DataFrame(rows)
    frame.attrs.update(person=person, trial=trial)
    return frame


def test_on_balanced_data_the_intercept_is_the_mean_and_its_se_the_crossed_formula():
    rows = planted_rows(8, 6, seen=6, sd_participant=0.03, sd_trial=0.05, sd_residual=0.02)
    cells = trial_cells(rows)
    res = crossed_mixed_model(cells)
    assert res.status == "ok" and (res.n_participants, res.n_trials, res.n_obs) == (8, 6, 48)
    assert res.estimate == pytest.approx(cells["diff"].mean(), abs=1e-9)
    # balanced crossed design: var(grand mean) = vp / P + vt / T + ve / (P T)
    se = np.sqrt(res.var_participant / 8 + res.var_trial / 6 + res.var_residual / 48)
    assert res.se == pytest.approx(se, rel=1e-6)
    assert res.ci95_low == pytest.approx(res.estimate - 1.959964 * res.se, rel=1e-4)


def test_the_variance_components_recover_a_planted_trial_effect():
    rows = planted_rows(40, 30, seen=15, sd_participant=0.03, sd_trial=0.1, sd_residual=0.03,
                        seed=5)
    res = crossed_mixed_model(trial_cells(rows))
    assert res.status == "ok"
    planted_trial = np.var(rows.attrs["trial"], ddof=1)
    planted_person = np.var(rows.attrs["person"], ddof=1)
    assert 0.8 < res.var_trial / planted_trial < 1.25
    assert 0.6 < res.var_participant / planted_person < 1.6
    assert res.var_residual == pytest.approx(0.03 ** 2, rel=0.2)
    # trials as a random factor widen the interval a participants-only test gives
    per_person = rows.groupby("participant_id")[["err_ours", "err_vae"]].mean()
    naive = paired_comparison(per_person["err_ours"], per_person["err_vae"])
    assert res.se > 2 * naive.sd_diff / np.sqrt(naive.n)


def test_degenerate_data_get_a_status_not_an_error():
    one_person = trial_cells(planted_rows(1, 5, 5, 0.03, 0.05, 0.02))
    assert crossed_mixed_model(one_person).status == "too_few_participants"
    one_trial = trial_cells(planted_rows(6, 1, 1, 0.03, 0.05, 0.02))
    assert crossed_mixed_model(one_trial).status == "too_few_trials"
    flat = trial_cells(planted_rows(6, 4, 4, 0.0, 0.0, 0.0, effect=0.0))
    res = crossed_mixed_model(flat)
    assert res.status == "no_variation" and res.estimate == 0.0 and np.isnan(res.se)


def test_a_variance_the_data_do_not_hold_is_on_the_boundary():
    rows = planted_rows(12, 10, seen=10, sd_participant=0.0, sd_trial=0.08, sd_residual=0.02,
                        seed=2)
    res = crossed_mixed_model(trial_cells(rows))
    assert res.status == "boundary" and "participant variance estimated as 0" in res.message
    assert res.var_participant < 1e-6 * res.var_trial
    assert np.isfinite(res.estimate) and np.isfinite(res.se)


def test_the_table_fits_each_arm_and_both_pooled():
    rows = planted_rows(10, 8, seen=8, sd_participant=0.03, sd_trial=0.05, sd_residual=0.02)
    table = mixed_model_table({"primary": rows, "family": rows})
    assert table[["arm", "answers"]].values.tolist() == [
        ["pooled", "primary"], ["pooled", "family"], ["models_disagree", "primary"],
        ["models_disagree", "family"], ["random", "primary"], ["random", "family"]]
    assert table.set_index(["arm", "answers"]).loc[("random", "primary"), "n_trials"] == 4


def test_leave_one_trial_out_names_a_planted_outlier_trial():
    rows = planted_rows(10, 8, seen=8, sd_participant=0.01, sd_trial=0.01, sd_residual=0.01,
                        effect=0.0, seed=3, trial_shift={5: -0.4})
    table = leave_one_trial_out({"primary": rows})
    top = table.iloc[0]
    assert top["trial_id"] == "t05" and top["shift"] > 0
    without = rows[rows["trial_id"] != "t05"].groupby("participant_id")
    diff = (without["err_ours"].mean() - without["err_vae"].mean()).mean()
    assert top["mean_diff"] == pytest.approx(diff, rel=1e-10)
    assert top["all_trials_verdict"] == "ours" and top["verdict"] == "neither"
    assert table["flips"].tolist() == [True] + [False] * 7
    summary = influence_summary(table)["obstacle"]["primary"]
    assert summary["most_influential"]["trial_id"] == "t05"
    assert summary["flipping_trials"] == ["t05"] and summary["any_flip"]
    assert (table["shift"].abs().diff().dropna() <= 0).all()  # largest move first
