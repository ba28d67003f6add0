"""The design goal (issue 30): the observer family reads the scene, the primary test treats
trials as random and holds its level, and the goal tells a design that can confirm the
hypothesis from one that cannot."""

import copy
import math

import numpy as np
import pytest
from scipy import stats

from analysis.crossed import crossed_test, crossed_verdicts, min_f_prime
from app.observers import inverse_planning
from app.observers.design_goal import Design, goal_met, run_design_goal, simulate_verdicts
from app.observers.family import (
    COARSE_VARIANTS,
    discriminability,
    expected_trial_diffs,
    observer_options,
    world_answers,
)
from app.study.config import StudyConfig, held_out_seeds
from app.study.trials import TrialRecord
from app.worlds.intents import scene_routes
from tests.analysis.fixed_data import OBSTACLE_SCENE, obstacle_segment, payload, trial_bank
from tests.observers.observer_inputs import CONFIG, QUIET, bank_with_examples


def crossed_sample(rng, people: int, clips: int, effect: float, clip_sd: float) -> tuple:
    """Every participant answers every clip: effect + clip effect + person effect + noise."""
    clip_effect = rng.normal(0, clip_sd, clips)
    person_effect = rng.normal(0, 0.5, people)
    ids = np.array([(p, c) for p in range(people) for c in range(clips)])
    values = effect + clip_effect[ids[:, 1]] + person_effect[ids[:, 0]] + rng.normal(
        0, 1, len(ids))
    return values, ids[:, 0], ids[:, 1]


def test_min_f_prime_is_clarks_formula_on_a_small_table():
    rng = np.random.default_rng(0)
    values, people, clips = crossed_sample(rng, 6, 5, 0.8, 0.3)
    got = crossed_test(values, people, clips)
    t1 = stats.ttest_1samp([values[people == p].mean() for p in range(6)], 0).statistic
    t2 = stats.ttest_1samp([values[clips == c].mean() for c in range(5)], 0).statistic
    f1, f2 = t1 ** 2, t2 ** 2
    df = (f1 + f2) ** 2 / (f1 ** 2 / 4 + f2 ** 2 / 5)
    assert got.t_participants == pytest.approx(t1) and got.t_trials == pytest.approx(t2)
    assert got.min_f == pytest.approx(f1 * f2 / (f1 + f2)) and got.df == pytest.approx(df)
    assert got.p_two_sided == pytest.approx(stats.f.sf(f1 * f2 / (f1 + f2), 1, df))


def test_trials_as_a_random_factor_hold_the_level_where_participants_only_do_not():
    rng = np.random.default_rng(1)
    rows = [crossed_sample(rng, 22, 10, 0.0, 0.6) for _ in range(600)]
    values = np.array([r[0] for r in rows])
    result = min_f_prime(values, np.array([r[1] for r in rows]), np.array([r[2] for r in rows]))
    crossed_rate = np.mean(result["p_two_sided"] < 0.05)
    by_person = np.array([[v[r[1] == p].mean() for p in range(22)] for v, r in zip(values, rows,
                                                                                   strict=True)])
    naive_rate = np.mean(stats.ttest_1samp(by_person, 0, axis=1).pvalue < 0.05)
    assert crossed_rate <= 0.07  # min F' is conservative: at or under its level
    assert naive_rate > 0.15  # ignoring the clips' own effects finds effects that are not there


def test_verdicts_need_both_factors_to_agree():
    result = {"p_two_sided": np.array([0.001, 0.001, 0.5, 0.001]),
              "t_participants": np.array([-5.0, 5.0, -5.0, -5.0]),
              "t_trials": np.array([-4.0, 4.0, -4.0, 4.0])}
    assert crossed_verdicts(result, 0.01).tolist() == [-1, 1, 0, 0]


def test_the_scene_aware_observer_goes_round_an_obstacle_the_straight_one_enters():
    start, goal = [2.0, 5.0], [9.0, 5.0]  # the obstacle at (5, 5) lies in between
    scene = copy.deepcopy(OBSTACLE_SCENE)
    scene["goals"][3] = {"x_m": goal[0], "y_m": goal[1], "radius_m": 0.5, "label": "east"}
    p = payload(scene, obstacle_segment([1.0, 5.0], goal), [[4.0, 5.05]])
    routes = scene_routes(scene)
    clearance = 0.8 + 0.3
    straight = inverse_planning.predict("coarse", p, np.random.default_rng(0), config=QUIET)
    around = inverse_planning.predict("coarse_scene", p, np.random.default_rng(0), config=QUIET)
    gap = np.linalg.norm(np.concatenate([straight[0], around[0]]) - [5.0, 5.0], axis=1)
    assert gap[:3].min() < clearance <= gap[3:].min() + 0.05
    assert routes.distance(3, np.array(start)) > 7.0  # longer than the straight 7 m


