"""What the report tests hand `analyze`: a bank with 3 seeds per model, its models and
exclusion rules, and simulated participants exported as the server exports them."""

import hashlib
import json

from app.core.contracts import ExclusionRules
from app.observers.simulated_study import simulate_participants
from tests.analysis.fixed_data import small_bank, trial_bank, with_seeds

RULES = ExclusionRules(failed_attention_check=True, incomplete=True, too_fast_trial_ms=4000,
                       too_fast_max_fraction=0.25)


SEEDED_BANK = with_seeds(small_bank(), n_seeds=3)
BANK_JSON = json.dumps(SEEDED_BANK).encode()
BANK_SHA = hashlib.sha256(BANK_JSON).hexdigest()
MODELS = {world: {model: {str(100 + k): f"{model}-{world}-{100 + k}" for k in range(3)}
                  for model in ("ours", "vae")} for world in ("highway", "obstacle")}


def simulated_export(kind: str, n: int, seed: int):
    """Simulated participants on the bank's primary answers, as the server exports them."""
    frame = simulate_participants(trial_bank(small_bank()), kind, n, 5, seed=seed,
                                  show_progress=False)
    frame["arm"] = frame["trial_id"].str[-1].astype(int).mod(2).map(
        {0: "random", 1: "models_disagree"})
    return frame.assign(bank_sha256=BANK_SHA)
