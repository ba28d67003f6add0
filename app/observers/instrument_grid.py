"""The instrument check over every seed pair and a declared range of click noise.

One training run, or one assumed precision of people's clicks, must not decide whether the
study can tell intent-level (coarse) from exact-policy (precise) observers. So the check of
simulated_study.py is rerun

- per seed pair k: Ours seed k against VAE seed k, from the bank's stored family answers (the
  simulated clicks never depend on a model, so each simulated population is scored against
  every pair);
- per click-noise level: each preset's perceptual direction noise (observers.yaml) combined in
  quadrature with a click's direction error of the level's SD: the declared levels, and the
  one the prediction view allows (one pixel of click error at the median robot step);

and reports per cell the pass rate over fresh simulated participants (the check's power), the
participants per population a Welch test needs for 80% power at the observed effect, and each
population's own Ours-vs-VAE test: a precise population that favours Ours as much as the
coarse one means the study cannot tell them apart.
"""

import math
import multiprocessing as mp
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass

import numpy as np
import pandas as pd
from scipy import stats
from tqdm import tqdm

from app.core.alignment import alignment_error
from app.observers.config import ObserversConfig
from app.observers.simulated_study import (
    INSTRUMENT_POPULATIONS,
    INSTRUMENT_ROWS,
    simulated_trials,
)
from app.study.clicks import clicks_to_actions, robot_starts
from app.study.trials import TrialBank

NOISE_LEVELS_DEG = (2.0, 5.0, 10.0, 20.0)
CONFIGURED = "observers.yaml"  # the noise label of the observers config as it is
TARGET_PASS_RATE = 0.8
TARGET_PAIR_SHARE = 0.8
POWER = 0.8


def with_click_noise(observers: ObserversConfig, sd_deg: float) -> ObserversConfig:
    """The observers with a click's direction error of SD `sd_deg` added in quadrature to each
    preset's perceptual direction noise (perception and pointing are independent)."""
    update = {}
    for preset in ("coarse_noise", "precise_noise"):
        noise = getattr(observers, preset)
        combined = math.hypot(noise.direction_sd_deg.value, sd_deg)
        direction = noise.direction_sd_deg.model_copy(update={
            "value": combined,
            "source": f"{noise.direction_sd_deg.source} Combined in quadrature with a "
                      f"click direction SD of {sd_deg:g} deg (instrument noise sweep)."})
        update[preset] = noise.model_copy(update={"direction_sd_deg": direction})
    return observers.model_copy(update=update)


def seed_pairs(bank: TrialBank) -> list[int]:
    """Seed-pair indices of a bank: Ours seed k with VAE seed k, k over the family."""
    trial = next(t for w in bank.data.worlds.values() for t in w.trials)
    return list(range(min(len(trial.predictions["ours"]), len(trial.predictions["vae"]))))


def family_answers(bank: TrialBank) -> tuple[dict[str, int], dict[tuple[str, int], np.ndarray]]:
    """Main trial id -> row index, and per (model, pair) the answers [trials, K, n, 2]."""
    trials = [t for w in sorted(bank.data.worlds) for t in bank.trials_of(w, "main")]
    index = {t.trial_id: i for i, t in enumerate(trials)}
    answers = {(model, pair): np.array([t.predictions[model][pair].actions for t in trials],
                                       dtype=np.float64)
               for model in ("ours", "vae") for pair in seed_pairs(bank)}
    return index, answers


@dataclass(frozen=True)
class PopulationAnswers:
    """One simulated population's answered main trials, as arrays (B answered trials)."""

    participant: np.ndarray  # [B]
    world: np.ndarray  # [B] world names
    trial: np.ndarray  # [B] rows into family_answers' arrays
    human: np.ndarray  # [B, K, n, 2] the simulated participants' actions (m/s)