def test_the_momentum_observer_starts_between_the_heading_it_sees_and_the_goal():
    p = payload(OBSTACLE_SCENE, obstacle_segment([5.0, 8.0], [9.0, 9.0]), [[5.0, 8.0]])
    p["start_states"][0]["robot_heading"] = -math.pi / 2  # drawn heading up the screen
    blend = inverse_planning.predict("coarse_momentum", p, np.random.default_rng(0),
                                     config=QUIET)
    straight = inverse_planning.predict("coarse", p, np.random.default_rng(0), config=QUIET)
    angle = [math.atan2(*(c[0, 0] - [5.0, 8.0])[::-1]) for c in (straight, blend)]
    assert -math.pi / 2 < angle[1] < angle[0]


def test_observer_options_are_weighted_by_the_posterior_and_never_read_a_model():
    bank = trial_bank(bank_with_examples())
    trial = bank.trials_of("obstacle", "main")[0]
    from app.observers.simulated_study import simulated_payload

    p = simulated_payload(bank, trial)
    options = observer_options("coarse", p, trial, CONFIG)
    assert sum(w for w, _ in options) == pytest.approx(1.0)
    scrambled = trial.model_copy(update={"predictions": {
        k: [a.model_copy(update={"actions": (np.asarray(a.actions) * -1).tolist()}) for a in v]
        for k, v in trial.predictions.items()}})
    again = observer_options("coarse", p, scrambled, CONFIG)
    assert all(np.array_equal(a, b) for (_, a), (_, b) in zip(options, again, strict=True))


def answered_by(bank, ours_from: str, vae_from: str) -> object:
    """The bank with every seed's Ours answers set to one observer's and the VAE's to another's."""
    from app.observers.simulated_study import simulated_payload

    for world in bank.data.worlds:
        for trial in bank.trials_of(world, "main"):
            p = simulated_payload(bank, trial)
            answers = {}
            for model, variant in (("ours", ours_from), ("vae", vae_from)):
                options = observer_options(variant, p, trial, CONFIG)
                best = max(options, key=lambda o: o[0])[1]
                answers[model] = [a.model_copy(update={"actions": best.tolist()})
                                  for a in trial.predictions[model]]
            trial.predictions.update(answers)
    return bank


def test_the_goal_is_met_where_ours_answers_as_coarse_people_and_the_vae_as_the_policy():
    bank = answered_by(trial_bank(bank_with_examples()), "coarse", "precise")
    result = run_design_goal(bank, Design(12, 8, 4), CONFIG, {"highway": 2.9, "obstacle": 2.9},
                             [1], reps=60, search=False)
    rows = [r for r in result["rows"] if r["arm"] == "all" and r["seeds"] == "family"]
    p_ours = {r["world"] + "/" + r["variant"]: r["p_ours"] for r in rows}
    p_vae = {r["world"] + "/" + r["variant"]: r["p_vae"] for r in rows}
    assert p_ours["highway/coarse"] >= 0.8 and p_vae["highway/precise"] >= 0.8
    assert p_ours["highway/precise"] == 0.0
    flipped = answered_by(trial_bank(bank_with_examples()), "precise", "coarse")
    again = run_design_goal(flipped, Design(12, 8, 4), CONFIG, {"highway": 2.9}, [1], reps=60,
                            search=False)
    assert not any(again["goal_met"].values())
    assert {"family", "held-out family", "pair 1"} <= {r["seeds"] for r in again["rows"]}


def test_resampled_trials_lower_power_where_the_effect_lives_in_few_clips():
    bank = answered_by(trial_bank(bank_with_examples()), "coarse", "precise")
    answers = world_answers(bank, "obstacle", CONFIG, 2.9)
    family = np.arange(len(answers.seeds))
    pool = np.arange(len(answers.trial_ids))
    rng = np.random.default_rng(0)
    out = simulate_verdicts(answers, "coarse", family, Design(30, 4, 4), pool, 80, 0.01, rng)
    assert np.mean(out["crossed"] == -1) <= np.mean(out["participants_only"]) + 0.05


def test_discriminability_is_the_smallest_coarse_gap_to_precise():
    answers = world_answers(trial_bank(bank_with_examples()), "highway", CONFIG, 2.9)
    seeds = np.array([0])
    precise = expected_trial_diffs(answers, "precise", seeds)
    gaps = np.array([precise - expected_trial_diffs(answers, v, seeds) for v in COARSE_VARIANTS])
    assert np.allclose(discriminability(answers, seeds), gaps.min(axis=0))


def test_goal_met_asks_every_coarse_variant_and_the_precise_observer():
    import pandas as pd

    rows = pd.DataFrame([{"variant": v, "p_ours": 0.9} for v in COARSE_VARIANTS]
                        + [{"variant": "precise", "p_ours": 0.0}])
    assert goal_met(rows, 0.01)
    rows.loc[rows["variant"] == "coarse_momentum", "p_ours"] = 0.5
    assert not goal_met(rows, 0.01)


