"""The instrument grid: per seed pair and click-noise level, scored exactly as the export path
scores simulated participants; noise combined as stated; power and the goal computed right."""

import math

import numpy as np
import pandas as pd
import pytest

from analysis.metrics import add_alignment_errors
from app.observers import inverse_planning
from app.observers.instrument_grid import (
    CONFIGURED,
    NOISE_LEVELS_DEG,
    family_answers,
    goal_met,
    noise_levels,
    participant_differences,
    participants_needed,
    population_answers,
    run_grid,
    seed_pairs,
    summarise_grid,
    with_click_noise,
)
from app.observers.simulated_study import participant_diffs, simulate_participants
from app.prediction_view import TARGET_STEP_PX, click_direction_sd_deg, prediction_view
from tests.analysis.fixed_data import small_bank, trial_bank
from tests.observers.observer_inputs import CONFIG, bank_with_examples


def test_click_noise_adds_in_quadrature_to_each_presets_own():
    noisy = with_click_noise(CONFIG, 5.0)
    for preset in ("coarse_noise", "precise_noise"):
        own = getattr(CONFIG, preset).direction_sd_deg.value
        got = getattr(noisy, preset).direction_sd_deg
        assert got.value == pytest.approx(math.hypot(own, 5.0))
        assert "5 deg" in got.source
        assert getattr(noisy, preset).speed_weber_fraction == getattr(
            CONFIG, preset).speed_weber_fraction
    rng = np.random.default_rng(0)
    draws = [inverse_planning.direction_noise(noisy.precise_noise, rng) for _ in range(4000)]
    assert np.degrees(np.std(draws)) == pytest.approx(math.hypot(0.5, 5.0), rel=0.05)


@pytest.mark.parametrize("pair", [0, 1])
def test_the_grid_scores_simulated_participants_as_the_export_path_does(pair):
    bank = trial_bank(bank_with_examples())
    index, family = family_answers(bank)
    lean = population_answers(bank, "coarse", 5, 4, 3, CONFIG, index)
    frame = simulate_participants(bank, "coarse", 5, 4, 3, False, CONFIG)
    for model in ("ours", "vae"):  # the export path, re-scored with this pair's answers
        answer = {t.trial_id: np.asarray(t.predictions[model][pair].actions)
                  for t in bank.by_id.values()}
        actions = np.stack([answer[t][s, j] for t, s, j in
                            frame[["trial_id", "start_index", "step"]].itertuples(index=False)])
        frame[f"{model}_vx"], frame[f"{model}_vy"] = actions[:, 0], actions[:, 1]
    expected = participant_diffs(add_alignment_errors(frame, ("ours", "vae")))
    for world in ("highway", "obstacle"):
        got = participant_differences(lean, family, pair, world)
        np.testing.assert_allclose(got, expected[expected["world"] == world]["diff"], atol=1e-12)


def test_the_grid_has_a_row_per_level_rerun_pair_world_and_reading():
    bank = trial_bank(small_bank(trials=4))
    grid = run_grid(bank, 3, CONFIG, n=4, replications=2, view_deg={"highway": 3.0,
                                                                    "obstacle": 9.0},
                    workers=1)
    levels = [CONFIGURED, *(f"{sd:g} deg" for sd in NOISE_LEVELS_DEG), "view"]
    assert list(dict.fromkeys(grid["noise"])) == levels
    assert len(grid) == len(levels) * 3 * len(seed_pairs(bank)) * 2 * 2
    view = grid[grid["noise"] == "view"].groupby("world")["click_sd_deg"].first()
    assert view.to_dict() == {"highway": 3.0, "obstacle": 9.0}
    assert grid.loc[grid["noise"] == CONFIGURED, "click_sd_deg"].isna().all()
    summary = summarise_grid(grid, 0.01)
    assert len(summary) == len(levels) * len(seed_pairs(bank)) * 2 * 2
    first = grid[grid["replication"] == 0].set_index(["noise", "pair", "world", "reading"])
    rates = grid[grid["replication"] > 0].groupby(["noise", "pair", "world", "reading"])[
        "passed"].mean()
    indexed = summary.set_index(["noise", "pair", "world", "reading"])
    pd.testing.assert_series_equal(indexed["pass_rate"], rates.reindex(indexed.index),
                                   check_names=False)
    assert (indexed["welch_t"] == first["welch_t"].reindex(indexed.index)).all()
    from statsmodels.stats.power import TTestIndPower

    for _, row in summary.iterrows():  # each cell's n follows its own effect size
        expected = participants_needed(TTestIndPower(), row["effect_size_d"], 0.01)
        assert row["n_for_power_0.8"] == expected or (math.isnan(expected)
                                                      and math.isnan(row["n_for_power_0.8"]))


def test_participants_needed_falls_with_the_effect_and_is_absent_without_one():
    from statsmodels.stats.power import TTestIndPower

    power = TTestIndPower()
    small, large = (participants_needed(power, d, 0.01) for d in (0.5, 1.5))
    assert large < small and small == math.ceil(power.solve_power(
        effect_size=0.5, alpha=0.01, power=0.8, alternative="larger"))
    assert math.isnan(participants_needed(power, -0.3, 0.01))
    assert math.isnan(participants_needed(power, float("nan"), 0.01))


def test_the_goal_needs_enough_pairs_passing_in_a_world():
    rows = [{"noise": "view", "reading": "absolute", "world": world, "pair": pair,
             "pass_rate": rate}
            for world, rates in (("highway", [0.9, 0.85, 0.8, 0.95, 0.2]),
                                 ("obstacle", [0.9, 0.5, 0.79, 0.99, 1.0]))
            for pair, rate in enumerate(rates)]
    rows.append({"noise": "view", "reading": "relative", "world": "obstacle", "pair": 0,
                 "pass_rate": 0.0})  # a sensitivity row never counts
    goal = goal_met(pd.DataFrame(rows), "view")
    assert goal["highway"] == {"pairs": 5, "share_passing": 0.8, "met": True}
    assert goal["obstacle"] == {"pairs": 5, "share_passing": 0.6, "met": False}


def test_noise_levels_name_the_view_per_world_only_when_measured():
    assert list(noise_levels(None)) == [CONFIGURED, "2 deg", "5 deg", "10 deg", "20 deg"]
    assert noise_levels({"highway": 1.2})["view"] == {"highway": 1.2}


def test_the_view_level_is_a_clicks_spread_at_the_views_own_scale():
    bank = small_bank()
    for world_bank in bank["worlds"].values():
        view = prediction_view(world_bank)
        # the view makes the median true step span TARGET_STEP_PX, whatever the world's metres
        assert view.median_step_px == pytest.approx(TARGET_STEP_PX, rel=1e-3)
        expected = math.degrees(math.atan2(CONFIG.click_sd_px.value, TARGET_STEP_PX))
        assert click_direction_sd_deg(world_bank, CONFIG.click_sd_px.value) == pytest.approx(
            expected, rel=1e-3)
    assert CONFIG.click_sd_px.value == 3.0 and "Soukoreff" in CONFIG.click_sd_px.source