def population_answers(bank: TrialBank, preset: str, n: int, trials_per_world: int, seed: int,
                       observers: ObserversConfig, index: dict[str, int],
                       readings: dict | None = None) -> PopulationAnswers:
    """n simulated participants of one preset (`simulated_trials`: the server's assignment, no
    model read), their clicks turned into actions as the server turns them."""
    answered = list(simulated_trials(bank, preset, n, trials_per_world, seed, False, observers,
                                     readings))
    return PopulationAnswers(
        participant=np.array([a.participant for a in answered]),
        world=np.array([a.payload["world"] for a in answered]),
        trial=np.array([index[a.trial.trial_id] for a in answered]),
        human=np.stack([clicks_to_actions(robot_starts(a.trial), a.clicks, a.payload["dt_s"])
                        for a in answered]))


def participant_differences(answers: PopulationAnswers, family: dict, pair: int,
                            world: str) -> np.ndarray:
    """Per participant of one world: mean err_ours - err_vae of seed pair `pair` over their
    trials, start states and steps (every trial has the same number of rows, so this is the
    mean over the participant's rows, as analysis.metrics.participant_means takes it)."""
    mine = answers.world == world
    human, rows = answers.human[mine], answers.trial[mine]
    per_trial = (alignment_error(human, family[("ours", pair)][rows])
                 - alignment_error(human, family[("vae", pair)][rows])).mean(axis=(1, 2))
    who = answers.participant[mine]
    counts = np.bincount(who)
    return np.bincount(who, weights=per_trial)[counts > 0] / counts[counts > 0]


def check_row(coarse: np.ndarray, precise: np.ndarray, alpha: float) -> dict:
    """The Welch check on two populations' per-participant differences, and each population's
    own one-sample test (does it, alone, prefer Ours or the VAE?)."""
    welch = stats.ttest_ind(coarse, precise, equal_var=False, alternative="less")
    row = {"welch_t": float(welch.statistic), "p_one_sided": float(welch.pvalue),
           "passed": bool(welch.pvalue < alpha)}
    for name, values in (("coarse", coarse), ("precise", precise)):
        own = stats.ttest_1samp(values, 0.0)
        row |= {f"{name}_mean_diff": float(values.mean()),
                f"{name}_sd_diff": float(values.std(ddof=1)),
                f"{name}_own_t": float(own.statistic), f"{name}_own_p": float(own.pvalue)}
    return row


def grid_rows(populations: dict[str, PopulationAnswers], family: dict, pairs: list[int],
              world: str, alpha: float) -> list[dict]:
    """One simulated study's check in one world for every seed pair and lane reading."""
    rows = []
    for pair in pairs:
        diffs = {preset: participant_differences(answers, family, pair, world)
                 for preset, answers in populations.items()}
        for reading, preset in INSTRUMENT_ROWS:
            rows.append({"pair": pair, "world": world, "reading": reading,
                         **check_row(diffs[preset], diffs["precise"], alpha)})
    return rows


def noise_levels(view_deg: dict[str, float] | None) -> dict[str, dict[str, float] | None]:
    """Noise label -> click SD per world (None: the observers config as it is)."""
    levels: dict[str, dict[str, float] | None] = {CONFIGURED: None}
    levels |= {f"{sd:g} deg": {"*": sd} for sd in NOISE_LEVELS_DEG}
    if view_deg:
        levels["view"] = dict(view_deg)
    return levels


def level_rows(bank: TrialBank, trials_per_world: int, observers: ObserversConfig, n: int,
               seed: int, alpha: float, replications: int, label: str,
               per_world: dict[str, float] | None) -> list[dict]:
    """Every (replication, seed pair, world, reading) check at one noise level."""
    index, family = family_answers(bank)
    readings = {preset: {} for preset in INSTRUMENT_POPULATIONS}  # not noise-dependent
    rows = []
    for r in range(replications + 1):
        for world in sorted(bank.data.worlds):
            sd = None if per_world is None else per_world.get(world, per_world.get("*"))
            noisy = observers if sd is None else with_click_noise(observers, sd)
            populations = {
                preset: population_answers(only_world(bank, world), preset, n, trials_per_world,
                                           seed + offset + 3 * r, noisy, index, readings[preset])
                for offset, preset in enumerate(INSTRUMENT_POPULATIONS)}
            rows += [dict(row, noise=label, click_sd_deg=sd, replication=r)
                     for row in grid_rows(populations, family, seed_pairs(bank), world, alpha)]
    return rows


