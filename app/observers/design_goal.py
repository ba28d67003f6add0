"""The goal a study design must meet, per world (issue 30): would the pre-registered primary
test confirm the hypothesis if people were coarse, and not if they were precise?

The primary test, fixed before any run: the **model family** (per participant and trial, the
mean over seeds of Ours' alignment error minus the mean over seeds of the VAE's), with
participants **and** trials random (Clark's min F', analysis/crossed.py), two-sided at alpha;
its verdict is Ours where it is significant and favours Ours.

The goal: for every coarse observer of the family (app/observers/family.py) the test
concludes Ours with probability >= GOAL_POWER, and for the precise observer with probability
<= alpha; met where it holds for the whole family and, when the design read only some seeds
(a discriminability rule's selection seeds), for the family of the held-out seeds too.
Probabilities are over simulated studies in which both factors are random: each study draws
its bank's T trials with replacement from the bank's main trials (the bank stands for the
population of clips), gives each of N observers `trials_per_world` of them (balanced,
as the server does), samples each observer's intent per trial from its posterior and each
click's direction error (the observer's perceptual noise and the view's click noise), and
runs the test. The observers never read a model; only the scoring does, as the analysis does.
"""

from dataclasses import dataclass

import numpy as np
import pandas as pd
from scipy import stats
from tqdm import tqdm

from analysis.crossed import crossed_verdicts, group_t, grouped_means, min_f_prime
from app.observers.family import (
    COARSE_VARIANTS,
    GOAL_VARIANTS,
    WorldAnswers,
    world_answers,
)
from app.study.trials import TrialBank

GOAL_POWER = 0.8
CHUNK_FLOATS = 4_000_000  # simulated error terms held at once (about 32 MB)
DESIGN_PARTICIPANTS = (22, 30, 40, 60, 80, 120, 160, 240)
DESIGN_TRIALS = (30, 60, 90, 120, 180, 240)


@dataclass(frozen=True)
class Design:
    """A study design in one world: N participants, T bank trials, m trials each."""

    participants: int
    bank_trials: int
    trials_each: int


