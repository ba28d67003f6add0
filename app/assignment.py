"""Balanced assignment: the least-used candidates first, ties broken at random.

The study server assigns world orders and trials this way (app/study/plan.py), and the
simulated studies (app/observers/simulated_study.py) assign their simulated participants'
trials the same way, so a simulated study samples trials as the real one does.
"""

import numpy as np


def least_used(candidates: list, counts: dict, k: int, rng: np.random.Generator) -> list:
    """The k candidates with the lowest counts, ties broken at random."""
    noise = rng.random(len(candidates))
    keys = np.lexsort((noise, [counts.get(c, 0) for c in candidates]))
    return [candidates[i] for i in keys[:k]]


def pick_trials(trial_ids: list, exposure: dict, k: int, rng: np.random.Generator) -> list:
    """One participant's k main trials of a world: the least seen, in random order."""
    chosen = least_used(trial_ids, exposure, k, rng)
    rng.shuffle(chosen)
    return chosen