def run_grid(bank: TrialBank, trials_per_world: int, observers: ObserversConfig, n: int = 22,
             seed: int = 0, alpha: float = 0.01, replications: int = 50,
             view_deg: dict[str, float] | None = None, workers: int = 2) -> pd.DataFrame:
    """Every (noise level, replication, seed pair, world, reading) check, one row each; the
    noise levels run `workers` at a time."""
    levels = noise_levels(view_deg)
    args = (bank, trials_per_world, observers, n, seed, alpha, replications)
    bar = tqdm(total=len(levels), desc="instrument grid", unit="noise level")
    rows: dict[str, list[dict]] = {}
    if workers == 1:
        for label, per_world in levels.items():
            rows[label] = level_rows(*args, label, per_world)
            bar.update(1)
    else:
        # spawn, not fork: the parent may have run torch or hold threads
        with ProcessPoolExecutor(workers, mp_context=mp.get_context("spawn")) as pool:
            futures = {pool.submit(level_rows, *args, label, per_world): label
                       for label, per_world in levels.items()}
            for done in as_completed(futures):
                rows[futures[done]] = done.result()
                bar.update(1)
    bar.close()
    return pd.DataFrame([row for label in levels for row in rows[label]])


def only_world(bank: TrialBank, world: str) -> TrialBank:
    """The bank with one world (each world gets its own click noise)."""
    return TrialBank(bank.data.model_copy(update={"worlds": {world: bank.world(world)}}),
                     bank.sha256)


def summarise_grid(grid: pd.DataFrame, alpha: float) -> pd.DataFrame:
    """Per noise, seed pair, world and reading: the first study's check and own tests, the pass
    rate over the reruns, and the participants per population for 80% power."""
    from statsmodels.stats.power import TTestIndPower

    keys = ["noise", "pair", "world", "reading"]
    first = grid[grid["replication"] == 0].set_index(keys)
    reruns = grid[grid["replication"] > 0].groupby(keys)
    out = first.drop(columns=["replication"]).assign(
        pass_rate=reruns["passed"].mean() if len(grid["replication"].unique()) > 1 else np.nan)
    out["effect_size_d"] = grid.groupby(keys).apply(standardised_gap, include_groups=False)
    out["n_for_power_0.8"] = [participants_needed(TTestIndPower(), d, alpha)
                              for d in out["effect_size_d"]]
    return out.reset_index()


def standardised_gap(rows: pd.DataFrame) -> float:
    """Cohen's d of the check: precise minus coarse mean err_ours - err_vae over the pooled SD
    of the per-participant differences, each averaged over the reruns."""
    gap = (rows["precise_mean_diff"] - rows["coarse_mean_diff"]).mean()
    pooled = np.sqrt((rows["coarse_sd_diff"] ** 2 + rows["precise_sd_diff"] ** 2) / 2).mean()
    return float(gap / pooled) if pooled > 0 else np.nan


def participants_needed(power, d: float, alpha: float) -> float:
    """Per-population n for a one-sided Welch/t test to reach POWER at effect d (NaN if the
    effect is absent or in the wrong direction)."""
    if not np.isfinite(d) or d <= 0:
        return np.nan
    return float(math.ceil(power.solve_power(effect_size=d, alpha=alpha, power=POWER,
                                             alternative="larger")))


def goal_met(summary: pd.DataFrame, noise: str) -> dict[str, dict]:
    """Per world, at one noise level: the share of seed pairs whose pass rate reaches the
    target (absolute reading), and whether that share reaches TARGET_PAIR_SHARE."""
    rows = summary[(summary["noise"] == noise) & (summary["reading"] == "absolute")]
    out = {}
    for world, group in rows.groupby("world"):
        share = float((group["pass_rate"] >= TARGET_PASS_RATE).mean())
        out[world] = {"pairs": len(group), "share_passing": share,
                      "met": share >= TARGET_PAIR_SHARE}
    return out


