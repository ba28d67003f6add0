"""Which candidate segments become attention checks (issue 30 item 6).

A check must catch a participant who is not watching, and must never reject one who is:
Prolific lets a researcher reject a submission on failed checks. So a candidate meets the
rule when
- constant velocity fails it: going straight on as the robot went (the bank's `cv_actions`)
  from each start state puts fewer than `min_passing_starts` first moves within
  `max_angle_deg` of the robot's true first move, the server's own check
  (app/study/clicks.py `check_passed`); and
- it is fair: every attentive observer of the family (app/observers/family.py
  GOAL_VARIANTS: each coarse variant and the precise one) passes it with probability at
  least `min_attentive_pass_rate`, at the view's click noise.

An observer's pass probability is exact. It acts on one intent per trial (its options'
weights); given the intent, each first click's direction is off by an independent Gaussian
error of the variant's SD, so a start passes with the wrapped normal's mass within the
threshold, and the number of passing starts is Poisson-binomial:
P(pass) = sum over intents of weight x P(at least `min_passing_starts` starts pass).
"""

import math
from dataclasses import dataclass

import numpy as np
from scipy.special import ndtr
from tqdm import tqdm

from app.core.alignment import ZERO_SPEED_MPS
from app.observers.config import ObserversConfig
from app.observers.family import GOAL_VARIANTS, angles, click_sd_rad, observer_options
from app.prediction_view import view_click_sd_deg
from app.study.clicks import check_passed
from app.study.config import AttentionChecks
from app.study.trial_payload import world_trial_payload
from app.study.trials import TrialRecord, WorldBank

WRAPS = np.arange(-2, 3)  # turns of the wrapped normal summed: exact (double) to an SD of 90 deg


@dataclass(frozen=True)
class CandidateScore:
    """How one candidate fares as a check: constant velocity against the policy, and every
    attentive observer's chance to pass."""

    cv_vs_policy_deg: list[float]  # per start: angle between the two first moves
    cv_fails: bool
    pass_probability: dict[str, float]  # per attentive observer

    @property
    def fairness(self) -> float:
        """The least likely attentive observer's pass probability."""
        return min(self.pass_probability.values())

    def meets_rule(self, rule: AttentionChecks) -> bool:
        """Failed by constant velocity and fair to every attentive observer."""
        return self.cv_fails and self.fairness >= rule.min_attentive_pass_rate


def within_probability(offset: np.ndarray, sd: float, max_angle: float) -> np.ndarray:
    """P(|offset + e| <= max_angle) with angles wrapped, for e ~ N(0, sd^2); radians."""
    offset = np.angle(np.exp(1j * np.asarray(offset, dtype=np.float64)))[..., None]
    shift = 2 * np.pi * WRAPS
    return (ndtr((max_angle - offset + shift) / sd)
            - ndtr((-max_angle - offset + shift) / sd)).sum(axis=-1)


def at_least(probabilities: np.ndarray, count: int) -> float:
    """P(at least `count` of independent events with these probabilities happen)."""
    distribution = np.array([1.0])
    for p in probabilities:
        distribution = np.convolve(distribution, [1.0 - p, p])
    return float(distribution[count:].sum())


def pass_probability(options: list[tuple[float, np.ndarray]], truth: np.ndarray, sd: float,
                     rule: AttentionChecks) -> float:
    """P(an observer answering with `options` (weight, actions [K, n, 2]) passes a check whose
    true first moves are `truth` [K, 2]), its first clicks off by N(0, sd^2) radians."""
    has_direction = np.hypot(truth[:, 0], truth[:, 1]) > ZERO_SPEED_MPS
    total = sum(weight for weight, _ in options)
    passed = 0.0
    for weight, actions in options:
        offset = angles(np.asarray(actions)[:, 0]) - angles(truth)
        within = np.where(has_direction,
                          within_probability(offset, sd, math.radians(rule.max_angle_deg)), 0.0)
        passed += weight / total * at_least(within, rule.min_passing_starts)
    return passed


def cv_vs_policy_deg(trial: TrialRecord) -> np.ndarray:
    """Per start state, the angle [deg] between constant velocity's and the policy's first move."""
    cv, policy = first_moves(trial.cv_actions), first_moves(trial.policy_actions)
    turn = np.angle(np.exp(1j * (angles(cv) - angles(policy))))
    return np.degrees(np.abs(turn))


