"""The pre-registered observer family as answers to a bank's main trials, ready to score.

Variants (parameters and sources: study_configs/observers.yaml; none reads a model):
- coarse: infers the robot's intent (inverse planning) and moves straight the way it goes;
- coarse_scene: the same intent read into the scene: Obstacle along the shortest way around
  the obstacles; a recorded world turning no further than it must to stay on the road the
  scene draws; in Highway the lane course already follows the road, so there it answers as
  coarse;
- coarse_momentum: the intent blended with the motion seen (representational momentum);
- precise: the world's own policy from each start state (the bank's `policy_actions`);
- constant_velocity: keeps going as the robot went (a named observer without an intent,
  reported, never part of the goal).

A coarse observer's answer is a mixture: one noise-free walk per intent it may act on,
weighted by its posterior (or its mode). A simulated click then rotates the chosen walk's
move by the observer's direction noise (perceptual, combined in quadrature with the view's
click noise). Speed noise is left out: alignment error is a cosine and does not see it.
"""

import math
from dataclasses import dataclass

import numpy as np

from app.core.alignment import has_direction
from app.core.contracts import COARSE_OBSERVERS
from app.observers import inverse_planning as ip
from app.observers.config import NoiseConfig, ObserversConfig
from app.study.clicks import clicks_to_actions, robot_starts
from app.study.trial_payload import world_trial_payload
from app.study.trials import TrialBank, TrialRecord, WorldBank

COARSE_VARIANTS = COARSE_OBSERVERS
GOAL_VARIANTS = (*COARSE_VARIANTS, "precise")
VARIANTS = (*GOAL_VARIANTS, "constant_velocity")


@dataclass(frozen=True)
class WorldAnswers:
    """Every variant's answers to one world's main trials, as angles against every model seed.

    delta[variant]: observer angle minus model angle [T, J, 2 models, S seeds, K, n] (J: the
    variant's options, padded with weight 0); weights[variant] [T, J]; valid [T, 2, S, K, n]:
    model actions with a direction; sd_rad[variant]: a click's direction SD."""

    world: str
    trial_ids: list[str]
    arms: np.ndarray
    seeds: list[int]
    variants: tuple[str, ...]
    delta: dict[str, np.ndarray]
    weights: dict[str, np.ndarray]
    valid: np.ndarray
    sd_rad: dict[str, float]


def observer_options(variant: str, payload: dict, trial: TrialRecord,
                     observers: ObserversConfig) -> list[tuple[float, np.ndarray]]:
    """(weight, actions [K, n, 2] m/s) of each answer `variant` may give to a trial."""
    if variant == "precise":
        return [(1.0, np.asarray(trial.policy_actions, dtype=np.float64))]
    if variant == "constant_velocity":
        return [(1.0, np.asarray(trial.cv_actions, dtype=np.float64))]
    return coarse_options(variant, payload, robot_starts(trial), observers)


def coarse_options(variant: str, payload: dict, starts: np.ndarray,
                   observers: ObserversConfig) -> list[tuple[float, np.ndarray]]:
    """(weight, actions [K, n, 2] m/s) of each intent a coarse variant may act on, from the
    robot's start positions `starts` [K, 2] (m)."""
    relative = ip.reads_relative("coarse", observers)
    intents, reading = ip.trial_reading(payload, observers, relative, ip.preset_route(variant))
    weights = reading.posterior
    if observers.inference.intent_choice.value == "map":
        weights = np.eye(len(weights))[int(np.argmax(weights))]
    momentum = observers.momentum_weight.value if variant == "coarse_momentum" else None
    return [(float(w), clicks_to_actions(starts, intent_walk(payload, intents, int(label),
                                                             momentum), payload["dt_s"]))
            for w, label in zip(weights, reading.intents, strict=True) if w > 0]


def intent_walk(payload: dict, intents, label: int, momentum: float | None) -> np.ndarray:
    """Noise-free clicks [K, n, 2] of an observer acting on intent `label`."""
    move = ip.intent_course(payload, intents, label, 1.0, momentum)

    def next_move(i: int, k: int, position: np.ndarray) -> tuple[np.ndarray, float]:
        direction, length = move(i, position)
        return direction, ip.clip_length(payload, length)

    return ip.walk(payload, next_move)


def angles(actions: np.ndarray) -> np.ndarray:
    """Direction [rad] of actions [..., 2]."""
    return np.arctan2(actions[..., 1], actions[..., 0])


