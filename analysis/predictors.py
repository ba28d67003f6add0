"""Every predictor against the people's predictions: per participant means, pairwise paired
tests with Holm's correction, and the crossed mixed model per pair.

The predictors are Ours, the VAE, constant velocity and every plug-in predictor whose columns
the export holds (app/predictors/; in the study config's order). The world's own policy is the
ground truth the participants try to guess: its error is reported beside them as a reference
and never tested.

The family of tests, fixed by the study config before any data: within each world, every pair
of predictors (P predictors give P(P-1)/2 pairs), each a two-sided paired t-test of the
per-participant mean alignment errors; Holm's step-down correction runs over the pairs of one
world (each world is its own question, as in the primary Ours-vs-VAE test). A pair's verdict
names the predictor with the lower error where its Holm-adjusted p is below ALPHA, else
`neither`. The crossed mixed model (analysis/trial_effects.py, trials as a random effect) is
fitted for every pair too (Ours vs the VAE's is the primary one, which report.py has fitted
already and hands in); its p-values get their own Holm correction over the same family.
The primary Ours-vs-VAE analysis (report.py) is unchanged by this module.
"""

from itertools import combinations

import numpy as np
import pandas as pd

from analysis.metrics import POOLED, participant_means
from analysis.stats import PAIR, holm, mean_ci95, paired_comparison, verdicts
from analysis.trial_effects import crossed_mixed_model, trial_cells
from app.core.contracts import plugin_names

BUILT_IN = ("ours", "vae", "cv")
REFERENCE = "policy"
FAMILY = ("within each world, every pair of predictors (Ours, VAE, constant velocity and each "
          "plug-in); Holm over that world's pairs, two-sided paired t-tests of per-participant "
          "mean alignment errors; the mixed models' p-values Holm-corrected over the same pairs")
TEST_COLUMNS = ("n", "mean_a", "mean_b", "mean_diff", "ci95_low", "ci95_high", "t",
                "p_two_sided", "d_z", "wilcoxon_p")
MIXED_COLUMNS = ("estimate", "ci95_low", "ci95_high", "p", "status")


def predictor_names(columns) -> list[str]:
    """The predictors compared: Ours, the VAE, constant velocity, then each plug-in."""
    return [*BUILT_IN, *plugin_names(columns)]


def predictor_means(kept: pd.DataFrame, names: list[str]) -> pd.DataFrame:
    """Per participant and world: mean alignment error of every predictor and the policy."""
    return participant_means(kept, (*names, REFERENCE))


def world_means(means: pd.DataFrame, names: list[str]) -> dict:
    """Per world and predictor (policy last): mean of the participants' means and its 95% CI."""
    out: dict = {}
    for world, group in means.groupby("world", sort=True):
        out[world] = {}
        for name in (*names, REFERENCE):
            mean, low, high = mean_ci95(group[f"err_{name}"])
            out[world][name] = {"mean": mean, "ci95": [low, high]}
    return out


def pair_row(world: str, a: str, b: str, means: pd.DataFrame, rows: pd.DataFrame,
             mixed: dict | None = None) -> dict:
    """One pair in one world: the paired test (diff = a - b) and the crossed mixed model
    (`mixed`, the values of its MixedModelResult, when it was fitted on these rows already)."""
    test = paired_comparison(means[f"err_{a}"], means[f"err_{b}"]).as_dict()
    if mixed is None:
        mixed = crossed_mixed_model(trial_cells(rows, a, b)).as_dict()
    return ({"world": world, "pair": f"{a}_vs_{b}", "a": a, "b": b}
            | {k: test[k] for k in TEST_COLUMNS}
            | {f"mixed_{k}": mixed[k] for k in MIXED_COLUMNS})


def primary_fits(mixed_model: pd.DataFrame, answers: str = "primary") -> dict[str, dict]:
    """Per world, the Ours-vs-VAE crossed mixed model of a mixed_model_table fitted on every
    row of `answers` (the arms pooled): the fit of pairwise_table's ours_vs_vae pair."""
    pooled = mixed_model[(mixed_model["arm"] == POOLED) & (mixed_model["answers"] == answers)]
    return {row["world"]: row for row in pooled.to_dict("records")}


def pairwise_table(kept: pd.DataFrame, names: list[str], means: pd.DataFrame,
                   fitted: dict[str, dict] | None = None) -> pd.DataFrame:
    """Every pair of predictors in every world, with Holm-adjusted p-values over each world's
    pairs (p_holm, mixed_p_holm) and the verdict at ALPHA; `means` are the rows'
    predictor_means. `fitted` (primary_fits, per world) holds the Ours-vs-VAE mixed models
    fitted on these rows already; the pair reuses them instead of fitting again."""
    fitted = fitted or {}
    parts = []
    for world, group in means.groupby("world", sort=True):
        rows = kept[kept["world"] == world]
        table = pd.DataFrame([pair_row(world, a, b, group, rows,
                                       fitted.get(world) if (a, b) == PAIR else None)
                              for a, b in combinations(names, 2)])
        table["p_holm"] = adjusted(table["p_two_sided"])
        table["mixed_p_holm"] = adjusted(table["mixed_p"])
        parts.append(table)
    table = pd.concat(parts, ignore_index=True)
    return table.assign(verdict=verdicts(table["mean_diff"], table["p_holm"], a=table["a"],
                                         b=table["b"]))


def adjusted(p_values: pd.Series) -> np.ndarray:
    """Holm-adjusted p-values of one family (NaN stays NaN; it counts as 1 in the family)."""
    p = p_values.to_numpy(np.float64)
    return np.where(np.isnan(p), np.nan, holm(p))
