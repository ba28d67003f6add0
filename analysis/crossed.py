"""The primary test with participants and trials random: Clark's (1973) min F'.

A study's claim is about people and about clips beyond the ones shown, so both are random
factors (Judd, Westfall & Kenny 2012, J Pers Soc Psychol 103:54-69). min F' combines the
by-participant test (F1: the participants' mean differences, df N-1) and the by-trial test
(F2: the trials' mean differences over the participants who saw them, df T-1):
min F' = F1 F2 / (F1 + F2) on (1, j) df, j = (F1 + F2)^2 / (F1^2 / df2 + F2^2 / df1)
(Clark 1973, J Verbal Learn Verbal Behav 12:335-359). It is a lower bound of the quasi-F,
so it never overstates significance, holds for designs where each participant sees a subset
of the trials, and needs no iterative fit: a simulated study can run it thousands of times.
"""

from dataclasses import asdict, dataclass

import numpy as np
import pandas as pd
from scipy import stats

from analysis.equivalence import conclusion, paired_bf10, t_interval, tost_p


@dataclass(frozen=True)
class CrossedResult:
    """min F' on per-(participant, trial) differences (negative favours the first model)."""

    mean_diff: float
    n_participants: int
    n_trials: int
    t_participants: float  # F1 = t^2, signed
    t_trials: float  # F2 = t^2, signed
    min_f: float
    df: float
    p_two_sided: float

    def as_dict(self) -> dict:
        """Plain numbers for JSON."""
        return asdict(self)


