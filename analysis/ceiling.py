"""How well people predict each other: the human noise ceiling beside every predictor.

Per world, trial, start state and step, each participant's predicted move is scored with
the study's alignment error against the other participants' mean direction (the mean of their
unit vectors; leave-one-out): the ceiling's **lower** bound, what a predictor that knew
everyone else's answers would reach. Against everyone's mean, the participant's own move
included, it is the **upper** bound (Nili et al. 2014, PLoS Comput Biol 10:e1003553; a
predictor's mean error below the lower bound would be better than people agree). Per
participant the mean over their cells, then the world's mean with a 95% CI.

Split-half reliability: the participants split at random into two halves, each cell's two
mean unit vectors, their components' correlation across the world's (or a trial's) cells,
Spearman-Brown corrected to the full sample, averaged over SPLITS random splits. A predictor's
share of the explainable alignment is (1 - its error) / (1 - the lower bound): 1 - error is
its agreement above chance (a random direction scores 1); it is left undefined where people
do not agree above chance. The upper bound counts each participant in the mean they are
scored against, so with few participants per cell it lies far below the lower one.
"""

import numpy as np
import pandas as pd

from analysis.stats import mean_ci95
from app.core.alignment import alignment_error

CELL = ["world", "trial_id", "start_index", "step"]
SPLITS = 50


def unit_moves(rows: pd.DataFrame) -> np.ndarray:
    """Participants' predicted moves [N, 2] as unit vectors (0 where a move has no length)."""
    moves = rows[["participant_vx", "participant_vy"]].to_numpy(np.float64)
    norm = np.hypot(moves[:, 0], moves[:, 1])[:, None]
    return np.divide(moves, norm, out=np.zeros_like(moves), where=norm > 0)


def cell_errors(rows: pd.DataFrame) -> pd.DataFrame:
    """Each row's leave-one-out (lower) and all-participants (upper) ceiling error, for cells
    that at least two participants answered."""
    units = unit_moves(rows)
    frame = rows[["participant_id", *CELL]].assign(ux=units[:, 0], uy=units[:, 1])
    grouped = frame.groupby(CELL, sort=False)
    totals = grouped[["ux", "uy"]].transform("sum").to_numpy()
    counts = grouped["ux"].transform("size").to_numpy()
    shared = counts >= 2
    others = totals - units
    return frame.loc[shared, ["participant_id", "world", "trial_id"]].assign(
        lower=alignment_error(units[shared], others[shared]),
        upper=alignment_error(units[shared], totals[shared]))


def ceiling_table(rows: pd.DataFrame) -> pd.DataFrame:
    """Per world: the lower and upper bound (mean over participants, 95% CI), participants,
    and the split-half reliability (Spearman-Brown)."""
    errors = cell_errors(rows)
    out = []
    for world, part in errors.groupby("world", sort=True):
        people = part.groupby("participant_id")[["lower", "upper"]].mean()
        lower, low_lo, low_hi = mean_ci95(people["lower"].to_numpy())
        upper, _, _ = mean_ci95(people["upper"].to_numpy())
        out.append({"world": world, "n_participants": len(people), "lower": lower,
                    "lower_ci95_low": low_lo, "lower_ci95_high": low_hi, "upper": upper,
                    "split_half_r": split_half(rows[rows["world"] == world])})
    return pd.DataFrame(out)


def split_half(rows: pd.DataFrame, splits: int = SPLITS, seed: int = 0) -> float:
    """Spearman-Brown corrected split-half correlation of the cells' mean directions."""
    people = np.array(sorted(rows["participant_id"].unique()))
    if len(people) < 4:
        return float("nan")
    rng = np.random.default_rng(seed)
    units = pd.DataFrame(unit_moves(rows), columns=["ux", "uy"], index=rows.index)
    keyed = rows[CELL].join(units)
    values = []
    for _ in range(splits):
        half = set(rng.permutation(people)[: len(people) // 2])
        mine = rows["participant_id"].isin(half)
        a = keyed[mine].groupby(CELL)[["ux", "uy"]].mean()
        b = keyed[~mine].groupby(CELL)[["ux", "uy"]].mean()
        both = a.add_suffix("_a").join(b.add_suffix("_b"), how="inner")
        if len(both) < 2:
            continue
        r = np.corrcoef(both[["ux_a", "uy_a"]].to_numpy().ravel(),
                        both[["ux_b", "uy_b"]].to_numpy().ravel())[0, 1]
        values.append(2 * r / (1 + r))
    return float(np.mean(values)) if values else float("nan")


def explainable_share(error: float, lower: float, lower_ci95_high: float) -> float:
    """A predictor's agreement above chance as a share of the ceiling's; NaN where people do
    not agree above chance (the lower bound's CI reaches 1): there is nothing to explain."""
    return (1 - error) / (1 - lower) if lower_ci95_high < 1 else float("nan")
