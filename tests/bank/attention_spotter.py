"""The attention-check spotting script of issue 22, run on what the browser receives.

A check used to place its start states a step beside or behind the robot, within 1.41
reachable radii (`max_step_m`) of its own start, where main trials' starts lie at least
1.99 (Highway) and 4.01 (Obstacle) radii away; a script that reads the starts' reach
flagged both checks. Two spotters:
- `threshold`: flag a trial whose start states all lie within THRESHOLD radii of the first;
- `closest`: in each world of a session, flag the trial whose starts lie closest.

    python -m tests.bank.attention_spotter var/trials/paper_study/bank.json
prints each spotter's hit rate over simulated sessions (each world: the check plus
`trials_per_world` main trials drawn at random), beside chance.
"""

import json
import sys
from pathlib import Path

import numpy as np

THRESHOLD = 1.5  # between the old checks' 1.41 and the main trials' 1.99


def reach(trial: dict, max_step_m: float) -> float:
    """How far the farthest start state lies from the first (the robot's own), in radii."""
    starts = np.array([s["robot"] for s in trial["start_states"]], dtype=np.float64)
    return float(np.linalg.norm(starts[1:] - starts[0], axis=1).max() / max_step_m)


def closest(reaches: list[float]) -> int:
    """The index the `closest` spotter flags."""
    return int(np.argmin(reaches))


def hit_rates(bank: dict, trials_per_world: int, sessions: int = 10_000,
              seed: int = 0) -> dict[str, dict[str, float]]:
    """Per world: each spotter's share of flagged trials that are checks, and chance."""
    rng = np.random.default_rng(seed)
    out = {}
    for name, world in bank["worlds"].items():
        step = world["max_step_m"]
        mains = [reach(t, step) for t in world["trials"] if t["kind"] == "main"]
        checks = [reach(t, step) for t in world["trials"] if t["kind"] == "attention"]
        hits = 0
        for _ in range(sessions):
            shown = list(rng.choice(mains, size=trials_per_world, replace=False))
            check = checks[int(rng.integers(len(checks)))]
            hits += closest([*shown, check]) == len(shown)
        flagged_checks = sum(r < THRESHOLD for r in checks)
        flagged = flagged_checks + sum(r < THRESHOLD for r in mains)
        out[name] = {"closest_hit_rate": hits / sessions,
                     "chance": 1 / (trials_per_world + 1),
                     "threshold_flagged_checks": f"{flagged_checks} of {len(checks)}",
                     "threshold_precision": flagged_checks / flagged if flagged else 0.0,
                     "check_reach": [round(r, 2) for r in checks],
                     "main_reach_min": round(min(mains), 2),
                     "main_reach_median": round(float(np.median(mains)), 2)}
    return out


if __name__ == "__main__":
    path = sys.argv[1] if len(sys.argv) > 1 else "var/trials/paper_study/bank.json"
    per_world = int(sys.argv[2]) if len(sys.argv) > 2 else 10
    print(json.dumps(hit_rates(json.loads(Path(path).read_text()), per_world), indent=1))
