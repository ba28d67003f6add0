"""Trials as a random factor: a crossed mixed model and leave-one-trial-out influence.

Both read per (participant, trial) cells: the mean over the trial's start states and steps
of err_ours - err_vae. The mixed model is

    diff[p, t] = b0 + u_p + v_t + e[p, t],   u_p ~ N(0, var_participant), v_t ~ N(0, var_trial)

fitted by REML with statsmodels' MixedLM: one group holding every cell, and participant and
trial as two variance components (the standard way to fit crossed random intercepts
there). b0 is the Ours - VAE difference with trials treated as a sample of possible trials;
with one cell per participant and trial, the residual also holds their interaction.
"""

import warnings
from dataclasses import asdict, dataclass

import numpy as np
import pandas as pd
from statsmodels.regression.mixed_linear_model import MixedLM, VCSpec

from analysis.metrics import answer_subsets
from analysis.stats import paired_comparison, plain_records, verdicts, with_verdicts

CELL_KEYS = ["participant_id", "world", "trial_id", "arm"]
COMPONENTS = {"participant": "participant_id", "trial": "trial_id"}
INFLUENCE_COLUMNS = ["trial_id", "arm", "seen_by", "n", "mean_diff", "shift", "t", "p_two_sided",
                     "verdict", "flips"]
# A variance component under this share of the outcome's variance is estimated as zero
# (the fit sits on the boundary and reduces to a model without that component).
BOUNDARY_SHARE = 1e-6
# statsmodels warns of a boundary whenever a variance is below 0.01 in absolute terms, which
# every component here is (errors are differences of cosines); BOUNDARY_SHARE decides instead.
STATSMODELS_BOUNDARY = "The MLE may be on the boundary"
# Derivative-free, as the profile likelihood has just two parameters: statsmodels' default
# gradient methods (bfgs, lbfgs, cg) stall near a zero variance on small studies and report a
# lower REML likelihood than Powell finds (measured on tests/analysis/fixed_data.py's rows).
FIT_METHODS = ["powell", "nm"]


def trial_cells(rows: pd.DataFrame, a: str = "ours", b: str = "vae") -> pd.DataFrame:
    """Per participant and trial: rows, sums of err_<a> and err_<b>, and `diff`, the mean of
    err_<a> - err_<b> over the trial's rows (Ours and the VAE unless another pair is named)."""
    grouped = rows.groupby(CELL_KEYS, sort=True)
    cells = grouped[[f"err_{a}", f"err_{b}"]].sum()
    cells.columns = [f"sum_{a}", f"sum_{b}"]
    cells["n_rows"] = grouped.size()
    cells["diff"] = (cells[f"sum_{a}"] - cells[f"sum_{b}"]) / cells["n_rows"]
    return cells.reset_index()


@dataclass
class MixedModelResult:
    """The crossed model's intercept (Ours - VAE) and variance components, or why not."""

    status: str  # ok, boundary, not_converged, too_few_participants, too_few_trials,
    #              no_variation, failed
    n_obs: int
    n_participants: int
    n_trials: int
    estimate: float = float("nan")
    se: float = float("nan")
    ci95_low: float = float("nan")
    ci95_high: float = float("nan")
    z: float = float("nan")
    p: float = float("nan")
    var_participant: float = float("nan")
    var_trial: float = float("nan")
    var_residual: float = float("nan")
    message: str = ""

    def as_dict(self) -> dict:
        """Plain values for JSON and CSV."""
        return asdict(self)


def crossed_mixed_model(cells: pd.DataFrame) -> MixedModelResult:
    """Fit diff ~ 1 + (1 | participant) + (1 | trial) on one world's cells; degenerate data
    (one participant or trial, no variation) and failed fits get a status, not an error."""
    diff = cells["diff"].to_numpy(np.float64)
    counts = {"n_obs": len(cells), "n_participants": int(cells["participant_id"].nunique()),
              "n_trials": int(cells["trial_id"].nunique())}
    mean = float(diff.mean()) if len(diff) else float("nan")
    if counts["n_participants"] < 2:
        return MixedModelResult("too_few_participants", **counts, estimate=mean,
                                message="a participant variance needs two participants")
    if counts["n_trials"] < 2:
        return MixedModelResult("too_few_trials", **counts, estimate=mean,
                                message="a trial variance needs two trials")
    if np.ptp(diff) == 0:
        return MixedModelResult("no_variation", **counts, estimate=mean,
                                message="every participant-trial difference is equal")
    try:
        fit, caught = _fit(cells)
    except (np.linalg.LinAlgError, ValueError) as err:
        return MixedModelResult("failed", **counts, estimate=mean, message=str(err))
    return _result(fit, caught, counts, float(np.var(diff)))


def _fit(cells: pd.DataFrame):
    """The REML fit and the warnings it raised."""
    indicators = {name: pd.get_dummies(cells[col], dtype=np.float64)
                  for name, col in COMPONENTS.items()}
    spec = VCSpec(list(indicators), [[list(m.columns)] for m in indicators.values()],
                  [[m.to_numpy()] for m in indicators.values()])
    model = MixedLM(cells["diff"].to_numpy(np.float64), np.ones((len(cells), 1)),
                    groups=np.zeros(len(cells)), exog_vc=spec)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        fit = model.fit(reml=True, method=FIT_METHODS)
    return fit, [str(w.message) for w in caught if STATSMODELS_BOUNDARY not in str(w.message)]


