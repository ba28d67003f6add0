"""Attention checks are chosen fairly (issue 30 item 6): an attentive observer's exact pass
probability matches a Monte-Carlo of the same observer clicked through the server's check; a
check goes where going straight on fails; where no candidate is fair the fairest is kept and
meta.json says the rule was not met; the new key leaves the shipped study served."""

from pathlib import Path

import numpy as np
import pytest
import yaml

from app.bank.attention import choose_checks, pass_probability, score_candidate
from app.bank.bundle import shipped_dir
from app.bank.verify import check_design, open_bundle
from app.observers.family import GOAL_VARIANTS, click_sd_rad, observer_options
from app.prediction_view import VIEW_FIELDS, click_direction_sd_deg
from app.server.flow.validation import attention_passed
from app.settings import Settings
from app.study.config import AttentionChecks, bank_design, load_study_config
from app.study.trial_payload import world_trial_payload
from tests.analysis.fixed_data import trial_bank
from tests.conftest import REPO
from tests.observers.observer_inputs import CONFIG, bank_with_examples, config_with

RULE = AttentionChecks()
STEPS = 3  # bank_with_examples' steps_to_predict
DRAWS = 4000
WIDE_VIEW_SD_DEG = 40.0  # wide enough that pass probabilities lie between 0 and 1


def rotated(moves: np.ndarray, turns: np.ndarray) -> np.ndarray:
    """Moves [K, 2] each rotated by its angle [K] (rad)."""
    c, s = np.cos(turns), np.sin(turns)
    return np.stack([c * moves[:, 0] - s * moves[:, 1], s * moves[:, 0] + c * moves[:, 1]],
                    axis=-1)


def simulated_pass_rate(world, trial, variant: str, rng: np.random.Generator) -> float:
    """Share of DRAWS simulated observers the server's check passes: each acts on one intent
    drawn by its weight; each first click is that intent's move turned by an independent
    Gaussian error of the variant's click SD."""
    options = observer_options(variant, world_trial_payload(world, STEPS, trial), trial, CONFIG)
    weights = np.array([w for w, _ in options])
    sd = click_sd_rad(variant, CONFIG, WIDE_VIEW_SD_DEG)
    starts = np.array([s.robot for s in trial.start_states])
    passed = 0
    for intent in rng.choice(len(options), size=DRAWS, p=weights / weights.sum()):
        moves = options[intent][1][:, 0] * world.dt_s
        clicks = starts + rotated(moves, rng.normal(0.0, sd, len(starts)))
        passed += attention_passed(RULE, trial, clicks[:, None])
    return passed / DRAWS


@pytest.mark.parametrize(("world", "index"), [("highway", 1), ("obstacle", 0),
                                              ("obstacle", 3)])
def test_the_exact_pass_probability_matches_a_monte_carlo_of_the_same_observer(world, index):
    world_bank = trial_bank(bank_with_examples()).world(world)
    trial = world_bank.trials[index]
    exact = score_candidate(world_bank, STEPS, trial, RULE, CONFIG, WIDE_VIEW_SD_DEG)
    rng = np.random.default_rng(index)
    for variant in GOAL_VARIANTS:
        p = exact.pass_probability[variant]
        simulated = simulated_pass_rate(world_bank, trial, variant, rng)
        assert abs(simulated - p) <= 4 * np.sqrt(p * (1 - p) / DRAWS) + 2e-3, (variant, p,
                                                                               simulated)


def test_starts_pass_or_fail_together_through_the_intent_chosen_once_per_trial():
    truth = np.array([[1.0, 0.0]] * 5)
    aligned = truth[:, None, :].repeat(3, axis=1)
    across = rotated(truth, np.full(5, np.pi / 2))[:, None, :].repeat(3, axis=1)
    p = pass_probability([(0.5, aligned), (0.5, across)], truth, np.radians(3.0), RULE)
    assert p == pytest.approx(0.5, abs=1e-9)  # independent starts would give 6/32


