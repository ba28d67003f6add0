"""Balanced assignment: the least-used candidates first, ties broken at random.

Main trials come in selection arms (random, models_disagree: app/study/config.py
MainTrialSelection); each participant gets every arm in proportion to its size, so every
participant's results can be read per arm.

The study server assigns world orders and trials this way (app/server/flow/plan.py), and the
simulated studies (app/observers/simulated_study.py) assign their simulated participants'
trials the same way, so a simulated study samples trials as the real one does.
"""

import numpy as np


def least_used(candidates: list, counts: dict, k: int, rng: np.random.Generator) -> list:
    """The k candidates with the lowest counts, ties broken at random."""
    noise = rng.random(len(candidates))
    keys = np.lexsort((noise, [counts.get(c, 0) for c in candidates]))
    return [candidates[i] for i in keys[:k]]


def arm_quotas(arm_sizes: dict[str, int], k: int) -> dict[str, int]:
    """How many of a participant's k main trials come from each arm: in proportion to the arms'
    sizes (largest remainders; ties to the arm named first), never more than an arm holds."""
    total = sum(arm_sizes.values())
    exact = {arm: k * size / total for arm, size in arm_sizes.items()}
    quotas = {arm: int(share) for arm, share in exact.items()}
    by_remainder = sorted(arm_sizes, key=lambda arm: quotas[arm] - exact[arm])
    for arm in by_remainder[: k - sum(quotas.values())]:
        quotas[arm] += 1
    return quotas


def pick_by_arm(trials: list[tuple[str, str]], exposure: dict, k: int,
                rng: np.random.Generator) -> list[str]:
    """One participant's k main trials of a world from (trial id, arm) pairs: each arm gives its
    quota (`arm_quotas`), the least seen within the arm; in random order."""
    arms: dict[str, list[str]] = {}
    for trial_id, arm in trials:
        arms.setdefault(arm, []).append(trial_id)
    quotas = arm_quotas({arm: len(ids) for arm, ids in arms.items()}, k)
    chosen = [tid for arm, ids in arms.items() for tid in least_used(ids, exposure, quotas[arm],
                                                                     rng)]
    rng.shuffle(chosen)
    return chosen