def study_with(**changes) -> dict:
    import yaml

    from app.settings import REPO_ROOT

    data = yaml.safe_load((REPO_ROOT / "study_configs" / "paper_study.yaml").read_text())
    data.update(changes)
    return data


def test_the_discriminability_rule_names_the_seeds_it_may_read():
    selection = {"rule": "discriminability", "candidates_per_trial": 3, "random_arm_trials": 15}
    with pytest.raises(ValueError, match="selection_seeds"):
        StudyConfig.model_validate(study_with(main_trial_selection=selection))
    with pytest.raises(ValueError, match="selection_seeds: must be some, not all"):
        StudyConfig.model_validate(study_with(main_trial_selection=selection | {
            "selection_seeds": [0, 1, 2, 3, 4]}))
    config = StudyConfig.model_validate(study_with(main_trial_selection=selection | {
        "selection_seeds": [0, 1, 2]}))
    assert held_out_seeds(config) == [3, 4]
    assert config.main_trial_selection.arm_sizes(30) == {"random": 15, "discriminability": 15}


def test_exploratory_worlds_are_worlds_of_the_study_with_a_reason():
    with pytest.raises(ValueError, match="exploratory_worlds: roundabout not in worlds"):
        StudyConfig.model_validate(study_with(exploratory_worlds={
            "roundabout": "no clip separates the hypotheses here"}))
    plain = StudyConfig.model_validate(study_with(exploratory_worlds={}))
    assert "exploratory_worlds" not in plain.model_dump()  # same config hash as before the key


def test_the_rule_keeps_the_highest_scored_candidates_per_label():
    from app.bank.build import main_trials

    def trial(label: int) -> TrialRecord:
        return TrialRecord.model_construct(robot_label=label, arm="")

    pool = [trial(0), trial(0), trial(1), trial(0), trial(1)]
    chosen = main_trials(pool, {"random": 1, "discriminability": 2}, [0.1, 0.9, 0.2, 0.5])
    assert [t.arm for t in chosen] == ["random", "discriminability", "discriminability"]
    assert chosen[1] is not pool[1] and chosen[1].robot_label == 0
    assert chosen[2].robot_label == 1


def test_power_reports_trials_random_beside_participants_only(tmp_path):
    import json

    import pandas as pd

    from app.observers.simulated_study import run_power

    bank = tmp_path / "bank.json"
    bank.write_text(json.dumps(bank_with_examples()))
    summary = run_power(bank, "coarse", 4, tmp_path / "p", n_max=6, pool=12, reps=50,
                        observers=CONFIG)
    curve = pd.read_csv(tmp_path / "p" / "power.csv")
    assert curve["power_trials_random"].between(0, 1).all()
    assert set(summary["n_for_power_0.8_trials_random"]) == {"highway", "obstacle"}
    run_power(bank, "random", 4, tmp_path / "r", n_max=4, pool=8, reps=20, observers=CONFIG)
    assert pd.read_csv(tmp_path / "r" / "power.csv")["power_trials_random"].isna().all()


def test_the_rule_never_reads_a_held_out_seed():
    bank = trial_bank(bank_with_examples())
    before = discriminability(world_answers(bank, "highway", CONFIG, 2.9), np.array([0]))
    for trial in bank.trials_of("highway", "main"):  # seed index 1 answers the opposite way
        held_out = trial.predictions["vae"][1]
        trial.predictions["vae"][1] = held_out.model_copy(update={
            "actions": (-np.asarray(held_out.actions)).tolist()})
    after = discriminability(world_answers(bank, "highway", CONFIG, 2.9), np.array([0]))
    assert np.array_equal(before, after)
    assert not np.array_equal(before, discriminability(
        world_answers(bank, "highway", CONFIG, 2.9), np.array([0, 1])))


def test_the_scene_aware_observer_keeps_a_recorded_car_on_the_drawn_road():
    from app.worlds.intents import Road, TurnIntents

    road = Road({"cell_m": 1.0, "x0_m": 0.0, "y0_m": 0.0,
                 "runs": [[row, 0, 60] for row in range(0, 3)]})  # a road 3 m wide along x
    track = np.array([[x, 2.5] for x in np.arange(0.0, 6.0, 1.0)])
    sharp = [np.array([[5 * np.cos(a), 5 * np.sin(a)] for a in np.linspace(0, 1.5, 7)])]
    starts = np.array([[5.0, 2.5]])  # turning 0.3 rad a step leaves the road by step 2
    for intents, stays in ((TurnIntents(0.5, track, sharp), False),
                           (TurnIntents(0.5, track, sharp, road), True)):
        move, position = intents.course(1, starts, 1.0), starts[0]
        ends = []
        for _ in range(3):
            direction, length = move(0, position)
            position = position + length * direction / np.linalg.norm(direction)
            ends.append(road.contains(position))
        assert all(ends) is stays