def view_sd_deg(world) -> float:
    """The click noise of the view a world's trials are shown in (as the bank computes it)."""
    return click_direction_sd_deg(world.model_dump(include=VIEW_FIELDS), CONFIG.click_sd_px.value)


def test_a_check_goes_where_going_straight_on_fails_though_fairer_ones_let_it_pass():
    world = trial_bank(bank_with_examples()).world("highway")
    scores = [score_candidate(world, STEPS, t, RULE, CONFIG, view_sd_deg(world))
              for t in world.trials]
    assert not any(s.cv_fails for s in scores) and min(s.fairness for s in scores) >= 0.95
    least_fair = int(np.argmin([s.fairness for s in scores]))
    trials = list(world.trials)
    cv = np.asarray(trials[least_fair].cv_actions)
    trials[least_fair] = trials[least_fair].model_copy(  # going straight on turns across
        update={"cv_actions": rotated(cv.reshape(-1, 2), np.full(cv.size // 2, np.pi / 2))
                .reshape(cv.shape).tolist()})
    candidates = world.model_copy(update={"trials": trials})
    chosen, meta = choose_checks(candidates, world, STEPS, RULE, CONFIG)
    assert chosen == [least_fair]
    assert meta["rule_met"] and meta["fair_and_cv_fails"] == 1
    check = meta["chosen"][0]
    assert check["cv_fails"] and check["rule_met"] and min(check["cv_vs_policy_deg"]) > 45
    assert set(check["pass_probability"]) == set(GOAL_VARIANTS)


def test_with_no_fair_candidate_the_fairest_is_kept_and_meta_says_the_rule_was_not_met():
    noisy = config_with(click_sd_px__value=60.0)  # a click's direction off by some 45 deg
    world = trial_bank(bank_with_examples()).world("obstacle")
    chosen, meta = choose_checks(world, world, STEPS, RULE, noisy)
    sd = click_direction_sd_deg(world.model_dump(include=VIEW_FIELDS), 60.0)
    fairness = [score_candidate(world, STEPS, t, RULE, noisy, sd).fairness
                for t in world.trials]
    assert max(fairness) < RULE.min_attentive_pass_rate and meta["fair"] == 0
    assert chosen == [int(np.argmax(fairness))]
    assert not meta["rule_met"] and not meta["chosen"][0]["rule_met"]
    assert len(meta["chosen"][0]["cv_vs_policy_deg"]) == len(world.trials[0].start_states)


def test_the_pass_rate_key_dumps_as_before_at_its_default_and_shapes_the_bank_otherwise():
    assert AttentionChecks(min_attentive_pass_rate=0.95).model_dump() == RULE.model_dump()
    assert "min_attentive_pass_rate" not in RULE.model_dump()
    study = yaml.safe_load((REPO / "study_configs" / "paper_study.yaml").read_text())
    assert study["attention_checks"]["min_attentive_pass_rate"] == RULE.min_attentive_pass_rate
    stricter = study | {"attention_checks": study["attention_checks"]
                        | {"min_attentive_pass_rate": 0.99}}
    assert bank_design(stricter)["attention_checks"] != bank_design(study)["attention_checks"]


def test_the_shipped_paper_bundle_still_shapes_the_bank_the_live_config_asks_for():
    configs = REPO / "study_configs"
    config = load_study_config(Settings(configs_dir=configs), "paper_study")
    check_design(open_bundle(shipped_dir(configs, "paper_study")), config,
                 Path(configs) / "paper_study.yaml")


def test_without_a_check_that_straight_fails_a_fair_one_where_straight_comes_nearest_is_kept():
    from app.bank.attention import CandidateScore, ranked_checks

    def score(angles, fairness):
        return CandidateScore(angles, False, {"coarse": fairness, "precise": 1.0})

    scores = [score([1, 2, 3, 4, 5], 0.999), score([1, 2, 3, 30, 40], 0.97),
              score([50, 60, 70, 80, 90], 0.5)]
    assert ranked_checks(scores, RULE) == [1]