def variant_noise(variant: str, observers: ObserversConfig) -> NoiseConfig:
    """The perceptual noise of a variant: precise's for precise, coarse's for the others."""
    return observers.precise_noise if variant == "precise" else observers.coarse_noise


def click_sd_rad(variant: str, observers: ObserversConfig, view_sd_deg: float) -> float:
    """A click's direction SD: perception and pointing combined in quadrature."""
    perceptual = variant_noise(variant, observers).direction_sd_deg.value
    return math.radians(math.hypot(perceptual, view_sd_deg))


def model_angles(trial: TrialRecord) -> tuple[np.ndarray, np.ndarray]:
    """Angles and has-a-direction mask of every seed's answers [2, S, K, n]."""
    actions = np.array([[a.actions for a in trial.predictions[m]] for m in ("ours", "vae")],
                       dtype=np.float64)
    return angles(actions), has_direction(actions)  # without one an answer scores 1


def padded(options: list[list[tuple[float, np.ndarray]]]) -> tuple[np.ndarray, np.ndarray]:
    """Per trial options -> weights [T, J] and observer angles [T, J, K, n], padded."""
    width = max(len(o) for o in options)
    shape = np.asarray(options[0][0][1]).shape[:-1]
    weights, obs = np.zeros((len(options), width)), np.zeros((len(options), width, *shape))
    for t, trial_options in enumerate(options):
        for j, (w, actions) in enumerate(trial_options):
            weights[t, j], obs[t, j] = w, angles(actions)
    return weights / weights.sum(axis=1, keepdims=True), obs


def world_answers(bank: TrialBank, world: str, observers: ObserversConfig,
                  view_sd_deg: float, variants: tuple[str, ...] = VARIANTS) -> WorldAnswers:
    """Every variant's answers to the world's main trials, scored against every seed."""
    return answers_of(bank.world(world), bank.trials_of(world, "main"),
                      bank.data.steps_to_predict, observers, view_sd_deg, variants)


def answers_of(world: WorldBank, trials: list[TrialRecord], steps_to_predict: int,
               observers: ObserversConfig, view_sd_deg: float,
               variants: tuple[str, ...] = VARIANTS) -> WorldAnswers:
    """Every variant's answers to `trials` of one world's bank (also one being built)."""
    payloads = [world_trial_payload(world, steps_to_predict, t) for t in trials]
    model = [model_angles(t) for t in trials]
    model_angle = np.array([m[0] for m in model])  # [T, 2, S, K, n]
    delta, weights = {}, {}
    for variant in variants:
        w, obs = padded([observer_options(variant, p, t, observers)
                         for p, t in zip(payloads, trials, strict=True)])
        weights[variant] = w
        delta[variant] = obs[:, :, None, None] - model_angle[:, None]
    return WorldAnswers(
        world=world.world, trial_ids=[t.trial_id for t in trials],
        arms=np.array([t.arm for t in trials]),
        seeds=[a.seed for a in trials[0].predictions["ours"]], variants=variants, delta=delta,
        weights=weights, valid=np.array([m[1] for m in model]),
        sd_rad={v: click_sd_rad(v, observers, view_sd_deg) for v in variants})


def expected_trial_diffs(answers: WorldAnswers, variant: str, seeds: np.ndarray) -> np.ndarray:
    """Per trial, the variant's expected family err_ours - err_vae [T] on `seeds` (indices):
    E[1 - cos(d + e)] = 1 - cos(d) exp(-sd^2 / 2) for a Gaussian direction error e."""
    shrink = math.exp(-answers.sd_rad[variant] ** 2 / 2)
    delta = answers.delta[variant][:, :, :, seeds]  # [T, J, 2, S, K, n]
    err = np.where(answers.valid[:, None][:, :, :, seeds], 1 - np.cos(delta) * shrink, 1.0)
    per_option = err.mean(axis=(3, 4, 5))  # [T, J, 2]
    expected = (answers.weights[variant][..., None] * per_option).sum(axis=1)
    return expected[:, 0] - expected[:, 1]


def discriminability(answers: WorldAnswers, seeds: np.ndarray) -> np.ndarray:
    """Per trial [T]: the smallest, over the coarse variants, of the precise observer's expected
    family err_ours - err_vae minus the coarse variant's, on `seeds` (indices). Large where
    every coarse observer favours Ours more than a precise one does."""
    precise = expected_trial_diffs(answers, "precise", seeds)
    return np.min([precise - expected_trial_diffs(answers, v, seeds) for v in COARSE_VARIANTS],
                  axis=0)