def _result(fit, caught: list[str], counts: dict, outcome_var: float) -> MixedModelResult:
    vcomp = dict(zip(fit.model.exog_vc.names, np.asarray(fit.vcomp, dtype=np.float64),
                     strict=True))
    on_boundary = [name for name, v in vcomp.items() if v < BOUNDARY_SHARE * outcome_var]
    notes = [f"{name} variance estimated as 0 (boundary)" for name in on_boundary] + caught
    status = "not_converged" if not fit.converged else "boundary" if on_boundary else "ok"
    low, high = np.asarray(fit.conf_int())[0]
    return MixedModelResult(
        status, **counts, estimate=float(fit.fe_params[0]), se=float(fit.bse_fe[0]),
        ci95_low=float(low), ci95_high=float(high), z=float(fit.tvalues[0]),
        p=float(fit.pvalues[0]), var_participant=float(vcomp["participant"]),
        var_trial=float(vcomp["trial"]), var_residual=float(fit.scale),
        message="; ".join(dict.fromkeys(notes)))


def mixed_model_table(answer_sets: dict[str, pd.DataFrame]) -> pd.DataFrame:
    """The crossed model per world, arm (pooled first) and set of answers."""
    return pd.DataFrame([labels | crossed_mixed_model(trial_cells(rows)).as_dict()
                         for labels, rows in answer_subsets(answer_sets)])


def _participant_test(cells: pd.DataFrame):
    """The paired test of per-participant mean errors over the given cells."""
    sums = cells.groupby("participant_id")[["sum_ours", "sum_vae", "n_rows"]].sum()
    return paired_comparison(sums["sum_ours"] / sums["n_rows"], sums["sum_vae"] / sums["n_rows"])


def _world_influence(cells: pd.DataFrame) -> list[dict]:
    base = _participant_test(cells)
    rows = []
    for trial, arm in cells[["trial_id", "arm"]].drop_duplicates().itertuples(index=False):
        res = _participant_test(cells[cells["trial_id"] != trial])
        rows.append({"trial_id": trial, "arm": arm,
                     "seen_by": int((cells["trial_id"] == trial).sum()), "n": res.n,
                     "mean_diff": res.mean_diff, "shift": res.mean_diff - base.mean_diff,
                     "ci95_low": res.ci95_low, "ci95_high": res.ci95_high, "t": res.t,
                     "p_two_sided": res.p_two_sided, "all_trials_mean_diff": base.mean_diff,
                     "all_trials_p_two_sided": base.p_two_sided})
    return rows


def leave_one_trial_out(answer_sets: dict[str, pd.DataFrame]) -> pd.DataFrame:
    """Per set of answers, world and main trial: the paired participant-level test without
    that trial (participants re-averaged over the rest), how far the mean difference moves
    (`shift`), and whether the verdict flips (sign, or significance at ALPHA). Sorted by
    |shift|, largest first, within each world and set of answers."""
    parts = []
    for answers, rows in answer_sets.items():
        for world, cells in trial_cells(rows).groupby("world", sort=True):
            parts += [{"world": world, "answers": answers, **row}
                      for row in _world_influence(cells)]
    table = with_verdicts(pd.DataFrame(parts))
    table["all_trials_verdict"] = verdicts(table["all_trials_mean_diff"],
                                           table["all_trials_p_two_sided"])
    table["flips"] = ((np.sign(table["mean_diff"]) != np.sign(table["all_trials_mean_diff"]))
                      | (table["verdict"] != table["all_trials_verdict"]))
    keys = {"_answers": table["answers"].map({a: i for i, a in enumerate(answer_sets)}),
            "_size": table["shift"].abs()}
    return (table.assign(**keys).sort_values(["world", "_answers", "_size"],
                                             ascending=[True, True, False], kind="stable")
            .drop(columns=list(keys)).reset_index(drop=True))


def influence_summary(table: pd.DataFrame, top: int = 5) -> dict:
    """Per world and set of answers: the all-trials result, the trial whose removal moves the
    mean difference most, the trials whose removal flips the verdict, and the `top` rows."""
    out: dict = {}
    for (world, answers), rows in table.groupby(["world", "answers"], sort=False):
        first = rows.iloc[0]  # rows are sorted by |shift|
        flipping = rows[rows["flips"]]
        out.setdefault(world, {})[answers] = {
            "all_trials": {"mean_diff": float(first["all_trials_mean_diff"]),
                           "p_two_sided": float(first["all_trials_p_two_sided"]),
                           "verdict": str(first["all_trials_verdict"])},
            "most_influential": plain_records(rows.head(1)[INFLUENCE_COLUMNS])[0],
            "flipping_trials": flipping["trial_id"].tolist(),
            "any_flip": bool(len(flipping)),
            "top": plain_records(rows.head(top)[INFLUENCE_COLUMNS]),
        }
    return out
