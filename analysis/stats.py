"""Paired tests of Ours vs the VAE across participants, and ADE/FDE against clicked positions."""

from dataclasses import asdict, dataclass

import numpy as np
import pandas as pd
from scipy import stats

from analysis.metrics import UNIT_KEYS, answer_subsets, participant_means
from app.core.contracts import MODELS

ALPHA = 0.01  # the preregistered significance level of every Ours-vs-VAE test
PAIR = ("ours", "vae")  # the two models every paired comparison contrasts
POSITION_MODELS = ("ours", "vae", "cv")
PREDICTION_KEYS = ["participant_id", "trial_id", "start_index"]
BREAKDOWN_STATS = ("mean_diff", "ci95_low", "ci95_high", "t", "p_two_sided", "p_one_sided_less",
                   "wilcoxon_p", "d_z")


@dataclass
class PairedResult:
    """Ours vs VAE across participants in one world (diff = a - b, negative favours a)."""

    n: int
    mean_a: float
    mean_b: float
    mean_diff: float
    sd_diff: float
    ci95_low: float
    ci95_high: float
    t: float
    p_two_sided: float
    p_one_sided_less: float
    wilcoxon_w: float
    wilcoxon_p: float
    d_z: float

    def as_dict(self) -> dict[str, float]:
        """Plain floats for JSON."""
        return {k: (float(v) if not isinstance(v, int) else v) for k, v in asdict(self).items()}


def paired_comparison(a: np.ndarray, b: np.ndarray) -> PairedResult:
    """ttest_rel, Wilcoxon signed-rank, Cohen's d_z and the t-based 95% CI of mean(a - b)."""
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    diff = a - b
    n = len(diff)
    nan = float("nan")
    if n < 2:
        return PairedResult(n, *(float(np.mean(x)) if n else nan for x in (a, b, diff)),
                            *(nan,) * 9)
    sd = float(np.std(diff, ddof=1))
    mean = float(np.mean(diff))
    t_two = stats.ttest_rel(a, b)
    ci = t_two.confidence_interval(confidence_level=0.95)
    t_less = stats.ttest_rel(a, b, alternative="less")
    if np.any(diff != 0):
        w = stats.wilcoxon(a, b)
        w_stat, w_p = float(w.statistic), float(w.pvalue)
    else:
        w_stat, w_p = nan, 1.0
    return PairedResult(
        n=n, mean_a=float(np.mean(a)), mean_b=float(np.mean(b)), mean_diff=mean, sd_diff=sd,
        ci95_low=float(ci.low), ci95_high=float(ci.high), t=float(t_two.statistic),
        p_two_sided=float(t_two.pvalue), p_one_sided_less=float(t_less.pvalue),
        wilcoxon_w=w_stat, wilcoxon_p=w_p, d_z=mean / sd if sd > 0 else nan,
    )


def verdicts(mean_diff, p_two_sided, alpha: float = ALPHA, a=PAIR[0], b=PAIR[1]) -> np.ndarray:
    """Which model a test favours: `a` or `b` (by the sign of a - b) where the two-sided p is
    below alpha, else 'neither' (also where p is NaN). `a` and `b` are names, one for every
    test or one per test (array-like); Ours and the VAE unless named."""
    mean_diff = np.asarray(mean_diff, dtype=np.float64)
    significant = np.asarray(p_two_sided, dtype=np.float64) < alpha
    return np.where(significant & (mean_diff < 0), a,
                    np.where(significant & (mean_diff > 0), b, "neither"))


def with_verdicts(table: pd.DataFrame) -> pd.DataFrame:
    """`table` (of paired results) with a `verdict` column: ours, vae or neither at ALPHA."""
    return table.assign(verdict=verdicts(table["mean_diff"], table["p_two_sided"]))


def compare_per_world(means: pd.DataFrame, a: str = "ours",
                      b: str = "vae") -> dict[str, PairedResult]:
    """Per world, the paired comparison of per-participant mean errors of models a and b."""
    return {world: paired_comparison(group[f"err_{a}"], group[f"err_{b}"])
            for world, group in means.groupby("world", sort=True)}


def breakdown(means: pd.DataFrame, keys: list[str], a: str = "ours", b: str = "vae",
              models: tuple[str, ...] = MODELS) -> pd.DataFrame:
    """Per group of `keys` (e.g. world and start_kind) of per-participant means: n
    participants, mean error per model, and the paired a-vs-b comparison (NaN below n = 2)."""
    rows = []
    for key, group in means.groupby(keys, sort=True):
        res = paired_comparison(group[f"err_{a}"], group[f"err_{b}"])
        rows.append({**dict(zip(keys, key, strict=True)), "n": res.n,
                     **{f"err_{m}": float(group[f"err_{m}"].mean()) for m in models},
                     **{name: getattr(res, name) for name in BREAKDOWN_STATS}})
    return pd.DataFrame(rows)