def group_t(means: np.ndarray, counts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """One-sample t and df of the group means [R, G] whose counts [R, G] > 0, per row."""
    present = counts > 0
    n = present.sum(axis=1)
    safe_n = np.maximum(n, 1)
    mean = np.where(present, means, 0.0).sum(axis=1) / safe_n
    var = np.where(present, (means - mean[:, None]) ** 2, 0.0).sum(axis=1) / np.maximum(n - 1, 1)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = mean / np.sqrt(var / safe_n)
    return t, (n - 1).astype(np.float64)


def grouped_means(values: np.ndarray, groups: np.ndarray, n_groups: int
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Per row of values [R, C] the mean and count of each group id [R, C] in 0..n_groups-1."""
    rows = values.shape[0]
    flat = (groups + np.arange(rows)[:, None] * n_groups).ravel()
    counts = np.bincount(flat, minlength=rows * n_groups).reshape(rows, n_groups)
    sums = np.bincount(flat, weights=values.ravel(), minlength=rows * n_groups)
    with np.errstate(divide="ignore", invalid="ignore"):
        means = sums.reshape(rows, n_groups) / counts
    return means, counts


def min_f_prime(values: np.ndarray, participants: np.ndarray, trials: np.ndarray
                ) -> dict[str, np.ndarray]:
    """min F' per row of per-cell differences [R, C] with participant and trial ids [R, C]
    (0-based, dense): mean, both t, min F', df and the two-sided p, each [R]."""
    values = np.atleast_2d(np.asarray(values, dtype=np.float64))
    participants, trials = np.atleast_2d(participants), np.atleast_2d(trials)
    by_person = grouped_means(values, participants, int(participants.max()) + 1)
    by_trial = grouped_means(values, trials, int(trials.max()) + 1)
    t1, df1 = group_t(*by_person)
    t2, df2 = group_t(*by_trial)
    f1, f2 = t1 ** 2, t2 ** 2
    with np.errstate(divide="ignore", invalid="ignore"):
        min_f = f1 * f2 / (f1 + f2)
        df = (f1 + f2) ** 2 / (f1 ** 2 / df2 + f2 ** 2 / df1)
    usable = np.isfinite(min_f) & np.isfinite(df) & (df > 0)
    p = np.where(usable, stats.f.sf(np.where(usable, min_f, 0.0), 1, np.where(usable, df, 1.0)),
                 1.0)
    return {"mean_diff": values.mean(axis=1), "t_participants": t1, "t_trials": t2,
            "min_f": min_f, "df": df, "p_two_sided": p}


def crossed_verdicts(result: dict[str, np.ndarray], alpha: float) -> np.ndarray:
    """-1 where the test favours the first model (both t negative, p < alpha), +1 the second,
    0 neither."""
    significant = result["p_two_sided"] < alpha
    first = significant & (result["t_participants"] < 0) & (result["t_trials"] < 0)
    second = significant & (result["t_participants"] > 0) & (result["t_trials"] > 0)
    return np.where(first, -1, np.where(second, 1, 0))


def crossed_test(diff, participant_ids, trial_ids) -> CrossedResult:
    """min F' on one study's per-(participant, trial) differences, ids of any type."""
    _, people = np.unique(np.asarray(participant_ids), return_inverse=True)
    _, clips = np.unique(np.asarray(trial_ids), return_inverse=True)
    out = min_f_prime(np.asarray(diff, dtype=np.float64)[None], people[None], clips[None])
    return CrossedResult(
        mean_diff=float(out["mean_diff"][0]), n_participants=int(people.max()) + 1,
        n_trials=int(clips.max()) + 1, t_participants=float(out["t_participants"][0]),
        t_trials=float(out["t_trials"][0]), min_f=float(out["min_f"][0]),
        df=float(out["df"][0]), p_two_sided=float(out["p_two_sided"][0]))


def crossed_standard_error(diff, participant_ids, trial_ids) -> tuple[float, float]:
    """The SE of the mean difference with participants and trials random, and its df:
    sqrt(SE_participants^2 + SE_trials^2) on Welch-Satterthwaite df. Where the participants'
    and the trials' means are the cells' mean (a balanced design), min F' is (mean / SE)^2
    on (1, df) exactly; unlike |mean| / sqrt(min F') it stays defined where the mean is 0."""
    frame = pd.DataFrame({"diff": np.asarray(diff, dtype=np.float64),
                          "participant": np.asarray(participant_ids),
                          "trial": np.asarray(trial_ids)})
    means = [frame.groupby(factor)["diff"].mean() for factor in ("participant", "trial")]
    variances = np.array([m.var(ddof=1) / len(m) if len(m) > 1 else np.nan for m in means])
    dfs = np.array([len(m) - 1 for m in means], dtype=np.float64)
    total = variances.sum()
    with np.errstate(divide="ignore", invalid="ignore"):
        df = total ** 2 / (variances ** 2 / dfs).sum()
    return float(np.sqrt(total)), float(df)


def crossed_verdict(result: CrossedResult, alpha: float) -> str:
    """ours, vae or neither: the first model where its error is significantly lower at alpha
    with both factors agreeing, the second where higher."""
    verdict = int(crossed_verdicts({k: np.array([v]) for k, v in result.as_dict().items()},
                                   alpha)[0])
    return {-1: "ours", 1: "vae", 0: "neither"}[verdict]


def primary_table(family_rows, alpha: float, exploratory: dict[str, str], sesoi: float):
    """The pre-registered primary test per world on the family's rows (err_ours, err_vae as the
    mean over seeds per kept row): per (participant, trial) mean difference, min F', verdict
    (ours, vae, neither at alpha; both factors must agree), whether the world is exploratory,
    and the evidence for a null beside it (analysis/equivalence.py): the 95% CI, TOST against
    +-sesoi, the JZS BF10 and the conclusion (ours, vae, equivalent or inconclusive)."""
    cells = (family_rows.assign(diff=family_rows["err_ours"] - family_rows["err_vae"])
             .groupby(["world", "participant_id", "trial_id"], sort=True)["diff"].mean()
             .reset_index())
    rows = []
    for world, part in cells.groupby("world", sort=True):
        result = crossed_test(part["diff"], part["participant_id"], part["trial_id"])
        verdict = crossed_verdict(result, alpha)
        rows.append({"world": world, **result.as_dict(), "verdict": verdict,
                     "exploratory": world in exploratory,
                     **null_evidence(part, result.mean_diff, verdict, alpha, sesoi)})
    return pd.DataFrame(rows)


def null_evidence(cells: pd.DataFrame, mean: float, verdict: str, alpha: float,
                  sesoi: float) -> dict:
    """One world's 95% CI, TOST p against +-sesoi, BF10 and conclusion from its cells."""
    se, df = crossed_standard_error(cells["diff"], cells["participant_id"], cells["trial_id"])
    low, high = t_interval(mean, se, df)
    tost = tost_p(mean, se, df, sesoi)
    people = cells.groupby("participant_id")["diff"].mean()
    return {"ci95_low": low, "ci95_high": high, "sesoi": sesoi, "tost_p": tost,
            "bf10": paired_bf10(people), "conclusion": conclusion(verdict, tost, alpha)}