def first_moves(actions: list) -> np.ndarray:
    """The first of each start state's actions [K, 2]."""
    return np.asarray(actions, dtype=np.float64)[:, 0]


def score_candidate(world: WorldBank, steps_to_predict: int, trial: TrialRecord,
                    rule: AttentionChecks, observers: ObserversConfig,
                    view_sd_deg: float) -> CandidateScore:
    """Constant velocity's verdict and every attentive observer's pass probability on `trial`."""
    payload = world_trial_payload(world, steps_to_predict, trial)
    truth = first_moves(trial.policy_actions)
    cv_moves = first_moves(trial.cv_actions) * world.dt_s  # as if clicked
    return CandidateScore(
        cv_vs_policy_deg=[round(float(a), 2) for a in cv_vs_policy_deg(trial)],
        cv_fails=not check_passed(rule, cv_moves, truth),
        pass_probability={variant: pass_probability(
            observer_options(variant, payload, trial, observers), truth,
            click_sd_rad(variant, observers, view_sd_deg), rule) for variant in GOAL_VARIANTS})


def ranked_checks(scores: list[CandidateScore], rule: AttentionChecks) -> list[int]:
    """Candidate indices to keep as the world's `per_world` checks: those that meet the rule
    first, the fairest first among equals; failing that, fair ones where going straight comes
    nearest to failing first, then the fairest."""
    def key(i: int) -> tuple:
        score = scores[i]
        fair = score.fairness >= rule.min_attentive_pass_rate
        nearest = -cv_margin_deg(score, rule) if fair and not score.meets_rule(rule) else 0.0
        return not score.meets_rule(rule), not fair, nearest, -score.fairness

    return sorted(range(len(scores)), key=key)[: rule.per_world]


def cv_margin_deg(score: CandidateScore, rule: AttentionChecks) -> float:
    """The angle going straight must be off at enough starts to fail the check: it fails when
    this exceeds `max_angle_deg` (the (K - min_passing_starts + 1)-th largest start angle)."""
    angles_deg = sorted(score.cv_vs_policy_deg, reverse=True)
    return angles_deg[len(angles_deg) - rule.min_passing_starts]


def choose_checks(candidates: WorldBank, served: WorldBank, steps_to_predict: int,
                  rule: AttentionChecks, observers: ObserversConfig) -> tuple[list[int], dict]:
    """The indices of `candidates.trials` to keep as checks, and meta.json's account of them;
    clicks carry the click noise of the view `served` (the world's main trials) is shown in."""
    view_sd_deg = view_click_sd_deg(served, observers.click_sd_px.value)
    scores = [score_candidate(candidates, steps_to_predict, t, rule, observers, view_sd_deg)
              for t in tqdm(candidates.trials, desc=f"attention checks {candidates.world}",
                            unit="candidate")]
    chosen = ranked_checks(scores, rule)
    meta = attention_meta(scores, chosen, rule, view_sd_deg)
    if not meta["rule_met"]:
        tqdm.write(f"{candidates.world}: no attention candidate that constant velocity fails "
                   f"is fair to every attentive observer; kept a fair one where going straight "
                   f"comes nearest to failing, else the fairest (meta.json)")
    return chosen, meta


def attention_meta(scores: list[CandidateScore], chosen: list[int], rule: AttentionChecks,
                   view_sd_deg: float) -> dict:
    """The rule, how many candidates met each half of it, and per chosen check (in check
    order) its angles, pass probabilities and verdicts."""
    def check(score: CandidateScore) -> dict:
        return {"cv_vs_policy_deg": score.cv_vs_policy_deg, "cv_fails": score.cv_fails,
                "pass_probability": {v: round(p, 4) for v, p in score.pass_probability.items()},
                "rule_met": score.meets_rule(rule)}

    fair = [s.fairness >= rule.min_attentive_pass_rate for s in scores]
    return {
        "max_angle_deg": rule.max_angle_deg, "min_passing_starts": rule.min_passing_starts,
        "min_attentive_pass_rate": rule.min_attentive_pass_rate,
        "view_click_sd_deg": round(view_sd_deg, 3), "candidates": len(scores),
        "fair": sum(fair), "cv_fails": sum(s.cv_fails for s in scores),
        "fair_and_cv_fails": sum(s.meets_rule(rule) for s in scores),
        "rule_met": all(scores[i].meets_rule(rule) for i in chosen),
        "chosen": [check(scores[i]) for i in chosen],
    }