def by_arm_table(answer_sets: dict[str, pd.DataFrame]) -> pd.DataFrame:
    """Per world, arm (pooled first) and set of answers (e.g. primary, family): n participants,
    n trials, mean errors and the paired Ours-vs-VAE comparison with its verdict."""
    parts = [breakdown(participant_means(rows, models=PAIR), ["world"], models=PAIR)
             .assign(arm=labels["arm"], answers=labels["answers"],
                     n_trials=rows["trial_id"].nunique())
             for labels, rows in answer_subsets(answer_sets)]
    table = pd.concat(parts, ignore_index=True)
    first = ["world", "arm", "answers", "n", "n_trials"]
    return with_verdicts(table[first + [c for c in table.columns if c not in first]])


def holm(p_values) -> list[float]:
    """Holm-Bonferroni adjusted p-values, in the input order (a NaN p counts as 1)."""
    from statsmodels.stats.multitest import multipletests

    p = np.nan_to_num(np.asarray(p_values, dtype=np.float64), nan=1.0)
    return multipletests(p, method="holm")[1].tolist() if len(p) else []


def plain_records(table: pd.DataFrame) -> list[dict]:
    """A table's rows as dicts of plain values, NaN as None (for JSON)."""
    return table.astype(object).where(table.notna(), None).to_dict("records")


def mean_ci95(values: np.ndarray) -> tuple[float, float, float]:
    """Mean and the t-based 95% confidence interval of the mean."""
    values = np.asarray(values, dtype=np.float64)
    mean = float(np.mean(values))
    if len(values) < 2:
        return mean, float("nan"), float("nan")
    ci = stats.ttest_1samp(values, 0.0).confidence_interval(confidence_level=0.95)
    return mean, float(ci.low), float(ci.high)


def prediction_ids(frame: pd.DataFrame) -> np.ndarray:
    """An integer id per prediction (participant, trial, start state); rows of one id are
    contiguous and in step order, as `analysis.load.normalise` sorts them."""
    keys = frame[PREDICTION_KEYS]
    changed = (keys != keys.shift()).any(axis=1).to_numpy()
    return np.cumsum(changed) - 1


def _first_rows(ids: np.ndarray) -> np.ndarray:
    return np.r_[True, ids[1:] != ids[:-1]]


def _last_rows(ids: np.ndarray) -> np.ndarray:
    return np.r_[ids[1:] != ids[:-1], True]


def _cumsum_within(values: np.ndarray, ids: np.ndarray) -> np.ndarray:
    """Running sum that restarts at each new id (ids contiguous)."""
    total = np.cumsum(values)
    starts = np.flatnonzero(_first_rows(ids))
    before = np.r_[0.0, total[starts[1:] - 1]]
    return total - np.repeat(before, np.diff(np.r_[starts, len(values)]))


def infer_dt_s(frame: pd.DataFrame, ids: np.ndarray | None = None) -> pd.Series:
    """Per world, the step dt [s] implied by clicks and human actions (median of |dp| / |v|)."""
    ids = prediction_ids(frame) if ids is None else ids
    first = _first_rows(ids)
    click_x = frame["participant_click_x"].to_numpy()
    click_y = frame["participant_click_y"].to_numpy()
    prev_x = np.where(first, frame["start_x"].to_numpy(), np.r_[np.nan, click_x[:-1]])
    prev_y = np.where(first, frame["start_y"].to_numpy(), np.r_[np.nan, click_y[:-1]])
    moved = np.hypot(click_x - prev_x, click_y - prev_y)
    speed = np.hypot(frame["participant_vx"].to_numpy(), frame["participant_vy"].to_numpy())
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = pd.Series(np.where(speed > 0, moved / speed, np.nan), index=frame.index)
    return ratio.groupby(frame["world"]).median().rename("dt_s")


def displacement_errors(frame: pd.DataFrame,
                        models: tuple[str, ...] = POSITION_MODELS) -> pd.DataFrame:
    """Per participant x world, ADE and FDE [m] of each model's rolled-out steps vs the clicks.

    Model positions are the start state plus dt times the running sum of the model's
    actions; dt per world comes from `infer_dt_s`. Rows must be sorted by step.
    """
    ids = prediction_ids(frame)
    dt = frame["world"].map(infer_dt_s(frame, ids)).to_numpy()
    last = _last_rows(ids)
    out = frame[UNIT_KEYS].copy()
    click_x = frame["participant_click_x"].to_numpy()
    click_y = frame["participant_click_y"].to_numpy()
    for model in models:
        px = frame["start_x"].to_numpy() + dt * _cumsum_within(frame[f"{model}_vx"].to_numpy(), ids)
        py = frame["start_y"].to_numpy() + dt * _cumsum_within(frame[f"{model}_vy"].to_numpy(), ids)
        dist = np.hypot(px - click_x, py - click_y)
        out[f"ade_{model}"] = dist
        out[f"fde_{model}"] = np.where(last, dist, np.nan)
    return out.groupby(UNIT_KEYS, sort=True).mean().reset_index()