def study_cells(rng: np.random.Generator, reps: int, design: Design, pool: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per simulated study: each cell's bank trial, participant and study-trial ids [R, C]; the
    study's T trials are drawn with replacement from `pool` (trials random)."""
    n, t = design.participants, design.bank_trials
    m = min(design.trials_each, t)
    draws = pool[rng.integers(len(pool), size=(reps, t))]
    order = rng.permuted(np.tile(np.arange(t), (reps, 1)), axis=1)
    seen = (np.arange(n)[:, None] * m + np.arange(m)[None]) % t  # balanced exposure
    slots = order[:, seen.ravel()]
    return (np.take_along_axis(draws, slots, axis=1),
            np.tile(np.repeat(np.arange(n), m), (reps, 1)), slots)


def cell_differences(answers: WorldAnswers, variant: str, seeds: np.ndarray,
                     trials: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Family err_ours - err_vae [R, C] of one simulated click set per cell (bank trials [R, C])."""
    cum = np.cumsum(answers.weights[variant], axis=1)[trials]  # [R, C, J]
    option = (rng.random(trials.shape)[..., None] > cum).sum(axis=-1)
    option = np.minimum(option, cum.shape[-1] - 1)
    delta = answers.delta[variant][trials, option][:, :, :, seeds]  # [R, C, 2, S, K, n]
    noise = rng.normal(0.0, answers.sd_rad[variant], size=(*trials.shape, *delta.shape[-2:]))
    err = np.where(answers.valid[trials][:, :, :, seeds], 1.0 - np.cos(delta + noise[:, :, None,
                                                                                     None]), 1.0)
    family = err.mean(axis=(3, 4, 5))  # [R, C, 2]
    return family[..., 0] - family[..., 1]


def simulate_verdicts(answers: WorldAnswers, variant: str, seeds: np.ndarray, design: Design,
                      pool: np.ndarray, reps: int, alpha: float, rng: np.random.Generator
                      ) -> dict[str, np.ndarray]:
    """Over `reps` simulated studies: the primary test's verdict (-1 Ours, +1 VAE, 0) and, for
    comparison, whether the earlier analysis's test (participants only: a one-sided paired t
    over the participants' means, blind to the clips' own effects) finds Ours < VAE in the same
    study."""
    cells = design.participants * min(design.trials_each, design.bank_trials)
    per_rep = cells * 2 * len(seeds) * answers.delta[variant].shape[-2] * \
        answers.delta[variant].shape[-1]
    chunk = max(1, CHUNK_FLOATS // per_rep)
    crossed, by_person = [], []
    for start in range(0, reps, chunk):
        trials, people, slots = study_cells(rng, min(chunk, reps - start), design, pool)
        diff = cell_differences(answers, variant, seeds, trials, rng)
        crossed.append(crossed_verdicts(min_f_prime(diff, people, slots), alpha))
        t, df = group_t(*grouped_means(diff, people, design.participants))
        by_person.append(paired_less(t, df) < alpha)
    return {"crossed": np.concatenate(crossed), "participants_only": np.concatenate(by_person)}


def paired_less(t: np.ndarray, df: np.ndarray) -> np.ndarray:
    """One-sided p (mean < 0) of one-sample t statistics; 1 where t is undefined."""
    ok = np.isfinite(t) & (df > 0)
    return np.where(ok, stats.t.cdf(np.where(ok, t, 0.0), np.where(ok, df, 1.0)), 1.0)


def seed_sets(seeds: list[int], held_out: list[int]) -> dict[str, np.ndarray]:
    """The seed sets the goal is read on: the whole family (the primary), the held-out
    family (seeds no design choice read) and each held-out seed pair alone."""
    index = {seed: i for i, seed in enumerate(seeds)}
    held_out = [s for s in held_out if s in index]  # a bank of other seeds has none of them
    sets = {"family": np.arange(len(seeds))}
    if held_out and len(held_out) < len(seeds):
        sets["held-out family"] = np.array([index[s] for s in held_out])
    for seed in held_out or seeds:
        sets[f"pair {seed}"] = np.array([index[seed]])
    return sets


def arm_pools(answers: WorldAnswers) -> dict[str, np.ndarray]:
    """Bank trial indices per arm, and `all` (the design as served)."""
    pools = {"all": np.arange(len(answers.trial_ids))}
    for arm in sorted(set(answers.arms)):
        pools[arm] = np.flatnonzero(answers.arms == arm)
    return pools if len(pools) > 2 else {"all": pools["all"]}


def goal_rows(answers: WorldAnswers, design: Design, seeds: dict[str, np.ndarray], reps: int,
              alpha: float, rng: np.random.Generator) -> list[dict]:
    """P(verdict Ours), P(verdict VAE) and the participants-only power per variant, seed set
    and arm, at one design."""
    rows = []
    for arm, pool in arm_pools(answers).items():
        for label, subset in seeds.items():
            for variant in answers.variants:
                out = simulate_verdicts(answers, variant, subset, design, pool, reps, alpha, rng)
                rows.append({"world": answers.world, "arm": arm, "seeds": label,
                             "variant": variant, "participants": design.participants,
                             "bank_trials": design.bank_trials,
                             "trials_each": design.trials_each,
                             "p_ours": float(np.mean(out["crossed"] == -1)),
                             "p_vae": float(np.mean(out["crossed"] == 1)),
                             "participants_only_power":
                                 float(np.mean(out["participants_only"]))})
    return rows


def goal_met(rows: pd.DataFrame, alpha: float) -> bool:
    """Every coarse variant concludes Ours with P >= GOAL_POWER; precise with P <= alpha."""
    coarse = rows[rows["variant"].isin(COARSE_VARIANTS)]
    precise = rows[rows["variant"] == "precise"]
    return bool(len(coarse) and (coarse["p_ours"] >= GOAL_POWER).all()
                and (precise["p_ours"] <= alpha).all())


def needed_design(answers: WorldAnswers, base: Design, seeds: dict[str, np.ndarray],
                  reps: int, alpha: float, rng: np.random.Generator) -> list[dict]:
    """Per bank size T, the fewest participants whose design meets the goal on the family and
    the held-out family (trials resampled from the whole bank), or None within
    DESIGN_PARTICIPANTS."""
    pool = np.arange(len(answers.trial_ids))
    sets = [seeds[label] for label in ("family", "held-out family") if label in seeds]
    out = []
    for bank_trials in DESIGN_TRIALS:
        found = None
        for n in DESIGN_PARTICIPANTS:
            outcome = design_outcome(answers, Design(n, bank_trials, base.trials_each), sets,
                                     pool, reps, alpha, rng)
            if outcome != "short":
                found = n if outcome == "met" else None
                break
        out.append({"world": answers.world, "bank_trials": bank_trials,
                    "trials_each": base.trials_each, "participants_needed": found})
    return out


def design_outcome(answers: WorldAnswers, design: Design, sets: list[np.ndarray],
                   pool: np.ndarray, reps: int, alpha: float, rng: np.random.Generator) -> str:
    """'met' (every seed set meets the goal), 'precise' (a precise population concludes Ours
    too often: more participants only make that likelier) or 'short'."""
    for subset in sets:
        verdicts = {v: simulate_verdicts(answers, v, subset, design, pool, reps, alpha,
                                         rng)["crossed"] for v in GOAL_VARIANTS}
        if precise_fails(verdicts["precise"], alpha):
            return "precise"
        if not all(np.mean(verdicts[v] == -1) >= GOAL_POWER for v in COARSE_VARIANTS):
            return "short"
    return "met"


def precise_fails(verdicts: np.ndarray, alpha: float) -> bool:
    """Whether a precise population concludes Ours more often than alpha."""
    return float(np.mean(verdicts == -1)) > alpha


def run_design_goal(bank: TrialBank, design: Design, observers, view_sd_deg: dict[str, float],
                    held_out_seeds: list[int], alpha: float = 0.01, reps: int = 400,
                    search_reps: int = 200, seed: int = 0, search: bool = True) -> dict:
    """The goal per world at `design`, and the designs that would meet it; plain records."""
    rng = np.random.default_rng(seed)
    rows, needed, met = [], [], {}
    for world in tqdm(sorted(bank.data.worlds), desc="design goal", unit="world"):
        answers = world_answers(bank, world, observers, view_sd_deg.get(world, 0.0))
        sets = seed_sets(answers.seeds, held_out_seeds)
        world_rows = pd.DataFrame(goal_rows(answers, design, sets, reps, alpha, rng))
        rows += world_rows.to_dict(orient="records")
        met[world] = {label: goal_met(world_rows[(world_rows["arm"] == "all")
                                                 & (world_rows["seeds"] == label)], alpha)
                      for label in ("family", "held-out family") if label in sets}
        if search:
            needed += needed_design(answers, design, sets, search_reps, alpha, rng)
    return {"alpha": alpha, "goal_power": GOAL_POWER, "reps": reps, "search_reps": search_reps,
            "design": design.__dict__, "held_out_seeds": held_out_seeds,
            "goal_met": {world: all(m.values()) for world, m in met.items()},
            "goal_met_by_seeds": met, "rows": rows, "needed": needed}


def run_goal_report(bank_path, design: Design, observers, held_out: list[int],
                    exploratory: dict[str, str], out_dir, alpha: float = 0.01, reps: int = 400,
                    search: bool = True, seed: int = 0) -> dict:
    """The design goal on a bank file at the view's click noise; goal.json and goal.csv."""
    from pathlib import Path

    from app.core.files import write_json
    from app.prediction_view import view_click_sd_deg

    bank = TrialBank.read(Path(bank_path))
    view = {world: view_click_sd_deg(world_bank, observers.click_sd_px.value)
            for world, world_bank in bank.data.worlds.items()}
    result = run_design_goal(bank, design, observers, view, held_out, alpha, reps,
                             max(20, reps // 2), seed, search)
    result |= {"bank_sha256": bank.sha256, "view_click_sd_deg": view,
               "exploratory": exploratory}
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    pd.DataFrame(result["rows"]).to_csv(out_dir / "goal.csv", index=False)
    write_json(out_dir / "goal.json", result)
    return result