def run_instrument_grid(bank_path, trials_per_world: int, out_dir, observers: ObserversConfig,
                        n: int = 22, seed: int = 0, alpha: float = 0.01, replications: int = 50,
                        view_deg: dict[str, float] | None = None) -> dict:
    """Run the grid on a bank; write grid.csv (every check), grid_summary.csv (per cell),
    grid.json and grid.png; return grid.json's content."""
    from pathlib import Path

    from analysis.plots import plot_grid_pass_rates
    from app.core.files import write_json
    from app.observers.simulated_study import load_bank
    from app.prediction_view import view_click_sd_deg

    bank = load_bank(bank_path)
    if view_deg is None:  # the noise the prediction view allows, from its pixel scale
        view_deg = {world: view_click_sd_deg(world_bank, observers.click_sd_px.value)
                    for world, world_bank in bank.data.worlds.items()}
    grid = run_grid(bank, trials_per_world, observers, n, seed, alpha, replications, view_deg)
    summary = summarise_grid(grid, alpha)
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    grid.to_csv(out_dir / "grid.csv", index=False)
    summary.to_csv(out_dir / "grid_summary.csv", index=False)
    figures = plot_grid_pass_rates(summary, TARGET_PASS_RATE, out_dir / "grid")
    goal_noise = "view" if view_deg else CONFIGURED
    result = {"n_per_population": n, "alpha": alpha, "replications": replications,
              "seed_pairs": seed_pairs(bank), "noise_levels": list(noise_levels(view_deg)),
              "view_click_sd_deg": view_deg,
              "goal": {"noise": goal_noise, "pass_rate": TARGET_PASS_RATE,
                       "share_of_pairs": TARGET_PAIR_SHARE,
                       "worlds": goal_met(summary, goal_noise)},
              "cells": summary.to_dict(orient="records"),
              "figures": [str(f) for f in figures]}
    write_json(out_dir / "grid.json", result)
    return result


def grid_table(result: dict) -> list[str]:
    """The grid per world and noise level: each seed pair's pass rate and n for 80% power,
    and which model each population favours on its own; then the goal and whether it is met."""
    cells = pd.DataFrame(result["cells"])
    cells = cells[cells["reading"] == "absolute"]
    alpha = result["alpha"]
    lines = [f"\n{'world':<14}{'noise':<16}{'pass rate per seed pair':<32}{'n for 80%':<18}"
             f"coarse favours   precise favours"]
    for (world, noise), group in cells.groupby(["world", "noise"], sort=False):
        group = group.sort_values("pair")
        rates = " ".join(f"{r:.2f}" for r in group["pass_rate"])
        needed = " ".join("-" if pd.isna(v) else f"{v:.0f}" for v in group["n_for_power_0.8"])
        lines.append(f"{world:<14}{noise:<16}{rates:<32}{needed:<18}"
                     f"{favours(group, 'coarse', alpha):<17}{favours(group, 'precise', alpha)}")
    if result.get("view_click_sd_deg"):
        view = ", ".join(f"{world} {sd:.2f} deg" for world, sd in
                         result["view_click_sd_deg"].items())
        lines.append(f"view = the prediction view's click spread ({view}) in quadrature with "
                     "each preset's own")
    goal = result["goal"]
    met = all(w["met"] for w in goal["worlds"].values())
    shares = ", ".join(f"{world} {w['share_passing']:.0%}" for world, w in goal["worlds"].items())
    lines.append(f"pass rate = share of {result['replications']} reruns where Welch p < {alpha}; "
                 f"n for 80% = participants per population for 80% power at the observed "
                 f"effect;\nfavours = seed pairs whose population alone prefers Ours / the VAE / "
                 f"neither (p < {alpha}, first run)\ngoal (pass rate >= {goal['pass_rate']} for "
                 f">= {goal['share_of_pairs']:.0%} of seed pairs in every world, at noise "
                 f"{goal['noise']}): {'met' if met else 'NOT met'} ({shares})")
    return lines


def favours(group: pd.DataFrame, population: str, alpha: float) -> str:
    """'Ours/VAE/neither' counts of seed pairs by a population's own Ours-vs-VAE test."""
    significant = group[f"{population}_own_p"] < alpha
    ours = int((significant & (group[f"{population}_mean_diff"] < 0)).sum())
    vae = int((significant & (group[f"{population}_mean_diff"] > 0)).sum())
    return f"{ours}/{vae}/{len(group) - ours - vae}"
